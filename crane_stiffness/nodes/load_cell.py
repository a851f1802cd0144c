"""load_cell: a simulated six-axis force/torque sensor (a thin adapter around sim.sensors.LoadCellModel).

Subscribes /crane/applied_wrench (WrenchStamped, reliable) = the load crane_model has in force after each command
(never the raw command: a command the model rejects reaches no sensor), held from its header stamp on. Nothing is
published before the first applied wrench (crane_model sends the load in force to a reader that joins, so a load
cell started before crane_model waits for it, says so on /diagnostics and in its log, and starts then). Publishes
/load_cell/wrench (WrenchStamped [N, N·m], sensor QoS, frame ``frame_id``) sampled at
``sample_rate_hz`` with noise, bias, drift, cross-talk, quantization and overload saturation (and, when asked, true
calibration errors and coloured noise: ``truth.*``, ``noise.*``; its certificate is declared as ``calibration.*``,
crane_stiffness.sim.calibration); a timer at
``publish_rate_hz`` publishes the samples taken since its last tick, each stamped with its own sample instant on the
grid k/sample_rate_hz of the node clock (like a DAQ delivering buffers; the timer ticks on the grid
k/publish_rate_hz, see nodes.sensor_timing.create_grid_timer). Service ~/tare (std_srvs/Trigger) zeroes
the sensor on the mean of ``tare_samples`` readings at the current load; the reply states the offsets. Overload is
reported on /diagnostics (WARN).

A re-zero is visible to a consumer: /diagnostics carries the tare ``offset``, ``tare_count`` and
``tared_at`` (node-clock stamp of the last tare [ns], 0 = none) and ``started_at`` (the node's start [ns]), so a
restart or a tare shows as a new start time or a new count. The tare count is also published, latched, on
/load_cell/tare (std_msgs/Float64, at start and after every tare): the estimator starts a new fit segment on it.
Counters: received = used + dropped_non_finite
(applied wrenches); published = samples; waiting_samples = sample instants passed before the first applied wrench.
"""
from __future__ import annotations

from typing import Any, cast

import numpy as np
from numpy.typing import NDArray
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from std_srvs.srv import Trigger

from crane_stiffness.contract import topics
from crane_stiffness.contract.axes import AXES
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.rosnode.qos import RELIABLE_QOS, sensor_qos, stream_qos
from crane_stiffness.rosnode.diagnostics import Diagnostics, SensorCounters
from crane_stiffness.rosnode.sensor_timing import (
    STATE_WAIT_PARAM, SampleSchedule, ZeroEpoch, check_sensor_params, sensor_timing_params,
)
from crane_stiffness.rosnode.sim_time import SimTimeParticipant, drain
from crane_stiffness.rosnode.messages import finite
from crane_stiffness.rosnode.control_callers import ServiceCallers
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.parameters import Params
from crane_stiffness.serde.stamps import split_ns, stamp_ns
from crane_stiffness.sim.sampling import SampleClock, StampedHold
from crane_stiffness.sim.calibration import LOAD_CELL_CALIBRATION_PARAMS
from crane_stiffness.sim.sensors import (LOAD_CELL_IMPERFECTION_PARAMS, LOAD_CELL_PARAMS, LoadCellModel,
                                         load_cell_from_params)
from crane_stiffness.contract.status import ERROR, OK, WARN

PARAMS = (
    *sensor_timing_params('load_cell', 'header.frame_id of the published wrench; axes aligned with crane_base [-]'),
    *LOAD_CELL_PARAMS,
    *LOAD_CELL_CALIBRATION_PARAMS,
    *LOAD_CELL_IMPERFECTION_PARAMS,
    ParamSpec('tare_samples', 100, 'readings averaged by the ~/tare service [samples]', low=1),
    STATE_WAIT_PARAM,
)


def _validate(values: dict[str, Any]) -> LoadCellModel:
    check_sensor_params(values)
    return load_cell_from_params(values)  # names a bad field


