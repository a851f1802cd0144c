"""Rotations of the independent reference model (independent_crane.py): Euler angles z-x-y, the fixed-frame
angular-velocity map, Rodrigues' formula. Like the model, it shares nothing with the ``crane_stiffness`` package:
numpy and the standard library only. Q = Rz(phi) Rx(theta) Ry(psi), body -> fixed.
"""

from __future__ import annotations

import math

import numpy as np


def rot_x(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_zxy(phi, theta, psi) -> np.ndarray:
    """Q = Rz(phi) Rx(theta) Ry(psi), body -> fixed."""
    return rot_z(phi) @ rot_x(theta) @ rot_y(psi)


def euler_zxy(Q) -> np.ndarray:
    """(phi, theta, psi) with Q = Rz(phi) Rx(theta) Ry(psi), theta in [-pi/2, pi/2].

    Third row of Q is (-cos(th) sin(psi), sin(th), cos(th) cos(psi)); second column is
    (-sin(phi) cos(th), cos(phi) cos(th), sin(th)).
    """
    Q = np.asarray(Q, dtype=float)
    theta = math.asin(max(-1.0, min(1.0, Q[2, 1])))
    psi = math.atan2(-Q[2, 0], Q[2, 2])
    phi = math.atan2(-Q[0, 1], Q[1, 1])
    return np.array([phi, theta, psi])


def cross(a, b) -> np.ndarray:
    """a x b for (..., 3) arrays (np.cross is slow for tiny arrays)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def skew(v) -> np.ndarray:
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rodrigues(w) -> np.ndarray:
    """exp([w]x)."""
    w = np.asarray(w, dtype=float)
    th = float(np.linalg.norm(w))
    S = skew(w)
    if th < 1e-8:
        return np.eye(3) + S + 0.5 * S @ S
    return np.eye(3) + math.sin(th) / th * S + (1.0 - math.cos(th)) / th ** 2 * S @ S


def euler_rate_map(phi, theta) -> np.ndarray:
    """Columns: fixed-frame angular velocity per unit rate of phi, theta, psi.

    dQ Q^T = [w]x with w = e_z dphi + Rz(phi) e_x dtheta + Rz(phi) Rx(theta) e_y dpsi.
    """
    Rz = rot_z(phi)
    return np.column_stack([np.array([0.0, 0.0, 1.0]), Rz[:, 0], (Rz @ rot_x(theta))[:, 1]])
