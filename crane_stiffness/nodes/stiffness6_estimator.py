"""stiffness6_estimator: the whole 6×6 stiffness live, from the load cell's wrench and a pose sensor (a thin adapter
around crane_stiffness.full6: pairs.Full6Pairing, identify.ComplianceEstimator).

Subscribes /crane/wrench_command (the load steps), /load_cell/wrench (WrenchStamped, moved to the platform centre in
crane_base by ``sensor_rotation``, ``sensor_position``, ``sensor_reaction`` as in the 1-D estimator) and
/pose_sensor/pose (PoseStamped: a motion-capture tracker, or the simulated pose_sensor). Every pose sample is paired
with the wrench interpolated at its stamp and labelled by the step in force once it has settled (``settle_s``);
the fit uses every labelled pair since the start (or the last ~/reset). A load-cell sample at its full scale
(``load_cell_full_scale``) is left out, and the status is never OK after one (crane_stiffness.full6.full_scale).

Publishes, at ``publish_rate_hz`` (node clock), /stiffness6/stiffness and /stiffness6/compliance
(Float64MultiArray: dims quantity (value, ci95_low, ci95_high) × row × column, row-major; the layout in
crane_stiffness.contract.stiffness6_layout), /stiffness6/stiffness_expanded (the same K with value ∓ U, its expanded
uncertainty, in the same layout) and /stiffness6/status
(DiagnosticArray: the fit's status, with the numbers behind it: pairs, steps, condition number, lack of fit, K2 and
its interval, K2's U, what U counts, the diagonal of K).
The status is never OK on a design that cannot determine C (crane_stiffness.full6
.identify: fewer than 8 steps, no pure error, condition number > 100) or on a non-linear window (lack of fit), and
it is STALE when a stream that was flowing stopped: no pose or wrench sample stamped within ``stale_after_s`` of
the node clock's now (checked every ``1 / publish_rate_hz``). Stale samples are never paired (the pairing's
``max_age_s``). While the load program runs (/load_program/state), a design that cannot determine C *yet* is
WAITING for its steps, not ERROR. On simulated time the inputs are taken in stamp order at each watermark, so the
same run gives the same pairs; offline, crane-stiffness analyze reproduces the fit from the bag.

U (GUM law of propagation, 95 %, crane_stiffness.full6.live_uncertainty) is computed at each publication (not per
sample) from the fit's step means and the sensors' declared calibrations: their ``calibration.*`` parameters
(and the load cell's ``full_scale``), read over ROS from the first answering node of ``load_cell_nodes``,
``pose_sensor_nodes`` and ``lvdt_array_nodes`` at start and again when they change
(crane_stiffness.rosnode.estimator_references, as the one-axis estimator reads them); the status's ``uncertainty``
names "statistical only" for every component not declared or not read. On simulated time the watermarks wait for
those reads while such a node is in the graph (the same U in every run).
"""
from __future__ import annotations

import json
import math
from collections import deque
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.node import Node
from rclpy.time import Time
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger

from crane_stiffness.contract import stiffness6_layout, topics
from crane_stiffness.estimation.frames import SensorMount
from crane_stiffness.full6.full_scale import at_limits, check_full_scale, full_scale_limits, with_full_scale
from crane_stiffness.full6.identify import ComplianceEstimator, ComplianceFit
from crane_stiffness.full6.live_uncertainty import LiveMatrixU, LiveMatrixUncertainty
from crane_stiffness.full6.pairs import DEFAULT_MAX_AGE_S, DEFAULT_MAX_GAP_S, Full6Pairing
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.rosnode.estimator_references import EstimatorReferences
from crane_stiffness.rosnode.parameters import Params
from crane_stiffness.rosnode.qos import LATCHED_QOS, RELIABLE_QOS, sensor_qos, stream_qos
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.sim_time import PeriodicOutput, SimTimeParticipant, uses_sim_time
from crane_stiffness.serde.cdr import CdrError, decode_stamped
from crane_stiffness.serde.stamps import stamp_seconds
from crane_stiffness.contract.status import ERROR, NAMES, STALE, WAITING, WAITING_PREFIX, wire_level

__all__ = ['PARAMS', 'Stiffness6EstimatorNode', 'main', 'shown_status']

