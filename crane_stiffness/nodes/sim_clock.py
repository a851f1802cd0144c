"""sim_clock: the clock source of the simulated rig (a thin adapter around crane_stiffness.sim.lockstep).

Publishes /clock (rosgraph_msgs/Clock, as Gazebo does) for the nodes that run with ``use_sim_time``, and with it the
per-stage watermarks on /sim/watermarks; listens to the participants' progress on /sim/progress. Time starts at
``start_time_s`` once every node of ``participants`` has reported (and ``settle_s`` of wall time later, so that
DDS has matched every reader before the first sample), then advances in steps of ``step_s``, ``real_time_factor``
times as fast as the wall clock (0: as fast as the rig keeps up) and never more than ``max_lead_s`` ahead of the
slowest participant: a busy machine slows simulated time instead of losing samples. While time is held it says
by whom (log, /diagnostics). This node itself keeps wall-clock time (it is the source: ``use_sim_time`` must be
false). It ends when every participant has left (their nodes ended) or on Ctrl-C.

Counters (FINAL_COUNTERS): steps published, simulated seconds, wall seconds since time started, the real-time
factor reached, and how often the participants held time back.
"""
from __future__ import annotations

import json
import time
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from std_msgs.msg import String

from crane_stiffness.contract import topics
from crane_stiffness.rosnode.diagnostics import Diagnostics
from crane_stiffness.rosnode.parameters import Params, check
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.sim_time import SIM_QOS
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.sim.lockstep import LockstepClock
from crane_stiffness.contract.status import OK, WARN
from crane_stiffness.serde.stamps import split_ns

#: The nodes of the simulated rig that follow the clock (crane_stiffness.launcher.rig_description passes the ones
#: started).
DEFAULT_PARTICIPANTS = ('load_program', 'crane_model', 'load_cell', 'lvdt', 'stiffness_estimator', 'session_recorder')

PARAMS = (
    ParamSpec('participants', list(DEFAULT_PARTICIPANTS), 'nodes that must report before time starts and that time '
              'waits for (node names) [-]'),
    ParamSpec('real_time_factor', 1.0, 'simulated seconds per wall second; 0 = as fast as the rig keeps up [-]',
              low=0.0, high=1000.0),
    ParamSpec('step_s', 0.05, 'resolution of simulated time: /clock moves in steps of this [s]', low=1e-4, high=1.0),
    ParamSpec('max_lead_s', 0.05, 'how far time may run ahead of the slowest participant; at step_s every node '
              'acts on every step in turn and the recording is the same at any load; more lets the stages overlap '
              '(faster), the estimators then batch their outputs as the load falls [s]', low=1e-4, high=10.0,
              rule='>= step_s'),
    ParamSpec('start_time_s', 1000.0, 'simulated time at start; the same in every run, so runs compare stamp for '
              'stamp [s]', low=1.0, high=2.0e9, rule='a multiple of step_s'),
    ParamSpec('settle_s', 1.0, 'wall time between every participant having reported and time starting (DDS '
              'matches the readers meanwhile) [s]', low=0.0, high=60.0),
    ParamSpec('log_period_s', 5.0, 'while time is held, say by whom this often (wall time) [s]', low=0.1,
              high=3600.0),
)
#: /clock as rclpy's TimeSource subscribes it (best effort would do; reliable reaches it too).
CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)


#: What cannot change once the clock exists (the pace can).
FIXED_AT_START = ('participants', 'step_s', 'start_time_s', 'settle_s')


def _validate(values: dict[str, Any]) -> dict[str, Any]:
    check(values['max_lead_s'] >= values['step_s'], 'max_lead_s', values['max_lead_s'],
          f'must be >= step_s ({values["step_s"]})')
    step_ns = round(values['step_s'] * 1e9)
    start_ns = round(values['start_time_s'] * 1e9)
    check(start_ns % step_ns == 0, 'start_time_s', values['start_time_s'],
          f'must be a multiple of step_s ({values["step_s"]})')
    check(all(isinstance(n, str) and n for n in values['participants']) and len(values['participants']) > 0,
          'participants', values['participants'], 'must list at least one node name')
    return values


