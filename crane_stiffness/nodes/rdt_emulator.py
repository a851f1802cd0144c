"""rdt_emulator: the simulated load cell served as an RDT F/T sensor on UDP (a thin adapter around
crane_stiffness.devices.rdt_device and sim.sensors.LoadCellModel), so the real driver ``netft`` can read it.

Subscribes /crane/applied_wrench (WrenchStamped, reliable) = the load crane_model has in force (never the raw
command: a command the model rejects reaches no sensor), held from arrival on, like ``load_cell``. Until the first
applied wrench arrives every record carries the status word :data:`STATUS_NOT_READY` (so the driver ``netft``
drops and reports them instead of publishing a reading of no known load), and /diagnostics says what it waits for.
Serves RDT on ``host:port`` (port 0 = a free port, logged and on /diagnostics): every sample of the
internal counter (``sample_rate_hz``, oscillator error ``clock_ppm``) is the load-cell model's reading of the held
wrench (noise, bias, drift, cross-talk, quantization, overload: the ``load_cell`` parameters of the same names) in
counts (``counts_per_force`` [counts/N], ``counts_per_torque`` [counts/(N·m)]). With ``http_port`` >= 0 it also
serves /netftapi2.xml like an ATI box (0 = a free port). The hardware bias command zeroes it like the real one.
True calibration errors and coloured noise as ``load_cell`` has them (``truth.*``, ``noise.*``; ``truth.mode: drawn``
draws from its own ``calibration.*``), all off by default.

Between sessions: an emulator that stays up (a lab's stand-in for the box, started once) forgets the held wrench when
the applied wrench's last publisher leaves (the session's crane_model ended) and on ~/reset (std_srvs/Trigger): its
records are not ready again until the next session's model says what load is in force, so a new session never reads
the previous one's load.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from std_srvs.srv import Trigger

from crane_stiffness.contract import topics
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.devices.rdt_device import RdtDevice
from crane_stiffness.drivers import rdt
from crane_stiffness.rosnode.qos import RELIABLE_QOS
from crane_stiffness.rosnode.diagnostics import Counters, Diagnostics, InputLag
from crane_stiffness.rosnode.messages import finite
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.parameters import Params, check, positive
from crane_stiffness.rosnode.device_params import MAX_INPUT_LAG, check_address, check_start_only
from crane_stiffness.sim.calibration import LOAD_CELL_CALIBRATION_PARAMS
from crane_stiffness.sim.sensors import (LOAD_CELL_IMPERFECTION_PARAMS, LOAD_CELL_PARAMS, LoadCellModel,
                                         load_cell_from_params)
from crane_stiffness.contract.status import ERROR, OK, WARN

#: Status word of the records served before the first applied wrench: bit 31, the summary error bit of an RDT
#: status word (crane_stiffness.drivers.rdt: 0 = healthy), and bit 16, this emulator's "no load known yet".
STATUS_NOT_READY = 0x80010000

PARAMS = (
    ParamSpec('host', '127.0.0.1', 'address to serve RDT on (keep it on loopback or a test network namespace) [-]'),
    ParamSpec('port', rdt.RDT_PORT, 'UDP port; 0 = a free port (logged and reported on /diagnostics) [-]',
              low=0, high=65535),
    ParamSpec('http_port', -1, 'serve /netftapi2.xml on this TCP port like an ATI box; 0 = a free port, -1 = no '
              'HTTP [-]', low=-1, high=65535),
    ParamSpec('sample_rate_hz', 7000.0, 'internal sample rate: the rate of ft_sequence [Hz]'),
    ParamSpec('clock_ppm', 0.0, "rate error of the device's oscillator, > 0 = fast [ppm]"),
    ParamSpec('counts_per_force', 1.0e6, 'counts per newton [counts/N]'),
    ParamSpec('counts_per_torque', 1.0e6, 'counts per newton-metre [counts/(N·m)]'),
    ParamSpec('records_per_packet', 10, 'records per datagram when a client asks for a buffered stream [-]'),
    MAX_INPUT_LAG,
    *LOAD_CELL_PARAMS,
    *LOAD_CELL_CALIBRATION_PARAMS,
    *LOAD_CELL_IMPERFECTION_PARAMS,
)
#: How often a long-running emulator looks whether the session's model is still there [s].
SESSION_CHECK_S = 0.2
START_ONLY = ('host', 'port', 'http_port', 'sample_rate_hz', 'clock_ppm', 'counts_per_force', 'counts_per_torque',
              'records_per_packet')


def _validate(values: dict[str, Any]) -> LoadCellModel:
    check_address(values, allow_zero=True)
    positive(values, 'sample_rate_hz', 'counts_per_force', 'counts_per_torque', 'max_input_lag_s')
    check(abs(values['clock_ppm']) < 1e5, 'clock_ppm', values['clock_ppm'], 'must be within ±100000 ppm')
    check(1 <= values['records_per_packet'] <= 40, 'records_per_packet', values['records_per_packet'],
          'must be in 1..40')
    return load_cell_from_params(values)


@dataclass
class EmulatorCounters(Counters):
    """``received`` = applied wrenches = ``used`` + ``dropped_non_finite``; ``published`` = RDT records sent;
    ``not_ready_records``: records sent with :data:`STATUS_NOT_READY` (before the first applied wrench)."""

    used: int = 0
    not_ready_records: int = 0

    stream_requests: int = 0
    bias_commands: int = 0
    resets: int = 0


class RdtEmulator(Node):
    """Holds the commanded wrench; the device thread measures it with the model for every sample it sends."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('rdt_emulator', **kwargs)
        self.counters = EmulatorCounters()
        self.applied: np.ndarray | None = None  # the load in force [N, N·m]; None until crane_model says
        self.model: LoadCellModel | None = None
        self.device: RdtDevice | None = None
        self.settings: dict[str, Any] = {}
        self.t0 = time.monotonic()
        self.params = Params(self, PARAMS, self._validate, self._apply)
        self.lag = InputLag()
        self.input = self.create_subscription(WrenchStamped, topics.APPLIED_WRENCH, self._on_applied, RELIABLE_QOS)
        self.create_service(Trigger, '~/reset', self._srv_reset)
        self._publisher_seen = False  # a publisher of the held input seen in the graph since
        self.create_timer(SESSION_CHECK_S, self._check_session)
        self.diagnostics = Diagnostics(self, self._report)
        self.get_logger().info(f'{topics.WAITING_FOR_LOAD}: until then every record has status '
                               f'0x{STATUS_NOT_READY:08x}')

    def _validate(self, values: dict[str, Any]) -> LoadCellModel:
        model = _validate(values)
        check_start_only(values, self.settings, START_ONLY)
        return model

    def _apply(self, model: LoadCellModel, values: dict[str, Any]) -> None:
        self.model = model  # the device thread picks the new model up at its next burst
        if self.device is None:
            self.device = RdtDevice(self._samples, host=values['host'], port=values['port'],
                                    sample_rate_hz=values['sample_rate_hz'],
                                    calibration=rdt.Calibration(values['counts_per_force'],
                                                                values['counts_per_torque']),
                                    records_per_packet=values['records_per_packet'], clock_ppm=values['clock_ppm'],
                                    http_port=None if values['http_port'] < 0 else values['http_port'], batch=True)
            self.device.start()
            http = f', /netftapi2.xml on port {self.device.http_port}' if values['http_port'] >= 0 else ''
            self.get_logger().info(f'serving RDT on {self.device.host}:{self.device.port}{http}')
        self.settings = values

    def _samples(self, n: int) -> np.ndarray:
        """The model's readings of the held wrench for the n samples of a burst (the device thread calls this, and
        then encodes the burst with the device's status word, set here for the same wrench)."""
        assert self.device is not None and self.model is not None  # _apply sets both, then starts the device
        applied = self.applied  # one read: the executor thread may replace it meanwhile
        if applied is None:
            self.device.status = STATUS_NOT_READY
            self.counters.not_ready_records += n
            applied = np.zeros(6)
        else:
            self.device.status = 0
        # The burst's instants, the last one now, 1/sample_rate_hz apart (coloured noise evolves within a burst).
        t = time.monotonic() - self.t0 - np.arange(n - 1, -1, -1) / self.device.sample_rate_hz
        readings, _ = self.model.measure(np.tile(applied, (n, 1)), t)
        return readings

    def _on_applied(self, msg: WrenchStamped) -> None:
        self.counters.received += 1
        self.lag.add(msg.header.stamp, self.get_clock().now().nanoseconds * 1e-9, self.settings['max_input_lag_s'])
        f, m = msg.wrench.force, msg.wrench.torque
        wrench = (f.x, f.y, f.z, m.x, m.y, m.z)
        if not finite(wrench):
            self.counters.dropped_non_finite += 1
            return
        if self.applied is None:
            self.get_logger().info(f'first applied wrench {list(wrench)}: records have status 0 from now on')
        self.applied = np.array(wrench)
        self.counters.used += 1

    def reset(self, why: str) -> None:
        """Forget the held wrench: records are not ready until the next applied wrench."""
        if self.applied is not None:
            self.applied = None
            self.counters.resets += 1
            self.get_logger().info(f'{why}: the held wrench is forgotten; records have status '
                                   f'0x{STATUS_NOT_READY:08x} until the next applied wrench')

    def _check_session(self) -> None:
        """The session's crane_model gone (no publisher of the applied wrench left): its load is no longer in force."""
        # Only a publisher seen in the graph and gone again counts: the graph may show a publisher later than its
        # first message arrives, and a reset then would leave the rig waiting for a reading that never comes.
        publishers = self.count_publishers(self.input.topic_name)  # (as remapped)
        if publishers:
            self._publisher_seen = True
        elif self._publisher_seen and self.applied is not None:
            self._publisher_seen = False
            self.reset(f'no publisher of {topics.APPLIED_WRENCH} left (the session ended)')

    def _srv_reset(self, request, response):
        self.reset('~/reset')
        response.success, response.message = True, f'records not ready until the next {topics.APPLIED_WRENCH}'
        return response

    def _report(self):
        dev = self.device
        self.counters.published = dev.records_sent
        self.counters.stream_requests = sum(1 for c, _ in dev.requests if c in rdt.STREAM_COMMANDS.values())
        self.counters.bias_commands = sum(1 for c, _ in dev.requests if c == rdt.CMD_BIAS)
        late, lag_pairs = self.lag.status('the applied wrench', self.settings['max_input_lag_s'])
        pairs = self.counters.as_pairs() + [('port', str(dev.port)), ('http_port', str(dev.http_port)),
                                            ('streaming', str(dev.streaming).lower())] + lag_pairs
        if dev.bad_requests:
            return ERROR, f'{dev.bad_requests} malformed RDT requests received', pairs
        if self.applied is None:
            return OK, f'{topics.WAITING_FOR_LOAD}; records have status 0x{STATUS_NOT_READY:08x}', pairs
        if late:
            return WARN, late, pairs
        return OK, f'serving RDT on {dev.host}:{dev.port}, {"streaming" if dev.streaming else "idle"}', pairs

    def close(self) -> None:
        if self.device is not None:
            self.device.stop()
            self.counters.published = self.device.records_sent


def main(args=None) -> int:
    return run(RdtEmulator, args)


if __name__ == '__main__':
    raise SystemExit(main())
