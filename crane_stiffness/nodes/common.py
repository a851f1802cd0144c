"""What every node shares: QoS profiles, a diagnostics publisher, message helpers, the sensors' sample schedule and
``run`` (the ``main`` of every node). Parameters (declared, described, validated on start and on change) are in
:mod:`crane_stiffness.nodes.parameters`.
"""
from __future__ import annotations

import json
import math
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Sequence

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from crane_stiffness import entry, topics
from crane_stiffness.serde import stamp_seconds
from crane_stiffness.nodes import parameters
from crane_stiffness.nodes.parameters import check, positive
from crane_stiffness.param_files import params_files_from_args
from crane_stiffness.sim.sampling import SampleClock


def rclpy_qos(qos: topics.QoS, depth: int | None = None) -> QoSProfile:
    """The rclpy profile of a QoS class of crane_stiffness.topics (KEEP_LAST; ``depth`` overrides the class's)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=qos.depth if depth is None else depth,
                      reliability=ReliabilityPolicy[qos.reliability.upper()],
                      durability=DurabilityPolicy[qos.durability.upper()])


#: The rig's three QoS classes (crane_stiffness.topics.TOPIC_QOS says which topic has which).
RELIABLE_QOS = rclpy_qos(topics.RELIABLE)
SENSOR_QOS = rclpy_qos(topics.SENSOR_DATA)
LATCHED_QOS = rclpy_qos(topics.LATCHED)


def stamp_to_s(stamp: Time) -> float:
    return stamp_seconds(stamp.sec, stamp.nanosec)


def finite(values: Iterable[float]) -> bool:
    return all(math.isfinite(v) for v in values)


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


#: Longest a node waits at start (or on a rate change) to put its timer on the clock grid [s].
MAX_ALIGN_WAIT_S = 0.05


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
    if period_s <= MAX_ALIGN_WAIT_S and not getattr(clock, 'ros_time_is_active', False):
        now = clock.now().nanoseconds
        start = (now // period_ns + 1) * period_ns
        if start - now > 300_000:
            time.sleep((start - now - 300_000) * 1e-9)
        while clock.now().nanoseconds < start:
            pass
    return node.create_timer(period_ns * 1e-9, callback)


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

    def configure(self, sample_rate_hz: float, publish_rate_hz: float) -> None:
        previous = self._rates or (None, None)
        if self.clock is None or sample_rate_hz != previous[0]:
            self.clock = SampleClock(sample_rate_hz, start_after_ns=None if self.clock is None else self.clock.last_ns)
        if self.timer is None or publish_rate_hz != previous[1]:
            if self.timer is not None:
                self._node.destroy_timer(self.timer)
            self.timer = create_grid_timer(self._node, 1.0 / publish_rate_hz, self._tick)
        self._rates = (sample_rate_hz, publish_rate_hz)

    def due(self):
        """The sample instants since the previous call (int64 ns, ascending; see SampleClock.due)."""
        return self.clock.due(self._node.get_clock().now().nanoseconds)


def make_executor(kind: str, context: Any):
    """'events': rclpy's EventsExecutor (in C++, about a quarter of the CPU per message of the standard one, which
    matters at 1 kHz on two cores); 'single': SingleThreadedExecutor."""
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except ImportError:  # an rclpy without it
            pass
    return SingleThreadedExecutor(context=context)


class ShutdownRequest:
    """SIGINT/SIGTERM as a flag the spin loop of :func:`run` reads.

    rclpy's own handlers raise KeyboardInterrupt wherever the main thread is, also inside a callback that the C++
    EventsExecutor called (pybind11 then aborts the process: ``terminate called after throwing ...
    error_already_set``), and shut the context down under callbacks that are still running (``Exception in 'timers'
    callback``). Here the Python handler only sets :attr:`signum`, and the signal's number, written by Python to a
    wake-up pipe whichever thread the kernel chose, is read by a thread of its own that also wakes the executor
    (``wake``): a main thread waiting in C++ sees the flag at once. A signal, once or repeated (Ctrl-C reaches every
    node and ``ros2 launch`` forwards it once more), ends the spin loop after the running callback; the node closes
    its files and exits with status 0. :meth:`ignore` keeps a late signal from killing the finished process.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.signum: int | None = None
        self.count = 0
        self.wake: Callable[[], None] | None = None

    def __bool__(self) -> bool:
        return self.signum is not None

    def handle(self, signum: int, frame: Any = None) -> None:
        self.count += 1
        if self.signum is None:
            self.signum = signum
        wake = self.wake
        if wake is not None:
            try:
                wake()
            except Exception:  # an executor already shut down: the flag is enough
                pass

    def install(self) -> bool:
        """Install the handlers and the wake-up thread (main thread only: Python runs signal handlers there);
        False if not possible."""
        if threading.current_thread() is not threading.main_thread():
            return False
        read_fd, write_fd = os.pipe()
        os.set_blocking(write_fd, False)
        # The pipe first, then the handlers: a signal in between still reaches the pipe.
        signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        for sig in self.SIGNALS:
            signal.signal(sig, lambda signum, frame: None)  # the flag is set by the thread; never an exception
        threading.Thread(target=self._wait, args=(read_fd,), name='shutdown_signals', daemon=True).start()
        for signum in entry.pending():  # arrived while the node's module was being imported
            self.handle(signum)
        return True

    def _wait(self, read_fd: int) -> None:
        while True:
            for signum in os.read(read_fd, 64):
                if signum in self.SIGNALS:
                    self.handle(signum)

    def ignore(self) -> None:
        """From now on SIGINT/SIGTERM do nothing: the process is ending, and Python's finalization would reset its
        handlers to the default (a signal then, e.g. launch forwarding Ctrl-C, would kill it with -2/-15)."""
        if threading.current_thread() is threading.main_thread():
            for sig in self.SIGNALS:
                signal.signal(sig, signal.SIG_IGN)


