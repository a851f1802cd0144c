"""Reading other nodes' parameters over ROS (their list_parameters / get_parameters services), without blocking: the
session recorder stores what the rig's nodes ran with."""
from __future__ import annotations

import array
from typing import Any, Callable, Sequence

from rcl_interfaces.srv import GetParameters, ListParameters
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python


def plain(value: Any) -> Any:
    """JSON-friendly copy of a parameter value (rclpy returns array.array for numeric arrays)."""
    if isinstance(value, (array.array, tuple, list)):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    return value


class NodeParameterReader:
    """Reads every parameter of each of ``nodes`` (names, e.g. '/crane_model'; empty entries skipped) once its
    services are up: :meth:`poll` advances the reads (list the names, then get the values) without waiting, and
    calls ``on_values(node name without the leading '/', {parameter: plain value})`` once per node read."""

    def __init__(self, node: Node, nodes: Sequence[str], on_values: Callable[[str, dict[str, Any]], None]) -> None:
        self._node = node
        self._on_values = on_values
        self._queries: dict[str, dict[str, Any]] = {}
        for name in nodes:
            if not name:
                continue
            target = '/' + name.strip('/')
            self._queries[target] = {
                'list': node.create_client(ListParameters, f'{target}/list_parameters'),
                'get': node.create_client(GetParameters, f'{target}/get_parameters'),
                'future': None, 'names': None}

    @property
    def pending(self) -> list[str]:
        """The nodes not read yet."""
        return list(self._queries)

    def poll(self) -> None:
        """Advance the reads: list the names once the node's service is up, then get the values."""
        for target, q in list(self._queries.items()):
            if target not in self._queries:  # closed by an on_values call of this poll
                continue
            future = q['future']
            if future is None:
                if q['list'].service_is_ready():
                    request = ListParameters.Request(depth=ListParameters.Request.DEPTH_RECURSIVE)
                    q['future'] = q['list'].call_async(request)
                continue
            if not future.done():
                continue
            result = future.result()
            if result is None:
                q['future'] = None  # failed: ask again
                continue
            if q['names'] is None:
                q['names'] = sorted(result.result.names)
                q['future'] = q['get'].call_async(GetParameters.Request(names=q['names']))
                continue
            values = {n: plain(parameter_value_to_python(v)) for n, v in zip(q['names'], result.values)}
            self._close(target)
            self._on_values(target.lstrip('/'), values)

    def _close(self, target: str) -> None:
        q = self._queries.pop(target)
        for key in ('list', 'get'):
            self._node.destroy_client(q[key])

    def close(self) -> None:
        """Stop the reads not finished (their clients destroyed)."""
        for target in list(self._queries):
            self._close(target)


__all__ = ['NodeParameterReader', 'plain']