PARAMS = (
    ParamSpec('settle_s', 0.5, 'time after each load step before its pairs are fitted (the platform settles) [s]',
              low=0.0),
    ParamSpec('max_gap_s', DEFAULT_MAX_GAP_S, 'widest gap of the wrench stream a pose sample is paired across [s]',
              above=0.0),
    ParamSpec('max_age_s', DEFAULT_MAX_AGE_S, 'a pose sample further behind the newest wrench is stale, not '
              'paired [s]', above=0.0),
    ParamSpec('stale_after_s', 0.5, 'a stream with no sample stamped within this of now is stale: status STALE [s]',
              above=0.0),
    ParamSpec('publish_rate_hz', 2.0, 'rate of the fit and of /stiffness6/* [Hz]', above=0.0, high=50.0),
    ParamSpec('sensor_rotation', [0.0, 0.0, 0.0, 1.0], 'the F/T sensor frame in crane_base: quaternion [x, y, z, w] '
              'or 9 numbers row-major [-]'),
    ParamSpec('sensor_position', [0.0, 0.0, 0.0], 'origin of the F/T sensor frame from the platform centre, '
              'crane_base [m]'),
    ParamSpec('sensor_reaction', False, 'the sensor measures the reaction of the load: negate the wrench [-]'),
    ParamSpec('load_cell_full_scale', [0.0] * 6, "the load cell's full scale in its own frame: a sample with any "
              'component at or beyond it is left out and the status is never OK (crane_stiffness.full6.full_scale); '
              '0 leaves an axis unchecked [N x3, N·m x3]', rule='6 numbers >= 0'),
    ParamSpec('load_cell_nodes', ['/load_cell', '/netft'], "nodes whose declared calibration (calibration.*, "
              "full_scale) counts in U of K: the first that answers is read, at start and when it changes; read at "
              "start [-]"),
    ParamSpec('pose_sensor_nodes', ['/pose_sensor'], "nodes whose declared calibration (calibration.*) counts in U "
              "of K, as load_cell_nodes; read at start [-]"),
    ParamSpec('lvdt_array_nodes', ['/lvdt_array'], "an LVDT array measuring the deflection: its channels' "
              "calibrations are named in U's statement as not counted, as load_cell_nodes; read at start [-]"),
)
_KIND_ORDER = {'command': 0, 'wrench': 1, 'pose': 2}  # at one stamp: the command first (it is in force at t)


def _validate(values: dict[str, Any]) -> SensorMount:
    check_full_scale(values['load_cell_full_scale'])  # Full6InputError (a ValueError) naming it
    return SensorMount.from_params(values)  # ParameterError (a ValueError) naming sensor_rotation / _position


def shown_status(fit: ComplianceFit, program_state: str) -> tuple[int, str]:
    """The level and message published for ``fit``: its own, except that a design that cannot determine C yet is
    WAITING while the load program is running or paused (``program_state``, /load_program/state): more steps come."""
    if fit.level == ERROR and fit.message.startswith('undetermined') and program_state in ('running', 'paused'):
        return WAITING, f'{WAITING_PREFIX}{fit.n_steps} steps so far, the program goes on: {fit.message}'
    return fit.level, fit.message


