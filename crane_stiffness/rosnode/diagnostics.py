"""What a node reports on /diagnostics: its message counters, the publisher of its status, and how late its inputs
arrive (InputLag)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from crane_stiffness.contract import topics
from crane_stiffness.rosnode.messages import stamp_to_s


@dataclass
class Counters:
    """Message counters a node reports on /diagnostics."""

    received: int = 0
    dropped_non_finite: int = 0
    dropped_absurd: int = 0
    published: int = 0

    def as_pairs(self) -> list[tuple[str, str]]:
        return [(k, str(v)) for k, v in self.__dict__.items()]


@dataclass
class SensorCounters(Counters):
    """``received`` = ``used`` + ``dropped_non_finite`` (input messages); ``published`` = samples published;
    ``waiting_samples``: sample instants that passed before there was an input to measure (none published)."""

    used: int = 0
    waiting_samples: int = 0


class Diagnostics:
    """Publishes a DiagnosticStatus for the node on /diagnostics at a fixed rate, from a callback."""

    def __init__(self, node: Node, report: Callable[[], tuple[int, str, list[tuple[str, str]]]],
                 period_s: float = 1.0) -> None:
        self._node = node
        self._report = report
        self._pub = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self._timer = node.create_timer(period_s, self.publish)

    def publish(self) -> None:
        if not self._node.context.ok():
            return  # shutting down (Ctrl-C / SIGTERM): nothing to report to
        level, message, pairs = self._report()
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.status.append(DiagnosticStatus(level=bytes([level]), name=self._node.get_fully_qualified_name(),
                                           message=message, hardware_id=self._node.get_name(),
                                           values=[KeyValue(key=k, value=v) for k, v in pairs]))
        self._pub.publish(msg)



class InputLag:
    """How late a device emulator's physics (the applied wrench, the platform pose) reached it after its stamp, on
    the node clock [s].

    An emulator serves the newest physics its executor has delivered; when the machine is starved the executor falls
    behind and the device serves stale physics that a driver stamps as current (once, in a lab run at load ~10, the
    LVDT lagged the pose by 3.5 s and the estimate came out +50 %). That must not be silent: :meth:`status` reports
    the worst lag since the previous report and WARNs above the node's ``max_input_lag_s``.
    """

    def __init__(self) -> None:
        self.period_max_s = 0.0   # worst lag since the last report [s]
        self.max_s = 0.0          # worst lag of the run [s]
        self.late = 0             # messages later than the limit [-]

    def add(self, stamp: Time, now_s: float, limit_s: float) -> None:
        """A physics message stamped ``stamp`` arrived at ``now_s`` (node clock, s); a zero stamp is not judged."""
        t = stamp_to_s(stamp)
        if t <= 0.0:
            return
        lag = now_s - t
        self.period_max_s = max(self.period_max_s, lag)
        self.max_s = max(self.max_s, lag)
        if lag > limit_s:
            self.late += 1

    def status(self, what: str, limit_s: float) -> tuple[str, list[tuple[str, str]]]:
        """(a WARN reason or '', key/values) for the period since the last call, which starts a new period."""
        worst, self.period_max_s = self.period_max_s, 0.0
        pairs = [('input_lag_max_ms', f'{worst * 1e3:.1f}'), ('input_lag_run_max_ms', f'{self.max_s * 1e3:.1f}'),
                 ('late_inputs', str(self.late))]
        if worst > limit_s:
            return (f'{what} reached this device up to {worst * 1e3:.0f} ms after its stamp (> max_input_lag_s '
                    f'{limit_s * 1e3:.0f} ms): the machine is starved and the device serves stale physics that the '
                    f'driver stamps as current'), pairs
        return '', pairs
