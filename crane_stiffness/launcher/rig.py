"""The simulated rig as separate node processes, started the way ``ros2 launch`` starts them, and the run's summary.

Used by ``make demo`` (scripts/demo.py), the tests and the benchmarks. Every node is started the way ``ros2 run``
starts it (crane_stiffness.launcher.rosrun) with what the launch file gives it
(crane_stiffness.launcher.rig_description:
parameter files from the install tree's config/ directory, parameters, remappings), all at the same instant: there
is no start order to keep, load_program waits until the rig is ready (crane_stiffness.nodes.load_program).
"""
from __future__ import annotations

import json
import re
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import Float64, Float64MultiArray, String

from crane_stiffness import __version__

from crane_stiffness.contract import topics
from crane_stiffness.contract.status import NAMES as LEVEL_NAMES, read_level
from crane_stiffness.params.geometry import geometry_from_params
from crane_stiffness.params.files import load_params
from crane_stiffness.analysis.sweep import unit
from crane_stiffness.model import (axis_stiffness, directional_stiffness, paper_stiffness, rest_pose,
                                   tangent_stiffness)
from crane_stiffness.rosnode.qos import KEPT_QOS, LATCHED_QOS
from crane_stiffness.rosnode.sim_time import SIM_QOS, drain
from crane_stiffness.bag import BagReader
from crane_stiffness.bag.session_metadata import cut_short, read_session_end
from crane_stiffness.launcher.domains import claim_domain, with_claim
from crane_stiffness.launcher.rig_description import PACKAGE, NodeStart, rig_nodes
from crane_stiffness.launcher.rig_description import config_files as rig_config_files
from crane_stiffness.sim.program import LoadProgram, load_program_file
from crane_stiffness.launcher.rosrun import Processes, RigInterrupted, RigStartError, RosRunError

#: A program whose progress has not moved for this long [s of wall time], past its own length plus a minute, has
#: stopped: the session fails.
PROGRESS_STALL_S = 60.0

if TYPE_CHECKING:
    from rclpy.executors import SingleThreadedExecutor


#: How long one spin of a rig host's executor lasts at most [s of wall time] (Observer.spin_once).
TICK_S = 0.05


