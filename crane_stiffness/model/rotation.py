"""Rotations in the paper's convention.

Q maps body coordinates to the fixed frame. The paper's sequence (text under eq. 5): first φ about the body z axis,
then θ about the new x axis, then ψ about the new y axis, so Q = R_z(φ)·R_x(θ)·R_y(ψ) (intrinsic z–x–y).
Its small-angle form is eq. (22): Q ≈ I + [ω]× with ω = (θ, ψ, φ). All angles in radians.
"""
from __future__ import annotations

import math

import numpy as np


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v]× with [v]× w = v × w, shape (3, 3)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def euler_zxy_to_matrix(phi: float, theta: float, psi: float) -> np.ndarray:
    """Q = R_z(φ)·R_x(θ)·R_y(ψ), shape (3, 3). φ about z, θ about x, ψ about y [rad]."""
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(theta), math.sin(theta)
    cp, sp = math.cos(psi), math.sin(psi)
    return np.array([[cf * cp - sf * st * sp, -sf * ct, cf * sp + sf * st * cp],
                     [sf * cp + cf * st * sp, cf * ct, sf * sp - cf * st * cp],
                     [-ct * sp, st, ct * cp]])


def matrix_to_euler_zxy(q: np.ndarray) -> np.ndarray:
    """The paper's angles [φ, θ, ψ] of a rotation matrix (inverse of :func:`euler_zxy_to_matrix`) [rad].

    θ is in [−π/2, π/2]; at θ = ±π/2 (gimbal lock, far outside any crane pose) φ + ψ is not unique.
    """
    theta = math.asin(max(-1.0, min(1.0, q[2, 1])))
    psi = math.atan2(-q[2, 0], q[2, 2])
    phi = math.atan2(-q[0, 1], q[1, 1])
    return np.array([phi, theta, psi])


def rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """Rotation matrix exp([w]×) of a rotation vector w [rad] (Rodrigues)."""
    angle = math.sqrt(float(w[0] ** 2 + w[1] ** 2 + w[2] ** 2))
    k = skew(w)
    if angle < 1e-8:
        return np.eye(3) + k + 0.5 * k @ k
    return np.eye(3) + math.sin(angle) / angle * k + (1.0 - math.cos(angle)) / angle ** 2 * k @ k


def matrix_to_quaternion(q: np.ndarray) -> np.ndarray:
    """Unit quaternion [x, y, z, w] (ROS order) of a rotation matrix, with w >= 0."""
    tr = q[0, 0] + q[1, 1] + q[2, 2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        xyzw = [(q[2, 1] - q[1, 2]) / s, (q[0, 2] - q[2, 0]) / s, (q[1, 0] - q[0, 1]) / s, 0.25 * s]
    elif q[0, 0] > q[1, 1] and q[0, 0] > q[2, 2]:
        s = math.sqrt(1.0 + q[0, 0] - q[1, 1] - q[2, 2]) * 2.0
        xyzw = [0.25 * s, (q[0, 1] + q[1, 0]) / s, (q[0, 2] + q[2, 0]) / s, (q[2, 1] - q[1, 2]) / s]
    elif q[1, 1] > q[2, 2]:
        s = math.sqrt(1.0 + q[1, 1] - q[0, 0] - q[2, 2]) * 2.0
        xyzw = [(q[0, 1] + q[1, 0]) / s, 0.25 * s, (q[1, 2] + q[2, 1]) / s, (q[0, 2] - q[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + q[2, 2] - q[0, 0] - q[1, 1]) * 2.0
        xyzw = [(q[0, 2] + q[2, 0]) / s, (q[1, 2] + q[2, 1]) / s, 0.25 * s, (q[1, 0] - q[0, 1]) / s]
    quat = np.array(xyzw)
    quat /= np.linalg.norm(quat)
    return quat if quat[3] >= 0 else -quat


def quaternion_to_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion [x, y, z, w] (normalised first)."""
    x, y, z, w = np.asarray(quat, dtype=float) / np.linalg.norm(quat)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def rotvec_to_quaternion(w: np.ndarray) -> np.ndarray:
    """Unit quaternions [x, y, z, w] (…, 4) of rotation vectors w (…, 3) [rad]: exp of half the vector.

    Vectorised, precise to rounding at any angle (below 1e-4 rad sin(a/2)/a is its series, so a zero vector gives
    [0, 0, 0, 1] exactly)."""
    w = np.asarray(w, dtype=float)
    angle = np.linalg.norm(w, axis=-1)
    small = angle < 1e-4
    safe = np.where(small, 1.0, angle)
    half_sinc = np.where(small, 0.5 - angle * angle / 48.0, np.sin(0.5 * safe) / safe)  # sin(a/2)/a
    return np.concatenate([w * half_sinc[..., None], np.cos(0.5 * angle)[..., None]], axis=-1)


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products a·b (…, 4) of quaternions [x, y, z, w] (broadcast): the rotation b, then a; as matrices
    R(a·b) = R(a)·R(b). Not normalised."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)
