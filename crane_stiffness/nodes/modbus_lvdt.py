"""modbus_lvdt: an LVDT read through an analog-input DAQ over Modbus TCP (LabJack T-series, ADAM-6017 style) — a
thin adapter around crane_stiffness.drivers.modbus.

Polls one channel (``register``, ``register_type``, ``data_type``, ``word_order``) of unit ``unit_id`` at
``host:port`` at ``poll_rate_hz`` (a timer on the clock grid, with the other sensors) and publishes
/lvdt/displacement (PointStamped, sensor QoS, frame ``frame_id``): point.x = ``gain`` · raw + ``offset`` − zero [m],
stamped at the middle of the request (the DAQ has no clock of its own to stamp with). /diagnostics: polls, failures
(timeouts, dropped connections, Modbus exception responses: ERROR with the reason) and the poll jitter (start of
each request against the ideal grid: p50, p99, max [µs]; late polls; instants of the grid the timer skipped because
the process was busy past the next one: their readings taken late at the next tick, ``caught_up_polls``, or never,
``missed_polls``). After a failure the
device is asked again every ``reconnect_interval_s``. Service ~/zero (std_srvs/Trigger) zeroes on the mean of the
last ``zero_samples`` readings; the number of zeros since start is published, latched, on /lvdt/zero
(std_msgs/Float64, at start and after every zero) so the estimator starts a new fit segment. At start a wrong
address or a silent device stops the node (exit 2) with the reason, after trying for ``wait_for_device_s``.
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from std_srvs.srv import Trigger

from crane_stiffness.contract import topics
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.drivers.errors import DeviceResponseError, DeviceSilentError, DriverError, ParameterError
from crane_stiffness.drivers.modbus import DATA_TYPES, MODBUS_TCP_PORT, REGISTER_TYPES, Channel, ModbusPoller
from crane_stiffness.rosnode.qos import SENSOR_QOS
from crane_stiffness.rosnode.diagnostics import Counters, Diagnostics
from crane_stiffness.rosnode.sensor_timing import ZeroEpoch, create_grid_timer
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.parameters import Params, check, positive
from crane_stiffness.rosnode.device_params import check_address, check_start_only, wait_for_device
from crane_stiffness.serde.stamps import split_ns
from crane_stiffness.contract.status import ERROR, OK, WARN
from crane_stiffness.sim.calibration import LVDT_CALIBRATION_PARAMS, LVDT_COMPONENTS, calibration_of

#: Parameters of the channel, shared with modbus_emulator so one parameter file describes both sides.
CHANNEL_PARAMS = (
    ParamSpec('unit_id', 1, 'Modbus unit (device) id; LabJack: 1 [-]', low=0, high=255),
    ParamSpec('register', 0, 'address of the first register of the channel, 0-based as on the wire (LabJack AINn: '
              '2·n) [-]'),
    ParamSpec('register_type', 'holding', f"register table: {' or '.join(REGISTER_TYPES)} (function 3 or 4) [-]"),
    ParamSpec('data_type', 'float32', f"how the registers hold the value: {', '.join(DATA_TYPES)} (LabJack: float32 "
              'volts; ADAM-6017: int16 counts) [-]'),
    ParamSpec('word_order', 'big', "32-bit values: 'big' = most significant register first (LabJack), 'little' = "
              'least significant first [-]'),
    ParamSpec('gain', 0.001, 'metres per raw unit: [m/V] for volts, [m/count] for counts (the LVDT conditioner '
              "sensitivity, e.g. 1 mm/V) [m per raw unit]"),
    ParamSpec('offset', 0.0, 'metres at a raw value of 0 [m]'),
)

PARAMS = (
    ParamSpec('host', '192.168.1.10', "the DAQ's IP address or host name [-]"),
    ParamSpec('port', MODBUS_TCP_PORT, 'Modbus TCP port [-]', low=1, high=65535),
    *CHANNEL_PARAMS,
    ParamSpec('poll_rate_hz', 500.0, 'requests per second; ticks on the clock grid with the other sensors. One '
              'request takes a round trip (~0.2 ms on loopback, 1-2 ms to a LabJack) [Hz]'),
    ParamSpec('timeout_s', 0.1, 'longest wait for an answer before the poll counts as failed [s]'),
    ParamSpec('reconnect_interval_s', 1.0, 'after a failure, interval between attempts to reach the device [s]'),
    ParamSpec('frame_id', 'lvdt', 'header.frame_id of the published reading [-]'),
    ParamSpec('zero_samples', 10, 'readings averaged by the ~/zero service [samples]', low=1),
    ParamSpec('wait_for_device_s', 3.0, 'at start, time to wait for a first answer before stopping with an error; '
              'longer when the DAQ (or its emulator) starts with the driver [s]'),
    *LVDT_CALIBRATION_PARAMS,
)
#: A tick after skipped grid instants takes their readings at once, up to this much of them [s of polls]: a stall
#: of the process (or of the device's answer) of more than 0.1 s was seen beside a busy process at load 15.
MAX_CATCH_UP_S = 1.0
START_ONLY = ('host', 'port', 'unit_id', 'timeout_s', 'wait_for_device_s')
CHANNEL_KEYS = ('register', 'register_type', 'data_type', 'word_order', 'gain', 'offset')


def channel_from(values: dict[str, Any]) -> Channel:
    """The Channel the parameters describe; ValueError (the drivers' ParameterError) names a bad one."""
    return Channel.from_params({k: values[k] for k in CHANNEL_KEYS})


def _validate(values: dict[str, Any]) -> Channel:
    check_address(values)
    positive(values, 'poll_rate_hz', 'timeout_s', 'reconnect_interval_s', 'wait_for_device_s')
    check(isinstance(values['frame_id'], str) and values['frame_id'] != '', 'frame_id', values['frame_id'],
          'must be a non-empty string')
    calibration_of(values, LVDT_COMPONENTS)  # the declared calibration: refused when malformed
    try:
        return channel_from(values)
    except ParameterError as exc:
        raise ValueError(str(exc)) from None


@dataclass
class PollCounters(Counters):
    """``received`` = successful polls; failures by kind; late polls (started more than half a period late);
    ``caught_up_polls``: grid instants the timer skipped (the process was busy past the next instant; counted exactly
    from the timer's own next call time) whose readings were taken late, at the next tick; ``missed_polls``: those
    with no reading at all (more than MAX_CATCH_UP_S behind, a failed poll, a device being waited for)."""

    failures: int = 0
    timeouts: int = 0
    exception_responses: int = 0
    reconnects: int = 0
    late_polls: int = 0
    missed_polls: int = 0
    caught_up_polls: int = 0
    stream_restarts: int = 0


class ModbusLvdt(Node):
    """Each timer tick reads the channel once and publishes the reading."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('modbus_lvdt', **kwargs)
        self.counters = PollCounters()
        self._reported = PollCounters()
        self.settings: dict[str, Any] = {}
        self.poller: ModbusPoller | None = None  # created by the first _apply (Params, below): _tick asserts it
        self.timer: Any = None  # the poll timer (create_grid_timer), made by the first _apply
        self.zero_m = 0.0
        self.last_error = ''
        self._retry_at = 0.0
        self._jitter_ns: deque[int] = deque(maxlen=5000)   # request start minus its grid instant
        self._recent: deque[float] = deque(maxlen=10)
        self._next_due_ns: int | None = None  # the timer's next call [ns of the node clock], as of the last tick
        self.pub = self.create_publisher(PointStamped, topics.LVDT_DISPLACEMENT, SENSOR_QOS)
        self.zero_epoch = ZeroEpoch(self, topics.LVDT_ZERO)  # zeros since start, latched on /lvdt/zero
        self.params = Params(self, PARAMS, self._validate, self._apply)
        self.create_service(Trigger, '~/zero', self._srv_zero)
        self.diagnostics = Diagnostics(self, self._report)

    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _validate(self, values: dict[str, Any]) -> Channel:
        channel = _validate(values)
        check_start_only(values, self.settings, START_ONLY)
        return channel

    def _apply(self, channel: Channel, values: dict[str, Any]) -> None:
        if self.poller is None:
            self.poller = ModbusPoller(values['host'], values['port'], values['unit_id'], channel,
                                       values['timeout_s'], clock_ns=self._now_ns)
            # A wrong address or a silent device stops the start with the reason, after wait_for_device_s.
            first = wait_for_device(self.poller.read, values['wait_for_device_s'], self.get_logger().warning)
            self.get_logger().info(f'reading {channel.data_type} {channel.register_type} register {channel.register} '
                                   f'of {self.poller.where}: raw {first.raw:.6g} = {first.metres:.6g} m')
        else:
            self.poller.channel = channel
        self._recent = deque(self._recent, maxlen=values['zero_samples'])
        if self.timer is None or values['poll_rate_hz'] != self.settings['poll_rate_hz']:
            if self.timer is not None:
                self.destroy_timer(self.timer)
            self.period_ns = round(1e9 / values['poll_rate_hz'])
            self.timer = create_grid_timer(self, 1.0 / values['poll_rate_hz'], self._tick)
            self._next_due_ns = None
        self.settings = values

    def _skipped(self) -> int:
        """Grid instants rcl's timer skipped since the previous tick (it skips those it is too late for): its next
        call, read at each tick, steps by one period when none was skipped."""
        until = self.timer.time_until_next_call() if self.timer is not None else None
        if until is None:
            return 0
        due = self._now_ns() + until
        skipped = 0 if self._next_due_ns is None else max(0, round((due - self._next_due_ns) / self.period_ns) - 1)
        self._next_due_ns = due
        return skipped

    def _tick(self) -> None:
        assert self.poller is not None
        skipped = self._skipped()
        now = time.monotonic()
        if now < self._retry_at:
            self.counters.missed_polls += skipped  # the device is being waited for: nothing to catch up on
            return
        # A busy process (or a slow answer) made the timer skip instants: their readings are taken now, late and
        # stamped when taken, rather than lost (at most MAX_CATCH_UP_S worth; the rest count as missed).
        catch_up = min(skipped, max(1, round(MAX_CATCH_UP_S * 1e9 / self.period_ns)))
        self.counters.missed_polls += skipped - catch_up
        for i in range(1 + catch_up):
            if not self._poll(now):
                self.counters.missed_polls += catch_up - i if i else catch_up
                return
            if i:
                self.counters.caught_up_polls += 1

    def _poll(self, now: float) -> bool:
        """One request and its reading published; False when it failed."""
        assert self.poller is not None
        try:
            reading = self.poller.read()
        except DriverError as exc:
            self._failed(exc, now)
            return False
        if self.last_error:
            self.get_logger().info(f'{self.poller.where} answers again')
            self.last_error = ''
        if self.poller.restarts != self.counters.stream_restarts:  # the device was gone: zero on new readings only
            self.counters.stream_restarts = self.poller.restarts
            self._recent.clear()
        self.counters.received += 1
        late = (reading.start_ns % self.period_ns)
        self._jitter_ns.append(late)
        if late > self.period_ns // 2:
            self.counters.late_polls += 1
        self._recent.append(reading.metres)
        msg = PointStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(reading.stamp_ns)
        msg.header.frame_id = self.settings['frame_id']
        msg.point.x = reading.metres - self.zero_m
        self.pub.publish(msg)
        self.counters.published += 1
        return True

    def _failed(self, exc: DriverError, now: float) -> None:
        self.counters.failures += 1
        if isinstance(exc, DeviceResponseError):
            self.counters.exception_responses += 1
        else:
            if isinstance(exc, DeviceSilentError):
                self.counters.timeouts += 1
            self.counters.reconnects += 1
            self._retry_at = now + self.settings['reconnect_interval_s']  # do not hammer a device that is gone
        self.last_error = str(exc)
        self.get_logger().warning(f'poll failed: {exc}', throttle_duration_sec=2.0)

    def _srv_zero(self, request, response):
        if not self._recent:
            response.success, response.message = False, f'no reading from {self.poller.where} yet'
            return response
        self.zero_m = float(np.mean(self._recent))
        self.zero_epoch.step()  # the readings step: the estimator starts a new fit segment on it
        response.success = True
        response.message = f'zeroed on {len(self._recent)} readings: zero = {self.zero_m:.9f} m'
        self.get_logger().info(response.message)
        return response

    def _report(self):
        c, prev = self.counters, self._reported
        self._reported = PollCounters(**c.__dict__)
        jitter = np.asarray(self._jitter_ns, dtype=np.float64) / 1e3
        stats = ((f'{np.percentile(jitter, 50):.1f}', f'{np.percentile(jitter, 99):.1f}', f'{jitter.max():.1f}')
                 if jitter.size else ('nan', 'nan', 'nan'))
        pairs = c.as_pairs() + [('poll_jitter_p50_us', stats[0]), ('poll_jitter_p99_us', stats[1]),
                                ('poll_jitter_max_us', stats[2]), ('zero_m', f'{self.zero_m:.9f}'),
                                ('device', self.poller.where), ('last_error', self.last_error),
                                ('last_restart', self.poller.last_restart)]
        new_failures = c.failures - prev.failures
        if self.last_error:
            return ERROR, f'{new_failures} failed polls since the last report: {self.last_error}', pairs
        restarts = c.stream_restarts - prev.stream_restarts
        if restarts:
            return WARN, f'{restarts} restart(s) since the last report: {self.poller.last_restart}', pairs
        if new_failures:
            return WARN, f'{new_failures} failed polls since the last report', pairs
        return OK, f'{c.published} readings published', pairs

    def close(self) -> None:
        if self.poller is not None:
            self.poller.close()


def main(args=None) -> int:
    return run(ModbusLvdt, args)


if __name__ == '__main__':
    raise SystemExit(main())
