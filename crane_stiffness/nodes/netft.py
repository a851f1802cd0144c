"""netft: a real six-axis F/T sensor over RDT (ATI Net F/T, Ethernet Axia, OnRobot HEX) — a thin adapter around
crane_stiffness.drivers.rdt_client and rdt_pipeline.

Requests the sensor's UDP stream (``command``: real-time or buffered) from ``host:port`` and publishes
/load_cell/wrench (WrenchStamped [N, N·m] in the sensor's own frame ``frame_id``, sensor QoS; remap it like any
topic). Counts become N and N·m with ``counts_per_force`` / ``counts_per_torque``, or, when those are 0, with the
box's ``/netftapi2.xml`` (``device:=ati``) or OnRobot's fixed factors (``device:=onrobot``). Stamps come from the
sensor's sample counter (ft_sequence / ``sample_rate_hz``) anchored to the host clock with drift tracking
(drivers.clock), not from arrival times. ``publish_rate_hz`` > 0 publishes the mean of the samples in each interval
1/publish_rate_hz instead of every sample (7 kHz in, 1 kHz out). A timer at ``flush_rate_hz`` (on the clock grid,
with the other sensors) publishes what arrived since its last tick.

/diagnostics: records received, published, lost, out of order, late or duplicate (from rdt_sequence), records with
a non-zero status word (ERROR with the word in hex; ``drop_status_mask`` decides which are not published), the
clock's estimated rate error, reconnects (ERROR while the sensor is silent: the stream is requested again every
``reconnect_interval_s``), and when it flows again the restart (WARN for one report: the stream restarted, or the
device restarted and the clock with it; nothing received before the outage is published after it). Service ~/tare
(std_srvs/Trigger): ``tare_mode`` 'software' subtracts the mean of the last ``tare_samples`` readings (of the
current stream); 'hardware' sends the device's bias command (0x0042); either way the number of tares since start
is published, latched, on /load_cell/tare (std_msgs/Float64, at start and after every tare) so the estimator starts
a new fit segment. At start a wrong address or a silent device stops the node (exit 2) with the reason, after
trying for ``wait_for_device_s``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from std_srvs.srv import Trigger

from crane_stiffness.contract import topics
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.drivers import rdt
from crane_stiffness.drivers.errors import DriverError
from crane_stiffness.drivers.rdt_client import RdtReceiver, fetch_netftapi2
from crane_stiffness.drivers.rdt_pipeline import RdtPipeline
from crane_stiffness.rosnode.qos import SENSOR_QOS
from crane_stiffness.rosnode.control_callers import ServiceCallers
from crane_stiffness.rosnode.diagnostics import Counters, Diagnostics
from crane_stiffness.rosnode.sensor_timing import ZeroEpoch, create_grid_timer
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.parameters import Params, check, positive
from crane_stiffness.rosnode.device_params import check_address, check_start_only, wait_for_device
from crane_stiffness.serde.stamps import split_ns
from crane_stiffness.contract.status import ERROR, OK, WARN
from crane_stiffness.sim.calibration import LOAD_CELL_CALIBRATION_PARAMS, LOAD_CELL_COMPONENTS, calibration_of

DEVICES = ('ati', 'onrobot')
TARE_MODES = ('software', 'hardware')

PARAMS = (
    ParamSpec('host', '192.168.1.1', "the sensor's IP address or host name (ATI factory default 192.168.1.1) [-]"),
    ParamSpec('port', rdt.RDT_PORT, 'RDT UDP port of the sensor [-]', low=1, high=65535),
    ParamSpec('device', 'ati', "'ati' (Net F/T, Axia: counts per unit from the box's /netftapi2.xml) or 'onrobot' "
              '(HEX: 10000 counts/N, 100000 counts/N·m); counts_per_force/torque > 0 override both [-]'),
    ParamSpec('http_port', 80, "port of the ATI box's web server that serves /netftapi2.xml [-]", low=1, high=65535),
    ParamSpec('counts_per_force', 0.0, 'counts per newton; 0 = from the device [counts/N]'),
    ParamSpec('counts_per_torque', 0.0, 'counts per newton-metre; 0 = from the device [counts/(N·m)]'),
    ParamSpec('command', 'realtime', "'realtime' (RDT 0x0002, one record per datagram) or 'buffered' (0x0003, the "
              "box's output buffer of several records per datagram) [-]"),
    ParamSpec('sample_rate_hz', 7000.0, "rate of the sensor's sample counter ft_sequence, its internal sample rate "
              '(Net F/T 7000; an Axia or OnRobot box: see its manual) [Hz]'),
    ParamSpec('publish_rate_hz', 0.0, '0 = publish every record; > 0 = publish the mean of the records in each '
              'interval 1/publish_rate_hz of the host clock, stamped at the mean of their stamps [Hz]'),
    ParamSpec('flush_rate_hz', 500.0, 'rate of the timer that publishes what arrived since its last tick; ticks on '
              'the clock grid like the simulated sensors [Hz]'),
    ParamSpec('frame_id', 'ft_sensor', "header.frame_id: the sensor's own frame (see estimation.frames to move the "
              'wrench to the platform centre) [-]'),
    ParamSpec('tare_mode', 'software', "~/tare: 'software' = subtract the mean of the last tare_samples readings in "
              "the driver; 'hardware' = the device's bias command 0x0042 (and clear the software tare) [-]"),
    ParamSpec('tare_samples', 100, 'readings averaged by a software tare [samples]', low=1),
    ParamSpec('drop_status_mask', 0xFFFFFFFF, 'records whose status word has any of these bits set are counted and '
              'not published; 0 = publish every record [-]', low=0, high=0xFFFFFFFF),
    ParamSpec('timeout_s', 0.5, 'silence after which the sensor counts as gone [s]'),
    ParamSpec('reconnect_interval_s', 1.0, 'interval between stream requests while the sensor is gone [s]'),
    ParamSpec('wait_for_device_s', 3.0, "at start, time to wait for the device (the ATI box's /netftapi2.xml, then "
              'the first record) before stopping with an error; longer when the device (or its emulator) starts with '
              'the driver [s]'),
    *LOAD_CELL_CALIBRATION_PARAMS,
)
#: Read at start only: changing them means talking to another device, so the node must be restarted.
START_ONLY = ('host', 'port', 'device', 'http_port', 'counts_per_force', 'counts_per_torque', 'command',
              'sample_rate_hz', 'timeout_s', 'reconnect_interval_s', 'wait_for_device_s')


def _validate(values: dict[str, Any]) -> dict[str, Any]:
    check_address(values, ports=('port', 'http_port'))
    calibration_of(values, LOAD_CELL_COMPONENTS)  # the declared calibration: refused when malformed
    check(values['device'] in DEVICES, 'device', values['device'], f'must be one of {", ".join(DEVICES)}')
    check(values['command'] in rdt.STREAM_COMMANDS, 'command', values['command'],
          f'must be one of {", ".join(rdt.STREAM_COMMANDS)}')
    for name in ('counts_per_force', 'counts_per_torque'):
        check(values[name] >= 0, name, values[name], 'must be 0 (from the device) or > 0')
    check((values['counts_per_force'] > 0) == (values['counts_per_torque'] > 0), 'counts_per_torque',
          values['counts_per_torque'], 'set counts_per_force and counts_per_torque together (or both 0)')
    positive(values, 'sample_rate_hz', 'flush_rate_hz', 'timeout_s', 'reconnect_interval_s', 'wait_for_device_s')
    check(values['publish_rate_hz'] >= 0 and values['publish_rate_hz'] <= values['sample_rate_hz'],
          'publish_rate_hz', values['publish_rate_hz'], '0 (every record) or a rate up to sample_rate_hz')
    check(isinstance(values['frame_id'], str) and values['frame_id'] != '', 'frame_id', values['frame_id'],
          'must be a non-empty string')
    check(values['tare_mode'] in TARE_MODES, 'tare_mode', values['tare_mode'],
          f'must be one of {", ".join(TARE_MODES)}')
    return values


@dataclass
class FtCounters(Counters):
    """The node's counters: ``received`` = RDT records received; the rest from the driver (see drivers.rdt)."""

    records_lost: int = 0
    records_out_of_order: int = 0
    records_late_dropped: int = 0
    records_duplicate: int = 0
    status_records: int = 0
    status_dropped: int = 0
    malformed_datagrams: int = 0
    reconnects: int = 0
    stream_restarts: int = 0
    clock_resets: int = 0
    records_stale_dropped: int = 0


