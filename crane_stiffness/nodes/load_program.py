"""load_program: plays a test program (steps, ramps, holds; loading then unloading; repeats).

The program comes from ROS parameters (name, rate_hz, repeats, segments.kind/axis/target/duration), normally from
one of config/program_*.yaml. Publishes the commanded wrench on /crane/wrench_command (WrenchStamped, reliable,
frame crane_base), progress on /load_program/progress (Float64 in [0, 1]) and state on /load_program/state (String,
JSON). Services (std_srvs/Trigger): ~/start (start, resume after pause, or restart when finished), ~/pause (hold the
current wrench), ~/stop (abort: command zero). Times follow the node clock, so use_sim_time works.

An automatic start waits until the rig is ready, however it was started (``ros2 launch`` starts every node at the
same instant; ``ros2 run`` in any order): a message has arrived on each topic of ``wait_for_messages`` (by default
crane_model's latched prediction and both sensor streams), and each node named in ``wait_for_subscribers`` is
subscribed to its topic (by default crane_model, the simulated load cell, the estimator and the recorder to the
command; the commands are published only once DDS has matched those readers). While it waits it logs one line per
missing item every ``ready_log_period_s``; after ``ready_timeout_s`` it logs an error naming what never came and
exits with status 1. A user running part of the rig lists only what runs (the launch file does that for its
arguments, see crane_stiffness.launcher.rig_description).

**How the load reaches the crane** (``load_application``, crane_stiffness.sim.program.LOAD_APPLICATIONS): ``model``
and ``actuator`` publish the commands and nothing more (crane_model, or an actuator's driver subscribed to
/crane/wrench_command, applies them). ``operator`` (wall-clock time): where the command reaches a new level
(:func:`~crane_stiffness.sim.program.load_prompts`: a step's start, a ramp's end) the program holds (state
``waiting``, the instruction in the state's ``prompt``, and in the log) until the level is confirmed: a call of
~/confirm (std_srvs/Trigger; ``ros2 service call /load_program/confirm std_srvs/srv/Trigger``) or, with
``operator_settle_s`` > 0, the measured load (/load_cell/wrench, the level's axis) within ``operator_tolerance`` of it
for that long. Each confirmation (how, when, by whom) is kept in the state's ``confirmed``.

**Tare and zero at the unloaded state**: ``tare_services`` (std_srvs/Trigger, e.g. /netft/tare, /modbus_lvdt/zero)
are called in turn just before the program's first step, with nothing applied yet; their answers (the offsets the
sensors report), when and by whom go into the state's ``tare``, so the recorder keeps them (the bag's
/load_program/state and its session end record). A tare that fails stops the node with status 1 before any load.
"""
from __future__ import annotations

import json
import time
from functools import partial
from typing import Any, Callable

from geometry_msgs.msg import WrenchStamped
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from std_msgs.msg import Float64, String
from std_srvs.srv import Trigger

from crane_stiffness.contract import topics
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.rosnode.qos import LATCHED_QOS, RELIABLE_QOS, rclpy_qos, stream_qos
from crane_stiffness.rosnode.diagnostics import Counters, Diagnostics
from crane_stiffness.rosnode.load_application import LoadApplication
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.parameters import Params, check
from crane_stiffness.rosnode.sim_time import SimTimeParticipant, uses_sim_time
from crane_stiffness.launcher.rig_description import NODES as RIG_NODES
from crane_stiffness.launcher.rig_description import readiness
from crane_stiffness.sim.program import (AXIS_UNITS, LOAD_APPLICATION_PARAMS, PROGRAM_KEYS, PROGRAM_PARAMS,
                                        LoadProgram, LoadPrompt, ProgramState, Settling, load_prompts)
from crane_stiffness.contract.status import OK, WARN
from crane_stiffness.contract.publishers import awaited_from
from crane_stiffness.serde.stamps import split_ns

