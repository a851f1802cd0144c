"""crane_model: the nonlinear crane under the commanded wrench (a thin adapter around crane_stiffness.model).

Subscribes /crane/wrench_command (WrenchStamped, frame crane_base); publishes /crane/platform_pose (PoseStamped,
frame crane_base = the paper's frame, z down; stamped with the command's stamp), /crane/wire_states (JointState:
wire_1..wire_6, position = length [m], effort = tension [N]), /crane/predicted_stiffness (Float64MultiArray 6×6
tangent) and /crane/predicted_axis_stiffness (Float64 along the commanded axis), and /crane/model_status (String:
'ok …' or 'no_equilibrium …'). Geometry from the geometry.* parameters, changeable at run time.

The stiffness topics and the status are latched. The pose is not (it is a stream), so a reader that joins late (the
simulated LVDT started after this node, in any order) is sent the current pose when it matches: it can publish
before the first command, and load_program waits for that (crane_stiffness.nodes.load_program).
"""
from __future__ import annotations

from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, String

from crane_stiffness import topics
from crane_stiffness.config import GEOMETRY_PARAMS, ParamSpec, geometry_from_params
from crane_stiffness.model import (AXES, WIRE_NAMES, CraneGeometry, Equilibrium, ModelError, axis_stiffness,
                                   rest_pose, solve_equilibrium, tangent_stiffness)
from crane_stiffness.model.rotation import matrix_to_quaternion
from crane_stiffness.nodes.common import LATCHED_QOS, RELIABLE_QOS, Counters, Diagnostics, finite, run
from crane_stiffness.nodes.parameters import Params, check
from crane_stiffness.status import ERROR, OK

MODEL_STATUS = topics.MODEL_STATUS

PARAMS = GEOMETRY_PARAMS + (
    ParamSpec('prediction_axis', 'auto', "axis of the predicted stiffness: fx fy fz mx my mz, or 'auto' = the "
              'largest component of the command (fy until a load arrives)'),
    ParamSpec('max_abs_force', 1.0e4, 'commands with a force component above this are absurd and dropped [N]',
              rule='> 0'),
    ParamSpec('max_abs_moment', 1.0e3, 'commands with a moment component above this are absurd and dropped [N·m]',
              rule='> 0'),
)


def _validate(values: dict[str, Any]) -> CraneGeometry:
    check(values['prediction_axis'] in ('auto',) + AXES, 'prediction_axis', values['prediction_axis'],
          f"must be 'auto' or one of {', '.join(AXES)}")
    for name in ('max_abs_force', 'max_abs_moment'):
        check(values[name] > 0, name, values[name], 'must be > 0')
    geometry = geometry_from_params(values)  # raises GeometryError (a ValueError) naming the field
    rest_pose(geometry)  # a geometry whose rest pose cannot be found is rejected too
    return geometry


class CraneModel(Node):
    """Holds the geometry and the last equilibrium; each command is solved warm-started from the last one."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('crane_model', **kwargs)
        self.counters = Counters()
        self.failures = 0
        self.status = 'starting'
        self.geometry: CraneGeometry | None = None
        self.equilibrium: Equilibrium | None = None
        self.load = np.zeros(6)
        self.axis = 'fy'
        self.stamp = None
        self.solved: tuple | None = None  # the load the published pose and stiffness belong to (None: re-solve)
        self.pub_pose = self.create_publisher(PoseStamped, topics.PLATFORM_POSE, RELIABLE_QOS,
                                              event_callbacks=PublisherEventCallbacks(matched=self._on_pose_matched))
        self.pub_wires = self.create_publisher(JointState, topics.WIRE_STATES, RELIABLE_QOS)
        self.pub_k = self.create_publisher(Float64MultiArray, topics.PREDICTED_STIFFNESS, LATCHED_QOS)
        self.pub_axis = self.create_publisher(Float64, topics.PREDICTED_AXIS_STIFFNESS, LATCHED_QOS)
        self.pub_status = self.create_publisher(String, MODEL_STATUS, LATCHED_QOS)
        self.diagnostics = Diagnostics(self, self._report)
        self.settings: dict[str, Any] = {}
        self.params = Params(self, PARAMS, _validate, self._set_geometry)
        self.create_subscription(WrenchStamped, topics.WRENCH_COMMAND, self._on_command, RELIABLE_QOS)

    # --- callbacks ---
    def _set_geometry(self, geometry: CraneGeometry, values: dict[str, Any]) -> None:
        changed = geometry != self.geometry
        self.geometry = geometry
        self.settings = values
        self.solved = None  # any parameter change: solve and publish everything again
        if changed:
            self.equilibrium = None  # a new crane: solve from its own rest pose
            self.get_logger().info(
                f'geometry: a = {geometry.a} m, b = {geometry.b} m, h = {geometry.height} m, '
                f'l0 = {geometry.l0:.6f} m, W = {geometry.weight} N, k = {geometry.k:.6g} N/m')
        self._solve_and_publish()

    def _on_command(self, msg: WrenchStamped) -> None:
        self.counters.received += 1
        f, m = msg.wrench.force, msg.wrench.torque
        load = np.array([f.x, f.y, f.z, m.x, m.y, m.z])
        if not finite(load):
            self.counters.dropped_non_finite += 1
            return
        if (np.abs(load[:3]).max() > self.settings['max_abs_force']
                or np.abs(load[3:]).max() > self.settings['max_abs_moment']):
            self.counters.dropped_absurd += 1
            self.get_logger().warning(f'absurd wrench command dropped: {load.tolist()}',
                                           throttle_duration_sec=2.0)
            return
        self.load = load
        self.stamp = msg.header.stamp if (msg.header.stamp.sec or msg.header.stamp.nanosec) else None
        if self.solved == tuple(load.tolist()):
            # A hold repeats the command at the program's rate: the same equilibrium, pose restamped. The latched
            # stiffness topics already carry its values.
            self._publish_pose(self.equilibrium)
            self.counters.published += 1
            return
        self._solve_and_publish()

    def _on_pose_matched(self, status) -> None:
        """A new pose reader: send it the current pose (stamped now), as a latched topic would."""
        if status.current_count_change > 0 and self.equilibrium is not None:
            stamp, self.stamp = self.stamp, None
            self._publish_pose(self.equilibrium)
            self.stamp = stamp

    # --- work ---
    def _solve_and_publish(self) -> None:
        g = self.geometry
        try:
            eq = solve_equilibrium(g, load=self.load, initial=self.equilibrium)
        except ModelError as exc:
            self.failures += 1
            self.solved = None  # the same load again must be solved again (and clear this status)
            self.status = f'no_equilibrium: {exc}'
            self.pub_status.publish(String(data=self.status))
            self.get_logger().error(str(exc), throttle_duration_sec=1.0)
            self.diagnostics.publish()
            return  # keep the last valid pose; nothing wrong is published
        self.equilibrium = eq
        self.solved = tuple(self.load.tolist())
        self._publish_pose(eq)
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
        new_status = f'ok: {int(eq.slack.sum())} slack wire(s)'
        if new_status != self.status:
            self.status = new_status
            self.pub_status.publish(String(data=self.status))

    def _publish_pose(self, eq: Equilibrium) -> None:
        """The platform pose and the wire states of ``eq``, stamped with the command's stamp (else now)."""
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
        pairs = self.counters.as_pairs() + [('failed_solves', str(self.failures)), ('axis', self.axis),
                                            ('load', str(self.load.tolist()))]
        return level, self.status, pairs


def main(args=None) -> int:
    return run(CraneModel, args)


if __name__ == '__main__':
    raise SystemExit(main())