class NetFt(Node):
    """Receives the sensor's stream on a thread; each timer tick publishes the samples processed since the last."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('netft', **kwargs)
        self.counters = FtCounters()
        # Both built by the first _apply (Params, below): the methods assert them.
        self.receiver: RdtReceiver | None = None
        self.pipeline: RdtPipeline | None = None
        self.timer = None
        self.settings: dict[str, Any] = {}
        self._reported = FtCounters()
        self.pub = self.create_publisher(WrenchStamped, topics.LOAD_CELL_WRENCH, SENSOR_QOS)
        self.tare_epoch = ZeroEpoch(self, topics.LOAD_CELL_TARE)  # tares/biases since start, latched
        self.params = Params(self, PARAMS, self._validate, self._apply)
        self.create_service(Trigger, '~/tare', self._srv_tare)
        self.callers = ServiceCallers(self)  # who tares (the live view names its client)
        self.diagnostics = Diagnostics(self, self._report)

    def _validate(self, values: dict[str, Any]) -> dict[str, Any]:
        _validate(values)
        check_start_only(values, self.settings, START_ONLY)
        return values

    def _calibration(self, v: dict[str, Any]) -> rdt.Calibration:
        if v['counts_per_force'] > 0:
            return rdt.Calibration(float(v['counts_per_force']), float(v['counts_per_torque']))
        if v['device'] == 'onrobot':
            return rdt.ONROBOT
        config = wait_for_device(lambda: fetch_netftapi2(v['host'], v['http_port']), v['wait_for_device_s'],
                                 self.get_logger().warning)
        self.get_logger().info(f'{v["host"]}: {config.product or "ATI box"}, {config.force_unit} / '
                               f'{config.torque_unit}, {config.calibration.counts_per_force:.6g} counts/N, '
                               f'{config.calibration.counts_per_torque:.6g} counts/(N·m), RDT rate '
                               f'{config.rdt_rate_hz} Hz')
        return config.calibration

    def _apply(self, values: dict[str, Any], _raw: dict[str, Any]) -> None:
        first = not self.settings
        if first:
            calibration = self._calibration(values)   # DriverError stops the start with the reason
            self.receiver = RdtReceiver(values['host'], values['port'], values['command'], values['timeout_s'],
                                        values['reconnect_interval_s'])
            self.receiver.start(values['wait_for_device_s'])
            self.get_logger().info(f'streaming from {self.receiver.where} ({values["command"]}), kernel arrival '
                                   f'stamps: {self.receiver.kernel_timestamps}')
        if first:
            self.pipeline = RdtPipeline(calibration, values['sample_rate_hz'], values['publish_rate_hz'],
                                        values['tare_samples'], values['drop_status_mask'])
        else:
            assert self.pipeline is not None
            self.pipeline.configure(values['publish_rate_hz'], values['tare_samples'], values['drop_status_mask'])
        if self.timer is None or values['flush_rate_hz'] != self.settings['flush_rate_hz']:
            if self.timer is not None:
                self.destroy_timer(self.timer)
            self.timer = create_grid_timer(self, 1.0 / values['flush_rate_hz'], self._tick)
        self.settings = values

    def _tick(self) -> None:
        assert self.receiver is not None and self.pipeline is not None
        datagrams = self.receiver.drain()
        if not datagrams:
            return
        batch = self.pipeline.process(datagrams)
        frame = self.settings['frame_id']
        for t_ns, w in zip(batch.stamps_ns.tolist(), batch.wrench.tolist()):
            msg = WrenchStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(t_ns)
            msg.header.frame_id = frame
            f, m = msg.wrench.force, msg.wrench.torque
            f.x, f.y, f.z, m.x, m.y, m.z = w
            self.pub.publish(msg)
        self.counters.published += len(batch)
        self._update_counters()

    def _update_counters(self) -> None:
        assert self.receiver is not None and self.pipeline is not None
        c = self.pipeline.counters()
        self.counters.received = c['records_received']
        for name in ('records_lost', 'records_out_of_order', 'records_late_dropped', 'records_duplicate',
                     'status_records', 'status_dropped', 'malformed_datagrams', 'stream_restarts', 'clock_resets',
                     'records_stale_dropped'):
            setattr(self.counters, name, c[name])
        self.counters.reconnects = self.receiver.reconnects

    def _srv_tare(self, request, response):
        try:
            if self.settings['tare_mode'] == 'hardware':
                self.receiver.bias()
                self.pipeline.clear_tare()
                response.message = (f'bias command (0x0042) sent to {self.receiver.where}: the device zeroes on the '
                                    'current load; software tare cleared')
            else:
                n = self.pipeline.tare_count
                offset = self.pipeline.tare()
                response.message = (f'tared on {n} samples: offset [fx fy fz] = '
                                    f'{[round(v, 6) for v in offset[:3].tolist()]} N, [mx my mz] = '
                                    f'{[round(v, 7) for v in offset[3:].tolist()]} N·m')
            response.success = True
            self.tare_epoch.step()  # software tare or hardware bias: the readings step either way
        except DriverError as exc:
            response.success, response.message = False, str(exc)
        self.get_logger().info(f'~/tare by {self.callers.caller(self.callers.service_name("~/tare"))}: '
                               f'{response.message}')
        return response

    def _report(self):
        self._update_counters()
        c, prev = self.counters, self._reported
        self._reported = FtCounters(**c.__dict__)
        rx, clock = self.receiver, self.pipeline.clock
        pairs = c.as_pairs() + [
            ('streaming', str(rx.streaming).lower()), ('last_status', f'0x{self.pipeline.last_status:08x}'),
            ('clock_skew_ppm', f'{clock.skew_ppm:.2f}'), ('clock_drift_tracked', str(clock.fitted).lower()),
            ('kernel_timestamps', str(rx.kernel_timestamps).lower()), ('device', rx.where),
            ('offset', str([round(v, 7) for v in self.pipeline.offset.tolist()])),
            ('last_restart', self.pipeline.last_restart)]
        if not rx.streaming:
            return ERROR, (f'no record from {rx.where} for more than {rx.timeout_s} s: requesting the stream again '
                           f'every {rx.reconnect_interval_s} s ({rx.reconnects} requests so far)'), pairs
        restarts = c.stream_restarts - prev.stream_restarts
        if restarts:
            note = ''
            if c.clock_resets > prev.clock_resets and self.settings['tare_mode'] == 'hardware':
                note = ' (its hardware bias is gone with the power cycle: tare again)'
            return WARN, (f'{restarts} stream restart(s) since the last report: {self.pipeline.last_restart}'
                          f'{note}'), pairs
        new_status = c.status_records - prev.status_records
        if new_status:
            return ERROR, (f'status word 0x{self.pipeline.last_status:08x} on {new_status} records since the last '
                           f'report ({c.status_dropped - prev.status_dropped} not published)'), pairs
        lost = c.records_lost - prev.records_lost
        late = c.records_out_of_order - prev.records_out_of_order
        if lost > 0 or late > 0 or c.malformed_datagrams > prev.malformed_datagrams:
            return WARN, (f'{max(lost, 0)} records lost, {late} out of order, '
                          f'{c.malformed_datagrams - prev.malformed_datagrams} malformed datagrams since the last '
                          'report'), pairs
        return OK, f'{c.published} samples published', pairs

    def close(self) -> None:
        if self.receiver is not None:
            self.receiver.stop()


def main(args=None) -> int:
    return run(NetFt, args)


if __name__ == '__main__':
    raise SystemExit(main())
