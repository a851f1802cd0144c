"""load_program: plays a test program (steps, ramps, holds; loading then unloading; repeats).

The program comes from ROS parameters (name, rate_hz, repeats, segments.kind/axis/target/duration), normally from
one of config/program_*.yaml. Publishes the commanded wrench on /crane/wrench_command (WrenchStamped, reliable,
frame crane_base), progress on /load_program/progress (Float64 in [0, 1]) and state on /load_program/state (String,
JSON). Services (std_srvs/Trigger): ~/start (start, resume after pause, or restart when finished), ~/pause (hold the
current wrench), ~/stop (abort: command zero). Times follow the node clock, so use_sim_time works.
"""
from __future__ import annotations

import json
from typing import Any

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from std_msgs.msg import Float64, String
from std_srvs.srv import Trigger

from crane_stiffness import topics
from crane_stiffness.config import ParamSpec
from crane_stiffness.nodes.common import LATCHED_QOS, RELIABLE_QOS, Diagnostics, run
from crane_stiffness.nodes.parameters import Params, check
from crane_stiffness.sim.program import LoadProgram
from crane_stiffness.status import OK, WARN

PARAMS = (
    ParamSpec('name', 'hold_zero', 'program name, recorded with the session'),
    ParamSpec('rate_hz', 100.0, 'command publication rate [Hz]', rule='> 0'),
    ParamSpec('repeats', 1, 'how many times the segment list is played (>= 1)', low=1),
    ParamSpec('segments.kind', ['hold'], 'segment kinds: ramp | hold | step'),
    ParamSpec('segments.axis', ['fy'], 'segment axes: fx fy fz [N] or mx my mz [N·m], fixed frame (z down)'),
    ParamSpec('segments.target', [0.0], 'segment end values [N or N·m]'),
    ParamSpec('segments.duration', [1.0], 'segment durations [s]',
              rule='one per segment; kind, axis, target and duration lists have the same length'),
    ParamSpec('autostart', True, 'start the program by itself (after start_delay_s)'),
    ParamSpec('start_delay_s', 1.0, 'wait before an automatic start [s]', low=0.0, high=86400.0),
    ParamSpec('min_subscribers', 1, 'an automatic start also waits until /crane/wrench_command has this many '
              'subscribers, so no command is lost while DDS discovery runs [-]', low=0),
    ParamSpec('exit_on_done', False, 'shut the node down when the program has finished'),
)
PROGRAM_KEYS = ('name', 'rate_hz', 'repeats', 'segments.kind', 'segments.axis', 'segments.target',
                'segments.duration')


