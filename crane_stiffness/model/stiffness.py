"""Stiffness matrices of the crane: exact tangent, the paper's linearized eq. (18), K0 (App. I), Kw (App. II).

All 6×6 matrices use the order [u_x, u_y, u_z, θ_x, θ_y, θ_z] (the paper's [δu_x, δu_y, δu_z, δθ, δψ, δφ]) and map a
small displacement [m, rad] to the external load [N, N·m] that holds it: P = K δu (eq. 17).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from crane_stiffness.contract.axes import AXES, axis_index  # noqa: F401 (AXES: re-exported by crane_stiffness.model)
from crane_stiffness.model.errors import GeometryError
from crane_stiffness.model.geometry import CraneGeometry

if TYPE_CHECKING:
    from crane_stiffness.model.equilibrium import Equilibrium


def tangent_stiffness(geometry: CraneGeometry, equilibrium: Equilibrium) -> np.ndarray:
    """Exact tangent stiffness K = −∂w/∂x at an equilibrium, (6, 6).

    Includes the axial wire stiffness, the geometric (tension) terms, slack wires (which contribute nothing) and the
    moment of the weight about the platform centre when the centre of mass is offset. Rotations are perturbed in the
    fixed frame; the external load is held fixed in space (so a fixed external couple leaves a small asymmetry).
    """
    # Imported here: the estimators use this module's axis functions, and .equilibrium brings numba (~0.4 s of CPU
    # at each node's start).
    from crane_stiffness.model.equilibrium import wrench_jacobian
    _, k = wrench_jacobian(geometry, equilibrium.displacement, equilibrium.rotation, equilibrium.load)
    return k


def compliance(stiffness: np.ndarray) -> np.ndarray:
    """C = K⁻¹ (6, 6); raises numpy.linalg.LinAlgError if K is singular (a mechanism: no stiffness at all)."""
    return np.linalg.inv(stiffness)


def directional_stiffness(stiffness: np.ndarray, direction) -> float:
    """Stiffness along a load direction d (6,): 1/(dᵀ C d) with every other DOF free to move.

    For d = unit force along y this is the side stiffness f_y/δu_y (for eq. 18 it equals K_j of eq. 19).
    Units follow the direction: N/m for a force axis, N·m/rad for a moment axis.
    """
    d = np.asarray(direction, dtype=float).reshape(6)
    if not np.any(d):
        raise ValueError('direction = 0: a load direction must be non-zero')
    d = d / np.linalg.norm(d)
    return float(1.0 / (d @ np.linalg.solve(stiffness, d)))


def axis_stiffness(stiffness: np.ndarray, axis: str) -> float:
    """:func:`directional_stiffness` along one named axis (fx … mz)."""
    d = np.zeros(6)
    d[axis_index(axis)] = 1.0
    return directional_stiffness(stiffness, d)


# --- The paper's closed forms ----------------------------------------------------------------------------------

def _horizontal2(g: CraneGeometry) -> float:
    return 4.0 * (g.a ** 2 + g.b ** 2 - g.a * g.b) / 3.0


def loaded_height(geometry: CraneGeometry) -> tuple[float, float]:
    """(h_w, l_w): height and wire length at the rest pose under W alone [m].

    Solves the vertical balance 6·k·(l_w − l0)·h_w/l_w = W with l_w = sqrt(h_w² + 4(a² + b² − ab)/3) (eq. 32;
    the printed "h_w = W/(6k(l_w − l0))" is dimensionally wrong, see docs/physics.md).
    """
    from scipy.optimize import brentq  # deferred: importing scipy.optimize costs a quarter second at start-up

    g = geometry
    s2 = _horizontal2(g)
    k, l0, w = g.k, g.l0, g.weight
    if w == 0.0:
        return g.height, l0

    def balance(hw: float) -> float:
        lw = math.sqrt(hw * hw + s2)
        return 6.0 * k * (lw - l0) * hw / lw - w

    lo, hi = g.height, g.height * 1.001 + 1e-9
    while balance(hi) < 0.0:
        hi = g.height + 2.0 * (hi - g.height)
        if hi > 1e6 * g.height:
            raise GeometryError('weight', w, 'the wires cannot carry it (no finite loaded height)')
    hw = brentq(balance, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200)
    return hw, math.sqrt(hw * hw + s2)


@dataclass(frozen=True)
class PaperCoefficients:
    """K1..K5 of eq. (18) [N/m, N/rad, N/m, N·m/rad, N·m/rad], with the loaded height h_w and length l_w [m]."""

    k1: float
    k2: float
    k3: float
    k4: float
    k5: float
    h_w: float
    l_w: float

    @property
    def side(self) -> float:
        """K_j = K1 − K2²/K4 (eq. 19): side stiffness with the coupled tilt free [N/m]."""
        return self.k1 - self.k2 ** 2 / self.k4


def paper_coefficients(geometry: CraneGeometry) -> PaperCoefficients:
    """The coefficients of eq. (18) at the rest pose under the weight W (symmetric crane, nominal k)."""
    g = geometry
    hw, lw = loaded_height(g)
    k, l0, a, b, w = g.k, g.l0, g.a, g.b, g.weight
    c = k * l0 / lw ** 3
    return PaperCoefficients(
        k1=4.0 * c * (a * a + b * b - a * b) + w / hw,
        k2=2.0 * c * a * (2.0 * a - b) * hw,
        k3=6.0 * c * hw * hw + w / hw,
        k4=4.0 * c * a * a * hw * hw + a * b * w / (3.0 * hw),
        k5=8.0 * c * a * a * b * b + 2.0 * a * b * w / (3.0 * hw),
        h_w=hw, l_w=lw)


def _eq18_matrix(k1: float, k2: float, k3: float, k4: float, k5: float) -> np.ndarray:
    return np.array([[k1, 0, 0, 0, -k2, 0],
                     [0, k1, 0, k2, 0, 0],
                     [0, 0, k3, 0, 0, 0],
                     [0, k2, 0, k4, 0, 0],
                     [-k2, 0, 0, 0, k4, 0],
                     [0, 0, 0, 0, 0, k5]], dtype=float)


def paper_stiffness(geometry: CraneGeometry) -> np.ndarray:
    """The linearized stiffness matrix of eq. (18) at the rest pose under W, (6, 6)."""
    c = paper_coefficients(geometry)
    return _eq18_matrix(c.k1, c.k2, c.k3, c.k4, c.k5)


def elastic_stiffness(geometry: CraneGeometry) -> np.ndarray:
    """K0 of Appendix I, eq. (28): the six wires as bilateral springs, no weight, at the unloaded pose (6, 6)."""
    g = geometry
    k, l0, a, b, h = g.k, g.l0, g.a, g.b, g.height
    s = k / l0 ** 2
    return _eq18_matrix(4 * s * (a * a + b * b - a * b), 2 * s * a * (2 * a - b) * h, 6 * s * h * h,
                        4 * s * a * a * h * h, 8 * s * a * a * b * b)


def pendulum_stiffness(geometry: CraneGeometry) -> np.ndarray:
    """Kw of Appendix II, eq. (46): the pendulum effect of the weight W at the loaded height h_w (6, 6)."""
    g = geometry
    hw, _ = loaded_height(g)
    w, a, b = g.weight, g.a, g.b
    return np.diag([w / hw, w / hw, w / hw, a * b * w / (3 * hw), a * b * w / (3 * hw), 2 * a * b * w / (3 * hw)])


def single_wire_pendulum_stiffness(geometry: CraneGeometry, fraction: float = 1.0 / 6.0) -> float:
    """Lateral stiffness of a single-wire crane of length h_w carrying ``fraction``·W: (fraction·W)/h_w [N/m].

    With fraction = 1/6 this is the paper's dashed comparison line of Figs. 5–9 (eq. 30 with W/6).
    """
    hw, _ = loaded_height(geometry)
    return fraction * geometry.weight / hw
