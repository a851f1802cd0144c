"""A node's part in simulated time (crane_stiffness.sim.lockstep): follow the stage's watermark, report progress.

A node of the simulated rig that runs with ``use_sim_time`` creates a :class:`SimTimeParticipant` with its stage.
The participant subscribes the clock source's watermarks (topics.SIM_WATERMARKS) and calls ``on_watermark(t_ns)``
each time its stage's watermark moves on and every input message the stages below published up to it has been
handled: each participant counts what it publishes (:meth:`counted`) and reports the counts with its progress, the
clock sums them per stage, and a node waits (taking what is queued, ``drain``) until it has handled as many messages
of each input topic (:meth:`received`). Nothing depends on the order in which the executor hands over messages or
on how fast DDS delivers them. The node calls :meth:`report` once it has published its own outputs up to some time.
On close, :meth:`leave` tells the clock not to wait for this node any more. Messages are std_msgs/String holding
JSON (topics.SIM_PROGRESS: name, stage, t [ns], sent {topic: count}; topics.SIM_WATERMARKS: t [ns] per stage, sent
per stage {topic: count}).

Without ``use_sim_time`` nothing of this exists (:attr:`active` is False) and the node keeps wall-clock time.
"""
from __future__ import annotations

import json
import time
from typing import Any, Callable, Sequence

from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from crane_stiffness.contract import topics
from crane_stiffness.sim.lockstep import LEFT_NS

