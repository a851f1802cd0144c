"""What the simulated sensor nodes share: the sample schedule on the clock grid (a DAQ buffer per timer tick), the
common sensor parameters, and the zero epoch they latch on a re-zero or tare."""
from __future__ import annotations

import time
from typing import Any, Callable, Mapping

from rclpy.node import Node
from std_msgs.msg import Float64

from crane_stiffness.rosnode.parameters import check, positive
from crane_stiffness.rosnode.qos import LATCHED_QOS
from crane_stiffness.rosnode.sim_time import uses_sim_time
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.sim.sampling import ReleaseGate, SampleClock, StampedHold


#: The longest a simulated sensor waits on wall-clock time for the input in force at a sample instant (see
#: crane_stiffness.sim.sampling.ReleaseGate); on simulated time it never needs to.
STATE_WAIT_PARAM = ParamSpec('state_wait_s', 0.0, 'on wall-clock time, the longest a sample waits for the '
                             "model's state at its instant before the state held is taken as in force; 0 = no "
                             'wait. Updates that arrive after samples at their stamps went out are counted '
                             '(late_state_updates on /diagnostics; WARN when this is > 0). Unused on simulated time, '
                             'where the clock waits instead [s]', low=0.0, high=10.0)


def sensor_timing_params(frame_id: str, frame_doc: str) -> tuple[ParamSpec, ...]:
    """The parameters every simulated sensor has, in this order: ``sample_rate_hz``, ``publish_rate_hz`` (the
    :class:`SampleSchedule`) and ``frame_id`` (default ``frame_id``, described by ``frame_doc``); see
    :func:`check_sensor_params`."""
    return (
        ParamSpec('sample_rate_hz', 1000.0, 'sample rate; stamps are 1/sample_rate_hz apart on a grid of the node '
                  'clock [Hz]', above=0.0),
        ParamSpec('publish_rate_hz', 500.0, 'rate of the timer that publishes the samples taken since its last tick '
                  '(a DAQ buffer); its ticks fall on multiples of its period of the node clock, so sensors at the same '
                  'rate deliver together. Higher: lower latency, more CPU [Hz]', above=0.0),
        ParamSpec('frame_id', frame_id, frame_doc),
    )


#: Longest a node waits at start (or on a rate change) to put its timer on the clock grid [s].
MAX_ALIGN_WAIT_S = 0.05
#: A grid timer whose calls fall further than this from the grid is made again, at most ALIGN_ATTEMPTS times [ns].
ALIGN_TOLERANCE_NS = 500_000
ALIGN_ATTEMPTS = 5