class LoadProgramNode(Node):
    """Idle → running ⇄ paused → done (or stopped); the program itself is crane_stiffness.sim.program."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('load_program', **kwargs)
        self.state = 'idle'
        self.elapsed = 0.0        # program time reached when last paused [s]
        self.started_at = None    # node-clock time of (re)start [s]
        self.last = None
        self.program: LoadProgram | None = None
        self.timer = None
        self.pub_cmd = self.create_publisher(WrenchStamped, topics.WRENCH_COMMAND, RELIABLE_QOS)
        self.pub_progress = self.create_publisher(Float64, topics.PROGRAM_PROGRESS, LATCHED_QOS)
        self.pub_state = self.create_publisher(String, topics.PROGRAM_STATE, LATCHED_QOS)
        self.params = Params(self, PARAMS, self._validate, self._apply)
        self.create_service(Trigger, '~/start', self._srv_start)
        self.create_service(Trigger, '~/pause', self._srv_pause)
        self.create_service(Trigger, '~/stop', self._srv_stop)
        self.diagnostics = Diagnostics(self, self._report)
        self._autostart = None
        if self.params['autostart']:
            self._not_before = self._now() + self.params['start_delay_s']
            self._autostart = self.create_timer(0.05, self._auto)

    # --- parameters ---
    def _validate(self, values: dict[str, Any]) -> LoadProgram:
        check(values['start_delay_s'] >= 0, 'start_delay_s', values['start_delay_s'], 'must be >= 0')
        check(values['min_subscribers'] >= 0, 'min_subscribers', values['min_subscribers'], 'must be >= 0')
        if self.state in ('running', 'paused') and self.program is not None:
            if any(values[k] != self.params[k] for k in PROGRAM_KEYS):
                raise ValueError('the program cannot change while it runs: call ~/stop first')
        return LoadProgram.from_params({k: values[k] for k in PROGRAM_KEYS})  # ValueError names the field

    def _apply(self, program: LoadProgram, values: dict[str, Any]) -> None:
        self.program = program
        if self.timer is not None:
            self.destroy_timer(self.timer)
        self.timer = self.create_timer(1.0 / program.rate_hz, self._tick)
        self.get_logger().info(f'program {program.name!r}: {len(program.segments)} segments x {program.repeats}, '
                               f'{program.duration_s:.3g} s')

    # --- time and state ---
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _program_time(self) -> float:
        if self.state == 'running':
            return self.elapsed + self._now() - self.started_at
        return self.elapsed

    def _auto(self) -> None:
        if self._now() < self._not_before:
            return
        if self.count_subscribers(topics.WRENCH_COMMAND) < self.params['min_subscribers']:
            self.get_logger().info(f'waiting for {self.params["min_subscribers"]} subscriber(s) of '
                                   f'{topics.WRENCH_COMMAND}', throttle_duration_sec=5.0)
            return
        self.destroy_timer(self._autostart)
        if self.state == 'idle':
            self._start()

    def _start(self) -> str:
        if self.state == 'running':
            return 'already running'
        if self.state in ('done', 'stopped', 'idle'):
            self.elapsed = 0.0
        self.started_at = self._now()
        self.state = 'running'
        self._publish_state()
        return f'running {self.program.name!r} from t = {self.elapsed:.3f} s'

    def _tick(self) -> None:
        if self.state not in ('running', 'paused'):
            return
        st = self.program.wrench_at(self._program_time())
        self.last = st
        cmd = WrenchStamped()
        cmd.header.stamp = self.get_clock().now().to_msg()
        cmd.header.frame_id = topics.FRAME_BASE
        w = [float(v) for v in st.wrench]
        cmd.wrench.force.x, cmd.wrench.force.y, cmd.wrench.force.z = w[:3]
        cmd.wrench.torque.x, cmd.wrench.torque.y, cmd.wrench.torque.z = w[3:]
        self.pub_cmd.publish(cmd)
        self.pub_progress.publish(Float64(data=float(st.progress)))
        if st.done and self.state == 'running':
            self.state = 'done'
            self.elapsed = self.program.duration_s
            self._publish_state()
            self.get_logger().info(f'program {self.program.name!r} finished')
            if self.params['exit_on_done']:
                # Linger a moment so the final state and command reach every subscriber before the exit.
                self.create_timer(1.0, self._exit)

    def _exit(self) -> None:
        self.exit_requested = True  # common.run ends the spin and exits with status 0

    def _publish_state(self) -> None:
        st = self.last
        self.pub_state.publish(String(data=json.dumps({
            'program': self.program.name, 'state': self.state, 'time_s': round(self._program_time(), 6),
            'duration_s': self.program.duration_s,
            'segment': None if st is None else int(st.segment_index),
            'repeat': None if st is None else int(st.repeat_index),
            'phase': None if st is None else st.phase})))

    # --- services ---
    def _srv_start(self, request, response):
        response.message = self._start()
        response.success = True
        return response

    def _srv_pause(self, request, response):
        if self.state != 'running':
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
        self._publish_state()
        response.success, response.message = True, 'stopped; zero wrench commanded'
        return response

    @property
    def counters(self) -> dict:
        """What ``run`` prints at exit (FINAL_COUNTERS): where the program stood."""
        return {'program': self.program.name, 'state': self.state, 'time_s': round(self._program_time(), 6)}

    def _report(self):
        level = WARN if self.state == 'stopped' else OK
        return level, self.state, [('program', self.program.name), ('time_s', f'{self._program_time():.3f}'),
                                   ('duration_s', f'{self.program.duration_s:.3f}')]


def main(args=None) -> int:
    return run(LoadProgramNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
