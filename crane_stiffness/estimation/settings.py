"""The live estimator's settings (the stiffness_estimator node's parameters, the offline analysis's too): each one
declared once, with its default, unit, rule and description (:func:`~crane_stiffness.params.spec.declared`), from
which the node's ROS parameters (:data:`ESTIMATOR_PARAMS`), their validation (:meth:`LiveSettings.from_params`) and the
reports' wording follow. Pure Python, no ROS.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from crane_stiffness.contract.axes import AXES
from crane_stiffness.errors import ParameterError
from crane_stiffness.estimation.estimator import StiffnessEstimator
from crane_stiffness.estimation.frames import SensorMount
from crane_stiffness.estimation.quality import noise_std
from crane_stiffness.estimation.sync import DISPLACEMENT, FORCE, ApproximateTimeSync, InterpolatingSync
from crane_stiffness.params.spec import ParamSpec, check_spec, declared, specs_of

BRANCH_SOURCES = ('auto', 'force')
#: Delays searched by the stream-delay estimate: ±this [s] (offset.estimate_delay's max_lag_s).
DELAY_MAX_LAG_S = 0.05
#: Pairing rules (``pairing``): 'nearest' pairs samples whose stamps are mutual nearest within ``slop_s``
#: (sync.ApproximateTimeSync: both sensors on one clock grid, as the simulated rig); 'interpolate_force' pairs
#: every displacement sample with the force interpolated at its stamp, 'interpolate_displacement' the other way
#: round (sync.InterpolatingSync: drivers at different rates, e.g. a 1 kHz F/T sensor and a 100 Hz Modbus LVDT).
PAIRINGS = {'nearest': None, 'interpolate_force': FORCE, 'interpolate_displacement': DISPLACEMENT}
#: The displacement messages the estimator takes (its ``displacement_type``) and the ROS type of each: a
#: PointStamped (point.x in m, its header stamp the sample's instant) or a std_msgs/Float64 in volts (converted by
#: :meth:`LiveSettings.volts_to_displacement`; without a stamp, its arrival stands in for the sample's instant: the
#: node's receipt time live, the bag's log time offline).
DISPLACEMENT_MSG_TYPES = {'point_stamped': 'geometry_msgs/msg/PointStamped', 'float64': 'std_msgs/msg/Float64'}
DISPLACEMENT_TYPES = tuple(DISPLACEMENT_MSG_TYPES)
#: The stiffness_estimator node's ``displacement_type`` (which message it subscribes the displacement as); the
#: offline analysis's ``--displacement-type`` is the same choice.
DISPLACEMENT_TYPE_PARAM = ParamSpec(
    'displacement_type', 'point_stamped', "displacement message: 'point_stamped' (PointStamped, point.x in m, header "
    "stamp) or 'float64' (Float64 in V, stamped on arrival) [-]", choices=DISPLACEMENT_TYPES)


@dataclass(frozen=True)
class LiveSettings:
    """Settings of :class:`~crane_stiffness.estimation.live.LiveStiffness`; units in the descriptions' brackets."""

    force_axis: str = declared('fy', 'wrench component fitted as the load: fx fy fz [N] or mx my mz [N·m]',
                               choices=AXES)
    pairing: str = declared(
        'nearest', "how force and displacement samples are paired: 'nearest' (mutual nearest stamps within slop_s: "
        "both sensors on one clock grid), 'interpolate_force' (each displacement sample with the force interpolated "
        "at its stamp: a fast F/T sensor, a slow DAQ), 'interpolate_displacement' (the other way round) [-]",
        choices=tuple(PAIRINGS))
    slop_s: float = declared(0.0006, "pairing 'nearest': largest stamp difference of a force/displacement pair [s]",
                             at_least=0.0)
    max_interpolation_gap_s: float = declared(
        0.005, 'interpolated pairing: widest gap between the two samples of the faster stream interpolated across; '
        'a slow sample in a wider gap (a dropout) is not paired [s]', above=0.0)
    max_age_s: float = declared(0.1, 'samples older than the other stream by more than this are stale; also the '
                                'longest a sample waits for its partner [s]', above=0.0, rule='>= slop_s')
    expected_period_s: float = declared(0.0, 'sample period of both streams, 0 = estimated online [s]', at_least=0.0)
    dropout_factor: float = declared(3.0, 'a stamp gap above this many periods counts as a dropout, 0 = not '
                                     'detected [-]', at_least=0.0, rule='0 or > 1')
    min_silence_s: float = declared(0.25, 'a stream silent this long at least (and dropout_factor periods) is dead: '
                                    'input ERROR, branches STALE; shorter gaps are a busy machine, not a sensor [s]',
                                    low=0.0)
    window: int = declared(500, 'pairs per windowed least-squares fit; span several load levels [pairs]', at_least=3)
    forgetting: float = declared(0.999, 'RLS forgetting factor in (0, 1], memory ~ 1/(1 - forgetting) [-]',
                                 above=0.0, at_most=1.0)
    displacement_noise: float = declared(
        -1.0, "white-noise standard deviation of the displacement reading, counted in the fits (errors in both "
        "variables: least squares alone is low by about (noise / spread of the displacement)²): -1 = estimated from "
        "the data (successive differences of each branch's displacements), 0 = not counted (ordinary least squares), "
        "> 0 = the sensor's specification [m or rad]", at_least=-1.0, rule='-1, 0 or > 0')
    hysteresis: float = declared(0.2, 'dead band of the loading/unloading switch; above the force noise when the '
                                 'branch follows the measured force [N or N·m]', at_least=0.0)
    branch_source: str = declared('auto', "'auto': branch from /crane/wrench_command once a command is seen, else "
                                  "from the measured force; 'force': always from the measured force [-]",
                                  choices=BRANCH_SOURCES)
    max_abs_force: float = declared(1.0e4, 'force samples above this magnitude are absurd and dropped [N or N·m]',
                                    above=0.0)
    max_abs_displacement: float = declared(0.1, 'displacement samples above this magnitude are absurd and dropped '
                                           '[m or rad]', above=0.0)
    displacement_gain: float = declared(1.0, 'float64 channel: metres per volt [m/V]', rule='non-zero')
    displacement_offset: float = declared(0.0, 'float64 channel: metres at 0 V [m]')
    lever_arm_m: float = declared(
        0.0, 'moment axis: the LVDT reads the tangential displacement at this distance from the rotation axis, '
        'converted to the angle asin(d / lever_arm_m) [rad]; 0 = the reading is fitted as it is (m, or rad from an '
        'angle sensor) [m]', low=0.0, rule='0 unless force_axis is a moment axis')
    max_scatter_ratio: float = declared(3.0, "a branch fit whose residual rms exceeds this many times what the "
                                        "sensors' noise explains (estimated from the data) is not OK [-]", above=1.0)
    nonlinearity_warn: float = declared(0.2, 'a branch whose nonlinearity (1 - k_upper/k_lower) exceeds this is '
                                        'reported WARN: slack wires [-]', above=0.0)
    max_clock_skew_s: float = declared(0.1, 'sensor samples stamped further ahead of their arrival (node clock) are '
                                       'dropped as clock skew; <= max_age_s, the longest such a sample may hold the '
                                       'pairing up [s]', above=0.0, rule='<= max_age_s')
    max_loss_fraction: float = declared(0.01, 'WARN when a sensor stream lost more than this fraction of its samples '
                                        '(expected from its own stamps) [-]', at_least=0.0, at_most=1.0)
    six_axis_program: bool = declared(
        False, 'the rig plays a six-axis program (the rig sets it from the program file, '
        'crane_stiffness.launcher.rig_description.is_six_axis_program): a one-axis fit of force_axis does not apply '
        "to the multi-axis load, so every status says 'not applicable' (OK) and points to /stiffness6/status; the "
        'pairs are still fitted and recorded [-]')
    # The F/T sensor's mounting (frames.SensorMount): wrenches are moved to the platform centre in crane_base before
    # the force_axis component is taken.
    sensor_rotation: tuple[float, ...] = declared(
        (0.0, 0.0, 0.0, 1.0), 'rotation of the F/T sensor frame in crane_base (sensor -> crane_base), quaternion '
        '[x, y, z, w]; the wrench is moved to the platform centre before force_axis is taken [-]',
        rule='a non-zero quaternion, or 9 numbers of a rotation matrix')
    sensor_position: tuple[float, ...] = declared((0.0, 0.0, 0.0), 'origin of the F/T sensor frame from the '
                                                  'platform centre, crane_base [m]', rule='3 finite numbers')
    sensor_reaction: bool = declared(False, 'the sensor measures the reaction of the load: negate the wrench [-]')
    # Clocks (offset.py): displacement stamps are corrected by t − displacement_delay_s before pairing; the delay
    # between the streams is estimated from the last delay_window_s of data and WARNed above max_stream_delay_s.
    displacement_delay_s: float = declared(0.0, "the displacement stamps are this late against the force's: "
                                           'corrected to t - displacement_delay_s before pairing [s]',
                                           rule='|value| <= max_age_s')
    max_stream_delay_s: float = declared(0.002, 'WARN when the delay between the streams estimated from the data, '
                                         'after displacement_delay_s, exceeds this [s]', above=0.0)
    delay_window_s: float = declared(5.0, 'recent data the stream delay is estimated from, every quarter of it '
                                     'and at pauses; 0 = not estimated [s]', at_least=0.0,
                                     rule=f'0 or >= {4 * DELAY_MAX_LAG_S:g}')

    @classmethod
    def from_params(cls, values: Mapping[str, Any]) -> LiveSettings:
        """Validated settings from a parameter dict (keys not named here are ignored, missing ones default): each
        value against its declared rule (:data:`ESTIMATOR_PARAMS`), then the rules between parameters.

        Raises:
            ParameterError (a ValueError) naming the parameter and its value.
        """
        v = {f.name: values.get(f.name, f.default) for f in fields(cls)}
        for spec in ESTIMATOR_PARAMS:
            value = v[spec.name]
            if isinstance(spec.default, float):
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise ParameterError(spec.name, value, 'must be a finite number')
                v[spec.name] = float(value)
            elif isinstance(spec.default, int) and not isinstance(spec.default, bool):
                if isinstance(value, bool) or not isinstance(value, int):
                    raise ParameterError(spec.name, value, f'must be an integer {spec.rule_text()}'.rstrip())
            check_spec(spec, v[spec.name])
        if v['max_age_s'] < v['slop_s']:
            raise ParameterError('max_age_s', v['max_age_s'], f'must be >= slop_s = {v["slop_s"]} (seconds)')
        if 0.0 < v['dropout_factor'] <= 1.0:
            raise ParameterError('dropout_factor', v['dropout_factor'], 'must be > 1, or 0 to disable dropout '
                                 'detection')
        if -1.0 < v['displacement_noise'] < 0.0:
            raise ParameterError('displacement_noise', v['displacement_noise'], 'must be -1 (estimated from the '
                                 "data), 0 (not counted) or > 0 (the sensor's noise, m or rad)")
        if v['displacement_gain'] == 0.0:
            raise ParameterError('displacement_gain', v['displacement_gain'], 'must be non-zero (m/V)')
        if v['max_clock_skew_s'] > v['max_age_s']:
            raise ParameterError('max_clock_skew_s', v['max_clock_skew_s'], f'must be <= max_age_s = '
                                 f'{v["max_age_s"]} (seconds): a sample stamped that far ahead holds the pairing up '
                                 'for as long')
        if v['lever_arm_m'] > 0.0 and not v['force_axis'].startswith('m'):
            raise ParameterError('lever_arm_m', v['lever_arm_m'], f'must be 0 for the force axis {v["force_axis"]} '
                                 '(a lever arm turns a tangential reading into an angle, for a moment axis mx my mz)')
        mount = SensorMount.from_params(v)  # ParameterError naming sensor_rotation / _position / _reaction
        if abs(v['displacement_delay_s']) > v['max_age_s']:
            raise ParameterError('displacement_delay_s', v['displacement_delay_s'], f'must be within ±max_age_s = '
                                 f'{v["max_age_s"]} (seconds)')
        if 0.0 < v['delay_window_s'] < 4 * DELAY_MAX_LAG_S:
            raise ParameterError('delay_window_s', v['delay_window_s'], f'must be 0 (not estimated) or >= '
                                 f'{4 * DELAY_MAX_LAG_S:g} s (4 x the ±{DELAY_MAX_LAG_S:g} s searched)')
        v['sensor_rotation'] = tuple(float(x) for x in np.ravel(v['sensor_rotation']))
        v['sensor_position'] = tuple(float(x) for x in mount.position)
        v['sensor_reaction'] = mount.reaction
        return cls(**v)

    def displacement_noise_of(self, displacement: Any) -> float:
        """The displacement noise a fit of these displacements counts (m or rad; in stamp order, one branch): the
        declared ``displacement_noise``, or with -1 the white noise estimated from them (:func:`~crane_stiffness.
        estimation.quality.noise_std`; 0 with fewer than 3). The live estimator (each branch's window) and
        ``analyze`` (each branch's pairs) both take it from here."""
        if self.displacement_noise >= 0.0:
            return self.displacement_noise
        sigma = noise_std(displacement)
        return sigma if math.isfinite(sigma) else 0.0

    def noise_text(self) -> str:
        """How the fits count the displacement noise, for people (:func:`noise_text`)."""
        return noise_text(self.displacement_noise, self.displacement_unit)

    def pairing_text(self) -> str:
        """The pairing rule for people (:func:`pairing_text`)."""
        return pairing_text(self.pairing, self.slop_s, self.max_interpolation_gap_s)

    @property
    def mount(self) -> SensorMount:
        """The sensor's mounting (validated in from_params)."""
        return SensorMount.from_params({k: getattr(self, k) for k in SensorMount.PARAM_NAMES})

    def force_row(self) -> tuple[float, ...] | None:
        """The fitted component as a dot product with the sensor's wrench (6 coefficients), or None when the
        sensor is at the platform centre, aligned, without sign change: then the component is taken as is."""
        mount = self.mount
        return None if mount.is_identity else mount.component_row(self.axis_index)

    def force_component(self, wrench: np.ndarray) -> np.ndarray:
        """The fitted component of sensor wrenches, shape (n, 6) → (n,), moved to the platform centre (vectorised
        form of :meth:`LiveStiffness.add_force`'s rule; the same matrix)."""
        mount = self.mount
        w = np.asarray(wrench, dtype=float).reshape(-1, 6)
        return w[:, self.axis_index] if mount.is_identity else mount.component(w, self.axis_index)

    def volts_to_displacement(self, volts: Any) -> Any:
        """Displacement reading, m (or rad), of a std_msgs/Float64 channel in volts (a float, or element-wise an
        array): ``displacement_gain * volts + displacement_offset``. The one conversion: the live estimator
        (LiveStiffness.add_volts) and ``analyze``/``compare`` (``--displacement-type float64``) both call it."""
        return self.displacement_gain * volts + self.displacement_offset

    def reading_to_displacement(self, reading: Any) -> Any:
        """The fitted displacement of displacement readings (a float, or element-wise an array): the reading itself
        (m, or rad), or with ``lever_arm_m`` > 0 the angle ``asin(reading / lever_arm_m)`` [rad] (NaN beyond the arm).
        The live estimator and ``analyze`` both convert with this."""
        if self.lever_arm_m == 0.0:
            return reading
        if isinstance(reading, float):
            ratio = reading / self.lever_arm_m
            return math.asin(ratio) if -1.0 <= ratio <= 1.0 else math.nan
        with np.errstate(invalid='ignore'):
            return np.arcsin(np.asarray(reading, dtype=float) / self.lever_arm_m)

    @property
    def displacement_unit(self) -> str:
        return 'm' if self.force_axis.startswith('f') else 'rad'

    @property
    def axis_index(self) -> int:
        return AXES.index(self.force_axis)

    @property
    def stiffness_unit(self) -> str:
        return 'N/m' if self.force_axis.startswith('f') else 'N·m/rad'

    @property
    def interpolated(self) -> str | None:
        """The stream interpolated (FORCE or DISPLACEMENT), or None for nearest-stamp pairing."""
        return PAIRINGS[self.pairing]

    def make_sync(self) -> ApproximateTimeSync | InterpolatingSync:
        period, dropout = self.expected_period_s or None, self.dropout_factor or None
        if self.interpolated is not None:
            return InterpolatingSync(self.interpolated, max_gap=self.max_interpolation_gap_s, max_age=self.max_age_s,
                                     expected_period=period, dropout_factor=dropout)
        return ApproximateTimeSync(self.slop_s, max_age=self.max_age_s, expected_period=period,
                                   dropout_factor=dropout)

    def make_estimator(self) -> StiffnessEstimator:
        return StiffnessEstimator(self.hysteresis, self.window, self.forgetting, nonlinearity=False,
                                  x_noise=max(self.displacement_noise, 0.0))

    def fit_key(self) -> tuple:
        """The settings whose change restarts pairing and fitting (the others are thresholds)."""
        return (self.force_axis, self.pairing, self.slop_s, self.max_interpolation_gap_s, self.max_age_s,
                self.expected_period_s, self.dropout_factor,
                self.window, self.forgetting, self.hysteresis, self.branch_source, self.displacement_gain,
                self.displacement_offset, self.sensor_rotation, self.sensor_position, self.sensor_reaction,
                self.displacement_delay_s, self.lever_arm_m, self.displacement_noise)




