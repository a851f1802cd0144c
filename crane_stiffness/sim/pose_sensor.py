"""Simulated pose sensor of the rig: a motion-capture tracker (VICON, OptiTrack through vrpn_mocap) watching the
platform.

It reports the platform centre's position [m] and orientation (unit quaternion [x, y, z, w], body -> frame) in its
frame (``crane_base``: the paper's fixed frame, origin at the unloaded platform centre, z down), as
geometry_msgs/PoseStamped. One reading of the true pose (u, q) at a sample instant::

    position    = u + position_bias + n_u                      n_u ~ N(0, position_noise_std^2 I_3)  [m]
    orientation = exp(angle_bias + n_w) * q   (normalised)     n_w ~ N(0, angle_noise_std^2 I_3)    [rad]

``exp`` maps a rotation vector (fixed frame) to its unit quaternion; multiplied on the left, the small rotation acts
in the fixed frame, as the deflection of crane_stiffness.full6.deflection does (there, to first order, the measured
rotation deflection is the true one plus ``angle_bias + n_w``). Each sample draws six standard normals from the
model's seeded :class:`numpy.random.Generator` (n_u, then n_w), whatever the noise levels, so a seed gives the same
stream sample for sample however the samples are batched.

``latency_s`` (in :data:`POSE_SENSOR_PARAMS`) is the node's, not the model's: on wall-clock time a sample stamped t
is published no earlier than t + latency_s, like a tracker's processing delay; its stamp and value do not change.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.model.rotation import quaternion_multiply, rotvec_to_quaternion
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.sim.errors import ParameterError
from crane_stiffness.sim.sensors import SEED_PARAM, RngLike, _check_keys, _float, _float_vector, _rng, _seed

#: A quaternion whose norm is off 1 by more than this is normalised (a product of unit quaternions is unit to
#: rounding and stays as it is: a noise-free sensor returns the pose it was given, bit for bit).
UNIT_TOLERANCE = 1e-12


def _batch(field: str, value: ArrayLike, size: int) -> tuple[NDArray[np.float64], bool]:
    """``value`` as shape (n, size) and whether it was a single row (size,)."""
    array = np.asarray(value, dtype=float)
    if array.shape[-1:] != (size,) or array.ndim > 2:
        raise ParameterError(field, value, f'must have shape ({size},) or (n, {size})')
    return np.atleast_2d(array), array.ndim == 1


def normalised(quaternion: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quaternions (n, 4) with rows off unit length by more than :data:`UNIT_TOLERANCE` divided by their norm."""
    norm = np.linalg.norm(quaternion, axis=-1, keepdims=True)
    return np.where(np.abs(norm - 1.0) > UNIT_TOLERANCE, quaternion / norm, quaternion)


