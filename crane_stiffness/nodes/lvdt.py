"""lvdt: a simulated LVDT touching the platform (a thin adapter around sim.sensors.LvdtModel).

Subscribes /crane/platform_pose (PoseStamped, frame crane_base), held from its header stamp on. Publishes
/lvdt/displacement (PointStamped, sensor QoS, frame ``frame_id``): point.x = the reading [m] along ``axis`` of the
contact point ``contact_point`` (body frame) relative to the zero, with noise, resolution and a stroke
``range_m`` outside which the reading saturates (throttled warning, WARN on /diagnostics), and when asked true
calibration errors and coloured noise (``truth.*``, ``noise.*``; its certificate is declared as ``calibration.*``,
crane_stiffness.sim.calibration). Samples at
``sample_rate_hz`` on the grid k/sample_rate_hz of the node clock, published in bursts at ``publish_rate_hz`` (ticks
on the grid k/publish_rate_hz, together with the load cell's).
Nothing is published before the first pose. Service ~/zero (std_srvs/Trigger) zeroes at the current pose;
``zero_on_first_pose`` zeroes at the first pose received (the loaded rest pose).

A re-zero is visible to a consumer: /diagnostics carries ``zero_offset_m`` (where the zero lies
along the axis from the rest pose [m]; a re-zero at another pose steps it), ``zero_count``, ``zeroed_at`` (node-clock
stamp of the last zero [ns], 0 = none) and ``started_at`` (the node's start [ns]): a restarted LVDT, which zeroes
itself again, shows a new start time. The zero count is also published, latched, on /lvdt/zero (std_msgs/Float64,
after every zero, and 0 at start unless ``zero_on_first_pose``): the estimator starts a new fit segment on it.
Counters: received = used + dropped_non_finite (poses); published = samples.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped
from rclpy.node import Node
from std_srvs.srv import Trigger

from crane_stiffness.contract import topics
from crane_stiffness.rosnode.qos import RELIABLE_QOS, sensor_qos, stream_qos
from crane_stiffness.rosnode.diagnostics import Diagnostics, SensorCounters
from crane_stiffness.rosnode.sensor_timing import (
    STATE_WAIT_PARAM, SampleSchedule, ZeroEpoch, check_sensor_params, sensor_timing_params,
)
from crane_stiffness.rosnode.sim_time import SimTimeParticipant, drain
from crane_stiffness.rosnode.messages import pose_vector
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.parameters import Params
from crane_stiffness.serde.stamps import split_ns, stamp_ns
from crane_stiffness.sim.sampling import SampleClock, StampedHold
from crane_stiffness.sim.calibration import LVDT_CALIBRATION_PARAMS
from crane_stiffness.sim.sensors import LVDT_IMPERFECTION_PARAMS, LVDT_PARAMS, LvdtModel, lvdt_from_params
from crane_stiffness.contract.status import ERROR, OK, WARN

PARAMS = (
    *sensor_timing_params('lvdt', 'header.frame_id of the published reading [-]'),
    *LVDT_PARAMS,
    *LVDT_CALIBRATION_PARAMS,
    *LVDT_IMPERFECTION_PARAMS,
    STATE_WAIT_PARAM,
)


def _validate(values: dict[str, Any]) -> LvdtModel:
    check_sensor_params(values)
    return lvdt_from_params(values)  # names a bad field


class Lvdt(Node):
    """Holds the platform pose; each timer tick measures and publishes the samples due since the last one."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('lvdt', **kwargs)
        self.counters = SensorCounters()
        self.started_at_ns = self.get_clock().now().nanoseconds
        self.t0_ns = self.started_at_ns  # the coloured noise's time origin (on simulated time: the first instant)
        self.zeroed_at_ns = 0
        self.out_of_range = 0       # saturated samples since start
        self._out_of_range_reported = 0
        self.zero_pose: np.ndarray | None = None  # [u, Q] of the pose the sensor was zeroed at
        self.pose = StampedHold(12)
        self.model: LvdtModel | None = None  # set by _apply (Params, below): the methods assert it
        self.schedule = SampleSchedule(self, self._tick)
        self.settings: dict[str, Any] = {}
        self.pub = self.create_publisher(PointStamped, topics.LVDT_DISPLACEMENT, sensor_qos(self.schedule.sim_time))
        self.zero_epoch = ZeroEpoch(self, topics.LVDT_ZERO, publish=False)  # zeros since start, latched
        self.params = Params(self, PARAMS, _validate, self._apply)
        # (else epoch 1 at the first pose, before any reading; on simulated time at the first watermark, counted, so
        # the recorder logs it at the start in every run)
        self._epoch_due = not self.settings['zero_on_first_pose']
        if self._epoch_due and not self.schedule.sim_time:
            self._epoch_due = False
            self.zero_epoch.step(0)
        self.sub_pose = self.create_subscription(PoseStamped, topics.PLATFORM_POSE, self._on_pose,
                                                 stream_qos(RELIABLE_QOS, self.schedule.sim_time))
        self.sim = SimTimeParticipant(self, 2, self._on_watermark, inputs=[topics.PLATFORM_POSE],
                                      drain=lambda: drain(self.sub_pose, self._on_pose))
        self.sim.counted(self.pub)
        self.sim.counted(self.zero_epoch.pub)
        self.create_service(Trigger, '~/zero', self._srv_zero)
        self.diagnostics = Diagnostics(self, self._report)

    @property
    def clock(self) -> SampleClock:
        """The sample clock (period, skipped samples)."""
        assert self.schedule.clock is not None  # configured by _apply (Params, in __init__)
        return self.schedule.clock

    @property
    def zero_count(self) -> int:
        """Zeros since start: the epoch latched on /lvdt/zero (one count, not two kept in step)."""
        return self.zero_epoch.count

    def _apply(self, model: LvdtModel, values: dict[str, Any]) -> None:
        self.model = model
        if self.zero_pose is not None:
            self._zero(self.zero_pose, new=False)  # the new sensor set-up keeps the zero
        self.schedule.configure(values['sample_rate_hz'], values['publish_rate_hz'])
        self.schedule.gate.wait_ns = round(values['state_wait_s'] * 1e9)
        self.settings = values

    def _zero(self, pose: np.ndarray, *, new: bool = True) -> None:
        """Zero the model at ``pose``; ``new``: a zero of its own (counted), not one carried over to a new model."""
        assert self.model is not None
        self.model.zero(pose[:3], pose[3:].reshape(3, 3))
        self.zero_pose = pose
        if new:
            self.zeroed_at_ns = self.get_clock().now().nanoseconds
            self.zero_epoch.step()  # before the next burst: the estimator starts a new segment on it

    def _on_pose(self, msg: PoseStamped) -> None:
        self.counters.received += 1
        self.sim.received(topics.PLATFORM_POSE)
        pose = pose_vector(msg)
        if pose is None:
            self.counters.dropped_non_finite += 1
            return
        first = not self.pose.has_value
        sent_ns = stamp_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)
        self.pose.update(pose, sent_ns, self.schedule.arrival_ns(sent_ns))
        self.counters.used += 1
        if first and self.settings['zero_on_first_pose']:
            self._zero(pose)
            assert self.model is not None
            self.get_logger().info(f'zeroed at the first pose: u = {pose[:3].tolist()} m, zero offset '
                                   f'{self.model.zero_offset:.9g} m')

    def _on_watermark(self, t_ns: int) -> None:
        """Simulated time: every pose up to ``t_ns`` is in: measure and publish the instants up to it."""
        if self._epoch_due:
            self._epoch_due = False
            self.zero_epoch.step(0)
        self._measure(self.schedule.due_until(t_ns))
        self.sim.report(t_ns)

    def _tick(self) -> None:
        self._measure(self.schedule.released(self.pose))

    def _measure(self, times) -> None:
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
        if self.t0_ns <= 0:
            self.t0_ns = int(times[0])
        readings, in_range = self.model.measure(poses[:, :3], poses[:, 3:].reshape(-1, 3, 3),
                                                (times - self.t0_ns) * 1e-9)
        if not in_range.all():
            self.out_of_range += int((~in_range).sum())
            self.get_logger().warning(f'displacement outside the stroke {self.model.range_m} m: reading saturated',
                                      throttle_duration_sec=2.0)
        frame = self.settings['frame_id']
        for t_ns, x in zip(times.tolist(), readings.tolist()):
            msg = PointStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(t_ns)
            msg.header.frame_id = frame
            msg.point.x = x
            self.pub.publish(msg)
        self.counters.published += times.size

    def _srv_zero(self, request, response):
        pose = self.pose.latest
        if pose is None:
            response.success, response.message = False, f'no pose received yet on {topics.PLATFORM_POSE}'
            return response
        self._zero(pose)
        response.success = True
        response.message = (f'zeroed at u = {[round(v, 9) for v in pose[:3].tolist()]} m, zero offset '
                            f'{self.model.zero_offset:.9g} m')
        self.get_logger().info(response.message)
        return response

    def _report(self):
        new = self.out_of_range - self._out_of_range_reported
        self._out_of_range_reported = self.out_of_range
        pairs = self.counters.as_pairs() + [('out_of_range', str(self.out_of_range)),
                                            ('skipped_samples', str(self.clock.skipped)),
                                            ('late_state_updates', str(self.pose.late)),
                                            ('zeroed', str(self.zero_pose is not None).lower()),
                                            ('zero_offset_m', repr(self.model.zero_offset)),
                                            ('zero_count', str(self.zero_count)),
                                            ('zeroed_at', str(self.zeroed_at_ns)),
                                            ('started_at', str(self.started_at_ns))]
        if new:
            return WARN, f'out of range: {new} samples saturated at the stroke {self.model.range_m} m', pairs
        if not self.pose.has_value:
            return OK, f'waiting for {topics.PLATFORM_POSE}', pairs
        if self.pose.late and self.sim.active:  # cannot happen on simulated time unless the clock's protocol failed
            return ERROR, f'{self.pose.late} pose(s) arrived after samples at their stamps were published', pairs
        if self.pose.late and self.settings['state_wait_s'] > 0:
            return WARN, (f'{self.pose.late} pose(s) arrived after samples at their stamps were published (longer '
                          f'than state_wait_s = {self.settings["state_wait_s"]:g} s)'), pairs
        return OK, f'{self.counters.published} samples published', pairs


#: The node a rig host loads (crane_stiffness.launcher.rig_host), built with its node arguments (``cli_args``).
COMPONENT = Lvdt


def main(args=None) -> int:
    return run(Lvdt, args)


if __name__ == '__main__':
    raise SystemExit(main())