#: The live estimator's parameters, as the stiffness_estimator node declares them.
ESTIMATOR_PARAMS: tuple[ParamSpec, ...] = specs_of(LiveSettings)


def noise_text(displacement_noise: float, unit: str) -> str:
    """How the fits count the displacement noise (``displacement_noise``, ``unit`` m or rad), for people: the
    node's log, the analysis and its report say it the same way."""
    if displacement_noise < 0.0:
        return "errors in both variables, displacement noise estimated from each branch's data"
    if displacement_noise == 0.0:
        return 'ordinary least squares, displacement noise not counted'
    return f'errors in both variables, displacement noise {displacement_noise:g} {unit}'


def pairing_text(pairing: str, slop_s: float, max_interpolation_gap_s: float) -> str:
    """The pairing rule for people (the node's log, the analysis and its report say it the same way)."""
    if PAIRINGS.get(pairing) is None:
        return f'nearest stamps within slop_s = {slop_s:g} s'
    return f'{pairing} across gaps up to max_interpolation_gap_s = {max_interpolation_gap_s:g} s'


__all__ = ['BRANCH_SOURCES', 'DISPLACEMENT_MSG_TYPES', 'DISPLACEMENT_TYPES', 'DISPLACEMENT_TYPE_PARAM',
           'ESTIMATOR_PARAMS', 'PAIRINGS', 'LiveSettings', 'noise_text', 'pairing_text']
