"""ProbeNode: the test node the probes of the node tests build on. A probe publishes a node's inputs and records what
the node publishes, under the topic prefix of one test (helpers.isolated)."""
from __future__ import annotations

from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node

from crane_stiffness.contract import topics


class ProbeNode:
    """A test node (``.node``) for the topics under ``prefix``: records topics into lists (:meth:`record`), makes
    publishers (:meth:`publisher`) and, given ``diagnostics_depth``, records /diagnostics (``.diagnostics``, every
    DiagnosticStatus in the order received) and looks a node's newest status up there (:meth:`status`,
    :meth:`diag`). Named ``probe<prefix>`` unless ``name`` is given."""

    def __init__(self, ctx, prefix: str = '', *, name: str | None = None, diagnostics_depth: int | None = None):
        self.node = Node(name or f'probe{prefix.replace("/", "_")}', context=ctx)
        self.prefix = prefix
        self.diagnostics: list = []
        if diagnostics_depth is not None:
            self.node.create_subscription(DiagnosticArray, prefix + topics.DIAGNOSTICS,
                                          lambda m: self.diagnostics.extend(m.status), diagnostics_depth)

    def record(self, topic: str, msg_type, qos, transform: Callable[[Any], Any] | None = None) -> list:
        """Subscribe to ``prefix + topic``; returns the list every message received (``transform(message)`` if
        given) is appended to."""
        received: list = []
        callback = received.append if transform is None else lambda m: received.append(transform(m))
        self.node.create_subscription(msg_type, self.prefix + topic, callback, qos)
        return received

    def publisher(self, topic: str, msg_type, qos):
        """A publisher of ``msg_type`` on ``prefix + topic``."""
        return self.node.create_publisher(msg_type, self.prefix + topic, qos)

    def status(self, hardware_id: str, level: bytes | None = None):
        """The newest diagnostic status of a node (at ``level`` if given), as (status, {key: value}) or None."""
        for s in reversed(self.diagnostics):
            if s.hardware_id == hardware_id and (level is None or s.level == level):
                return s, {kv.key: kv.value for kv in s.values}
        return None

    def diag(self, hardware_id: str) -> dict | None:
        """The newest diagnostic status of a node as {'message': ..., key: value, ...}, or None."""
        newest = self.status(hardware_id)
        return None if newest is None else {'message': newest[0].message, **newest[1]}
