"""pose_sensor: a simulated motion-capture tracker watching the platform (a thin adapter around
sim.pose_sensor.PoseSensorModel).

Subscribes /crane/platform_pose (PoseStamped, frame crane_base), held from its header stamp on. Publishes
/pose_sensor/pose (PoseStamped, sensor QoS, frame ``frame_id``): the platform centre's position [m] and orientation
(unit quaternion [x, y, z, w], body -> crane_base) with white noise and a constant bias, as a motion-capture driver
publishes a rigid body's pose: vrpn_mocap's /vrpn_mocap/<tracker>/pose takes this node's place by remapping alone
(mocap4r2's drivers publish mocap4r2_msgs/RigidBodies, which a one-body relay turns into PoseStamped). Samples at
``sample_rate_hz`` on the grid k/sample_rate_hz of the node clock, with the simulated LVDT's semantics: a reading
stamped t is the pose in force at t (the last pose stamped at or before it) plus the noise. Nothing is published
before the first pose.

On wall-clock time the samples go out at the ticks of ``publish_rate_hz`` (on the grid k/publish_rate_hz), each no
earlier than ``latency_s`` after its stamp (a tracker's processing delay) and, with ``state_wait_s``, once the pose at
its stamp is known. On simulated time the node is a sensor of stage 2: it samples up to the stage's watermark once
every pose published up to it is in, and publishes at once; ``latency_s`` changes no stamp and no value there, and
delays nothing.

/diagnostics: the counters, ``skipped_samples``, ``late_state_updates``, ``latency_s``, ``publish_delay_min_ms`` (the
shortest time from a stamp to its publication in the run, wall-clock time; at least ``latency_s``),
``publish_delay_max_ms`` (the longest since the previous report), ``started_at`` (the node's start [ns]).
Counters (and FINAL_COUNTERS): received = used + dropped_non_finite (poses); published = samples.
"""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node

from crane_stiffness.contract import topics
from crane_stiffness.rosnode.diagnostics import Diagnostics, SensorCounters
from crane_stiffness.rosnode.messages import pose_position_quaternion, pose_stamped
from crane_stiffness.rosnode.parameters import Params
from crane_stiffness.rosnode.qos import RELIABLE_QOS, sensor_qos, stream_qos
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.sensor_timing import STATE_WAIT_PARAM, SampleSchedule, check_sensor_params, \
    sensor_timing_params
from crane_stiffness.rosnode.sim_time import SimTimeParticipant, drain
from crane_stiffness.serde.stamps import stamp_ns
from crane_stiffness.sim.calibration import POSE_SENSOR_CALIBRATION_PARAMS, POSE_SENSOR_COMPONENTS, calibration_of
from crane_stiffness.sim.pose_sensor import POSE_SENSOR_PARAMS, PoseSensorModel, pose_sensor_from_params
from crane_stiffness.sim.sampling import ReleaseGate, SampleClock, StampedHold
from crane_stiffness.contract.status import ERROR, OK, WARN

#: A motion-capture system's frame rate, and one message per frame.
SAMPLE_RATE_HZ = 250.0
_TIMING_DEFAULTS = {'sample_rate_hz': SAMPLE_RATE_HZ, 'publish_rate_hz': SAMPLE_RATE_HZ}

PARAMS = (
    *(dataclasses.replace(spec, default=_TIMING_DEFAULTS.get(spec.name, spec.default)) for spec in
      sensor_timing_params(topics.FRAME_BASE, 'header.frame_id of the published pose; the pose is in crane_base '
                           'whatever it says (a label, as a tracker names its world frame) [-]')),
    *POSE_SENSOR_PARAMS,
    *POSE_SENSOR_CALIBRATION_PARAMS,
    STATE_WAIT_PARAM,
)


def _validate(values: dict[str, Any]) -> PoseSensorModel:
    check_sensor_params(values)
    calibration_of(values, POSE_SENSOR_COMPONENTS)  # the declared accuracy: refused when malformed
    return pose_sensor_from_params(values)  # names a bad field