def run(node_factory: Callable[[], Node], args: Sequence[str] | None = None,
        executor: str | Callable[[Node], str] = 'events') -> int:
    """The ``main`` of every node: init, build, spin until SIGINT (Ctrl-C), SIGTERM or ``node.exit_requested``,
    clean up; returns the exit status (``node.exit_status``, default 0).

    Signals only set a flag (:class:`ShutdownRequest`; rclpy's handlers are not installed), so every exit takes
    the same path: the spin loop ends, ``close()`` (if the node has one) runs, the node's final counters are
    printed, the node is destroyed and rclpy shut down. A node that cannot start (bad parameter) exits with
    status 2 and the reason on stderr. It is a process's main: SIGINT and SIGTERM are ignored after it returns.
    """
    name = getattr(node_factory, '__name__', 'node')
    request = ShutdownRequest()
    request.install()
    argv = list(sys.argv if args is None else args)
    # A missing or malformed --params-file would make rclpy.init raise (RCLError): say which file and why.
    reason = next(filter(None, map(parameters.params_file_problem, params_files_from_args(argv))), None)
    if reason is None:
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except Exception as exc:  # e.g. a parameter file rcl reads differently
            reason = parameters.one_line(f'{type(exc).__name__}: {exc}')
    if reason is not None:
        print(f'[{name}] cannot start: {reason}', file=sys.stderr)
        return 2
    try:
        with parameters.started_with(argv):
            node = node_factory()
        try:  # a misspelt -p name would be ignored by rclpy: the node would run with the default
            parameters.check_command_line_params(argv, node.get_name(), set(node._parameters))
        except ValueError:
            node.destroy_node()
            raise
    except (ValueError, TypeError) as exc:
        print(f'[{name}] cannot start: {exc}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    except Exception as exc:  # e.g. rclpy's InvalidParameterTypeException from a params file
        print(f'[{name}] cannot start: {type(exc).__name__}: {exc}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    ex = make_executor(executor(node) if callable(executor) else executor, node.context)
    ex.add_node(node)
    request.wake = ex.wake
    try:
        while not request and rclpy.ok(context=node.context) and not getattr(node, 'exit_requested', False):
            ex.spin_once(timeout_sec=0.1)
    except ExternalShutdownException:
        pass
    finally:
        close = getattr(node, 'close', None)
        if close is not None:
            close()
        final_counters(node)
        ex.remove_node(node)
        ex.shutdown()
        request.wake = None
        node.destroy_node()
        rclpy.try_shutdown()
        request.ignore()
    return int(getattr(node, 'exit_status', 0) or 0)


def final_counters(node: Node) -> None:
    """Print the node's message counters once at exit (``FINAL_COUNTERS <node> {json}``): the totals a benchmark or
    an engineer reads after a run, when /diagnostics has stopped."""
    counters = getattr(node, 'counters', None)
    if counters is None:
        return
    values = counters.__dict__ if hasattr(counters, '__dict__') else counters
    try:
        text = json.dumps({k: v for k, v in dict(values).items() if isinstance(v, (int, float, str))})
    except (TypeError, ValueError):
        return
    print(f'FINAL_COUNTERS {node.get_name()} {text}', flush=True)


class ZeroEpoch:
    """The latched zero epoch of a sensor (topics.LVDT_ZERO, topics.LOAD_CELL_TARE): std_msgs/Float64, the number of
    zero/tare operations since the node started [-]. Published at once (0) and again by :meth:`step` after every
    zero or tare, so the estimator starts a new fit segment when a re-zero steps the readings.
    ``publish=False``: nothing at once (a sensor that zeroes itself before its first reading publishes epoch 1 then,
    so the estimator never sees 0 -> 1 race its first readings)."""

    def __init__(self, node: Node, topic: str, count: int = 0, *, publish: bool = True) -> None:
        from std_msgs.msg import Float64  # local: the other nodes of this module need no std_msgs
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