class Stiffness6EstimatorNode(Node):
    """Feeds the three streams to Full6Pairing and the pairs to ComplianceEstimator; publishes the fit."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('stiffness6_estimator', **kwargs)
        self.mount: SensorMount | None = None
        self.pairing: Full6Pairing | None = None
        self.estimator = ComplianceEstimator()
        self.timer: Any = None
        self.counters = {'commands': 0, 'wrenches': 0, 'poses': 0, 'malformed': 0, 'at_full_scale': 0, 'pairs': 0,
                         'fits': 0}
        self.full_scale_limits = np.full(6, np.inf)  # full6.full_scale.full_scale_limits of the parameter
        self.saturated = np.zeros(6, dtype=np.int64)  # samples left out at full scale per axis, since the reset
        self.newest = {'wrench': -math.inf, 'pose': -math.inf}  # newest stamp per sensor stream [s]
        self.fit: ComplianceFit | None = None
        self.budget = LiveMatrixUncertainty()  # U of K from the step means and the calibrations read
        self.uncertainty: LiveMatrixU | None = None  # the U published with the last fit
        self.sim_time = uses_sim_time(self)
        self.held: list[tuple[float, int, int, str, Any]] = []  # simulated time: (stamp, kind order, seq, kind, data)
        self._seq = 0
        # How far behind the pose stream the fit is: node clock at handling − the pose's stamp, last samples [s]
        # (the benchmark compares it with the transport's own lag; on simulated time it means nothing).
        self.lags: deque[float] = deque(maxlen=5000)
        self.pub_k = self.create_publisher(Float64MultiArray, topics.STIFFNESS6, LATCHED_QOS)
        self.pub_c = self.create_publisher(Float64MultiArray, topics.COMPLIANCE6, LATCHED_QOS)
        self.pub_status = self.create_publisher(DiagnosticArray, topics.STIFFNESS6_STATUS, LATCHED_QOS)
        self.params = Params(self, PARAMS, _validate, self._apply)
        self.pub_expanded = self.create_publisher(Float64MultiArray, topics.STIFFNESS6_EXPANDED, LATCHED_QOS)
        self.create_subscription(WrenchStamped, topics.WRENCH_COMMAND, self._on_command,
                                 stream_qos(RELIABLE_QOS, self.sim_time))
        self.create_subscription(WrenchStamped, topics.LOAD_CELL_WRENCH, self._on_wrench, sensor_qos(self.sim_time),
                                 raw=True)
        self.create_subscription(PoseStamped, topics.POSE_SENSOR_POSE, self._on_pose, sensor_qos(self.sim_time),
                                 raw=True)
        # While the load program runs, a design that cannot determine C yet is waiting for its steps, not an error.
        self.program_state = ''
        self.create_subscription(String, topics.PROGRAM_STATE, self._on_program_state, LATCHED_QOS)
        self.create_service(Trigger, '~/reset', self._srv_reset)
        self.sim = SimTimeParticipant(self, 3, self._on_watermark,
                                      inputs=[topics.WRENCH_COMMAND, topics.LOAD_CELL_WRENCH, topics.POSE_SENSOR_POSE])
        for pub in (self.pub_k, self.pub_expanded, self.pub_c, self.pub_status):  # (the recorder, a stage above,
            self.sim.counted(pub)  # waits for them)
        self.references = EstimatorReferences(
            self, {'load_cell': self.params['load_cell_nodes'], 'pose_sensor': self.params['pose_sensor_nodes'],
                   'lvdt_array': self.params['lvdt_array_nodes']}, lambda: None, lambda: '',
            on_calibration=self.budget.set_calibration)

    def _apply(self, mount: SensorMount, values: dict[str, Any]) -> None:
        self.mount = mount
        self.full_scale_limits = full_scale_limits(values['load_cell_full_scale'])
        pairing = (values['settle_s'], values['max_gap_s'], values['max_age_s'])
        if self.pairing is None or self.pairing.settings != pairing:
            if self.pairing is not None:
                self.get_logger().info('pairing settings changed: the fit starts again')
            self.pairing = Full6Pairing(settle_s=pairing[0], max_gap_s=pairing[1], max_age_s=pairing[2])
            self.estimator.reset()
            self.saturated[:] = 0
        if self.timer is None:  # (on simulated time: at the watermarks, see _on_watermark)
            self.timer = PeriodicOutput(self, 1.0 / values['publish_rate_hz'], self._publish, self.sim_time)
        else:
            self.timer.set_period(1.0 / values['publish_rate_hz'])

    # --- inputs: on the wall clock handled as they come; on simulated time held until the watermark ---
    def _on_command(self, msg: WrenchStamped) -> None:
        self.sim.received(topics.WRENCH_COMMAND)
        f, m = msg.wrench.force, msg.wrench.torque
        stamp = stamp_seconds(msg.header.stamp.sec, msg.header.stamp.nanosec)
        self._take(stamp, 'command', (f.x, f.y, f.z, m.x, m.y, m.z))

    def _on_wrench(self, data: bytes) -> None:
        self.sim.received(topics.LOAD_CELL_WRENCH)
        self._decoded(data, 6, 'wrench')

    def _on_pose(self, data: bytes) -> None:
        self.sim.received(topics.POSE_SENSOR_POSE)
        self._decoded(data, 7, 'pose')

    def _decoded(self, data: bytes, count: int, kind: str) -> None:
        try:
            sec, nanosec, values = decode_stamped(data, count)
        except CdrError:
            self.counters['malformed'] += 1
            return
        if not all(math.isfinite(v) for v in values):
            self.counters['malformed'] += 1
            return
        self._take(stamp_seconds(sec, nanosec), kind, values)

    def _take(self, stamp: float, kind: str, values: tuple[float, ...]) -> None:
        if self.sim_time:
            self._seq += 1
            self.held.append((stamp, _KIND_ORDER[kind], self._seq, kind, values))
        else:
            self._handle(stamp, kind, values)

    def _on_watermark(self, t_ns: int) -> None:
        """Simulated time: every input stamped up to ``t_ns`` is in; handled in stamp order (the same in every run).
        Held while the sensors' calibrations are being read (EstimatorReferences.holds): the same U in every run."""
        if self.references.holds(t_ns, self._on_watermark):
            return
        mark = t_ns * 1e-9
        now = sorted(h for h in self.held if h[0] <= mark)
        self.held = [h for h in self.held if h[0] > mark]
        for stamp, _, _, kind, values in now:
            self._handle(stamp, kind, values)
        if self.timer is not None:
            self.timer.at_watermark(t_ns)
        self.sim.report(t_ns)

    def _handle(self, stamp: float, kind: str, values: tuple[float, ...]) -> None:
        assert self.pairing is not None and self.mount is not None
        if kind == 'command':
            self.counters['commands'] += 1
            pairs = self.pairing.command(stamp, values)
        elif kind == 'wrench':
            self.counters['wrenches'] += 1
            self.newest['wrench'] = max(self.newest['wrench'], stamp)
            at = at_limits(values, self.full_scale_limits)[0]
            if at.any():  # not a measurement: left out before pairing (no pose is paired across the gap it leaves)
                self.counters['at_full_scale'] += 1
                self.saturated += at
                return
            pairs = self.pairing.wrench(stamp, self.mount.apply(values))
        else:
            self.counters['poses'] += 1
            self.newest['pose'] = max(self.newest['pose'], stamp)
            if not self.sim_time:
                self.lags.append(self.get_clock().now().nanoseconds * 1e-9 - stamp)
            pairs = self.pairing.pose(stamp, values[:3], values[3:])
        for _, w, d, step in pairs:
            self.estimator.add(w, d, step)
        self.counters['pairs'] += len(pairs)

    def _on_program_state(self, msg: String) -> None:
        try:
            self.program_state = str(json.loads(msg.data).get('state', ''))
        except (ValueError, AttributeError):
            self.program_state = ''

    # --- outputs ---
    def _now_ns(self) -> int:
        """The node's time [ns]: on simulated time the last watermark handled (PeriodicOutput.now_ns)."""
        return self.timer.now_ns() if self.timer is not None else self.get_clock().now().nanoseconds

    def _stale(self) -> str:
        """Which flowing stream stopped (no sample within stale_after_s of now), or ''."""
        now = self._now_ns() * 1e-9
        limit = self.params['stale_after_s']
        return ', '.join(f'{topics.LOAD_CELL_WRENCH if k == "wrench" else topics.POSE_SENSOR_POSE} (newest sample '
                         f'{now - t:.2f} s old)' for k, t in self.newest.items()
                         if math.isfinite(t) and now - t > limit)

    def _publish(self) -> None:
        stats = self.estimator.statistics() if self.estimator.n else None
        fit = self.fit = self.estimator.fit(stats) if stats is not None else None
        self.counters['fits'] += 1
        stale = self._stale()
        if fit is None or stats is None:
            level, message = WAITING, f'{WAITING_PREFIX}no labelled pairs yet (a pose sensor on ' \
                                      f'{topics.POSE_SENSOR_POSE} and load steps)'
            self.uncertainty = None
        else:
            level, message = with_full_scale(*shown_status(fit, self.program_state), self.saturated)
            # U of this fit (the law of propagation from its step means, ~7 ms; again only when they changed)
            u = self.uncertainty = self.budget.of(stats)
            self.pub_k.publish(stiffness6_layout.to_message(fit.stiffness, fit.stiffness_low, fit.stiffness_high))
            self.pub_expanded.publish(stiffness6_layout.to_message(fit.stiffness, fit.stiffness - u.U,
                                                                   fit.stiffness + u.U))
            self.pub_c.publish(stiffness6_layout.to_message(fit.compliance, fit.compliance_low, fit.compliance_high))
        if stale:
            level, message = STALE, f'stale: {stale}; the fit holds the pairs before it'
        status = DiagnosticStatus(name=f'{self.get_name()}: 6x6', hardware_id='crane', level=bytes([wire_level(level)]),
                                  message=message)
        status.values = [KeyValue(key=k, value=v) for k, v in self._values(fit, level)]
        out = DiagnosticArray()
        out.header.stamp = Time(nanoseconds=self._now_ns()).to_msg()
        out.status = [status]
        self.pub_status.publish(out)

    def _values(self, fit: ComplianceFit | None, level: int) -> list[tuple[str, str]]:
        pairs = [('level', NAMES.get(level, str(level))), ('pairs', str(self.counters['pairs'])),
                 ('unlabelled_pairs', str(self.pairing.unlabelled if self.pairing else 0)),
                 ('at_full_scale', str(int(self.saturated.sum())))]
        if fit is not None:
            pairs += [('steps', str(fit.n_steps)), ('condition', f'{fit.condition:.4g}'),
                      ('lack_of_fit', f'{fit.lack_of_fit:.4g}'), ('k2', f'{fit.k2:.8g}'),
                      ('k2_ci95', f'{fit.k2_low:.8g} .. {fit.k2_high:.8g}')]
            pairs += [(f'k_{i + 1}{i + 1}', f'{fit.stiffness[i, i]:.8g}') for i in range(6)]
        u = self.uncertainty
        if fit is not None and u is not None:  # K2's U about the fit's K2; U of K: /stiffness6/stiffness_expanded
            pairs += [('k2_U', f'{u.k2_U:.8g}'), ('k2_coverage_factor', f'{u.k2_k:.4g}'),
                      ('k2_U_interval', f'{fit.k2 - u.k2_U:.8g} .. {fit.k2 + u.k2_U:.8g}'),
                      ('statistical_only', 'true' if u.statistical_only else 'false'),
                      ('uncertainty', u.statement), ('uncertainty_steps', str(u.steps))]
        if self.lags:
            p50, p99 = np.percentile(np.fromiter(self.lags, float), [50, 99]) * 1e3
            pairs += [('pose_lag_p50_ms', f'{p50:.3f}'), ('pose_lag_p99_ms', f'{p99:.3f}'),
                      ('pose_lag_n', str(len(self.lags)))]
        return pairs

    def _srv_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        assert self.pairing is not None
        n = self.estimator.n
        self.estimator.reset()
        self.pairing.reset()
        self.saturated[:] = 0
        response.success, response.message = True, f'forgot {n} pairs; the next pose is the new rest'
        return response

    def close(self) -> None:
        """At exit: the last fit of everything received (what crane-stiffness analyze reproduces)."""
        self._publish()  # (on simulated time what is held past the last watermark is left: it may be partial)
        fit = self.fit
        if fit is not None:
            level, message = with_full_scale(fit.level, fit.message, self.saturated)
            self.get_logger().info(f'final 6x6 fit: {NAMES.get(level, level)} {message}; K2 = '
                                   f'{fit.k2:.6g} [{fit.k2_low:.6g}, {fit.k2_high:.6g}] N/rad, diagonal of K '
                                   f'{np.array2string(np.diag(fit.stiffness), precision=6)}')
            u = self.uncertainty
            if u is not None:
                self.get_logger().info(f'U (GUM, 95 %) of K2 {u.k2_U:.4g} N/rad (k = {u.k2_k:.3g}), of the diagonal '
                                       f'of K {np.array2string(np.diag(u.U), precision=4)}; {u.statement}')
        self.references.close()


#: The node a rig host loads (crane_stiffness.launcher.rig_host), built with its node arguments (``cli_args``).
COMPONENT = Stiffness6EstimatorNode


def main(args=None) -> int:
    return run(Stiffness6EstimatorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
