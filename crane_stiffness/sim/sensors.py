"""Simulated sensors of the rig: a six-axis force/torque load cell and an LVDT.

Frames and units: the paper's fixed frame (origin at the platform centre at rest, x and y horizontal, z down), SI.
A wrench is ``[fx, fy, fz, mx, my, mz]`` in N and N·m; the load cell's axes are taken aligned with that frame.
The platform pose is ``(u, Q)``: u the translation of the platform centre (m, fixed frame), Q the rotation matrix
mapping body coordinates to the fixed frame, so a body point p sits at ``u + Q·p``.

Randomness comes from one seeded :class:`numpy.random.Generator` per model, so a seed reproduces a run.
``from_params`` builds a model from a flat, ROS-parameter-friendly dict and names the offending field on error.

Beyond white noise, a model may carry true calibration errors (:mod:`crane_stiffness.sim.truth`: sensitivity and
misalignment of the load cell, sensitivity and linearity of the LVDT) and coloured noise with zero drift
(:mod:`crane_stiffness.sim.noise`), drawn from a generator of their own; without them (the default) a model reads
exactly as it did before they existed.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.model.rotation import rotvec_to_matrix
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.sim.errors import ParameterError
from crane_stiffness.sim.noise import ColouredNoise, noise_params
from crane_stiffness.sim.truth import (LOAD_CELL_TRUTH_PARAMS, LVDT_TRUTH_PARAMS, LoadCellTruth, LvdtTruth,
                                      load_cell_truth, lvdt_truth)

RngLike = np.random.Generator | int | None


def _float_vector(field: str, value: Any, size: int, *, minimum: float | None = None, strict: bool = False,
                  allow_inf: bool = False) -> NDArray[np.float64]:
    """A float vector of ``size`` entries from a scalar (broadcast) or a sequence, checked element-wise."""
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(field, value, f'must be a number or {size} numbers') from None
    if array.ndim == 0:
        array = np.full(size, float(array))
    if array.shape != (size,):
        raise ParameterError(field, value, f'must be a number or a list of {size} numbers')
    if np.isnan(array).any() or (not allow_inf and np.isinf(array).any()):
        raise ParameterError(field, value, 'must be finite' + (' or inf' if allow_inf else ''))
    if minimum is not None:
        bad = array <= minimum if strict else array < minimum
        if bad.any():
            raise ParameterError(field, value, f'every entry must be {">" if strict else ">="} {minimum}')
    return array


def _float(field: str, value: Any, *, minimum: float | None = None) -> float:
    if isinstance(value, bool):
        raise ParameterError(field, value, 'must be a number')
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParameterError(field, value, 'must be a number') from None
    if not math.isfinite(number):
        raise ParameterError(field, value, 'must be finite')
    if minimum is not None and number < minimum:
        raise ParameterError(field, value, f'must be >= {minimum}')
    return number


def _rng(field: str, value: RngLike) -> np.random.Generator:
    if isinstance(value, np.random.Generator):
        return value
    if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0):
        raise ParameterError(field, value, 'must be a non-negative integer seed, a numpy Generator or None')
    return np.random.default_rng(value)


def _check_keys(params: Mapping[str, Any], known: tuple[str, ...], required: tuple[str, ...] = ()) -> None:
    for key in params:
        if key not in known:
            raise ParameterError(str(key), params[key], f'unknown parameter; known: {", ".join(known)}')
    for key in required:
        if key not in params:
            raise ParameterError(key, None, 'is required')


def _quantize(values: NDArray[np.float64], resolution: NDArray[np.float64] | float) -> NDArray[np.float64]:
    """Round to multiples of ``resolution`` where it is > 0 (an ADC count); unchanged where it is 0."""
    resolution = np.asarray(resolution, dtype=float)
    step = np.where(resolution > 0.0, resolution, 1.0)
    return np.where(resolution > 0.0, np.round(values / step) * step, values)


class LoadCellModel:
    """Six-axis force/torque sensor.

    One reading, per axis i (vectors over the six wrench components)::

        raw = C·S·T·w_true + bias + drift_per_s·t + noise + e(t)      (noise ~ N(0, noise_std²))
        saturated_i = |raw_i| > full_scale_i ;  raw_i clipped to ±full_scale_i
        reading = quantize(raw, resolution) − offset            (offset set by tare, on the same grid)

    C is the 6×6 cross-talk matrix (identity plus small off-diagonal terms: load on axis j leaking into the
    reading of axis i); S = diag(1 + s) the true sensitivity errors and T = diag(Rᵀ, Rᵀ) the true misalignment R
    (:class:`~crane_stiffness.sim.truth.LoadCellTruth`; both identity without one); e(t) the coloured noise and
    random-walk drift (:class:`~crane_stiffness.sim.noise.ColouredNoise`; zero without one). The offset makes the
    sensor behave like a real F/T driver after a bias/tare command; drift keeps running after a tare, as on a real
    gauge.
    """

    PARAM_NAMES = ('noise_std', 'bias', 'drift_per_s', 'crosstalk', 'resolution', 'full_scale', 'seed')

    def __init__(self, noise_std: ArrayLike = 0.0, bias: ArrayLike = 0.0, drift_per_s: ArrayLike = 0.0,
                 crosstalk: ArrayLike | None = None, resolution: ArrayLike = 0.0, full_scale: ArrayLike = math.inf,
                 rng: RngLike = None, truth: LoadCellTruth | None = None, noise: ColouredNoise | None = None
                 ) -> None:
        """Create the model. Per-axis arguments take one number for all six axes or six numbers.

        Args:
            noise_std: Standard deviation of white noise, N / N·m, ≥ 0.
            bias: Constant offset, N / N·m.
            drift_per_s: Linear drift of the offset, N/s / N·m/s.
            crosstalk: 6×6 matrix (or 36 numbers, row-major); None for the identity.
            resolution: Quantization step, N / N·m, ≥ 0 (0: none).
            full_scale: Overload limit, N / N·m, > 0 (inf: none); readings saturate at ±full_scale.
            rng: Seed or Generator.
            truth: True calibration errors; None: none.
            noise: Coloured noise and drift of six channels; None: none.
        """
        self._noise_std = _float_vector('noise_std', noise_std, 6, minimum=0.0)
        self._bias = _float_vector('bias', bias, 6)
        self._drift = _float_vector('drift_per_s', drift_per_s, 6)
        if crosstalk is None:
            self._crosstalk = np.eye(6)
        else:
            matrix = np.array(crosstalk, dtype=float)
            if matrix.size != 36 or matrix.ndim not in (1, 2) or (matrix.ndim == 2 and matrix.shape != (6, 6)):
                raise ParameterError('crosstalk', crosstalk, 'must be a 6x6 matrix or 36 numbers (row-major)')
            if not np.isfinite(matrix).all():
                raise ParameterError('crosstalk', crosstalk, 'must be finite')
            self._crosstalk = matrix.reshape(6, 6)
        self._resolution = _float_vector('resolution', resolution, 6, minimum=0.0)
        self._full_scale = _float_vector('full_scale', full_scale, 6, minimum=0.0, strict=True, allow_inf=True)
        self._rng = _rng('rng', rng)
        self._offset = np.zeros(6)
        self.truth = truth
        self._gain = self._crosstalk  # the reading's matrix: C without true errors (the same numbers as before)
        if truth is not None and not truth.perfect:
            turn = rotvec_to_matrix(truth.misalignment).T  # the sensor reads the wrench in its own axes
            self._gain = self._crosstalk @ np.diag(1.0 + truth.sensitivity) @ np.kron(np.eye(2), turn)
        if noise is not None and noise.channels != 6:
            raise ParameterError('noise', noise.channels, 'must have 6 channels')
        self._coloured = noise if noise is not None and noise.enabled else None

    @classmethod
    def from_params(cls, params: Mapping[str, Any], *, truth: LoadCellTruth | None = None,
                    noise: ColouredNoise | None = None) -> LoadCellModel:
        """Build from a dict with keys from :attr:`PARAM_NAMES` (all optional; ``seed`` an int)."""
        _check_keys(params, cls.PARAM_NAMES)
        kwargs = {key: params[key] for key in cls.PARAM_NAMES if key in params and key != 'seed'}
        return cls(**kwargs, rng=_rng('seed', params.get('seed')), truth=truth, noise=noise)

    @property
    def offset(self) -> NDArray[np.float64]:
        """Current tare offset, N and N·m (a copy)."""
        return self._offset.copy()

    @property
    def crosstalk(self) -> NDArray[np.float64]:
        """The 6×6 cross-talk matrix (a copy)."""
        return self._crosstalk.copy()

    def measure(self, true_wrench: ArrayLike, t_s: ArrayLike = 0.0
                ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """One reading (or a batch) of the true wrench at time ``t_s``.

        Args:
            true_wrench: ``[fx, fy, fz, mx, my, mz]`` in N and N·m, shape (6,) or (n, 6).
            t_s: Time for the drift, s; a scalar or shape (n,).

        Returns:
            ``(wrench, saturated)``: the reading, same shape as ``true_wrench``, and per-axis overload flags (bool).
        """
        wrench = np.asarray(true_wrench, dtype=float)
        if wrench.shape[-1:] != (6,) or wrench.ndim > 2:
            raise ParameterError('true_wrench', true_wrench, 'must have shape (6,) or (n, 6)')
        t = np.asarray(t_s, dtype=float)
        if t.ndim == 1:
            t = t[:, None]
        raw = wrench @ self._gain.T + self._bias + self._drift * t
        raw = raw + self._rng.normal(0.0, 1.0, raw.shape) * self._noise_std
        if self._coloured is not None:
            n = 1 if raw.ndim == 1 else len(raw)
            raw = raw + self._coloured.sample(np.broadcast_to(np.asarray(t_s, dtype=float), (n,))).reshape(raw.shape)
        saturated = np.abs(raw) > self._full_scale
        raw = np.clip(raw, -self._full_scale, self._full_scale)
        return _quantize(raw, self._resolution) - self._offset, saturated

    def tare(self, samples: ArrayLike) -> NDArray[np.float64]:
        """Zero the sensor on the mean of N readings taken at no load, like an F/T driver's bias command.

        Args:
            samples: Readings returned by :meth:`measure`, shape (N, 6) or (6,), N ≥ 1.

        Returns:
            The new offset (cumulative: a second tare corrects what the first left).
        """
        samples = np.atleast_2d(np.asarray(samples, dtype=float))
        if samples.ndim != 2 or samples.shape[1] != 6 or samples.shape[0] < 1:
            raise ParameterError('samples', samples.shape, 'must have shape (N, 6) with N >= 1')
        if not np.isfinite(samples).all():
            raise ParameterError('samples', 'NaN/Inf', 'must be finite')
        # Kept on the ADC grid so tared readings stay multiples of the resolution.
        self._offset = _quantize(self._offset + samples.mean(axis=0), self._resolution)
        return self._offset.copy()

    def clear_tare(self) -> None:
        """Forget the tare offset."""
        self._offset = np.zeros(6)


class LvdtModel:
    """Linear variable differential transformer touching a point of the platform.

    The reading is the displacement of the contact point along the sensor axis, relative to the point's position
    when the sensor was zeroed::

        d = axis · ((u + Q·p) − r_zero)
        reading = clip(quantize(g(d) + noise + e(t), resolution), range_m[0], range_m[1])
        in_range = range_m[0] <= d <= range_m[1]        (the core is within its stroke)

    with ``axis`` a unit vector in the fixed frame and ``p`` the contact point in the body frame. Until
    :meth:`zero` is called, ``r_zero = p`` (the rest pose u = 0, Q = I). Lateral motion of the contact point
    (across the axis) is not seen, as with a flat-tipped spring-loaded probe. g(d) = d without true calibration
    errors, else ``(1 + s)·d + L·FS·T3(d/FS)`` (:class:`~crane_stiffness.sim.truth.LvdtTruth`; FS the half stroke
    max(|range_m|)); e(t) the coloured noise and random-walk drift (:class:`~crane_stiffness.sim.noise.ColouredNoise`;
    zero without one).
    """

    PARAM_NAMES = ('axis', 'contact_point', 'noise_std', 'resolution', 'range_m', 'seed')

    def __init__(self, axis: ArrayLike, contact_point: ArrayLike = (0.0, 0.0, 0.0), noise_std: float = 0.0,
                 resolution: float = 0.0, range_m: tuple[float, float] = (-math.inf, math.inf),
                 rng: RngLike = None, truth: LvdtTruth | None = None, noise: ColouredNoise | None = None) -> None:
        """Create the model.

        Args:
            axis: Measuring direction in the fixed frame; normalised, must be non-zero.
            contact_point: Contact point in the platform (body) frame, m.
            noise_std: Standard deviation of white noise, m, ≥ 0.
            resolution: Quantization step, m, ≥ 0 (0: none).
            range_m: Stroke (min, max) relative to the zero, m, min < max.
            rng: Seed or Generator.
            truth: True calibration errors; None: none.
            noise: Coloured noise and drift of one channel; None: none.
        """
        axis_vector = _float_vector('axis', axis, 3)
        norm = float(np.linalg.norm(axis_vector))
        if norm == 0.0:
            raise ParameterError('axis', axis, 'must be a non-zero 3-vector')
        self._axis = axis_vector / norm
        self._point = _float_vector('contact_point', contact_point, 3)
        self._noise_std = _float('noise_std', noise_std, minimum=0.0)
        self._resolution = _float('resolution', resolution, minimum=0.0)
        limits = np.array(range_m, dtype=float) if np.ndim(range_m) == 1 else np.array([])
        if limits.shape != (2,) or np.isnan(limits).any() or not limits[0] < limits[1]:
            raise ParameterError('range_m', range_m, 'must be two numbers [min, max] in metres with min < max')
        self._range = (float(limits[0]), float(limits[1]))
        self._rng = _rng('rng', rng)
        self._reference = self._point.copy()
        self.truth = truth if truth is not None and not truth.perfect else None
        self._full_scale = max(abs(self._range[0]), abs(self._range[1]))
        if self.truth is not None and self.truth.linearity and not math.isfinite(self._full_scale):
            raise ParameterError('truth.linearity', 100.0 * self.truth.linearity,
                                 'a linearity error needs a finite range_m (its share of the half stroke)')
        if noise is not None and noise.channels != 1:
            raise ParameterError('noise', noise.channels, 'must have 1 channel')
        self._coloured = noise if noise is not None and noise.enabled else None

    @classmethod
    def from_params(cls, params: Mapping[str, Any], *, truth: LvdtTruth | None = None,
                    noise: ColouredNoise | None = None) -> LvdtModel:
        """Build from a dict with keys from :attr:`PARAM_NAMES` (``axis`` required; ``seed`` an int)."""
        _check_keys(params, cls.PARAM_NAMES, required=('axis',))
        kwargs = {key: params[key] for key in cls.PARAM_NAMES if key in params and key != 'seed'}
        if 'range_m' in kwargs and np.ndim(kwargs['range_m']) == 1:
            kwargs['range_m'] = tuple(kwargs['range_m'])
        return cls(**kwargs, rng=_rng('seed', params.get('seed')), truth=truth, noise=noise)

    @property
    def axis(self) -> NDArray[np.float64]:
        """Unit measuring direction, fixed frame (a copy)."""
        return self._axis.copy()

    @property
    def range_m(self) -> tuple[float, float]:
        """Stroke (min, max), m."""
        return self._range

    def _contact(self, u: ArrayLike, q: ArrayLike) -> NDArray[np.float64]:
        u = np.asarray(u, dtype=float)
        q = np.asarray(q, dtype=float)
        if u.shape[-1:] != (3,) or u.ndim > 2:
            raise ParameterError('u', u, 'must have shape (3,) or (n, 3)')
        if q.shape[-2:] != (3, 3) or q.ndim > 3:
            raise ParameterError('Q', q, 'must have shape (3, 3) or (n, 3, 3)')
        return u + np.einsum('...ij,j->...i', q, self._point)

    def true_displacement(self, u: ArrayLike, q: ArrayLike) -> NDArray[np.float64] | float:
        """Noise-free displacement d along the axis, m (scalar for one pose, shape (n,) for a batch)."""
        d = (self._contact(u, q) - self._reference) @ self._axis
        return float(d) if np.ndim(d) == 0 else d

    def indicated(self, d: ArrayLike) -> NDArray[np.float64]:
        """The displacement ``d`` [m] as the channel indicates it with its true calibration errors (before noise):
        g(d) of the class docstring; ``d`` itself without errors."""
        d = np.asarray(d, dtype=float)
        if self.truth is None:
            return d
        reading = (1.0 + self.truth.sensitivity) * d
        if self.truth.linearity:
            x = d / self._full_scale
            reading = reading + self.truth.linearity * self._full_scale * (4.0 * x ** 3 - 3.0 * x)
        return reading

    def measure(self, u: ArrayLike, q: ArrayLike, t_s: ArrayLike | None = None) -> tuple[Any, Any]:
        """Reading for the pose ``(u, Q)``.

        Args:
            u: Platform translation, m, fixed frame; shape (3,) or (n, 3).
            q: Rotation matrix body → fixed; shape (3, 3) or (n, 3, 3).
            t_s: Sample instants, s, scalar or shape (n,): needed by coloured noise (ignored without it).

        Returns:
            ``(reading_m, in_range)``: floats/bools for one pose, arrays of shape (n,) for a batch.
        """
        d = np.asarray(self.true_displacement(u, q))
        noisy = self.indicated(d) + self._rng.normal(0.0, 1.0, d.shape) * self._noise_std
        if self._coloured is not None:
            if t_s is None:
                raise ParameterError('t_s', t_s, 'the sample instants are needed with coloured noise')
            n = max(d.size, 1)
            noisy = noisy + self._coloured.sample(np.broadcast_to(np.asarray(t_s, dtype=float), (n,)))[:, 0].reshape(
                d.shape)
        low, high = self._range
        reading = np.clip(_quantize(noisy, self._resolution), low, high)
        in_range = (d >= low) & (d <= high)
        if reading.ndim == 0:
            return float(reading), bool(in_range)
        return reading, in_range

    @property
    def zero_offset(self) -> float:
        """Where the zero lies along the axis from the contact point at the rest pose (u = 0, Q = I), m: the step a
        re-zero puts into the readings (0 until :meth:`zero` is called away from the rest pose)."""
        return float((self._reference - self._point) @ self._axis)

    def zero(self, u: ArrayLike = (0.0, 0.0, 0.0), q: ArrayLike | None = None) -> None:
        """Make the current contact-point position (pose ``(u, Q)``, default the rest pose) the zero."""
        q = np.eye(3) if q is None else q
        contact = self._contact(u, q)
        if contact.shape != (3,):
            raise ParameterError('u', u, 'zero() takes a single pose')
        self._reference = contact


# --- the simulated sensors' parameters, declared once (the sensor nodes and the device emulators declare them) ---
_IDENTITY_6X6 = [1.0 if i == j else 0.0 for i in range(6) for j in range(6)]
#: The seed of a simulated sensor's noise generator.
SEED_PARAM = ParamSpec('seed', -1, 'seed of the noise generator, -1 = random [-]', low=-1)
#: :class:`LoadCellModel`'s parameters with the lab's F/T sensor as defaults (the load_cell node, rdt_emulator).
LOAD_CELL_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('noise_std', [0.01, 0.01, 0.01, 0.0005, 0.0005, 0.0005],
              'white-noise standard deviation per axis fx fy fz mx my mz [N, N, N, N·m, N·m, N·m]'),
    ParamSpec('bias', [0.05, -0.03, 0.08, 0.001, -0.001, 0.0005],
              'constant offset per axis before a tare [N, N, N, N·m, N·m, N·m]'),
    ParamSpec('drift_per_s', [0.0] * 6, 'linear drift of the offset per axis [N/s, N/s, N/s, N·m/s, N·m/s, N·m/s]'),
    ParamSpec('crosstalk', _IDENTITY_6X6, '6x6 cross-talk matrix C, 36 numbers row-major: reading_i = '
              'sum_j C_ij w_j [-]'),
    ParamSpec('resolution', [0.002, 0.002, 0.002, 0.0001, 0.0001, 0.0001],
              'quantization step per axis, 0 = none [N, N, N, N·m, N·m, N·m]'),
    ParamSpec('full_scale', [40.0, 40.0, 120.0, 2.0, 2.0, 2.0],
              'overload limit per axis; readings saturate at +-full_scale [N, N, N, N·m, N·m, N·m]'),
    SEED_PARAM,
)
#: :class:`LvdtModel`'s parameters with the lab's LVDT as defaults (the lvdt node, modbus_emulator).
LVDT_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('axis', [0.0, 1.0, 0.0], 'measuring direction in crane_base (normalised; default along y) [-]'),
    ParamSpec('contact_point', [0.0, 0.0, 0.0], 'contact point on the platform, body frame (default: its centre) '
              '[m]'),
    ParamSpec('noise_std', 2.0e-7, 'white-noise standard deviation of the reading [m]', low=0.0),
    ParamSpec('resolution', 1.0e-7, 'quantization step of the reading, 0 = none [m]', low=0.0),
    ParamSpec('range_m', [-2.5e-3, 2.5e-3], 'stroke [min, max] relative to the zero; the reading saturates '
              'outside [m]'),
    ParamSpec('zero_on_first_pose', True, 'zero at the first pose received, so the reading is the displacement '
              'from the loaded rest pose [-]'),
    SEED_PARAM,
)


#: The simulated load cell's imperfections beyond LOAD_CELL_PARAMS (the load_cell node, which declares its
#: calibration too, crane_stiffness.sim.calibration): true calibration errors and coloured noise, all off by default.
LOAD_CELL_IMPERFECTION_PARAMS: tuple[ParamSpec, ...] = (
    *LOAD_CELL_TRUTH_PARAMS, *noise_params('N, N, N, N·m, N·m, N·m', 6))
#: The simulated LVDT's imperfections beyond LVDT_PARAMS (the lvdt node), all off by default.
LVDT_IMPERFECTION_PARAMS: tuple[ParamSpec, ...] = (*LVDT_TRUTH_PARAMS, *noise_params('m', 1))


def _seed(values: Mapping[str, Any]) -> int | None:
    return None if values['seed'] < 0 else int(values['seed'])


def _coloured(values: Mapping[str, Any], channels: int) -> ColouredNoise | None:
    """The coloured noise of parameter values with ``noise.*`` keys (None without them), from a generator of its own
    seeded by ``seed`` (-1: random), so the white noise of a seed is the same with it on or off."""
    if 'noise.ar1_std' not in values:
        return None
    seed = _seed(values)
    return ColouredNoise.from_params(channels, values, rng=None if seed is None else np.random.default_rng((seed, 1)))


def load_cell_from_params(values: Mapping[str, Any]) -> LoadCellModel:
    """The :class:`LoadCellModel` of parameter values (:data:`LOAD_CELL_PARAMS`, and when present
    :data:`LOAD_CELL_IMPERFECTION_PARAMS` with the calibration; other keys ignored; seed -1 = random). Raises
    ParameterError naming a bad value."""
    truth = load_cell_truth(values) if 'truth.mode' in values else None
    return LoadCellModel.from_params({**{k: values[k] for k in LoadCellModel.PARAM_NAMES if k != 'seed'},
                                      'seed': _seed(values)}, truth=truth, noise=_coloured(values, 6))


def lvdt_from_params(values: Mapping[str, Any]) -> LvdtModel:
    """The :class:`LvdtModel` of parameter values (:data:`LVDT_PARAMS`, and when present
    :data:`LVDT_IMPERFECTION_PARAMS` with the calibration; other keys ignored; seed -1 = random). Raises
    ParameterError naming a bad value."""
    truth = lvdt_truth(values) if 'truth.mode' in values else None
    return LvdtModel.from_params({**{k: values[k] for k in LvdtModel.PARAM_NAMES if k != 'seed'},
                                  'seed': _seed(values)}, truth=truth, noise=_coloured(values, 1))