class PoseSensorModel:
    """A tracker's reading of the platform pose: white noise and a constant bias on position and orientation (see
    the module docstring)."""

    PARAM_NAMES = ('position_noise_std', 'angle_noise_std', 'position_bias', 'angle_bias', 'seed')

    def __init__(self, position_noise_std: float = 2.0e-6, angle_noise_std: float = 20.0e-6,
                 position_bias: ArrayLike = (0.0, 0.0, 0.0), angle_bias: ArrayLike = (0.0, 0.0, 0.0),
                 rng: RngLike = None) -> None:
        """Create the model.

        Args:
            position_noise_std: Standard deviation of white noise on each position coordinate, m, >= 0.
            angle_noise_std: Standard deviation of each component of the white-noise rotation vector applied to the
                true orientation (fixed frame), rad, >= 0.
            position_bias: Constant offset of the position (x, y, z), m, in the frame of the poses (crane_base).
            angle_bias: Constant rotation vector applied to the true orientation before the noise, rad, fixed frame.
            rng: Seed or Generator.
        """
        self._position_noise_std = _float('position_noise_std', position_noise_std, minimum=0.0)
        self._angle_noise_std = _float('angle_noise_std', angle_noise_std, minimum=0.0)
        self._position_bias = _float_vector('position_bias', position_bias, 3)
        self._angle_bias = _float_vector('angle_bias', angle_bias, 3)
        self._rng = _rng('rng', rng)

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> PoseSensorModel:
        """Build from a dict with keys from :attr:`PARAM_NAMES` (all optional; ``seed`` an int or None)."""
        _check_keys(params, cls.PARAM_NAMES)
        kwargs = {key: params[key] for key in cls.PARAM_NAMES if key in params and key != 'seed'}
        return cls(**kwargs, rng=_rng('seed', params.get('seed')))

    @property
    def position_noise_std(self) -> float:
        """Position white noise per coordinate, m."""
        return self._position_noise_std

    @property
    def angle_noise_std(self) -> float:
        """Rotation-vector white noise per component, rad."""
        return self._angle_noise_std

    @property
    def position_bias(self) -> NDArray[np.float64]:
        """Position bias, m (a copy)."""
        return self._position_bias.copy()

    @property
    def angle_bias(self) -> NDArray[np.float64]:
        """Orientation bias as a rotation vector, rad, fixed frame (a copy)."""
        return self._angle_bias.copy()

    def continue_noise_of(self, other: PoseSensorModel) -> None:
        """Draw the noise from ``other``'s generator from now on: a new set-up of the same sensor (a parameter
        changed, not the seed) continues its noise stream instead of repeating it from the start."""
        self._rng = other._rng

    def measure(self, position: ArrayLike, orientation: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Readings of the true poses.

        Args:
            position: Platform centre, m, in the sensor's frame; shape (3,) or (n, 3).
            orientation: Unit quaternion [x, y, z, w] body -> frame; shape (4,) or (n, 4), as many as positions.
                A non-unit one is normalised.

        Returns:
            ``(position, orientation)`` measured: shapes (3,) and (4,) for one pose, (n, 3) and (n, 4) for n.
        """
        u, single = _batch('position', position, 3)
        q, single_q = _batch('orientation', orientation, 4)
        if len(u) != len(q) or single != single_q:
            raise ParameterError('orientation', orientation, f'must be one quaternion per position ({len(u)})')
        if not (np.isfinite(u).all() and np.isfinite(q).all()) or (np.linalg.norm(q, axis=1) == 0.0).any():
            raise ParameterError('pose', 'NaN/Inf or a zero quaternion', 'must be finite with a non-zero quaternion')
        draws = self._rng.standard_normal((len(u), 6))
        measured_u = u + self._position_bias + self._position_noise_std * draws[:, :3]
        turn = rotvec_to_quaternion(self._angle_bias + self._angle_noise_std * draws[:, 3:])
        measured_q = normalised(quaternion_multiply(turn, normalised(q)))
        if single:
            return measured_u[0], measured_q[0]
        return measured_u, measured_q


#: :class:`PoseSensorModel`'s parameters and the tracker's latency, with a lab motion-capture system as defaults (the
#: pose_sensor node).
POSE_SENSOR_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('position_noise_std', 2.0e-6, 'white-noise standard deviation of each position coordinate, '
              'crane_base [m]', low=0.0),
    ParamSpec('angle_noise_std', 20.0e-6, 'white-noise standard deviation of each component of the small rotation '
              'vector (fixed frame) applied to the true orientation [rad]', low=0.0),
    ParamSpec('position_bias', [0.0, 0.0, 0.0], 'constant offset of the position x y z, crane_base [m]'),
    ParamSpec('angle_bias', [0.0, 0.0, 0.0], 'constant rotation vector (fixed frame) applied to the true '
              'orientation before the noise [rad]'),
    ParamSpec('latency_s', 0.0, 'on wall-clock time, how long after its stamp a sample is published at the '
              "earliest (a tracker's processing delay); stamps and values do not change. Unused on simulated "
              'time [s]', low=0.0, high=5.0),
    SEED_PARAM,
)


def pose_sensor_from_params(values: Mapping[str, Any]) -> PoseSensorModel:
    """The :class:`PoseSensorModel` of parameter values (:data:`POSE_SENSOR_PARAMS`; other keys ignored; seed -1 =
    random). Raises ParameterError naming a bad value."""
    return PoseSensorModel.from_params({**{k: values[k] for k in PoseSensorModel.PARAM_NAMES if k != 'seed'},
                                        'seed': _seed(values)})


__all__ = ['POSE_SENSOR_PARAMS', 'PoseSensorModel', 'normalised', 'pose_sensor_from_params']