def create_grid_timer(node: Node, period_s: float, callback: Callable[[], None]):
    """A timer of ``period_s`` whose calls fall on multiples of the period on the node clock.

    Two sensor nodes publishing buffers at the same rate then deliver them at the same instants, like two channels
    of one DAQ sharing a sample clock: the newest force and displacement samples reach a consumer together, so a
    pair never waits up to a whole buffer for its partner. rcl timers keep their phase (the next call is the
    previous due time plus the period), so aligning the start is enough. The start waits for the next grid instant
    (sleeping, then spinning the last 0.3 ms for precision) when that is at most ``MAX_ALIGN_WAIT_S`` away; longer
    periods and simulated time (no wall-clock grid to share) start at once.
    """
    period_ns = max(1, round(period_s * 1e9))
    clock = node.get_clock()
    if period_s > MAX_ALIGN_WAIT_S or getattr(clock, 'ros_time_is_active', False):
        return node.create_timer(period_ns * 1e-9, callback)
    for _ in range(ALIGN_ATTEMPTS):
        now = clock.now().nanoseconds
        start = (now // period_ns + 1) * period_ns
        if start - now > 300_000:
            time.sleep((start - now - 300_000) * 1e-9)
        while clock.now().nanoseconds < start:
            pass
        timer = node.create_timer(period_ns * 1e-9, callback)
        # The process may be preempted between the grid instant and the timer's creation (a loaded machine): the
        # timer then keeps that lag for good. Check where its calls fall, and start again if off the grid.
        if grid_phase_ns(timer, clock, period_ns) <= ALIGN_TOLERANCE_NS:
            return timer
        node.destroy_timer(timer)
    return node.create_timer(period_ns * 1e-9, callback)  # best effort (never seen: the machine is starved)


def grid_phase_ns(timer: Any, clock: Any, period_ns: int) -> int:
    """How far the timer's next call falls from the nearest multiple of ``period_ns`` on ``clock`` [ns]."""
    due = clock.now().nanoseconds + int(timer.time_until_next_call() or 0)
    off = due % period_ns
    return min(off, period_ns - off)


def check_sensor_params(values: Mapping[str, Any]) -> int | None:
    """The parameters every simulated sensor has: ``sample_rate_hz``, ``publish_rate_hz``, ``frame_id``, ``seed``.
    Raises ValueError naming a bad one; returns the noise seed (None = random)."""
    positive(values, 'sample_rate_hz', 'publish_rate_hz')
    check(isinstance(values['frame_id'], str) and values['frame_id'] != '', 'frame_id', values['frame_id'],
          'must be a non-empty string')
    check(values['seed'] >= -1, 'seed', values['seed'], 'must be -1 (random) or a seed >= 0')
    SampleClock(values['sample_rate_hz'])  # raises for a rate it cannot represent
    return None if values['seed'] < 0 else values['seed']


class SampleSchedule:
    """A simulated sensor's timing: the sample clock (``sample_rate_hz``; stamps on its grid) and the grid timer
    (``publish_rate_hz``) whose ``tick`` publishes the samples due (:meth:`due`).

    :meth:`configure` runs on start and on every parameter change: it re-creates only what changed, and a new
    sample rate continues after the last instant already handed out.
    """

    def __init__(self, node: Node, tick: Callable[[], None]) -> None:
        self._node = node
        self._tick = tick
        self._rates: tuple[float, float] | None = None
        self.clock: SampleClock | None = None
        self.timer = None
        #: On simulated time the stage's watermark drives the sampling (:meth:`due_until`), not a timer.
        self.sim_time = uses_sim_time(node)
        self.gate = ReleaseGate(0)

    def configure(self, sample_rate_hz: float, publish_rate_hz: float) -> None:
        previous = self._rates or (None, None)
        if self.clock is None or sample_rate_hz != previous[0]:
            self.clock = SampleClock(sample_rate_hz, start_after_ns=None if self.clock is None else self.clock.last_ns)
        if self.sim_time:
            pass
        elif self.timer is None or publish_rate_hz != previous[1]:
            if self.timer is not None:
                self._node.destroy_timer(self.timer)
            self.timer = create_grid_timer(self._node, 1.0 / publish_rate_hz, self._tick)
        self._rates = (sample_rate_hz, publish_rate_hz)

    def due(self):
        """The sample instants since the previous call (int64 ns, ascending; see SampleClock.due)."""
        return self.clock.due(self._node.get_clock().now().nanoseconds)

    def arrival_ns(self, stamp_ns: int) -> int:
        """The node clock's now for an input stamped ``stamp_ns`` (StampedHold.update's ``now_ns``). On simulated
        time the watermarks, not the node's clock (updated by /clock on its own schedule), say what is known: a
        stamp is never "in the future" there."""
        now = self._node.get_clock().now().nanoseconds
        return max(now, stamp_ns) if self.sim_time else now

    def due_until(self, t_ns: int):
        """Simulated time: the sample instants since the previous call up to ``t_ns`` (the stage's watermark)."""
        assert self.clock is not None
        return self.clock.due(t_ns)

    def released(self, hold: StampedHold):
        """Wall-clock time: the instants due now, held back until ``hold`` knows the input at them or
        ``state_wait_s`` has passed (:class:`~crane_stiffness.sim.sampling.ReleaseGate`)."""
        now = self._node.get_clock().now().nanoseconds
        assert self.clock is not None  # configured on start
        self.gate.add(self.clock.due(now))
        return self.gate.release(hold.known_through_ns, now)


class ZeroEpoch:
    """The latched zero epoch of a sensor (topics.LVDT_ZERO, topics.LOAD_CELL_TARE): std_msgs/Float64, the number of
    zero/tare operations since the node started [-]. Published at once (0) and again by :meth:`step` after every
    zero or tare, so the estimator starts a new fit segment when a re-zero steps the readings.
    ``publish=False``: nothing at once (a sensor that zeroes itself before its first reading publishes epoch 1 then,
    so the estimator never sees 0 -> 1 race its first readings)."""

    def __init__(self, node: Node, topic: str, count: int = 0, *, publish: bool = True) -> None:
        self._msg_type = Float64
        self.count = count
        self.pub = node.create_publisher(Float64, topic, LATCHED_QOS)
        if publish:
            self._publish()

    def _publish(self) -> None:
        self.pub.publish(self._msg_type(data=float(self.count)))

    def step(self, by: int = 1) -> int:
        """``by`` more zeros/tares (0: publish the current epoch): publish the epoch; returns it."""
        self.count += by
        self._publish()
        return self.count
