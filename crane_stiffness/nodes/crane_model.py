"""crane_model: the nonlinear crane under the commanded wrench (a thin adapter around crane_stiffness.model).

Subscribes /crane/wrench_command (WrenchStamped, frame crane_base); publishes /crane/platform_pose (PoseStamped,
frame crane_base = the paper's frame, z down; stamped with the command's stamp), /crane/wire_states (JointState:
wire_1..wire_6, position = length [m], effort = tension [N]), /crane/predicted_stiffness (Float64MultiArray 6×6
tangent) and /crane/predicted_axis_stiffness (Float64 along the commanded axis), and /crane/model_status (String:
'ok …' or 'no_equilibrium …'). Geometry from the geometry.* parameters, changeable at run time.

Every command is either accepted or rejected, and said so (crane_stiffness.contract.topics): after EVERY command this
node
publishes /crane/applied_wrench (WrenchStamped, frame crane_base, the command's stamp) = the load in force after it:
the command when accepted, the previous load when rejected; a rejected command (non-finite, absurd, no equilibrium)
is also republished unchanged on /crane/rejected_command. The simulated sensors apply /crane/applied_wrench, never
the raw command, so a command the model rejects reaches no sensor. A reader of /crane/applied_wrench or of the pose
that joins late (a sensor started after this node) is sent the load in force and the pose, stamped now, on matching
and again RESEND_AFTER_MATCH_S later (a message sent on matching alone is often lost across processes).

Solving is cached on the wrench: the current equilibrium answers a repeated command (a hold), and a command that
failed is answered from a bounded cache of failures keyed on (load in force, command), since the continuation
solve starts from the load in force; a repeated failing command (a program holding an impossible load at 100 Hz)
therefore costs no solve. Any parameter change empties the caches.

Counters (FINAL_COUNTERS, /diagnostics): received = used + dropped_non_finite + dropped_absurd +
dropped_no_equilibrium; solves and cache_hits say how each used or no-equilibrium command was answered.

The stiffness topics and the status are latched. The pose is not (it is a stream), so a reader that joins late (the
simulated LVDT started after this node, in any order) is sent the current pose when it matches: it can publish
before the first command, and load_program waits for that (crane_stiffness.nodes.load_program).
"""
from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.timer import Timer
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, String

from crane_stiffness.contract import topics
from crane_stiffness.contract.command_limits import CommandLimits, command_fault
from crane_stiffness.params.geometry import GEOMETRY_PARAMS, geometry_from_params
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.model import (AXES, WIRE_NAMES, CraneGeometry, Equilibrium, ModelError, axis_stiffness,
                                   rest_pose, solve_equilibrium, tangent_stiffness)
from crane_stiffness.model.rotation import matrix_to_quaternion
from crane_stiffness.rosnode.qos import LATCHED_QOS, RELIABLE_QOS, stream_qos
from crane_stiffness.rosnode.diagnostics import Counters, Diagnostics
from crane_stiffness.rosnode.messages import finite
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.parameters import Params, check
from crane_stiffness.rosnode.sim_time import SimTimeParticipant, drain, uses_sim_time
from crane_stiffness.contract.status import ERROR, OK

MODEL_STATUS = topics.MODEL_STATUS
#: Most failed (load in force, command) pairs remembered; the oldest is forgotten first.
FAILURE_CACHE_SIZE = 256
#: After a reader of the applied wrench or the pose matches, the values in force are sent again this long after
#: the match [s] (see CraneModel._late_joiner).
RESEND_AFTER_MATCH_S = (0.2, 0.6, 1.5, 3.0)


@dataclass
class ModelCounters(Counters):
    """``received`` = ``used`` + every ``dropped_*`` (each command is counted once, in one of them).

    ``used``: commands accepted (their load is in force); ``dropped_no_equilibrium``: commands without an
    equilibrium (solved or from the cache); ``solves``: equilibria computed for commands; ``cache_hits``: commands
    answered without a solve (the current equilibrium, or a cached failure); ``published``: poses published for
    commands; ``resent``: times the load in force and the pose were sent again for readers that joined.
    """

    used: int = 0
    dropped_no_equilibrium: int = 0
    solves: int = 0
    cache_hits: int = 0
    resent: int = 0  # the load in force and the pose sent again for readers that joined (not commands)