#: What the program waits for by default: the whole simulated rig with the recorder, as
#: crane_stiffness.launcher.rig_description
#: describes it (the launch file passes the lists for the nodes it starts): a message on the model's latched
#: prediction and on both sensor streams, and every node subscribed to the topics it reads.
_FULL_RIG = readiness(list(RIG_NODES))
DEFAULT_WAIT_FOR_MESSAGES = tuple(_FULL_RIG['wait_for_messages'])
DEFAULT_WAIT_FOR_SUBSCRIBERS = tuple(_FULL_RIG['wait_for_subscribers'])
#: exit_on_done: how long the node lingers after the program so the last commands and state reach every reader [s];
#: on simulated time the run ends there, the same instant in every run.
EXIT_LINGER_S = 1.0
#: Wall-clock time: the longest stretch of program ticks a late timer call catches up on [s] (older ones skipped).
MAX_CATCH_UP_S = 2.0
#: Longest exit_on_done waits for every reader to acknowledge the last commands and state [s].
EXIT_ACK_TIMEOUT_S = 5.0
#: How the log names the source of a topic waited for.
SOURCES = {topics.PREDICTED_AXIS_STIFFNESS: "crane_model's prediction", topics.LOAD_CELL_WRENCH: 'the load cell',
           topics.LVDT_DISPLACEMENT: 'the LVDT', topics.STIFFNESS_VALUES: 'the estimator, pairing both streams'}

PARAMS = (
    *PROGRAM_PARAMS,
    *LOAD_APPLICATION_PARAMS,
    ParamSpec('autostart', True, 'start the program by itself once the rig is ready (see wait_for_*), '
              'start_delay_s after that'),
    ParamSpec('start_delay_s', 0.5, 'wait between the rig being ready and an automatic start [s]', low=0.0,
              high=86400.0),
    ParamSpec('min_subscribers', 1, 'an automatic start also waits until /crane/wrench_command has this many '
              'subscribers in all, so no command is lost while DDS discovery runs [-]', low=0),
    ParamSpec('wait_for_messages', list(DEFAULT_WAIT_FOR_MESSAGES),
              'an automatic start waits for a message on each of these topics (default: the model\'s latched '
              'prediction and both sensor streams); empty entries are ignored, so [\'\'] waits for none'),
    ParamSpec('wait_for_subscribers', list(DEFAULT_WAIT_FOR_SUBSCRIBERS),
              "an automatic start waits until each listed node subscribes to the topic: entries "
              "'TOPIC: NODE [NODE ...]' (default: the whole rig with the recorder); empty entries are ignored"),
    ParamSpec('ready_timeout_s', 60.0, 'an automatic start gives up when the rig is not ready after this long: the '
              'node logs what never came and exits with status 1; 0 = wait forever [s]', low=0.0,
              high=86400.0),
    ParamSpec('ready_log_period_s', 5.0, 'while waiting for the rig, log what is still missing this often [s]'),
    ParamSpec('exit_on_done', False, 'shut the node down when the program has finished'),
)


def wanted_subscribers(entries: list[str]) -> list[tuple[str, str]]:
    """(topic, node) pairs of ``wait_for_subscribers`` entries 'TOPIC: NODE [NODE ...]' (empty entries skipped);
    ValueError names a malformed entry."""
    pairs = []
    for entry in entries:
        if not entry.strip():
            continue
        topic, sep, nodes = entry.partition(':')
        check(bool(sep and topic.strip() and nodes.split()), 'wait_for_subscribers', entry,
              "entries must read 'TOPIC: NODE [NODE ...]'")
        pairs += [(topic.strip(), node) for node in nodes.split()]
    return pairs


