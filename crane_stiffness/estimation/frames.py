"""Sensor frames: a wrench measured in a force/torque sensor's own frame, moved to the platform centre in crane_base.

A six-axis sensor reports ``[f, m]`` in its frame S: force [N] and moment [N·m] about S's origin. With the sensor
mounted at rotation R (S → crane_base: a vector with coordinates v in S has coordinates R·v in crane_base) and
its origin at r [m] from the platform centre (crane_base coordinates), the same load acting on the platform, about
the platform centre and in crane_base, is

    f' = R·f,        m' = R·m + r × (R·f)

A sensor in the load path measures the reaction of the load it carries: with ``reaction=True`` the result is
negated, so it is the wrench applied to the platform (the sign convention of ``/crane/wrench_command``).
Pure numpy, no ROS; :class:`SensorMount` takes the parameters as ROS nodes declare them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.estimation.errors import ParameterError
from crane_stiffness.model.rotation import quaternion_to_matrix


def _rotation(value: ArrayLike, name: str = 'rotation') -> NDArray[np.float64]:
    """A rotation matrix from a 3×3 matrix (or 9 numbers row-major) or a quaternion [x, y, z, w]; checked."""
    a = np.asarray(value, dtype=float)
    if a.size == 4 and a.ndim == 1:
        if not np.isfinite(a).all() or np.linalg.norm(a) < 1e-9:
            raise ParameterError(name, value, 'a quaternion [x, y, z, w] must be finite and non-zero')
        return quaternion_to_matrix(a)
    if a.size != 9 or a.ndim not in (1, 2) or (a.ndim == 2 and a.shape != (3, 3)):
        raise ParameterError(name, value, 'must be a quaternion [x, y, z, w] or a 3x3 matrix (9 numbers, row-major)')
    m = a.reshape(3, 3)
    if not np.isfinite(m).all() or not np.allclose(m @ m.T, np.eye(3), atol=1e-6) or np.linalg.det(m) < 0:
        raise ParameterError(name, value, 'must be a proper rotation matrix (orthonormal, det +1)')
    return m


def _wrenches(wrench: ArrayLike) -> NDArray[np.float64]:
    """``wrench`` as floats of shape (6,) or (n, 6); checked."""
    w = np.asarray(wrench, dtype=float)
    if w.shape[-1:] != (6,) or w.ndim > 2:
        raise ParameterError('wrench', w.shape, 'must have shape (6,) or (n, 6)')
    return w


def _vector3(value: ArrayLike, name: str) -> NDArray[np.float64]:
    a = np.asarray(value, dtype=float)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise ParameterError(name, value, 'must be 3 finite numbers')
    return a


def transform_wrench(wrench: ArrayLike, rotation: ArrayLike, position: ArrayLike = (0.0, 0.0, 0.0),
                     reaction: bool = False) -> NDArray[np.float64]:
    """Move wrenches from the sensor frame to the platform centre in crane_base (see the module docstring).

    Args:
        wrench: ``[fx, fy, fz, mx, my, mz]`` in the sensor frame [N, N·m], shape (6,) or (n, 6).
        rotation: Sensor frame → crane_base: a quaternion [x, y, z, w] or a 3×3 rotation matrix.
        position: Sensor origin relative to the platform centre, crane_base [m].
        reaction: The sensor measures the reaction: negate, giving the wrench applied to the platform.

    Returns:
        The wrench about the platform centre in crane_base, same shape as ``wrench``.
    """
    w = _wrenches(wrench)
    r_mat = _rotation(rotation)
    r = _vector3(position, 'position')
    f = w[..., :3] @ r_mat.T
    m = w[..., 3:] @ r_mat.T + np.cross(r, f)
    out = np.concatenate([f, m], axis=-1)
    return -out if reaction else out


@dataclass(frozen=True)
class SensorMount:
    """A sensor's mounting: rotation (sensor → crane_base), position of its origin from the platform centre [m] in
    crane_base, and whether it measures the reaction. ``apply`` moves wrenches to the platform centre."""

    rotation: NDArray[np.float64] = field(default_factory=lambda: np.eye(3))
    position: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    reaction: bool = False
    #: :meth:`matrix`, made once: a live estimator moves every sample (1 kHz) with it.
    _matrix: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    PARAM_NAMES = ('sensor_rotation', 'sensor_position', 'sensor_reaction')

    def __post_init__(self) -> None:
        # transform_wrench of the six unit wrenches: its rows are T's columns
        object.__setattr__(self, '_matrix', transform_wrench(np.eye(6), self.rotation, self.position,
                                                             self.reaction).T.copy())

    @classmethod
    def from_params(cls, values: Mapping[str, Any]) -> SensorMount:
        """From ``sensor_rotation`` (quaternion [x, y, z, w] or 9 numbers), ``sensor_position`` [m] and
        ``sensor_reaction`` (bool); missing ones take the identity, the centre and False."""
        reaction = values.get('sensor_reaction', False)
        if not isinstance(reaction, bool):
            raise ParameterError('sensor_reaction', reaction, 'must be true or false')
        return cls(_rotation(values.get('sensor_rotation', [0.0, 0.0, 0.0, 1.0]), 'sensor_rotation'),
                   _vector3(values.get('sensor_position', [0.0, 0.0, 0.0]), 'sensor_position'), reaction)

    def apply(self, wrench: ArrayLike) -> NDArray[np.float64]:
        """:func:`transform_wrench` with this mounting, as the product with :meth:`matrix` (shape (6,) or (n, 6)):
        the rotation is checked once, when the mount is made."""
        return _wrenches(wrench) @ self._matrix.T

    @property
    def is_identity(self) -> bool:
        """True when the sensor frame is the platform centre's (no rotation, no offset, no sign): nothing to do."""
        return (not self.reaction and bool(np.array_equal(self.rotation, np.eye(3)))
                and not bool(np.any(self.position)))

    def matrix(self) -> NDArray[np.float64]:
        """The 6×6 matrix T with ``apply(w) == T @ w`` (rows: crane_base components at the platform centre)."""
        return self._matrix.copy()

    def component_row(self, axis_index: int) -> tuple[float, ...]:
        """Row ``axis_index`` of :meth:`matrix` as 6 floats: the one component the estimator fits, as a dot
        product with the sensor's wrench (the live per-sample form; :meth:`component` is the vectorised one)."""
        return tuple(float(v) for v in self.matrix()[axis_index])

    def component(self, wrench: ArrayLike, axis_index: int) -> NDArray[np.float64]:
        """Component ``axis_index`` of the moved wrench for wrenches of shape (n, 6) (vectorised)."""
        return np.asarray(wrench, dtype=float) @ self.matrix()[axis_index]

