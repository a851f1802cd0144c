"""The pose deflection the 6×6 identification fits: the platform's pose under load relative to its pose without
external load, as the 6-vector d = [δu_x, δu_y, δu_z, δθ_x, δθ_y, δθ_z].

- Translations δu [m]: the centre's position minus its position under the weight alone, fixed frame (z down).
- Rotations δθ [rad]: the rotation vector of Q·Q0ᵀ (Q, Q0 body→fixed rotation matrices under load and without), in
  the fixed frame: the rotation that carries the unloaded platform to the loaded one. To first order
  Q ≈ (I + [δθ]×)·Q0, the perturbation the exact tangent stiffness uses (crane_stiffness.model.stiffness), so
  d ≈ C·w with C = K⁻¹ for a small wrench w. A motion-capture pose (position and quaternion [x, y, z, w], as
  geometry_msgs/PoseStamped holds it) converts with :func:`pose_deflection` after
  crane_stiffness.model.rotation.quaternion_to_matrix.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

# Below this angle the rotation vector is read off the skew part alone (sin θ ≈ θ to 1e-16 relative).
_SMALL_ANGLE = 1e-8


def rotation_vector(rotation: ArrayLike) -> NDArray[np.float64]:
    """Rotation vectors (…, 3) [rad] of rotation matrices (…, 3, 3): axis times angle.

    Read off the skew part, which is exact for angles well below π (a platform deflection is a fraction of a
    degree); near π the skew part vanishes and the axis is lost."""
    q = np.asarray(rotation, dtype=float)
    skew = np.stack([q[..., 2, 1] - q[..., 1, 2], q[..., 0, 2] - q[..., 2, 0], q[..., 1, 0] - q[..., 0, 1]],
                    axis=-1)
    sin2 = np.linalg.norm(skew, axis=-1)  # 2·sin θ
    angle = np.arctan2(sin2, np.trace(q, axis1=-2, axis2=-1) - 1.0)  # atan2(2 sin θ, 2 cos θ): precise at any θ
    small = angle < _SMALL_ANGLE
    scale = np.where(small, 0.5, angle / np.where(small, 1.0, sin2))
    return skew * scale[..., None]


def pose_deflection(position: ArrayLike, rotation: ArrayLike, rest_position: ArrayLike,
                    rest_rotation: ArrayLike) -> NDArray[np.float64]:
    """Deflections d (…, 6) = [position − rest_position [m], rotation_vector(rotation · rest_rotationᵀ) [rad]].

    Args:
        position: centre of the platform under load (…, 3) [m], fixed frame.
        rotation: its rotation matrix, body→fixed (…, 3, 3).
        rest_position: the centre without external load (3,) [m] (under the weight alone).
        rest_rotation: its rotation matrix (3, 3).
    """
    p = np.asarray(position, dtype=float)
    q = np.asarray(rotation, dtype=float)
    q0 = np.asarray(rest_rotation, dtype=float)
    turn = q @ q0.T
    return np.concatenate([p - np.asarray(rest_position, dtype=float), rotation_vector(turn)], axis=-1)


__all__ = ['pose_deflection', 'rotation_vector']