class _Readiness:
    """What an automatic start waits for: each item is (description, is it there now?). Messages are awaited with
    a subscription of the topic's contract QoS (crane_stiffness.contract.topics), dropped once a message has come."""

    def __init__(self, node: Node, messages: list[str], subscribers: list[tuple[str, str]],
                 min_subscribers: int, matched: Callable[[], int]) -> None:
        from crane_stiffness.rosnode.session_qos import message_class
        self.node = node
        self.items: list[tuple[str, Callable[[], bool]]] = []
        self._received: dict[str, bool] = {}
        self._subscriptions: dict[str, Subscription | None] = {}  # None: dropped once its message came
        for name in dict.fromkeys(m.strip() for m in messages if m.strip()):
            topic = node.resolve_topic_name(name)
            msg_type = topics.RIG_TOPICS.get(topic)  # a topic outside the contract: missing() finds its type
            self._received[topic] = False
            if msg_type is not None:
                self._subscribe(topic, message_class(msg_type))
            self.items.append((f'a message on {topic}{awaited_from(topic, [r for _, r in subscribers])}',
                               partial(self._received.__getitem__, topic)))
        self._pending_types = [t for t in self._received if t not in self._subscriptions]
        command_readers = set()
        for name, reader in subscribers:
            topic = node.resolve_topic_name(name)
            if topic == topics.WRENCH_COMMAND:
                command_readers.add(reader)
            self.items.append((f'{reader} subscribed to {topic}', partial(self._subscribed, topic, reader)))
        # The graph can show a reader before our publisher has matched it: count the matches of the command too.
        need = max(min_subscribers, len(command_readers))
        if need:
            self.items.append((f'{need} subscriber(s) matched to {topics.WRENCH_COMMAND}',
                               lambda: matched() >= need))

    def _subscribe(self, topic: str, msg_class) -> None:
        contract = topics.TOPIC_QOS.get(topic)
        qos = rclpy_qos(contract) if contract is not None else rclpy_qos(topics.SENSOR_DATA, depth=1)

        def received(_msg, t=topic):
            self._received[t] = True
        self._subscriptions[topic] = self.node.create_subscription(msg_class, topic, received, qos, raw=True)

    def _subscribed(self, topic: str, reader: str) -> bool:
        for info in self.node.get_subscriptions_info_by_topic(topic):
            full = f"{info.node_namespace.rstrip('/')}/{info.node_name}"
            if reader in (info.node_name, full):
                return True
        return False

    def missing(self) -> list[str]:
        """Descriptions of what is not there yet (and tidies up: a subscription whose message came is dropped)."""
        from crane_stiffness.rosnode.session_qos import message_class
        for topic in list(self._pending_types):
            types = {t for name, ts in self.node.get_topic_names_and_types() if name == topic for t in ts}
            if len(types) == 1:
                try:
                    msg_class = message_class(types.pop())
                except ValueError as exc:  # a type this machine does not have: the item stays missing
                    self.node.get_logger().warning(f'cannot wait for {topic}: {exc}', throttle_duration_sec=30.0)
                    continue
                self._subscribe(topic, msg_class)
                self._pending_types.remove(topic)
        for topic, sub in list(self._subscriptions.items()):
            if self._received[topic] and sub is not None:
                self.node.destroy_subscription(sub)
                self._subscriptions[topic] = None
        return [what for what, there in self.items if not there()]

    def close(self) -> None:
        for sub in self._subscriptions.values():
            if sub is not None:
                self.node.destroy_subscription(sub)
        self._subscriptions = {}