class PoseSensor(Node):
    """Holds the platform pose; each timer tick (or watermark) measures and publishes the samples due."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('pose_sensor', **kwargs)
        self.counters = SensorCounters()
        self.started_at_ns = self.get_clock().now().nanoseconds
        self.pose = StampedHold(7)  # [position (3), quaternion x y z w (4)]
        self.model: PoseSensorModel | None = None  # set by _apply (Params, below): the methods assert it
        self.schedule = SampleSchedule(self, self._tick)
        self.latency = ReleaseGate(0)  # wall-clock time: instants wait latency_s after their stamp
        self.delay_min_ns: int | None = None  # shortest stamp -> publication of the run (wall-clock time)
        self.delay_max_ns = 0                 # longest since the previous report
        self.settings: dict[str, Any] = {}
        self.pub = self.create_publisher(PoseStamped, topics.POSE_SENSOR_POSE, sensor_qos(self.schedule.sim_time))
        self.params = Params(self, PARAMS, _validate, self._apply)
        self.sub_pose = self.create_subscription(PoseStamped, topics.PLATFORM_POSE, self._on_pose,
                                                 stream_qos(RELIABLE_QOS, self.schedule.sim_time))
        self.sim = SimTimeParticipant(self, 2, self._on_watermark, inputs=[topics.PLATFORM_POSE],
                                      drain=lambda: drain(self.sub_pose, self._on_pose))
        self.sim.counted(self.pub)
        self.diagnostics = Diagnostics(self, self._report)

    @property
    def clock(self) -> SampleClock:
        """The sample clock (period, skipped samples)."""
        assert self.schedule.clock is not None  # configured by _apply (Params, in __init__)
        return self.schedule.clock

    def _apply(self, model: PoseSensorModel, values: dict[str, Any]) -> None:
        if self.model is not None and values['seed'] == self.settings['seed']:
            model.continue_noise_of(self.model)  # a new set-up, the same noise stream (a new seed restarts it)
        self.model = model
        self.schedule.configure(values['sample_rate_hz'], values['publish_rate_hz'])
        self.schedule.gate.wait_ns = round(values['state_wait_s'] * 1e9)
        self.latency.wait_ns = round(values['latency_s'] * 1e9)
        self.settings = values

    def _on_pose(self, msg: PoseStamped) -> None:
        self.counters.received += 1
        self.sim.received(topics.PLATFORM_POSE)
        pose = pose_position_quaternion(msg)
        if pose is None:
            self.counters.dropped_non_finite += 1
            return
        sent_ns = stamp_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)
        self.pose.update(pose, sent_ns, self.schedule.arrival_ns(sent_ns))
        self.counters.used += 1

    def _on_watermark(self, t_ns: int) -> None:
        """Simulated time: every pose up to ``t_ns`` is in: measure and publish the instants up to it."""
        self._measure(self.schedule.due_until(t_ns))
        self.sim.report(t_ns)

    def _tick(self) -> None:
        """Wall-clock time: the instants whose pose is known (or waited for), once ``latency_s`` has passed them."""
        self.latency.add(self.schedule.released(self.pose))
        self._measure(self.latency.release(-1, self.get_clock().now().nanoseconds))

    def _measure(self, times: np.ndarray) -> None:
        """Measure and publish the sample instants ``times`` (int64 ns, ascending)."""
        if times.size == 0:
            return
        poses, valid = self.pose.read(times)
        if not valid.all():  # instants before the first pose: nothing to measure
            self.counters.waiting_samples += int((~valid).sum())
            times, poses = times[valid], poses[valid]
            if times.size == 0:
                return
        assert self.model is not None
        positions, quaternions = self.model.measure(poses[:, :3], poses[:, 3:])
        frame = self.settings['frame_id']
        for t_ns, u, q in zip(times.tolist(), positions.tolist(), quaternions.tolist()):
            self.pub.publish(pose_stamped(t_ns, frame, u, q))
        self.counters.published += times.size
        if not self.sim.active:
            delays = self.get_clock().now().nanoseconds - times
            self.delay_max_ns = max(self.delay_max_ns, int(delays.max()))
            shortest = int(delays.min())
            self.delay_min_ns = shortest if self.delay_min_ns is None else min(self.delay_min_ns, shortest)

    def _report(self):
        worst, self.delay_max_ns = self.delay_max_ns, 0
        pairs = self.counters.as_pairs() + [
            ('skipped_samples', str(self.clock.skipped)),
            ('late_state_updates', str(self.pose.late)),
            ('latency_s', repr(self.settings['latency_s'])),
            ('publish_delay_min_ms', '' if self.delay_min_ns is None else f'{self.delay_min_ns * 1e-6:.3f}'),
            ('publish_delay_max_ms', f'{worst * 1e-6:.3f}'),
            ('started_at', str(self.started_at_ns))]
        if not self.pose.has_value:
            return OK, f'waiting for {topics.PLATFORM_POSE}', pairs
        if self.pose.late and self.sim.active:  # cannot happen on simulated time unless the clock's protocol failed
            return ERROR, f'{self.pose.late} pose(s) arrived after samples at their stamps were published', pairs
        if self.pose.late and self.settings['state_wait_s'] > 0:
            return WARN, (f'{self.pose.late} pose(s) arrived after samples at their stamps were published (longer '
                          f'than state_wait_s = {self.settings["state_wait_s"]:g} s)'), pairs
        return OK, f'{self.counters.published} samples published', pairs


#: The node a rig host loads (crane_stiffness.launcher.rig_host), built with its node arguments (``cli_args``).
COMPONENT = PoseSensor


def main(args=None) -> int:
    return run(PoseSensor, args)


if __name__ == '__main__':
    raise SystemExit(main())