PARAMS = GEOMETRY_PARAMS + (
    ParamSpec('prediction_axis', 'auto', "axis of the predicted stiffness: fx fy fz mx my mz, or 'auto' = the "
              'largest component of the command (fy until a load arrives)'),
    ParamSpec('max_abs_force', 1.0e4, 'commands with a force component above this are absurd and dropped [N]',
              above=0.0),
    ParamSpec('max_abs_moment', 1.0e3, 'commands with a moment component above this are absurd and dropped [N·m]',
              above=0.0),
)


def _validate(values: dict[str, Any]) -> CraneGeometry:
    check(values['prediction_axis'] in ('auto',) + AXES, 'prediction_axis', values['prediction_axis'],
          f"must be 'auto' or one of {', '.join(AXES)}")
    for name in ('max_abs_force', 'max_abs_moment'):
        check(values[name] > 0 and math.isfinite(values[name]), name, values[name], 'must be finite and > 0')
    geometry = geometry_from_params(values)  # raises GeometryError (a ValueError) naming the field
    rest_pose(geometry)  # a geometry whose rest pose cannot be found is rejected too
    return geometry


class CraneModel(Node):
    """Holds the geometry and the last equilibrium; each command is solved warm-started from the last one."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('crane_model', **kwargs)
        # Simulated time: the pose, wires and load in force go out from time's start on (counted, stamped on the
        # grid), never at construction, when a reader may or may not have matched yet.
        self.sim_time = uses_sim_time(self)
        self._sim_start_ns: int | None = None  # simulated time: when time starts, and whether the state went out
        self._sim_started = False
        self.counters = ModelCounters()
        self.failures = 0  # solves that found no equilibrium (also on a parameter change)
        self.status = 'starting'
        self.geometry: CraneGeometry | None = None  # set by _apply (Params, below): the methods assert it
        self.equilibrium: Equilibrium | None = None
        self.load = np.zeros(6)  # the load in force [N, N·m], crane_base: the last accepted command (rest: zero)
        self.axis = 'fy'
        self.stamp = None
        self.solved: tuple | None = None  # the load the published pose and stiffness belong to (None: re-solve)
        # (load in force, command) -> the no-equilibrium reason, newest last (see the module docstring).
        self.failed: OrderedDict[tuple[tuple, tuple], str] = OrderedDict()
        self._resends: list[float] = []
        self._resend_kinds: set[str] = set()
        self._readers: dict[str, int] = {}  # matched readers by kind, as last reported
        self._resend_from = 0
        self._resend_timer: Timer | None = None
        self.pub_applied = self.create_publisher(
            WrenchStamped, topics.APPLIED_WRENCH, stream_qos(RELIABLE_QOS, self.sim_time),
            event_callbacks=PublisherEventCallbacks(matched=self._on_applied_matched))
        self.pub_rejected = self.create_publisher(WrenchStamped, topics.REJECTED_COMMAND,
                                                  stream_qos(RELIABLE_QOS, self.sim_time))
        self.pub_pose = self.create_publisher(PoseStamped, topics.PLATFORM_POSE,
                                              stream_qos(RELIABLE_QOS, self.sim_time),
                                              event_callbacks=PublisherEventCallbacks(matched=self._on_pose_matched))
        self.pub_wires = self.create_publisher(JointState, topics.WIRE_STATES, stream_qos(RELIABLE_QOS, self.sim_time))
        self.pub_k = self.create_publisher(Float64MultiArray, topics.PREDICTED_STIFFNESS, LATCHED_QOS)
        self.pub_axis = self.create_publisher(Float64, topics.PREDICTED_AXIS_STIFFNESS, LATCHED_QOS)
        self.pub_status = self.create_publisher(String, MODEL_STATUS, LATCHED_QOS)
        self.diagnostics = Diagnostics(self, self._report)
        self.settings: dict[str, Any] = {}
        self.params = Params(self, PARAMS, _validate, self._set_geometry)
        self.sub_command = self.create_subscription(WrenchStamped, topics.WRENCH_COMMAND, self._on_command,
                                                    stream_qos(RELIABLE_QOS, self.sim_time))
        # Simulated time: every command up to the watermark is in (drained first) and answered; once the sensors
        # have acknowledged the answers, the model's progress says so.
        self.sim = SimTimeParticipant(self, 1, self._on_watermark, inputs=[topics.WRENCH_COMMAND],
                                      drain=lambda: drain(self.sub_command, self._on_command))
        for pub in (self.pub_applied, self.pub_pose, self.pub_wires, self.pub_rejected):
            self.sim.counted(pub)
        for pub in (self.pub_k, self.pub_axis):  # (the recorder waits for them and logs them in their step)
            self.sim.counted(pub)

    def _on_watermark(self, t_ns: int) -> None:
        if self._sim_start_ns is None:
            self._sim_start_ns = t_ns  # the first watermark: the start, while time waits for every node to join
        elif not self._sim_started and t_ns > self._sim_start_ns:
            # Time has started, so every reader has matched (sim_clock waited): the state in force is sent once,
            # stamped with the start, instead of re-sent on matching at times that differ from run to run.
            self._sim_started = True
            start = Time(sec=self._sim_start_ns // 1_000_000_000, nanosec=self._sim_start_ns % 1_000_000_000)
            self._publish_applied(start)
            if self.equilibrium is not None:
                stamp, self.stamp = self.stamp, start
                self._publish_pose(self.equilibrium)
                self.stamp = stamp
                self._publish_prediction(self.equilibrium)  # (held back until now: see _publish_solution)
        self.sim.report(t_ns)

    # --- callbacks ---
    def _set_geometry(self, geometry: CraneGeometry, values: dict[str, Any]) -> None:
        changed = geometry != self.geometry
        self.geometry = geometry
        self.settings = values
        self.limits = CommandLimits(float(values['max_abs_force']), float(values['max_abs_moment']))
        self.solved = None  # any parameter change: solve and publish everything again
        self.failed.clear()  # ... and a command that failed may now have an equilibrium
        if changed:
            self.equilibrium = None  # a new crane: solve from its own rest pose
            self.get_logger().info(
                f'geometry: a = {geometry.a} m, b = {geometry.b} m, h = {geometry.height} m, '
                f'l0 = {geometry.l0:.6f} m, W = {geometry.weight} N, k = {geometry.k:.6g} N/m')
        self._solve_and_publish()

    def _on_command(self, msg: WrenchStamped) -> None:
        self.counters.received += 1
        self.sim.received(topics.WRENCH_COMMAND)
        f, m = msg.wrench.force, msg.wrench.torque
        load = np.array([f.x, f.y, f.z, m.x, m.y, m.z])
        fault = self._command_fault(load)
        if fault is not None:
            counter, reason = fault
            setattr(self.counters, counter, getattr(self.counters, counter) + 1)
            self.get_logger().warning(f'wrench command rejected ({reason}): {load.tolist()}',
                                      throttle_duration_sec=2.0)
            self._reject(msg)
            return
        key = tuple(load.tolist())
        stamp = msg.header.stamp if (msg.header.stamp.sec or msg.header.stamp.nanosec) else None
        if self.solved == key:
            # A hold repeats the command at the program's rate: the same equilibrium, pose restamped. The latched
            # stiffness topics already carry its values.
            self.counters.cache_hits += 1
            assert self.equilibrium is not None  # set with solved
            self._accept(msg, load, stamp)
            self._publish_pose(self.equilibrium)
            self.counters.published += 1
            self._set_status(self._ok_status(self.equilibrium))  # e.g. back to ok after a rejected command
            return
        failed_key = (tuple(self.load.tolist()), key)
        failed_before = self.failed.get(failed_key)
        if failed_before is not None:  # failed before from this same load in force: the same answer, no solve
            self.failed.move_to_end(failed_key)
            self.counters.cache_hits += 1
            self._no_equilibrium(msg, failed_before)
            return
        self.counters.solves += 1
        assert self.geometry is not None
        try:
            eq = solve_equilibrium(self.geometry, load=load, initial=self.equilibrium)
        except ModelError as exc:
            self.failures += 1
            self.failed[failed_key] = str(exc)
            while len(self.failed) > FAILURE_CACHE_SIZE:
                self.failed.popitem(last=False)
            self._no_equilibrium(msg, str(exc))
            return
        self._accept(msg, load, stamp)
        self._publish_solution(eq)

    def _command_fault(self, load: np.ndarray) -> tuple[str, str] | None:
        """(counter, reason) when the command is not a load to apply, else None: the rule the estimator applies
        too (crane_stiffness.contract.command_limits)."""
        reason = command_fault(load, self.limits)
        if reason is None:
            return None
        return ('dropped_non_finite' if not finite(load) else 'dropped_absurd'), reason

    def _accept(self, msg: WrenchStamped, load: np.ndarray, stamp) -> None:
        """The command's load is in force from its stamp on: say so on /crane/applied_wrench."""
        self.counters.used += 1
        self.load = load
        self.stamp = stamp
        self._publish_applied(msg.header.stamp)

    def _reject(self, msg: WrenchStamped) -> None:
        """A rejected command: republished unchanged, and the load still in force restated with its stamp."""
        self.pub_rejected.publish(msg)
        self._publish_applied(msg.header.stamp)

    def _no_equilibrium(self, msg: WrenchStamped, reason: str) -> None:
        self.counters.dropped_no_equilibrium += 1
        self._set_status(f'no_equilibrium: {reason}')
        self.get_logger().error(reason, throttle_duration_sec=1.0)
        self._reject(msg)  # keep the last valid pose; nothing wrong is published

    def _publish_applied(self, stamp) -> None:
        """The load in force on /crane/applied_wrench [N, N·m], frame crane_base, with ``stamp``."""
        if self.sim_time and not self._sim_started:
            return
        out = WrenchStamped()
        out.header.stamp = stamp
        out.header.frame_id = topics.FRAME_BASE
        f, m = out.wrench.force, out.wrench.torque
        f.x, f.y, f.z, m.x, m.y, m.z = (float(v) for v in self.load)
        self.pub_applied.publish(out)

    def _on_applied_matched(self, status) -> None:
        """A new reader of the applied wrench (a sensor started after this node): send it the load in force,
        stamped now, so it can start measuring before the first command (and again, see :meth:`_late_joiner`)."""
        if self._new_reader('applied', status) and not self.sim_time:
            self._publish_applied(self.get_clock().now().to_msg())
            self._late_joiner('applied')

    def _on_pose_matched(self, status) -> None:
        """A new pose reader: send it the current pose (stamped now), as a latched topic would."""
        if self._new_reader('pose', status) and not self.sim_time:
            self._publish_current_pose()
            self._late_joiner('pose')

    def _new_reader(self, kind: str, status) -> bool:
        """Whether a matched event brings a new reader. rmw_fastrtps reports a reader that was already there when
        the publisher was created (a sensor started first) with current_count_change 0: the count tells."""
        before = self._readers.get(kind, 0)
        self._readers[kind] = status.current_count
        return status.current_count_change > 0 or status.current_count > before

    def _publish_current_pose(self) -> None:
        if self.equilibrium is not None:
            stamp, self.stamp = self.stamp, None
            self._publish_pose(self.equilibrium)
            self.stamp = stamp

    def _late_joiner(self, kind: str) -> None:
        """Send the load in force ('applied') or the pose ('pose') again, stamped now, RESEND_AFTER_MATCH_S after a
        reader of it matched.

        The writer sees a new reader before that reader has matched the writer (discovery runs both ways, on its
        own timing in each process); a volatile reader drops what was published in between, so the message sent
        on matching alone is often lost across processes. Re-sending the same values is harmless to a hold."""
        self._resend_kinds.add(kind)
        self._resends = list(RESEND_AFTER_MATCH_S)
        self._resend_from = self.get_clock().now().nanoseconds
        if self._resend_timer is None:
            self._resend_timer = self.create_timer(0.05, self._resend)
        else:
            self._resend_timer.reset()

    def _resend(self) -> None:
        elapsed = (self.get_clock().now().nanoseconds - self._resend_from) * 1e-9
        if self._resends and elapsed >= self._resends[0]:
            while self._resends and elapsed >= self._resends[0]:
                self._resends.pop(0)
            self.counters.resent += 1
            if 'applied' in self._resend_kinds:
                self._publish_applied(self.get_clock().now().to_msg())
            if 'pose' in self._resend_kinds:
                self._publish_current_pose()
        if not self._resends:
            self._resend_kinds.clear()
            assert self._resend_timer is not None  # the timer calling this
            self._resend_timer.cancel()

    # --- work ---
    def _solve_and_publish(self) -> None:
        """Solve the load in force again (start, parameter change) and publish everything."""
        assert self.geometry is not None
        try:
            eq = solve_equilibrium(self.geometry, load=self.load, initial=self.equilibrium)
        except ModelError as exc:
            self.failures += 1
            self.solved = None  # the same load again must be solved again (and clear this status)
            self._set_status(f'no_equilibrium: {exc}')
            self.get_logger().error(str(exc), throttle_duration_sec=1.0)
            self.diagnostics.publish()
            return  # keep the last valid pose; nothing wrong is published
        self._publish_solution(eq)

    def _publish_solution(self, eq: Equilibrium) -> None:
        g = self.geometry
        assert g is not None
        self.equilibrium = eq
        self.solved = tuple(self.load.tolist())
        self._publish_pose(eq)
        if self.sim_time and not self._sim_started:
            # Simulated time, before it starts: the prediction goes out (counted) once time has started; sent now,
            # a later one could replace it in the latched history before the recorder matched, in some runs only.
            self._set_status(self._ok_status(eq))
            return
        self._publish_prediction(eq)

    def _publish_prediction(self, eq: Equilibrium) -> None:
        """The model's tangent stiffness at ``eq`` (6x6) and along the prediction axis, and the status."""
        g = self.geometry
        assert g is not None
        k = tangent_stiffness(g, eq)
        km = Float64MultiArray()
        km.layout.dim = [MultiArrayDimension(label='load [fx fy fz mx my mz]', size=6, stride=36),
                         MultiArrayDimension(label='displacement [ux uy uz thx thy thz]', size=6, stride=6)]
        km.data = [float(v) for v in k.ravel()]
        self.pub_k.publish(km)
        axis = self.settings['prediction_axis']
        if axis == 'auto':
            if np.any(self.load):
                axis = AXES[int(np.argmax(np.abs(self.load)))]
            else:
                axis = self.axis
        self.axis = axis
        self.pub_axis.publish(Float64(data=float(axis_stiffness(k, axis))))
        self.counters.published += 1
        self._set_status(self._ok_status(eq))

    @staticmethod
    def _ok_status(eq: Equilibrium) -> str:
        return f'ok: {int(eq.slack.sum())} slack wire(s)'

    def _set_status(self, status: str) -> None:
        """Publish the (latched) status when it changes."""
        if status != self.status:
            self.status = status
            self.pub_status.publish(String(data=status))

    def _publish_pose(self, eq: Equilibrium) -> None:
        """The platform pose and the wire states of ``eq``, stamped with the command's stamp (else now)."""
        if self.sim_time and not self._sim_started:
            return
        pose = PoseStamped()
        pose.header.stamp = self.stamp or self.get_clock().now().to_msg()
        pose.header.frame_id = topics.FRAME_BASE
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in eq.displacement)
        q = matrix_to_quaternion(eq.rotation)
        o = pose.pose.orientation
        o.x, o.y, o.z, o.w = (float(v) for v in q)
        self.pub_pose.publish(pose)
        wires = JointState()
        wires.header = pose.header
        wires.name = list(WIRE_NAMES)
        wires.position = [float(v) for v in eq.wire_lengths]
        wires.effort = [float(v) for v in eq.wire_tensions]
        self.pub_wires.publish(wires)

    def _report(self):
        level = ERROR if self.status.startswith('no_equilibrium') else OK
        pairs = self.counters.as_pairs() + [('failed_solves', str(self.failures)),
                                            ('cached_failures', str(len(self.failed))), ('axis', self.axis),
                                            ('load', str(self.load.tolist()))]
        return level, self.status, pairs


#: The node a rig host loads (crane_stiffness.launcher.rig_host), built with its node arguments (``cli_args``).
COMPONENT = CraneModel


def main(args=None) -> int:
    return run(CraneModel, args)


if __name__ == '__main__':
    raise SystemExit(main())