class LoadProgramNode(LoadApplication, Node):
    """Idle → running ⇄ paused → done (or stopped); the program itself is crane_stiffness.sim.program."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('load_program', **kwargs)
        # Simulated time: the stage-0 watermark (the clock) drives the program's ticks, each command stamped on the
        # grid k / rate_hz, and the program starts start_delay_s after the time starts: the same commands at the
        # same stamps in every run, whatever the machine's load (see _on_watermark).
        self.sim_time = uses_sim_time(self)
        self._ready = not self.sim_time  # simulated time: the readiness below was met
        self._start_at_ns: int | None = None
        self._last_tick_ns: int | None = None
        self._end_ns: int | None = None  # simulated time, exit_on_done: where the run ends
        self.state = 'idle'
        self.elapsed = 0.0        # program time reached when last paused [s]
        self.started_at: float | None = None    # node-clock time of (re)start [s]
        self.last: ProgramState | None = None
        self.program: LoadProgram | None = None  # set by _apply (Params, below): the methods assert it
        self.timer: Timer | None = None
        self.counters = Counters()  # published = commands published (FINAL_COUNTERS at exit)
        self.exit_status = 0
        self.pub_cmd = self.create_publisher(WrenchStamped, topics.WRENCH_COMMAND,
                                             stream_qos(RELIABLE_QOS, self.sim_time))
        self.pub_progress = self.create_publisher(Float64, topics.PROGRAM_PROGRESS, LATCHED_QOS)
        self.pub_state = self.create_publisher(String, topics.PROGRAM_STATE, LATCHED_QOS)
        self.params = Params(self, PARAMS, self._validate, self._apply)
        self.sim = SimTimeParticipant(self, 0, self._on_watermark)
        self.sim.counted(self.pub_cmd)
        self.sim.counted(self.pub_progress)  # (the recorder waits for them and logs them in their step)
        self.sim.counted(self.pub_state)
        self.create_service(Trigger, '~/start', self._srv_start)
        self.create_service(Trigger, '~/pause', self._srv_pause)
        self.create_service(Trigger, '~/stop', self._srv_stop)
        # load_application operator: the levels to be confirmed, the next one, the confirmations, the settle rule.
        assert self.program is not None  # (set by the Params above)
        self.prompts: list[LoadPrompt] = load_prompts(self.program) if self._operator_mode else []
        self.prompt_index = 0
        self.confirmations: list[dict[str, Any]] = []
        self._settling: Settling | None = None
        self.create_service(Trigger, '~/confirm', self._srv_confirm)
        if self._operator_mode and self.params['operator_settle_s'] > 0:
            self.create_subscription(WrenchStamped, topics.LOAD_CELL_WRENCH, self._on_measured,
                                     rclpy_qos(topics.SENSOR_DATA))
        # tare_services: called once, before the first start; their answers.
        self.tare: list[dict[str, Any]] = []
        self._tare_todo: list[str] | None = None  # None: not begun
        self._tare_timer: Timer | None = None
        self._tare_future: Any = None
        self._tare_client: Any = None
        self._tare_wait_started = 0.0
        self.diagnostics = Diagnostics(self, self._report)
        self._autostart: Timer | None = None
        self._exit_timer: Timer | None = None
        self._readiness: _Readiness | None = None
        self._wait_started: float = 0.0  # time.monotonic() [s], set with the readiness
        self._next_report: float = 0.0
        if self.params['autostart']:
            assert self.program is not None
            # On simulated time no message can come before time starts, and time starts only when every node of
            # the rig is there (sim_clock): the program waits for the readers of its commands alone.
            self._readiness = _Readiness(self, [] if self.sim_time else self.params['wait_for_messages'],
                                         wanted_subscribers(self.params['wait_for_subscribers']),
                                         self.params['min_subscribers'], self.pub_cmd.get_subscription_count)
            self._wait_started = time.monotonic()
            self._next_report = self._wait_started + self.params['ready_log_period_s']  # the line below says it all
            self._ready_at: float | None = None
            what = '; '.join(w for w, _ in self._readiness.items) or 'nothing'
            timeout = self.params['ready_timeout_s']
            self.get_logger().info(f'waiting for the rig before starting {self.program.name!r} '
                                   f'({f"at most {timeout:g} s" if timeout > 0 else "no time limit"}): {what}')
            self._autostart = self.create_timer(0.05, self._auto, clock=Clock(clock_type=ClockType.STEADY_TIME)
                                                if self.sim_time else None)
        else:
            self._ready = True

    # --- parameters ---
    def _validate(self, values: dict[str, Any]) -> LoadProgram:
        check(values['ready_log_period_s'] > 0, 'ready_log_period_s', values['ready_log_period_s'], 'must be > 0')
        check(not (self.sim_time and values['load_application'] == 'operator'), 'load_application', 'operator',
              'needs wall-clock time (use_sim_time false): a person applies the load')
        check(not (self.sim_time and any(str(v).strip() for v in values['tare_services'])), 'tare_services',
              list(values['tare_services']), 'needs wall-clock time (use_sim_time false): the simulated sensors '
              'start zeroed')
        if self.state not in ('idle',) and self.program is not None:
            for key in ('load_application', 'tare_services'):
                if values[key] != self.params[key]:
                    raise ValueError(f'{key} cannot change once the program has started')
        wanted_subscribers(values['wait_for_subscribers'])  # raises naming a malformed entry
        if self.state in ('running', 'paused') and self.program is not None:
            if any(values[k] != self.params[k] for k in PROGRAM_KEYS):
                raise ValueError('the program cannot change while it runs: call ~/stop first')
        return LoadProgram.from_params({k: values[k] for k in PROGRAM_KEYS})  # ValueError names the field

    def _apply(self, program: LoadProgram, values: dict[str, Any]) -> None:
        self.program = program
        if hasattr(self, 'prompts'):  # (a program set while idle: its own levels)
            self.prompts = load_prompts(program) if values['load_application'] == 'operator' else []
            self.prompt_index = 0
        if self.timer is not None:
            self.destroy_timer(self.timer)
        if not self.sim_time:
            self.timer = self.create_timer(1.0 / program.rate_hz, self._tick)
        self.get_logger().info(f'program {program.name!r}: {len(program.segments)} segments x {program.repeats}, '
                               f'{program.duration_s:.3g} s')

    # --- time and state ---
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _program_time(self, now_s: float | None = None) -> float:
        """Program time [s] at node-clock time ``now_s`` (default: now)."""
        if self.state == 'running':
            assert self.started_at is not None  # set by _start
            return self.elapsed + (self._now() if now_s is None else now_s) - self.started_at
        return self.elapsed

    def _auto(self) -> None:
        # The autostart timer's callback: __init__ set the readiness, the program and the timer.
        assert self._readiness is not None and self.program is not None and self._autostart is not None
        now = time.monotonic()
        if self._ready_at is None:
            missing = self._readiness.missing()
            waited = now - self._wait_started
            if not missing:
                self._ready_at = now
                self._readiness.close()
                if self.sim_time:  # the program starts start_delay_s of simulated time after time starts
                    self.destroy_timer(self._autostart)
                    self._autostart = None
                    self._ready = True
                    self.get_logger().info(f'rig ready; {self.program.name!r} starts '
                                           f'{self.params["start_delay_s"]:g} s after simulated time starts')
                    return
                self.get_logger().info(f'rig ready after {waited:.1f} s; starting {self.program.name!r} in '
                                       f'{self.params["start_delay_s"]:g} s')
            elif 0 < self.params['ready_timeout_s'] <= waited:
                self.destroy_timer(self._autostart)
                self._readiness.close()
                self.get_logger().error(f'gave up after {waited:.0f} s (ready_timeout_s): the program did not start; '
                                        f'never came: {"; ".join(missing)}')
                self.exit_status = 1
                self.exit_requested = True  # run.run ends the spin; main returns exit_status
                return
            else:
                if now >= self._next_report:
                    self._next_report = now + self.params['ready_log_period_s']
                    for what in missing:
                        self.get_logger().info(f'waiting ({waited:.0f} s) for {what}')
                return
        if now < self._ready_at + self.params['start_delay_s']:
            return
        self.destroy_timer(self._autostart)
        self._autostart = None
        if self.state == 'idle':
            self._begin()

    def _start(self, at_s: float | None = None) -> str:
        if self.state == 'running':
            return 'already running'
        if self.state in ('done', 'stopped', 'idle'):
            self.elapsed = 0.0
        assert self.program is not None
        self.started_at = self._now() if at_s is None else at_s
        self.state = 'running'
        self._publish_state()
        return f'running {self.program.name!r} from t = {self.elapsed:.3f} s'

    def _on_watermark(self, t_ns: int) -> None:
        """Simulated time reached ``t_ns``: play the program's ticks on the grid k / rate_hz up to it, then report."""
        if not self._ready:
            return  # not reporting holds simulated time at its start
        assert self.program is not None
        period = round(1e9 / self.program.rate_hz)
        if self._last_tick_ns is None:
            self._last_tick_ns = t_ns // period * period
            if self.params['autostart']:
                start = t_ns + round(self.params['start_delay_s'] * 1e9)
                self._start_at_ns = -(-start // period) * period
        tick = self._last_tick_ns + period
        while tick <= t_ns:
            if self.state == 'idle' and self._start_at_ns is not None and tick >= self._start_at_ns:
                self._start_at_ns = None
                self._start(at_s=tick * 1e-9)
                self.get_logger().info(f'started {self.program.name!r} at simulated time {tick * 1e-9:.3f} s')
                if self.params['exit_on_done']:  # the run's end, known now: simulated time stops there
                    self._end_ns = tick + -(-round(self.program.duration_s * 1e9) // period) * period \
                        + round(EXIT_LINGER_S * 1e9)
            self._emit(tick)
            tick += period
        self._last_tick_ns = tick - period
        self.sim.report(t_ns, end_ns=self._end_ns)
        if (self._end_ns is not None and t_ns >= self._end_ns and self.state == 'done'
                and not getattr(self, 'exit_requested', False)):
            self._exit()

    def _tick(self) -> None:
        """Wall-clock time: the program's ticks on the grid k / rate_hz since the last call, each its own command
        stamped on the grid (a busy machine delays them, it does not drop them: at most MAX_CATCH_UP_S of them)."""
        assert self.program is not None
        now = self.get_clock().now().nanoseconds
        period = round(1e9 / self.program.rate_hz)
        running = self.state in ('running', 'paused', 'waiting')
        if self._last_tick_ns is None or not running:
            self._last_tick_ns = now // period * period  # nothing to catch up while nothing plays
            if not running:
                return
        first = max(self._last_tick_ns + period, (now - round(MAX_CATCH_UP_S * 1e9)) // period * period)
        for tick in range(first, now // period * period + 1, period):
            self._emit(tick)
            self._last_tick_ns = tick

    def _emit(self, t_ns: int) -> None:
        """The program's command at node-clock time ``t_ns`` (while running, paused or waiting for the operator),
        stamped ``t_ns``."""
        if self.state not in ('running', 'paused', 'waiting'):
            return
        if self.state == 'running' and self.started_at is not None and t_ns * 1e-9 < self.started_at:
            return  # a tick before the (re)start: the program had not begun
        assert self.program is not None
        if (self.state == 'running' and self.prompt_index < len(self.prompts)
                and self._program_time(t_ns * 1e-9) >= self.prompts[self.prompt_index].time_s):
            self._wait_for_operator(self.prompts[self.prompt_index])
        st = self.program.wrench_at(self._program_time(t_ns * 1e-9))
        self.last = st
        cmd = WrenchStamped()
        cmd.header.stamp.sec, cmd.header.stamp.nanosec = split_ns(t_ns)
        cmd.header.frame_id = topics.FRAME_BASE
        w = [float(v) for v in st.wrench]
        cmd.wrench.force.x, cmd.wrench.force.y, cmd.wrench.force.z = w[:3]
        cmd.wrench.torque.x, cmd.wrench.torque.y, cmd.wrench.torque.z = w[3:]
        self.pub_cmd.publish(cmd)
        self.counters.published += 1
        self.pub_progress.publish(Float64(data=float(st.progress)))
        if st.done and self.state == 'running':
            self.state = 'done'
            self.elapsed = self.program.duration_s
            self._publish_state()
            self.get_logger().info(f'program {self.program.name!r} finished')
            if self.params['exit_on_done'] and not self.sim_time:  # (simulated time: at _end_ns, _on_watermark)
                # Linger a moment so the final state and command reach every subscriber before the exit.
                self._exit_timer = self.create_timer(EXIT_LINGER_S, self._exit)

    def _exit(self) -> None:
        if self._exit_timer is not None:
            self.destroy_timer(self._exit_timer)
        # A reliable command lost at a busy reader's socket is sent again only at the writer's next heartbeat
        # (Fast DDS: 3 s): leaving before every reader acknowledged would take the repair with it, and a recorder
        # would miss a command for good.
        deadline = time.monotonic() + EXIT_ACK_TIMEOUT_S  # one limit for both
        for pub, what in ((self.pub_cmd, 'commands'), (self.pub_state, 'program state')):
            if not pub.wait_for_all_acked(Duration(seconds=max(0.0, deadline - time.monotonic()))):
                self.get_logger().warning(f'exiting although not every reader acknowledged the {what} within '
                                          f'{EXIT_ACK_TIMEOUT_S:g} s: a reader may miss the last ones')
        self.exit_requested = True  # run.run ends the spin and exits with status 0

    def _publish_state(self) -> None:
        assert self.program is not None
        st = self.last
        state: dict[str, Any] = {
            'program': self.program.name, 'state': self.state, 'time_s': round(self._program_time(), 6),
            'duration_s': self.program.duration_s,
            'segment': None if st is None else int(st.segment_index),
            'repeat': None if st is None else int(st.repeat_index),
            'phase': None if st is None else st.phase, 'load_application': self.params['load_application']}
        if self.state == 'waiting':
            prompt = self.prompts[self.prompt_index]
            state['prompt'] = {'level': prompt.index + 1, 'of': len(self.prompts), 'axis': prompt.axis,
                               'value': prompt.level, 'unit': AXIS_UNITS[prompt.axis],
                               'text': prompt.text(len(self.prompts))}
        if self.confirmations:
            state['confirmed'] = self.confirmations
        if self.tare:
            state['tare'] = self.tare
        self.pub_state.publish(String(data=json.dumps(state)))

    # --- services ---
    def _srv_start(self, request, response):
        response.message = self._begin() if self.state == 'idle' else self._start()
        response.success = True
        return response

    def _srv_pause(self, request, response):
        if self.state != 'running':  # (waiting for the operator: it holds already)
            response.success, response.message = False, f'not running (state {self.state})'
            return response
        self.elapsed = self._program_time()
        self.state = 'paused'
        self._publish_state()
        response.success, response.message = True, f'paused at t = {self.elapsed:.3f} s, holding the wrench'
        return response

    def _srv_stop(self, request, response):
        self.state = 'stopped'
        self.elapsed = 0.0
        cmd = WrenchStamped()
        cmd.header.stamp = self.get_clock().now().to_msg()
        cmd.header.frame_id = topics.FRAME_BASE
        self.pub_cmd.publish(cmd)  # abort: take the load off
        self.counters.published += 1
        self._publish_state()
        response.success, response.message = True, 'stopped; zero wrench commanded'
        return response

    def _report(self):
        level = WARN if self.state == 'stopped' else OK
        return level, self.state, [('program', self.program.name), ('time_s', f'{self._program_time():.3f}'),
                                   ('duration_s', f'{self.program.duration_s:.3f}')]


#: The node a rig host loads (crane_stiffness.launcher.rig_host), built with its node arguments (``cli_args``).
COMPONENT = LoadProgramNode


def main(args=None) -> int:
    """Runs the node (run.run, which returns its exit_status: 1 when an automatic start gave up waiting)."""
    return run(LoadProgramNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