class Observer(Node):
    """Watches the rig: program progress and state, the estimator's numbers, the model's prediction."""

    _executor: SingleThreadedExecutor | None  # created by the first spin_once

    def __init__(self, name: str = 'rig_observer', executor: Any = None, **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        # An executor given (a rig host's, which spins the rig's nodes too) is used and left running at the end; else
        # the observer makes its own at the first spin.
        self._executor = executor
        self._own_executor = executor is None
        self._tick = Future()
        if executor is not None:
            self.create_timer(TICK_S, self._on_tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
            executor.add_node(self)
        self.progress = 0.0
        self.state: dict = {}
        #: Called with each new operator instruction of the program state (``prompt.text``), once each.
        self.on_prompt: Callable[[str], None] | None = None
        self._last_prompt: str | None = None
        self.values: Float64MultiArray | None = None
        self.values_count = 0
        self.predicted: float | None = None
        self.running_at: float | None = None  # time.monotonic() when the state first said 'running'
        self.predicted_at: float | None = None  # ... when the model's prediction first arrived
        self.create_subscription(Float64, topics.PROGRAM_PROGRESS, self._on_progress, LATCHED_QOS)
        self.create_subscription(String, topics.PROGRAM_STATE, self._on_state, LATCHED_QOS)
        self.create_subscription(Float64MultiArray, topics.STIFFNESS_VALUES, self._on_values, KEPT_QOS)
        self.create_subscription(Float64, topics.PREDICTED_AXIS_STIFFNESS, self._on_predicted, LATCHED_QOS)
        #: The estimator's latest statuses: {'loading' | 'unloading' | 'input': (level name, message)}.
        self.statuses: dict[str, tuple[str, str]] = {}
        self.create_subscription(DiagnosticArray, topics.STIFFNESS_ESTIMATE, self._on_estimate, KEPT_QOS)
        #: Simulated time (sim_clock's watermarks): where the run ends, and through when every node has published.
        self.sim_end_ns: int | None = None
        self.sim_done_ns = -1
        self.create_subscription(String, topics.SIM_WATERMARKS, self._on_marks, SIM_QOS)
        #: The six-axis fit (stiffness6_estimator), when the rig runs it: the last K data and the last status.
        self.stiffness6: Any = None
        self.status6: tuple[str, str, dict[str, str]] | None = None
        self.create_subscription(Float64MultiArray, topics.STIFFNESS6, self._on_stiffness6, KEPT_QOS)
        self.create_subscription(DiagnosticArray, topics.STIFFNESS6_STATUS, self._on_status6, KEPT_QOS)
        #: Asked between spins: True stops the run (RigInterrupted), e.g. Ctrl-C in a campaign's main thread.
        self.should_stop: Callable[[], bool] | None = None

    def _on_marks(self, msg: String) -> None:
        marks = json.loads(msg.data)
        self.sim_end_ns = marks.get('end')
        self.sim_done_ns = int(marks.get('done', -1))

    @property
    def sim_ended(self) -> bool:
        """Simulated time reached the run's end and every node has published through it."""
        return self.sim_end_ns is not None and self.sim_done_ns >= self.sim_end_ns

    def settle(self, procs: Processes | None = None, wall_s: float = 1.5) -> None:
        """After the program: on simulated time until every node has published through the run's end (then the
        estimator's last outputs, 0.3 s), else ``wall_s`` for the last samples to reach the estimator."""
        if self.sim_end_ns is not None:
            self.spin_until(lambda: self.sim_ended, 60.0, 'every node to reach the end of simulated time', procs)
            wall_s = 0.3
        end = time.monotonic() + wall_s
        while time.monotonic() < end:
            self.spin_once(0.05)

    def _on_tick(self) -> None:
        if not self._tick.done():
            self._tick.set_result(None)

    def drain(self) -> None:
        """Handle every message already queued on the observer's subscriptions, without waiting and without the
        executor: what the nodes published before they went (a rig host delivers within the process at once) is
        all seen, however busy the machine was while :meth:`settle` spun."""
        for subscription in self.subscriptions:
            drain(subscription, subscription.callback)

    def _on_progress(self, msg: Float64) -> None:
        self.progress = msg.data

    def _on_state(self, msg: String) -> None:
        self.state = json.loads(msg.data)
        text = (self.state.get('prompt') or {}).get('text') if self.state.get('state') == 'waiting' else None
        if text and text != self._last_prompt and self.on_prompt is not None:
            self.on_prompt(text)
        self._last_prompt = text or self._last_prompt
        # (paused or done: the program did start; DDS matched this observer after it had, which on simulated time
        # flat out can be after the whole program)
        if self.running_at is None and self.state.get('state') in ('running', 'paused', 'done'):
            self.running_at = time.monotonic()

    def _on_values(self, msg: Float64MultiArray) -> None:
        self.values = msg
        self.values_count += 1

    def _on_estimate(self, msg: DiagnosticArray) -> None:
        for st in msg.status:  # a part that has not begun reads WAITING (published as OK, 'waiting: ...')
            level = read_level(st.level[0], st.message)
            self.statuses[st.name.rpartition(': ')[2]] = (LEVEL_NAMES.get(level, str(level)), st.message)

    def _on_stiffness6(self, msg: Float64MultiArray) -> None:
        self.stiffness6 = list(msg.data)

    def _on_status6(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            level = read_level(st.level[0], st.message)
            self.status6 = (LEVEL_NAMES.get(level, str(level)), st.message, {kv.key: kv.value for kv in st.values})

    def _on_predicted(self, msg: Float64) -> None:
        self.predicted = msg.data
        if self.predicted_at is None:
            self.predicted_at = time.monotonic()

    @property
    def done(self) -> bool:
        return self.state.get('state') == 'done'

    def spin_once(self, timeout_sec: float = 0.05) -> None:
        """One spin in the node's own context (the default one or a test's); RigInterrupted if asked to stop."""
        if self.should_stop is not None and self.should_stop():
            raise RigInterrupted('the run was interrupted')
        executor = getattr(self, '_executor', None)
        if executor is None:
            from rclpy.executors import SingleThreadedExecutor
            executor = self._executor = SingleThreadedExecutor(context=self.context)
            executor.add_node(self)
        if self._own_executor:
            executor.spin_once(timeout_sec=timeout_sec)
        else:
            # A rig host's executor, which runs every node of the rig: what comes until the next tick (TICK_S) handled
            # in one call (spin_once takes one callback per call: tens of thousands of calls a session). The tick's
            # timer ends the call: the executor's own timeout is only looked at when no event is waiting, which on
            # simulated time flat out is never before the program's end.
            self._tick = Future()
            executor.spin_until_future_complete(self._tick, timeout_sec=timeout_sec)

    def spin_until(self, predicate, timeout_s: float, what: str, procs: Processes | None = None,
                   error: type[RosRunError] = RosRunError) -> None:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                raise error(f'timed out after {timeout_s:.0f} s waiting for {what}')
            if procs is not None:
                procs.check_alive(allow_exit=('load_program',))  # it ends with its program (exit_on_done)
            self.spin_once(0.05)

    def destroy_node(self) -> None:
        executor = getattr(self, '_executor', None)
        if executor is not None:
            executor.remove_node(self)
            if self._own_executor:
                executor.shutdown()
            self._executor = None
        super().destroy_node()


def ros_args(node: NodeStart, overrides: Mapping[str, Any] | None = None) -> list[str]:
    """The ROS arguments that give ``node`` what the launch file gives it, ``overrides`` set on top (``-p``)."""
    args = ['--ros-args', *(a for f in node.parameter_files for a in ('--params-file', str(f)))]
    for name, value in {**node.parameters, **(overrides or {})}.items():
        if isinstance(value, bool):
            text = 'true' if value else 'false'
        elif isinstance(value, (list, tuple)):
            text = json.dumps([str(v) if isinstance(v, Path) else v for v in value])  # a YAML flow sequence
        else:
            text = str(value)
        args += ['-p', f'{name}:={text}']
    return args + [a for old, new in node.remappings for a in ('-r', f'{old}:={new}')]


def start_node(procs: Processes, node: NodeStart, overrides: Mapping[str, Any] | None = None) -> None:
    """Start ``node`` as ``ros2 run`` would, with :func:`ros_args`."""
    procs.start(node.name, PACKAGE, node.executable, ros_args(node, overrides))


def config_files(share: Path, program: str) -> dict[str, Path]:
    """The rig's parameter files for ``program``; RigError names a missing one (as the launch file does)."""
    return {role: Path(path) for role, path in rig_config_files(share, {'program': program}).items()}


def start_rig(procs: Processes, share: Path, program: str, session: str, bags: Path, record: bool = True,
              ready_timeout_s: float = 60.0, overrides: Mapping[str, Mapping[str, Any]] | None = None,
              arguments: Mapping[str, str] | None = None, live_view: bool = False) -> LoadProgram:
    """Start every node of the rig at the same instant, as ``ros2 launch crane_stiffness rig.launch.py`` does:
    load_program waits until the rig is ready (at most ``ready_timeout_s``) and exits when the program is done.
    ``overrides``: extra parameters by node name; ``arguments``: other launch arguments (transport, sim_sensors,
    drivers, ...); ``live_view``: start the live view too. Returns the program."""
    prog = load_program_file(config_files(share, program)['program'])
    nodes = rig_nodes(share, {**(arguments or {}), 'program': program, 'record': record, 'session': session,
                              'live_view': live_view})
    start_nodes(procs, nodes, bags if record else None, ready_timeout_s, overrides)
    return prog


def start_nodes(procs: Processes, nodes: Sequence[NodeStart], bags: Path | None, ready_timeout_s: float,
                overrides: Mapping[str, Mapping[str, Any]] | None = None, start_program: bool = True) -> None:
    """Start ``nodes`` (of rig_nodes) at the same instant, the recorder writing to ``bags`` (made if missing; None:
    its own default), load_program exiting when the program is done and waiting at most ``ready_timeout_s`` for
    the rig. ``overrides``: extra parameters by node name. ``start_program`` False leaves load_program out."""
    if bags is not None:
        bags.mkdir(parents=True, exist_ok=True)
    for node in nodes:
        if node.runs_program and not start_program:
            continue
        start_node(procs, node, start_overrides(node, bags, ready_timeout_s, (overrides or {}).get(node.name)))


def start_overrides(node: NodeStart, bags: Path | None, ready_timeout_s: float,
                    extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The parameters a run of the rig sets on ``node`` beyond the launch file's: the recorder writes to ``bags``
    (None: its own default), load_program exits when the program is done and waits at most ``ready_timeout_s`` for
    the rig; ``extra`` on top."""
    own: dict[str, Any] = {'output_dir': bags} if node.name == 'session_recorder' and bags is not None else {}
    if node.runs_program:
        own = {'exit_on_done': True, 'ready_timeout_s': ready_timeout_s}
    return {**own, **(extra or {})}


def wait_for_program_start(observer: Observer, procs: Processes, timeout_s: float) -> None:
    """Spin ``observer`` until load_program reports 'running'; RosRunError with its log if it exits first,
    RigStartError after ``timeout_s``."""
    def started() -> bool:
        program = procs.procs.get('load_program')
        if observer.running_at is None and program is not None and program.poll() is not None:
            if program.returncode == 0 and re.search(r"program '[^']*' finished", procs.log('load_program')):
                observer.running_at = time.monotonic()  # it ran to its end before DDS matched the observer
                return True
            raise RosRunError(f'load_program exited with status {program.returncode} before starting the program:\n'
                              f'{procs.log("load_program")[-3000:]}')
        return observer.running_at is not None
    try:
        observer.spin_until(started, timeout_s, 'the program to start', procs=None, error=RigStartError)
    except RigStartError as exc:
        log = procs.log('sim_clock') if 'sim_clock' in procs.procs else ''
        waiting = re.findall(r'waiting for [^\n]* to join', log)
        raise RigStartError(f'{exc}' + (f' (sim_clock: {waiting[-1]})' if waiting else '')) from None


def estimate_fields() -> tuple[str, ...]:
    from crane_stiffness.nodes.stiffness_estimator import VALUE_FIELDS
    return tuple(VALUE_FIELDS)


def decode_values(msg: Float64MultiArray | Sequence[float]) -> dict[str, dict[str, float]]:
    """The estimator's Float64MultiArray (or its data) as {branch: {field: value}}."""
    fields = estimate_fields()
    data = np.asarray(getattr(msg, 'data', msg), dtype=float).reshape(2, len(fields))
    return {branch: dict(zip(fields, row.tolist())) for branch, row in zip(('loading', 'unloading'), data)}


def summarize(share: Path, program: str, session: str, bags: Path, observer: Observer,
              exit_codes: dict[str, int]) -> dict[str, Any]:
    """The run's summary: geometry, program, estimate with interval, prediction, relative error, files."""
    cfg = config_files(share, program)
    g = geometry_from_params(load_params(cfg['crane']))
    prog = load_program_file(cfg['program'])
    axis = prog.segments[-1].axis
    if observer.values is None:
        raise RosRunError('the estimator published no estimate')
    est = decode_values(observer.values)
    predicted = axis_stiffness(tangent_stiffness(g, rest_pose(g)), axis)
    eq18 = directional_stiffness(paper_stiffness(g), unit(axis))
    loading = est['loading']['stiffness']
    force_unit, stiffness_unit = ('N', 'N/m') if axis.startswith('f') else ('N·m', 'N·m/rad')
    bag = bags / session
    levels = prog.levels(axis)
    return {
        'software_version': __version__,
        'geometry': {**g.to_dict(), 'l0': g.l0, 'k': g.k},
        'program': {'name': prog.name, 'axis': axis, 'unit': force_unit, 'peak': float(np.abs(levels).max()),
                    'levels': levels.tolist(), 'duration_s': prog.duration_s, 'file': str(cfg['program'])},
        'estimate': est,
        'status': {part: {'level': level, 'message': message} for part, (level, message) in observer.statuses.items()},
        'unit': stiffness_unit,
        'prediction': {'stiffness': predicted, 'eq18': eq18, 'unit': stiffness_unit, 'from_node': observer.predicted,
                       'what': f'exact tangent of the nonlinear model at the rest pose under W, along {axis} with '
                               'the other DOFs free (eq. 18 at the loaded rest: K_j (eq. 19) for fy, K_3 for fz, '
                               'K_5 for mz)'},
        'relative_error': (loading - predicted) / predicted,
        'estimates_received': observer.values_count,
        'bag': str(bag) if bag.exists() else None,
        'recording': recording_check(bag),
        'node_exit_codes': exit_codes,
    }


def recording_check(bag: Path) -> dict[str, Any] | None:
    """What the session record's end says of a recorded bag (``None``: nothing recorded): why the recording stopped,
    and ``problem``: '' when the bag holds the whole run, else why not (crane_stiffness.bag.session_metadata.cut_short:
    stopped from outside, cut, incomplete). The demo and the campaign read it: a bag that is not the whole run is
    never kept as if it were."""
    if not bag.exists():
        return None
    with BagReader(bag) as reader:
        end = read_session_end(reader)
    return {'stop_reason': end.get('stop_reason'), 'complete': end.get('complete'), 'problem': cut_short(end)}


class ProgramWatch:
    """When to give up waiting for a program of ``duration_s``: once it is ``margin_s`` [s of wall time] past its
    length and its progress (0 .. 1) has not moved for ``stall_s``. On simulated time a busy machine slows the rig
    down (half real time at load 10): that must not fail the session, so the wait goes on as long as the program
    keeps advancing."""

    def __init__(self, duration_s: float, margin_s: float = 60.0, stall_s: float = PROGRESS_STALL_S) -> None:
        now = time.monotonic()
        self.deadline = now + duration_s + margin_s
        self.stall_s = stall_s
        self.seen: float | None = None
        self.seen_at = now

    def expired(self, progress: float, holding: bool = False) -> bool:
        """Give up now? ``progress``: the program's latest reported progress; ``holding``: the program says it waits
        for someone (an operator applying a level, a tare), which is no stall however long it takes."""
        now = time.monotonic()
        if progress != self.seen or holding:
            self.seen, self.seen_at = progress, now
        return now >= self.deadline and now - self.seen_at >= self.stall_s

    def reason(self) -> str:
        """Where the program stopped, for the error."""
        return f'its progress stayed at {self.seen or 0.0:.3f} for {time.monotonic() - self.seen_at:.0f} s'


def wait_for_program_end(procs: Processes, observer: Observer, duration_s: float,
                         progress: Callable[[float], None] | None = None, margin_s: float = 60.0,
                         stall_s: float = PROGRESS_STALL_S) -> None:
    """Spin ``observer`` until load_program has exited with status 0; RosRunError when it failed, another node
    died, or :class:`ProgramWatch` gives up on it."""
    watch = ProgramWatch(duration_s, margin_s, stall_s)
    while procs.procs['load_program'].poll() is None and not watch.expired(
            observer.progress, observer.state.get('state') in ('waiting', 'taring')):
        procs.check_alive(allow_exit=('load_program',))
        observer.spin_once(0.1)
        if progress is not None:
            progress(observer.progress)
    if procs.procs['load_program'].poll() != 0:
        stalled = f' ({watch.reason()})' if procs.procs['load_program'].poll() is None else ''
        raise RosRunError(f'load_program did not finish{stalled}: {procs.log("load_program")[-3000:]}')


def run_rig(share: Path, env: Mapping[str, str], out: Path, program: str, session: str = 'rig', record: bool = True,
            ready_timeout_s: float = 120.0, overrides: Mapping[str, Mapping[str, Any]] | None = None,
            executables: Path | None = None, bags: Path | None = None,
            progress: Callable[[float], None] | None = None, arguments: Mapping[str, str] | None = None,
            domain_id: int | None = None, should_stop: Callable[[], bool] | None = None,
            prompt: Callable[[str], None] | None = None) -> tuple[dict[str, Any], Observer, float, dict[str, str]]:
    """Every node of the rig started at once (:func:`start_rig`) in a DDS context of its own, the program played to
    its end: (summary, observer, launch-to-program-start [s], each node's log). Logs in ``out/logs``, bags in
    ``bags`` (default ``out/bags``). ``executables``: see :class:`~crane_stiffness.launcher.rosrun.Processes`;
    ``progress`` is called with the program's progress (0 .. 1) as it is reported. ``domain_id``: the ROS domain of
    the nodes and the observer (default: ROS_DOMAIN_ID of ``env``); ``should_stop``: asked between spins, True stops
    the nodes and raises RigInterrupted; ``prompt``: called with each new instruction load_program waits on (the
    operator's level: its state's ``prompt``)."""
    import rclpy
    bags = out / 'bags' if bags is None else bags
    # The domain claimed host-wide for the run (crane_stiffness.launcher.domains): one in use is passed over.
    claim = claim_domain(int(env.get('ROS_DOMAIN_ID', 0) or 0) if domain_id is None else domain_id,
                         f'rig {session}', env=env)
    env = with_claim(env, claim.domain)
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx, domain_id=claim.domain)  # not sys.argv: a NAME:=VALUE there warns
    # (rigs side by side in one process: one observer each, named apart, as rcl's logging keys its publisher by name)
    observer = Observer(f'rig_observer_{domain_id}' if domain_id is not None else 'rig_observer', context=ctx)
    observer.should_stop = should_stop
    observer.on_prompt = prompt
    try:
        with Processes(env, out / 'logs', executables=executables) as procs:
            launched = time.monotonic()
            prog = start_rig(procs, share, program, session, bags, record=record,
                             ready_timeout_s=ready_timeout_s, overrides=overrides, arguments=arguments)
            wait_for_program_start(observer, procs, ready_timeout_s + 30)
            assert observer.running_at is not None  # set when the program started
            started_after = observer.running_at - launched
            wait_for_program_end(procs, observer, prog.duration_s, progress)
            observer.settle()  # the last samples reach the estimator
            codes = procs.stop()
            observer.drain()  # what reached this process before the nodes went
            logs = {name: procs.log(name) for name in procs.procs}
        summary = summarize(share, program, session, bags, observer, codes)
        summary['ros_domain_id'] = claim.domain
    finally:
        observer.destroy_node()
        rclpy.shutdown(context=ctx)
        claim.release()
    return summary, observer, started_after, logs
