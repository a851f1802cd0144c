"""The crane at one pose: inverse problem, equilibrium, the stiffness split into forces and moments, tensions.

**How the stiffness is split.** The exact tangent K (6×6, [u; θ] → [F; M]) mixes N/m, N/rad and N·m/rad, so its
eigenvalues mean nothing physical. Instead: the compliance C = K⁻¹ answers "this load, what motion", with every
other degree of freedom free to move. Its force block C_FF (3×3, m/N) is the centre's displacement under a force
through the centre with no moment applied (the platform free to tilt); its moment block C_MM (3×3, rad/(N·m)) is
the rotation under a pure couple (the platform free to shift). The stiffness along a unit force direction d is
1/(dᵀ C_FF d) N/m (the same as :func:`crane_stiffness.model.directional_stiffness` on [d, 0]); its minimum over all
directions is 1/λ_max of the symmetric part of C_FF, reached along that eigenvector. The moment part likewise. The
matrices K_F = C_FF⁻¹ (N/m) and K_M = C_MM⁻¹ (N·m/rad) are the Schur complements of K; both have one unit only.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from crane_stiffness.model import CraneGeometry, Equilibrium, tangent_stiffness
from crane_stiffness.model.geometry import WIRE_NAMES
from crane_stiffness.model.inverse import PoseSolution, inverse_pose
from crane_stiffness.model.rotation import matrix_to_euler_zxy
from crane_stiffness.model.stiffness import loaded_height


def _oriented(v: np.ndarray) -> np.ndarray:
    """An eigenvector with its largest component positive (eigenvectors have no sign of their own)."""
    return v if v[np.argmax(np.abs(v))] >= 0 else -v


def split_stiffness_batch(k: np.ndarray) -> dict[str, np.ndarray]:
    """The split of many tangents K (N, 6, 6): minimum force stiffness (N,) [N/m] and its direction (N, 3),
    minimum moment stiffness (N,) [N·m/rad] and its axis (N, 3). NaN where K is singular or NaN."""
    k = np.asarray(k, dtype=float).reshape(-1, 6, 6)
    n = k.shape[0]
    out = {'force_min': np.full(n, np.nan), 'force_dir': np.full((n, 3), np.nan),
           'moment_min': np.full(n, np.nan), 'moment_dir': np.full((n, 3), np.nan)}
    good = np.all(np.isfinite(k), axis=(1, 2))
    good[good] = np.abs(np.linalg.det(k[good])) > 0.0
    if not good.any():
        return out
    c = np.linalg.inv(k[good])
    for name, block in (('force', c[:, :3, :3]), ('moment', c[:, 3:, 3:])):
        sym = 0.5 * (block + np.swapaxes(block, 1, 2))
        vals, vecs = np.linalg.eigh(sym)
        top = vecs[:, :, -1]
        flip = np.take_along_axis(top, np.argmax(np.abs(top), axis=1)[:, None], axis=1) < 0
        out[f'{name}_min'][good] = 1.0 / vals[:, -1]
        out[f'{name}_dir'][good] = np.where(flip, -top, top)
    return out


@dataclass(frozen=True)
class SplitStiffness:
    """Force and moment stiffness kept apart (see the module doc for how the split is made).

    Attributes:
        force_matrix: K_F = C_FF⁻¹ (3, 3) [N/m]; moment_matrix: K_M = C_MM⁻¹ (3, 3) [N·m/rad].
        force_min: smallest stiffness to a force, any direction [N/m]; force_direction: that unit direction (3,).
        moment_min: smallest stiffness to a couple [N·m/rad]; moment_axis: that unit axis (3,).
    """

    force_matrix: np.ndarray
    moment_matrix: np.ndarray
    force_min: float
    force_direction: np.ndarray
    moment_min: float
    moment_axis: np.ndarray


def split_stiffness(k: np.ndarray) -> SplitStiffness:
    """:class:`SplitStiffness` of one tangent K (6, 6). Raises numpy.linalg.LinAlgError when K is singular."""
    c = np.linalg.inv(np.asarray(k, dtype=float))
    parts = []
    for block in (c[:3, :3], c[3:, 3:]):
        vals, vecs = np.linalg.eigh(0.5 * (block + block.T))
        parts.append((np.linalg.inv(block), 1.0 / vals[-1], _oriented(vecs[:, -1])))
    (kf, fmin, fdir), (km, mmin, mdir) = parts
    return SplitStiffness(kf, km, float(fmin), fdir, float(mmin), mdir)


def centre_height(geometry: CraneGeometry) -> float:
    """z of the centred, level platform of the symmetric crane under W: the sag h_w − h [m] (z down)."""
    hw, _ = loaded_height(geometry.replace(com_offset=(0.0, 0.0, 0.0), length_offsets=(0.0,) * 6))
    return hw - geometry.height


@dataclass(frozen=True)
class PoseReport:
    """Everything the design view says about one pose (units in the field names' docs)."""

    solution: PoseSolution
    stiffness: np.ndarray  # exact tangent K (6, 6)
    split: SplitStiffness

    @property
    def equilibrium(self) -> Equilibrium:
        return self.solution.equilibrium

    @property
    def tension_min(self) -> tuple[float, int]:
        """(smallest tension [N], its wire index 0..5)."""
        t = self.equilibrium.wire_tensions
        return float(t.min()), int(np.argmin(t))

    def to_dict(self) -> dict[str, Any]:
        eq, s = self.equilibrium, self.split
        tmin, wmin = self.tension_min
        return {
            'position_m': eq.displacement.tolist(),
            'rotation_zxy_rad': matrix_to_euler_zxy(eq.rotation).tolist(),
            'length_offsets_m': dict(zip(WIRE_NAMES, self.solution.offsets.tolist())),
            'tensions_N': dict(zip(WIRE_NAMES, eq.wire_tensions.tolist())),
            'tension_min_N': tmin, 'tension_min_wire': WIRE_NAMES[wmin],
            'force_stiffness_min_N_per_m': s.force_min, 'force_stiffness_direction': s.force_direction.tolist(),
            'moment_stiffness_min_Nm_per_rad': s.moment_min, 'moment_stiffness_axis': s.moment_axis.tolist(),
            'force_stiffness_matrix_N_per_m': s.force_matrix.tolist(),
            'moment_stiffness_matrix_Nm_per_rad': s.moment_matrix.tolist(),
            'tangent_stiffness': self.stiffness.tolist(),
            'residual': eq.residual.tolist(),
        }


def at_pose(geometry: CraneGeometry, position=None, rotation=None) -> PoseReport:
    """The crane set to hold ``position`` [m] (default: the centre at the sag under W) and ``rotation`` ([φ, θ, ψ]
    rad, default level): offsets, equilibrium, tangent, split stiffness. Raises UnreachablePoseError."""
    if position is None:
        position = (0.0, 0.0, centre_height(geometry))
    sol = inverse_pose(geometry, position, rotation)
    k = tangent_stiffness(sol.geometry, sol.equilibrium)
    return PoseReport(sol, k, split_stiffness(k))
