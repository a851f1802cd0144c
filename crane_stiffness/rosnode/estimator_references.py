"""What the live stiffness estimator reads of the rig's other nodes to state U and E_n: the load cell's and the LVDT's
declared calibrations (their ``calibration.*``, ``full_scale`` and ``range_m`` parameters) and the crane model's
geometry (its ``geometry.*``, the crane file), over ROS as the session recorder reads them
(:class:`~crane_stiffness.rosnode.parameter_reader.NodeParameterReader`), at start and again when one of those nodes
reports a change of them on /parameter_events.

Of each kind the first node of its list that answers is the one read (``/load_cell`` or the driver ``/netft``; the
others' clients are closed then): a node absent from the rig costs a readiness check a second, nothing once every
kind is read.
"""
from __future__ import annotations

from typing import Any, Callable, Sequence

from rcl_interfaces.msg import ParameterEvent
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_parameter_events

from crane_stiffness.rosnode.parameter_reader import NodeParameterReader

#: The kinds read, and which of a node's parameters matter for each (a change of any other is ignored).
KINDS = ('load_cell', 'lvdt', 'model')
_RELEVANT: dict[str, Callable[[str], bool]] = {
    'load_cell': lambda name: name.startswith('calibration.') or name == 'full_scale',
    'lvdt': lambda name: name.startswith('calibration.') or name == 'range_m',
    'model': lambda name: name.startswith('geometry.'),
}
#: How often the reads are advanced while one is pending [s] (steady clock: also on simulated time).
POLL_PERIOD_S = 0.5


class EstimatorReferences:
    """Reads the nodes ``nodes[kind]`` (kinds :data:`KINDS`) and calls ``on_read(kind, node, values)`` with the
    relevant parameters of the first node of each kind read, at start and after each change."""

    def __init__(self, node: Node, nodes: dict[str, Sequence[str]],
                 on_read: Callable[[str, str, dict[str, Any]], None]) -> None:
        self._node = node
        self._nodes = {kind: ['/' + n.strip('/') for n in nodes.get(kind, ()) if n.strip('/')] for kind in KINDS}
        self._on_read = on_read
        self.read_from: dict[str, str] = {}  # kind -> the node read (without '/')
        self._readers: dict[str, NodeParameterReader] = {}
        for kind in KINDS:
            self._start(kind, self._nodes[kind])
        self._timer = node.create_timer(POLL_PERIOD_S, self._poll, clock=Clock(clock_type=ClockType.STEADY_TIME))
        node.create_subscription(ParameterEvent, '/parameter_events', self._on_event, qos_profile_parameter_events)

    @property
    def pending(self) -> list[str]:
        """The kinds not read yet."""
        return [kind for kind in KINDS if kind in self._readers]

    def _start(self, kind: str, names: Sequence[str]) -> None:
        if names and kind not in self._readers:
            self._readers[kind] = NodeParameterReader(self._node, names, lambda node, values: self._read(kind, node,
                                                                                                            values))

    def _poll(self) -> None:
        for reader in list(self._readers.values()):
            reader.poll()
        if not self._readers:
            self._timer.cancel()

    def _read(self, kind: str, node: str, values: dict[str, Any]) -> None:
        reader = self._readers.pop(kind, None)
        if reader is not None:
            reader.close()  # the other candidates of this kind: not read
        self.read_from[kind] = node
        self._on_read(kind, node, {k: v for k, v in values.items() if _RELEVANT[kind](k)})

    def _on_event(self, event: ParameterEvent) -> None:
        """A node read reports changed parameters: read it again if one of them matters."""
        node = event.node.lstrip('/')
        for kind, read in self.read_from.items():
            if node != read:
                continue
            changed = [p.name for p in list(event.new_parameters) + list(event.changed_parameters)]
            if any(_RELEVANT[kind](name) for name in changed):
                self._start(kind, ['/' + node])
                if self._timer.is_canceled():
                    self._timer.reset()

    def close(self) -> None:
        for reader in self._readers.values():
            reader.close()
        self._readers.clear()
        self._timer.cancel()


__all__ = ['KINDS', 'POLL_PERIOD_S', 'EstimatorReferences']