class SimClock(Node):
    """Publishes /clock and the watermarks, paced by the wall clock and held by the slowest participant."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('sim_clock', **kwargs)
        if self.get_parameter('use_sim_time').value:
            raise ValueError('use_sim_time = True: sim_clock is the source of simulated time and keeps wall time')
        self.wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.lockstep: LockstepClock | None = None
        self.counters: dict[str, Any] = {'steps': 0, 'simulated_s': 0.0, 'wall_s': 0.0, 'real_time_factor': 0.0,
                                         'held': 0}
        self.exit_requested = False
        self._started_values: dict[str, Any] | None = None
        self.params = Params(self, PARAMS, self._checked, self._apply)
        self._started_values = {k: self.params[k] for k in FIXED_AT_START}
        self.pub_clock = self.create_publisher(ClockMsg, topics.CLOCK, CLOCK_QOS)
        self.pub_marks = self.create_publisher(String, topics.SIM_WATERMARKS, SIM_QOS)
        self.create_subscription(String, topics.SIM_PROGRESS, self._on_progress, SIM_QOS)
        self.sent: dict[str, dict[str, int]] = {}  # per participant: messages published per topic
        self._all_heard_at: float | None = None   # time.monotonic() when every participant had reported
        self._started_at: float | None = None
        self._last_log = time.monotonic()
        self._last_marks: list[int] = []
        self._last_clock_pub = 0.0
        self._held_since: float | None = None  # time.monotonic() since the participants hold time, None: not held
        self._held_by = ''
        self.diagnostics = Diagnostics(self, self._report)
        self.timer = self.create_timer(self._period(), self._tick, clock=self.wall)
        assert self.lockstep is not None  # built by _apply (Params, above)
        self.get_logger().info(f'simulated time for {", ".join(self.lockstep.participants)}; starting at '
                               f'{self.params["start_time_s"]:g} s once all have reported')

    def _checked(self, values: dict[str, Any]) -> dict[str, Any]:
        if self._started_values is not None:
            for name in FIXED_AT_START:
                check(values[name] == self._started_values[name], name, values[name],
                      'cannot change while the clock runs (only real_time_factor and max_lead_s can)')
        return _validate(values)

    def _period(self) -> float:
        rtf = self.params['real_time_factor']
        return 0.001 if rtf == 0 else max(0.001, self.params['step_s'] / rtf)

    def _apply(self, values: dict[str, Any], _all: dict[str, Any]) -> None:
        if self.lockstep is not None:  # after start only the pace may change (_validate refuses the rest)
            self.lockstep.real_time_factor = float(values['real_time_factor'])
            self.lockstep.max_lead_ns = round(values['max_lead_s'] * 1e9)
            self.lockstep.repace()
            self.destroy_timer(self.timer)
            self.timer = self.create_timer(self._period(), self._tick, clock=self.wall)
            return
        self.lockstep = LockstepClock(list(values['participants']), round(values['start_time_s'] * 1e9),
                                      round(values['step_s'] * 1e9), float(values['real_time_factor']),
                                      round(values['max_lead_s'] * 1e9))

    # --- participants ---
    def _on_progress(self, msg: String) -> None:
        assert self.lockstep is not None
        try:
            p = json.loads(msg.data)
            if self.lockstep.report(str(p['name']), int(p['stage']), int(p['t'])):
                self.sent[str(p['name'])] = {str(k): int(v) for k, v in dict(p['sent']).items()}
                if 'end' in p and self.lockstep.end_ns is None:
                    self.lockstep.end_ns = int(p['end'])
                    self.get_logger().info(f'{p["name"]}: the run ends at simulated time {int(p["end"]) * 1e-9:.3f} s')
        except (ValueError, KeyError, TypeError):
            self.get_logger().warning(f'malformed progress {msg.data[:200]!r} ignored', throttle_duration_sec=5.0)
            return
        self._step()

    # --- time ---
    def _tick(self) -> None:
        self._step()
        now = time.monotonic()
        if now - self._last_clock_pub > 0.1:  # a node that joined late, or lost a message, hears the time again
            self._publish_clock()
            self._publish_marks(again=True)

    def _step(self) -> None:
        ls = self.lockstep
        assert ls is not None
        now = time.monotonic()
        if self._started_at is None:
            missing = ls.missing()
            if missing:  # the participants join by answering the start time's watermarks
                self._all_heard_at = None
                self._log_held(now, f'waiting for {", ".join(missing)} to join')
                self._publish_marks()
                return
            if self._all_heard_at is None:
                self._all_heard_at = now
                self.get_logger().info(f'every participant is there; time starts in {self.params["settle_s"]:g} s')
            if now - self._all_heard_at < self.params['settle_s']:
                self._publish_marks()
                return
            self._started_at = now
        if ls.slowest() is None:
            self.get_logger().info('every participant has left: the clock stops')
            self.exit_requested = True
            return
        if ls.advance(self.wall.now().nanoseconds):
            self.counters['steps'] += 1
            self._publish_clock()
            self._last_log = now
        else:
            slowest = ls.slowest()
            if slowest is not None and slowest.progress_ns + ls.max_lead_ns <= ls.now_ns:
                if self._held_since is None:
                    self._held_since = now
                self._held_by = slowest.name
                self._log_held(now, f'held at {ls.now_ns * 1e-9:.3f} s for {now - self._held_since:.0f} s by '
                                    f'{slowest.name} (through {slowest.progress_ns * 1e-9:.3f} s)', warn=True)
                self._publish_marks()
                return
        self._held_since = None
        self._publish_marks()

    def _log_held(self, now: float, what: str, warn: bool = False) -> None:
        if now - self._last_log >= self.params['log_period_s']:
            self._last_log = now
            # One call site per severity: rclpy's logger refuses a call site whose severity changes between calls
            # (ValueError; it ended the clock the first time a held message followed a waiting one, under load).
            if warn:
                self.get_logger().warning(what)
            else:
                self.get_logger().info(what)

    def _publish_clock(self) -> None:
        assert self.lockstep is not None
        msg = ClockMsg()
        msg.clock.sec, msg.clock.nanosec = split_ns(self.lockstep.now_ns)
        self.pub_clock.publish(msg)
        self._last_clock_pub = time.monotonic()

    def _publish_marks(self, again: bool = False) -> None:
        """The watermarks when they changed (``again``: also when not)."""
        assert self.lockstep is not None
        marks = self.lockstep.watermarks()
        if again or marks != self._last_marks:
            self._last_marks = marks
            sums: list[dict[str, int]] = []
            for stage in range(len(marks)):  # what the stages below published, per topic
                total: dict[str, int] = {}
                for p in self.lockstep.table.values():
                    if 0 <= p.stage < stage:
                        for topic, n in self.sent.get(p.name, {}).items():
                            total[topic] = total.get(topic, 0) + n
                sums.append(total)
            self.pub_marks.publish(String(data=json.dumps({'t': marks, 'sent': sums, 'done': self.lockstep.done_ns(),
                                                           'end': self.lockstep.end_ns})))

    def close(self) -> None:
        ls = self.lockstep
        if ls is not None and self._started_at is not None:
            wall = time.monotonic() - self._started_at
            sim = (ls.now_ns - ls.start_ns) * 1e-9
            self.counters.update(simulated_s=round(sim, 3), wall_s=round(wall, 3),
                                 real_time_factor=round(sim / wall, 3) if wall > 0 else 0.0, held=ls.held)

    def _report(self):
        ls = self.lockstep
        assert ls is not None
        pairs = [('time_s', f'{ls.now_ns * 1e-9:.3f}'), ('steps', str(self.counters['steps'])),
                 ('held', str(ls.held))] + [(f'progress_{p.name}', f'{p.progress_ns * 1e-9:.3f}')
                                            for p in ls.table.values()]
        missing = ls.missing()
        if missing:
            return WARN, f'waiting for {", ".join(missing)}', pairs
        if self._held_since is not None and time.monotonic() - self._held_since >= self.params['log_period_s']:
            return WARN, (f'simulated time held at {ls.now_ns * 1e-9:.3f} s for '
                          f'{time.monotonic() - self._held_since:.0f} s by {self._held_by}'), pairs
        if ls.end_ns is not None and ls.now_ns >= ls.end_ns:
            return OK, f'the run ended at simulated time {ls.end_ns * 1e-9:.3f} s', pairs
        return OK, f'simulated time {ls.now_ns * 1e-9:.3f} s', pairs


#: The node a rig host loads (crane_stiffness.launcher.rig_host), built with its node arguments (``cli_args``).
COMPONENT = SimClock


def main(args=None) -> int:
    return run(SimClock, args)


if __name__ == '__main__':
    raise SystemExit(main())