class LoadCell(Node):
    """Holds the applied wrench; each timer tick measures and publishes the samples due since the last one."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('load_cell', **kwargs)
        self.counters = SensorCounters()
        self.saturated = np.zeros(6, dtype=np.int64)    # saturated samples per axis, since start
        self._saturated_reported = np.zeros(6, dtype=np.int64)
        self.applied = StampedHold(6)  # no value until crane_model says which load is in force
        self.tared_at_ns = 0
        self.model: LoadCellModel | None = None  # set by _apply (Params, below): _tick asserts it
        self.schedule = SampleSchedule(self, self._tick)
        self.settings: dict[str, Any] = {}
        # Drift time origin; also the start reported. On simulated time the clock reads 0 until the first /clock:
        # then the first sample instant is the origin.
        self.t0_ns = self.get_clock().now().nanoseconds
        self.pub = self.create_publisher(WrenchStamped, topics.LOAD_CELL_WRENCH, sensor_qos(self.schedule.sim_time))
        # Tares since start, latched on /load_cell/tare; on simulated time sent at the first watermark, counted, so the
        # recorder logs it at the start in every run (not whenever DDS matched it).
        self.tare_epoch = ZeroEpoch(self, topics.LOAD_CELL_TARE, publish=not self.schedule.sim_time)
        self.params = Params(self, PARAMS, _validate, self._apply)
        self.sub_applied = self.create_subscription(WrenchStamped, topics.APPLIED_WRENCH, self._on_applied,
                                                    stream_qos(RELIABLE_QOS, self.schedule.sim_time))
        self.sim = SimTimeParticipant(self, 2, self._on_watermark, inputs=[topics.APPLIED_WRENCH],
                                      drain=lambda: drain(self.sub_applied, self._on_applied))
        self.sim.counted(self.pub)
        self.sim.counted(self.tare_epoch.pub)
        self._epoch_sent = not self.schedule.sim_time
        self.create_service(Trigger, '~/tare', self._srv_tare)
        self.callers = ServiceCallers(self)  # who tares (the live view names its client)
        self.diagnostics = Diagnostics(self, self._report)
        self.get_logger().info(f'{topics.WAITING_FOR_LOAD} before publishing')

    @property
    def clock(self) -> SampleClock:
        """The sample clock (period, skipped samples)."""
        assert self.schedule.clock is not None  # configured by _apply (Params, in __init__)
        return self.schedule.clock

    @property
    def tare_count(self) -> int:
        """Tares since start: the epoch latched on /load_cell/tare (one count, not two kept in step)."""
        return self.tare_epoch.count

    def _apply(self, model: LoadCellModel, values: dict[str, Any]) -> None:
        if self.model is not None and self.model.offset.any():
            model.tare(self.model.offset)  # keep the tare across a parameter change
        if model.truth is not None and not model.truth.perfect and (
                self.model is None or self.model.truth is None or model.truth.as_dict() != self.model.truth.as_dict()):
            self.get_logger().info(f'true calibration errors ({values["truth.mode"]}): {model.truth.as_dict()}')
        self.model = model
        self.schedule.configure(values['sample_rate_hz'], values['publish_rate_hz'])
        self.schedule.gate.wait_ns = round(values['state_wait_s'] * 1e9)
        self.settings = values

    def _on_applied(self, msg: WrenchStamped) -> None:
        self.counters.received += 1
        self.sim.received(topics.APPLIED_WRENCH)
        f, m = msg.wrench.force, msg.wrench.torque
        wrench = (f.x, f.y, f.z, m.x, m.y, m.z)
        if not finite(wrench):  # crane_model never sends one; another publisher might
            self.counters.dropped_non_finite += 1
            self.get_logger().warning(f'non-finite applied wrench dropped: {list(wrench)}', throttle_duration_sec=2.0)
            return
        first = not self.applied.has_value
        sent_ns = stamp_ns(msg.header.stamp.sec, msg.header.stamp.nanosec)
        self.applied.update(wrench, sent_ns, self.schedule.arrival_ns(sent_ns))
        self.counters.used += 1
        if first:
            self.get_logger().info(f'first applied wrench {list(wrench)}: publishing')

    def _on_watermark(self, t_ns: int) -> None:
        """Simulated time: every applied wrench up to ``t_ns`` is in: measure and publish the instants up to it."""
        if not self._epoch_sent:
            self._epoch_sent = True
            self.tare_epoch.step(0)
        self._measure(self.schedule.due_until(t_ns))
        self.sim.report(t_ns)

    def _tick(self) -> None:
        self._measure(self.schedule.released(self.applied))

    def _measure(self, times) -> None:
        """Measure and publish the sample instants ``times`` (int64 ns, ascending)."""
        if times.size == 0:
            return
        if self.t0_ns <= 0:
            self.t0_ns = int(times[0])
        true_wrench, valid = self.applied.read(times)
        if not valid.all():  # instants before the first applied wrench: nothing to measure
            self.counters.waiting_samples += int((~valid).sum())
            times, true_wrench = times[valid], true_wrench[valid]
            if times.size == 0:
                return
        assert self.model is not None
        readings, saturated = self.model.measure(true_wrench, (times - self.t0_ns) * 1e-9)
        if saturated.any():
            self.saturated += saturated.sum(axis=0)
            per_axis = cast(NDArray[np.bool_], saturated.any(axis=0))  # a batch (n, 6): one flag per axis
            self.get_logger().warning(
                f'overload: {", ".join(a for a, s in zip(AXES, per_axis) if s)} saturated at '
                f'full scale {self.settings["full_scale"]}', throttle_duration_sec=2.0)
        frame = self.settings['frame_id']
        for t_ns, r in zip(times.tolist(), readings.tolist()):
            msg = WrenchStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(t_ns)
            msg.header.frame_id = frame
            f, m = msg.wrench.force, msg.wrench.torque
            f.x, f.y, f.z, m.x, m.y, m.z = r
            self.pub.publish(msg)
        self.counters.published += times.size

    def _srv_tare(self, request, response):
        n = self.params['tare_samples']
        now_ns = self.get_clock().now().nanoseconds
        load = self.applied.latest
        if load is None:
            response.success, response.message = False, f'cannot tare: {topics.WAITING_FOR_LOAD}'
            return response
        readings, _ = self.model.measure(np.tile(load, (n, 1)), np.full(n, (now_ns - self.t0_ns) * 1e-9))
        offset = self.model.tare(readings)
        self.tared_at_ns = now_ns
        self.tare_epoch.step()  # before the next burst: the estimator starts a new segment on it
        response.success = True
        response.message = (f'tared on {n} samples: offset [fx fy fz] = {[round(v, 6) for v in offset[:3].tolist()]} '
                            f'N, [mx my mz] = {[round(v, 7) for v in offset[3:].tolist()]} N·m')
        self.get_logger().info(f'~/tare by {self.callers.caller(self.callers.service_name("~/tare"))}: '
                               f'{response.message}')
        return response

    def _report(self):
        new = self.saturated - self._saturated_reported
        self._saturated_reported = self.saturated.copy()
        pairs = self.counters.as_pairs() + [
            ('skipped_samples', str(self.clock.skipped)), ('late_state_updates', str(self.applied.late)),
            ('offset', str([round(v, 7) for v in self.model.offset.tolist()])),
            ('tare_count', str(self.tare_count)), ('tared_at', str(self.tared_at_ns)),
            ('started_at', str(self.t0_ns)),
        ] + [(f'saturated_{a}', str(int(n))) for a, n in zip(AXES, self.saturated)]
        if new.any():
            axes = ', '.join(f'{a} ({int(n)} samples)' for a, n in zip(AXES, new) if n)
            return WARN, f'overload: {axes} saturated at full scale since the last report', pairs
        if not self.applied.has_value:
            return OK, topics.WAITING_FOR_LOAD, pairs
        if self.applied.late and self.sim.active:  # cannot happen on simulated time unless the clock's protocol failed
            return ERROR, (f'{self.applied.late} applied wrench(es) arrived after samples at their stamps were '
                           'published'), pairs
        if self.applied.late and self.settings['state_wait_s'] > 0:
            return WARN, (f'{self.applied.late} applied wrench(es) arrived after samples at their stamps were '
                          f'published (longer than state_wait_s = {self.settings["state_wait_s"]:g} s)'), pairs
        return OK, f'{self.counters.published} samples published', pairs


#: The node a rig host loads (crane_stiffness.launcher.rig_host), built with its node arguments (``cli_args``).
COMPONENT = LoadCell


def main(args=None) -> int:
    return run(LoadCell, args)


if __name__ == '__main__':
    raise SystemExit(main())