#: The progress and watermark topics: reliable, deep enough for a reader starved of CPU for a while, and transient
#: local: DDS matches the two directions between two nodes separately, often seconds apart, so a node's report that
#: it joined (sent once, on the first watermark it hears) can go out before the clock's reader is matched to it; a
#: volatile writer would drop it for that reader and time would wait for the node forever (seen in about 1 session in
#: 20 on a loaded machine). Kept by the writer, it reaches the reader when they match.
SIM_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: While a watermark waits for input messages the stages below published, the node says which this often (wall
#: time, ERROR in its log) [s]. It keeps waiting: simulated time holds rather than a reading being guessed.
WAIT_REPORT_S = 5.0
#: How long a watermark waits for messages of a *soft* input (an output the stages below count but publish with a
#: history of depth 1, e.g. a latched status: one replaced before it was delivered never comes) [s of wall time];
#: then the node takes them as lost, says so, and goes on.
SOFT_WAIT_S = 10.0
_STEADY = Clock(clock_type=ClockType.STEADY_TIME)


def uses_sim_time(node: Node) -> bool:
    """Whether ``node`` runs on simulated time (its ``use_sim_time`` parameter)."""
    return bool(node.get_parameter('use_sim_time').value)


def take_queued(subscription) -> tuple[Any, Any] | None:
    """The next (message, message info) already queued on ``subscription`` (what the executor would take next), or
    None. Draining with it before acting on a watermark makes the order of callbacks irrelevant."""
    with subscription.handle:
        return subscription.handle.take_message(subscription.msg_type, subscription.raw)


def drain(subscription, handle: Callable[[Any], Any], limit: int = 100_000) -> None:
    """Hand every message queued on ``subscription`` to ``handle`` (at most ``limit``)."""
    n = 0
    while n < limit:
        taken = take_queued(subscription)
        if taken is None:
            break
        handle(taken[0])
        n += 1


class SimTimeParticipant:
    """This node's part in simulated time (see the module docstring).

    Args:
        node: The node (its ``use_sim_time`` parameter decides whether anything happens).
        stage: 0 the load program, 1 the crane model, 2 the sensors, 3 the consumers (estimator, recorder).
        on_watermark: Called with the stage's new watermark [ns], once every input message the stages below have
            published up to it has been handled (``drain`` takes what is queued).
        drain: Takes every input already queued (see :func:`drain`); None: nothing to take.
        inputs: Topics this node reads from the stages below: their messages are counted (:meth:`received`) and
            a watermark waits until as many have arrived as the stages below published (:meth:`counted`).
        soft: Of ``inputs``, those published with a history of depth 1 (latched outputs: a status, a fit, the
            prediction): a message replaced before it was delivered never comes, so a watermark waits for them at
            most :data:`SOFT_WAIT_S`, then takes them as lost (said in the log) rather than hold time for ever.
    """

    def __init__(self, node: Node, stage: int, on_watermark: Callable[[int], None],
                 drain: Callable[[], None] | None = None, inputs: Sequence[str] = (),
                 soft: Sequence[str] = ()) -> None:
        self.node = node
        self.stage = stage
        self.active = uses_sim_time(node)
        self.watermark_ns = -1
        self.reported_ns = -1
        self.inputs = [node.resolve_topic_name(t) for t in inputs]
        self.soft = {node.resolve_topic_name(t) for t in soft}
        self.sent: dict[str, int] = {}       # messages published per topic since the first report
        self.got: dict[str, int] = {t: 0 for t in self.inputs}  # messages handled per input topic
        self.left = False
        self._counting = False
        self._pending: tuple[int, dict[str, int]] | None = None
        self._pending_sent: dict[str, int] = {}
        self._pending_since = 0.0
        self._said_at = 0.0
        self._resolved: dict[str, str] = {}
        self._end_ns: int | None = None  # where the run ends, once this node said so (repeated in every report)
        #: Where the clock says the run ends [ns] (the load program fixed it), once a watermark said so; else None.
        self.end_ns: int | None = None
        #: What the stages below had published, per topic, through the last watermark acted on (every topic they
        #: count, not only this node's inputs): the rig's own publish counters, e.g. for the recorder's session end.
        self.published: dict[str, int] = {}
        self._on_watermark = on_watermark
        self._drain = drain
        self._name = node.get_fully_qualified_name().lstrip('/')
        self._pub: Publisher | None = None
        self._timer: Any = None  # a wall-clock timer re-trying a watermark whose inputs are still in flight
        if self.active:
            self._pub = node.create_publisher(String, topics.SIM_PROGRESS, SIM_QOS)
            node.create_subscription(String, topics.SIM_WATERMARKS, self._on_marks, SIM_QOS)

    # --- counting ---
    def counted(self, pub: Publisher) -> Publisher:
        """``pub`` with its messages counted (from the first report on): the stages above wait for them."""
        if not self.active:
            return pub
        publish, topic = pub.publish, pub.topic_name

        def counting(msg: Any) -> None:
            publish(msg)
            if self._counting:
                self.sent[topic] = self.sent.get(topic, 0) + 1
        pub.publish = counting  # type: ignore[method-assign]
        return pub

    def received(self, topic: str, n: int = 1) -> None:
        """``n`` messages of input ``topic`` (its name in the code; resolved here, remappings included) handled."""
        if not self.active:
            return
        resolved = self._resolved.get(topic)
        if resolved is None:
            resolved = self._resolved[topic] = self.node.resolve_topic_name(topic)
        if resolved in self.got:
            self.got[resolved] += n

    # --- watermarks ---
    def _on_marks(self, msg: String) -> None:
        if self.left:
            return
        marks = json.loads(msg.data)
        mark = int(marks['t'][self.stage])
        if mark < self.watermark_ns or (mark == self.watermark_ns and self.reported_ns >= 0):
            return  # nothing new (a mark repeated for nodes that join late)
        sent = marks['sent'][self.stage]
        if marks.get('end') is not None:
            self.end_ns = int(marks['end'])
        if self._pending is None or self._pending[0] != mark:
            self._pending_since = time.monotonic()  # a repeated mark does not restart the wait
        self._pending = (mark, {t: int(sent.get(t, 0)) for t in self.inputs})
        self._pending_sent = {t: int(n) for t, n in sent.items()}
        self._try()

    def _try(self) -> None:
        """Act on the pending watermark once every input message up to it is in."""
        if self._pending is None:
            return
        if self._drain is not None:
            self._drain()
        mark, expected = self._pending
        short = {t: n - self.got[t] for t, n in expected.items() if self.got[t] < n}
        now = time.monotonic()
        if short and set(short) <= self.soft and now - self._pending_since >= SOFT_WAIT_S:
            self.node.get_logger().error(
                f'simulated time {mark * 1e-9:.3f} s: {", ".join(f"{n} message(s) on {t}" for t, n in short.items())} '
                f'never came in {SOFT_WAIT_S:g} s (replaced in their publisher\'s history before delivery?): taken '
                'as lost')
            for t, n in short.items():
                self.got[t] += n
            short = {}
        if short:
            if now - self._pending_since >= WAIT_REPORT_S and now - self._said_at >= WAIT_REPORT_S:
                self._said_at = now
                self.node.get_logger().error(
                    f'simulated time held at {mark * 1e-9:.3f} s for {now - self._pending_since:.0f} s: still '
                    f'missing {", ".join(f"{n} message(s) on {t}" for t, n in short.items())} that the rig\'s '
                    'nodes published (a reader that never matched?)')
            if self._timer is None:
                self._timer = self.node.create_timer(0.002, self._try, clock=_STEADY)
            else:
                self._timer.reset()
            return
        if self._timer is not None:
            self._timer.cancel()
        self._pending = None
        self.published = self._pending_sent
        self.watermark_ns = max(self.watermark_ns, mark)
        self._counting = True  # from time's start on: what was sent before (to readers not yet matched) is not
        self._on_watermark(mark)

    def report(self, progress_ns: int, *, end_ns: int | None = None) -> None:
        """Everything this node publishes up to ``progress_ns`` is out (counted): say so to the clock. ``end_ns``:
        simulated time is to stop there (the load program, when it will end the run)."""
        if self._pub is None or self.left or (progress_ns <= self.reported_ns and end_ns is None):
            return
        self._counting = True
        self.reported_ns = max(self.reported_ns, progress_ns)
        self._publish(self.reported_ns, end_ns)

    def leave(self) -> None:
        """This node ends (or stops taking part): the clock waits for it no more."""
        if self._pub is not None and not self.left and self.node.context.ok():
            self.left = True
            self._publish(LEFT_NS)
            self._pub.wait_for_all_acked(Duration(seconds=1.0))  # the process may end right after

    def _publish(self, progress_ns: int, end_ns: int | None = None) -> None:
        assert self._pub is not None
        if end_ns is not None:
            self._end_ns = end_ns
        report: dict[str, Any] = {'name': self._name, 'stage': self.stage, 't': progress_ns, 'sent': self.sent}
        if self._end_ns is not None:
            report['end'] = self._end_ns
        self._pub.publish(String(data=json.dumps(report)))


class PeriodicOutput:
    """A node's periodic output (a status, a fit): a timer of ``period_s`` on the wall clock; on simulated time
    (``sim_time``) called from the node's watermark handler instead, by :meth:`at_watermark`, each time simulated time
    passes a multiple of the period: after every input up to that time has been handled, so each output holds the
    same data in every run; :meth:`now_ns` is the time those outputs are made at. (A timer on simulated time fires
    when /clock moves, before or after the watermark's inputs are handled as the executor happens to order them: the
    same instant's status then counted 100 samples more in one run than in another.)"""

    def __init__(self, node: Node, period_s: float, callback: Callable[[], None], sim_time: bool) -> None:
        self._node, self._callback, self._sim_time = node, callback, sim_time
        self._timer: Any = None
        self._period_ns = 0
        self._slot: int | None = None  # the last multiple of the period an output went out for (simulated time)
        self._mark_ns: int | None = None  # simulated time: the last watermark whose inputs were all handled [ns]
        self.set_period(period_s)

    def now_ns(self) -> int:
        """The node's time for its outputs [ns]: on simulated time the last watermark passed to :meth:`at_watermark`
        (every input up to it handled), the same in every run; the node clock would read wherever /clock had got to
        when the callback ran. The node clock on the wall clock, and before the first watermark."""
        if self._sim_time and self._mark_ns is not None:
            return self._mark_ns
        return self._node.get_clock().now().nanoseconds

    def set_period(self, period_s: float) -> None:
        """A new period [s] (> 0)."""
        self._period_ns = max(1, round(period_s * 1e9))
        if self._sim_time:
            return
        if self._timer is not None:
            self._node.destroy_timer(self._timer)
        self._timer = self._node.create_timer(period_s, self._callback)

    def at_watermark(self, t_ns: int) -> None:
        """Simulated time: every input up to ``t_ns`` has been handled; the output goes out if a multiple of the
        period was reached since the last one. The first watermark (the node joining, before time starts, while
        DDS may still be matching what it reads: what it has then differs from run to run) sends none."""
        if not self._sim_time:
            return
        self._mark_ns = t_ns
        slot = t_ns // self._period_ns
        if self._slot is not None and slot > self._slot:
            self._callback()
        if self._slot is None or slot > self._slot:
            self._slot = slot
