"""What an identified 6×6 stiffness is compared with: the exact tangent stiffness of the nonlinear model at the rest
pose, the paper's linearised eq. (18), and where the side–tilt coupling K2 sits in them.

Matrices follow crane_stiffness.model.stiffness: K maps a small displacement [δu_x, δu_y, δu_z, δθ_x, δθ_y, δθ_z]
(m, rad; the paper's [δu_x, δu_y, δu_z, δθ, δψ, δφ]) to the wrench [fx, fy, fz, mx, my, mz] (N, N·m) that holds it,
fixed frame, z down; row i is the load axis i, column j the displacement j. Units of an entry K[i, j]: N/m for a
force per translation, N/rad for a force per rotation and for a moment per translation (N·m/m), N·m/rad for a
moment per rotation. The compliance C = K⁻¹ holds the reciprocal units (m/N, m/(N·m), rad/N, rad/(N·m)).

K2 in eq. (18): a side force along y at the platform centre comes with a tilt about x and a side force along x with
a tilt about y of the other sign (the wires pull the platform's rim, above which the centre swings)::

    K[fy, θx] = K[mx, u_y] = +K2,    K[fx, θy] = K[my, u_x] = −K2,    K2 = 2·k·l0·a·(2a − b)·h_w / l_w³ > 0.

:data:`K2_ENTRIES` lists the four (row, column, sign); :func:`k2_of` reads K2 from a matrix as the mean of the four
signed entries. At the rest pose of a symmetric crane (no centre-of-mass offset, equal wires, loads through the
centre) eq. (18) equals the exact tangent to rounding error (docs/physics.md); anywhere else only the tangent holds.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.contract.axes import AXES
from crane_stiffness.model import CraneGeometry, PaperCoefficients, paper_coefficients, paper_stiffness

if TYPE_CHECKING:
    from crane_stiffness.model import Equilibrium

#: The displacement names of K's columns (and C's rows), in order.
DISPLACEMENTS: tuple[str, ...] = ('u_x', 'u_y', 'u_z', 'θ_x', 'θ_y', 'θ_z')
#: Where K2 sits in eq. (18): (row, column, sign of K2 there).
K2_ENTRIES: tuple[tuple[int, int, float], ...] = ((1, 3, 1.0), (3, 1, 1.0), (0, 4, -1.0), (4, 0, -1.0))


def entry_name(row: int, column: int, *, compliance: bool = False) -> str:
    """'K[fy, θ_x]' for the stiffness entry (row, column); 'C[u_y, mx]' for the compliance entry with
    ``compliance=True``."""
    if compliance:
        return f'C[{DISPLACEMENTS[row]}, {AXES[column]}]'
    return f'K[{AXES[row]}, {DISPLACEMENTS[column]}]'


def k2_weights() -> NDArray[np.float64]:
    """The (6, 6) weights whose sum with a stiffness matrix is :func:`k2_of` (±1/4 at :data:`K2_ENTRIES`)."""
    g = np.zeros((6, 6))
    for i, j, sign in K2_ENTRIES:
        g[i, j] = sign / len(K2_ENTRIES)
    return g


def k2_of(stiffness: ArrayLike) -> float:
    """K2 read from a stiffness matrix (6, 6): the mean of its four signed K2 entries [N/rad]."""
    return float(np.sum(k2_weights() * np.asarray(stiffness, dtype=float)))


@dataclass(frozen=True)
class Reference:
    """The model's 6×6 at the rest pose under the weight alone (no external load).

    Attributes:
        equilibrium: that rest pose.
        tangent: exact tangent stiffness K = −∂w/∂x (6, 6) (units in the module docstring).
        compliance: C = K⁻¹ (6, 6).
        paper: eq. (18) (6, 6), or None when it does not apply (a centre-of-mass offset, unequal wires, a load
            point off the centre).
        coefficients: K1..K5, h_w, l_w of eq. (18), or None likewise.
    """

    equilibrium: Equilibrium
    tangent: NDArray[np.float64]
    compliance: NDArray[np.float64]
    paper: NDArray[np.float64] | None
    coefficients: PaperCoefficients | None

    @property
    def k2(self) -> float:
        """K2 of the tangent (:func:`k2_of`) [N/rad]."""
        return k2_of(self.tangent)


def paper_applies(geometry: CraneGeometry) -> bool:
    """True when eq. (18) describes ``geometry`` at rest: symmetric crane, loads at the centre."""
    return (not any(geometry.com_offset) and not any(geometry.length_offsets) and not any(geometry.load_point)
            and geometry.weight > 0.0)


def reference_at_rest(geometry: CraneGeometry) -> Reference:
    """The :class:`Reference` of ``geometry`` at its rest pose under the weight W."""
    # Imported here: the solver brings numba (~0.4 s of CPU), which the six-axis estimator and the live view, importing
    # this module for k2_weights and for this function on a six-axis rig only, need not load at start.
    from crane_stiffness.model import rest_pose, tangent_stiffness
    eq = rest_pose(geometry)
    k = tangent_stiffness(geometry, eq)
    applies = paper_applies(geometry)
    return Reference(eq, k, np.linalg.inv(k), paper_stiffness(geometry) if applies else None,
                     paper_coefficients(geometry) if applies else None)


#: A tangent entry smaller than this share of sqrt(|K_ii·K_jj|) is a zero of the model (a coupling the symmetry
#: removes; the computed tangent holds rounding noise there, ~1e-13 of it): no relative error, only whether an
#: interval holds it. Used by the offline analysis and the live view alike.
ZERO_COUPLING = 1e-6


def structural_zeros(tangent: ArrayLike) -> NDArray[np.bool_]:
    """(6, 6) True where the tangent's entry is a zero of the model (:data:`ZERO_COUPLING`)."""
    t = np.asarray(tangent, dtype=float)
    d = np.sqrt(np.abs(np.outer(np.diag(t), np.diag(t))))
    return np.abs(t) <= ZERO_COUPLING * d


def relative_error(measured: ArrayLike, reference: ArrayLike) -> NDArray[np.float64]:
    """measured / reference − 1 (6, 6), NaN at the reference's zeros (:func:`structural_zeros`)."""
    ref = np.asarray(reference, dtype=float)
    zero = structural_zeros(ref)
    return np.where(zero, np.nan, np.asarray(measured, dtype=float) / np.where(zero, 1.0, ref) - 1.0)


__all__ = ['DISPLACEMENTS', 'K2_ENTRIES', 'ZERO_COUPLING', 'Reference', 'entry_name', 'k2_of', 'k2_weights',
           'paper_applies', 'reference_at_rest', 'relative_error', 'structural_zeros']
