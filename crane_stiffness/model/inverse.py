"""The inverse problem: the per-wire length offsets that hold the platform at a chosen pose under its weight.

Six wires and six balance equations: at a given pose (centre u, rotation Q) the wire directions are known, so the
tensions that balance the weight W (at its centre of mass) solve one linear 6×6 system, exactly. A wire can only
pull: a pose needing a tension <= 0 is out of reach. The tension then fixes each wire's unstretched length
(k = A·E/l0 per wire, or the given k), and so the offsets from the nominal l0 — the paper's length actuators.
Kernels in :mod:`._pose_kernels`. Frames and units: fixed frame, z down, origin at the centre of the unloaded
platform at rest (docs/physics.md); m, rad, N.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crane_stiffness.model import _pose_kernels as pk
from crane_stiffness.model.equilibrium import Equilibrium, wrench_jacobian
from crane_stiffness.model.errors import GeometryError
from crane_stiffness.model.geometry import CraneGeometry
from crane_stiffness.model.rotation import euler_zxy_to_matrix, matrix_to_euler_zxy
# The pose kernels other packages call (crane_stiffness.design: maps over the workspace, slack margins), public here.
from crane_stiffness.model._pose_kernels import (REACHABLE as REACHABLE, SINGULAR as SINGULAR,
                                                 UNREACHABLE as UNREACHABLE, map_points as map_points,
                                                 slack_margin as slack_margin)


class UnreachablePoseError(GeometryError):
    """A pose the wires cannot hold: names the pose and the rule (a tension that would have to push)."""


@dataclass(frozen=True)
class PoseSolution:
    """The crane set up to hold a pose.

    Attributes:
        geometry: the input geometry with ``length_offsets`` set so that the pose is its rest pose under W.
        equilibrium: that equilibrium (no external load): pose, wire lengths, tensions, residual.
        offsets: the per-wire length offsets, wires 1..6, shape (6,) [m] (also in ``geometry``).
    """

    geometry: CraneGeometry
    equilibrium: Equilibrium
    offsets: np.ndarray


def wire_material(geometry: CraneGeometry) -> tuple[float, float]:
    """(A·E [N], k [N/m]): the kernels' way of saying which wire model the geometry uses."""
    if geometry.wire_stiffness is not None:
        return 0.0, float(geometry.wire_stiffness)
    area, modulus = geometry.wire_area, geometry.youngs_modulus
    assert area is not None and modulus is not None  # CraneGeometry: without k both d and E are given
    return float(area * modulus), 0.0


def rotation_of(rotation) -> np.ndarray:
    """Q (3, 3) from the paper's angles [φ, θ, ψ] [rad] (z–x–y) or from a rotation matrix; validated."""
    arr = np.asarray(rotation if rotation is not None else np.zeros(3), dtype=float)
    if arr.shape == (3,):
        if not np.all(np.isfinite(arr)):
            raise GeometryError('rotation', arr.tolist(), 'angles must be finite')
        return euler_zxy_to_matrix(*arr)
    if arr.shape != (3, 3) or not np.allclose(arr @ arr.T, np.eye(3), atol=1e-9) or np.linalg.det(arr) < 0:
        raise GeometryError('rotation', arr.tolist(), 'must be [phi, theta, psi] in rad or a rotation matrix')
    return arr


def inverse_pose(geometry: CraneGeometry, position, rotation=None) -> PoseSolution:
    """Length offsets that make (position, rotation) the rest pose of ``geometry`` under its weight.

    Args:
        geometry: the crane (a, b, h, W, wire, centre of mass; its own length_offsets are replaced).
        position: platform centre [x, y, z] in the fixed frame [m] (z down; z = 0 is the unloaded rest height).
        rotation: [φ, θ, ψ] [rad] (Q = R_z(φ)R_x(θ)R_y(ψ)) or a rotation matrix; default level.

    Raises UnreachablePoseError when a wire would have to push (tension <= 0) or the wires' lines of action are
    degenerate, GeometryError when an offset breaks the geometry's rules.
    """
    u = np.asarray(position, dtype=float).reshape(-1)
    if u.shape != (3,) or not np.all(np.isfinite(u)):
        raise GeometryError('position', np.asarray(position).tolist(), 'must be 3 finite numbers [x, y, z] in m')
    q = np.ascontiguousarray(rotation_of(rotation))
    if geometry.weight <= 0.0:
        raise GeometryError('weight', geometry.weight, 'must be > 0 to hold a pose (the wires need tension)')
    top = np.ascontiguousarray(geometry.top_points)
    plat = np.ascontiguousarray(geometry.platform_points)
    lengths, tensions = np.empty(6), np.empty(6)
    status = pk.inverse_tensions(top, plat, geometry.weight, np.array(geometry.com_offset, dtype=float), u, q,
                                 lengths, tensions, np.empty((6, 6)), np.empty(6), np.empty((6, 6)), np.empty(6))
    where = f'position {u.tolist()} m, angles (phi, theta, psi) {matrix_to_euler_zxy(q).round(12).tolist()} rad'
    if status == pk.SINGULAR:
        raise UnreachablePoseError('pose', where, 'the wires are degenerate there (their wrench matrix is singular)')
    if status == pk.UNREACHABLE:
        worst = int(np.argmin(tensions))
        raise UnreachablePoseError('pose', where, f'out of reach: wire_{worst + 1} would need tension '
                                   f'{tensions[worst]:.6g} N, and a wire can only pull (tension > 0)')
    ae, k = wire_material(geometry)
    l0, kw = np.empty(6), np.empty(6)
    pk.wire_lengths_for(lengths, tensions, ae, k, l0, kw)
    offsets = l0 - geometry.l0
    short = int(np.argmin(l0))
    if l0[short] <= 0.5 * geometry.l0:  # the geometry's own rule on offsets, said of the pose
        raise UnreachablePoseError('pose', where, f'out of reach: wire_{short + 1} would have to shorten to '
                                   f'{l0[short]:.6g} m, less than half of l0 = {geometry.l0:.6g} m')
    held = geometry.replace(length_offsets=tuple(float(x) for x in offsets))
    w, _ = wrench_jacobian(held, u, q, np.zeros(6))
    tens = held.wire_stiffnesses * (lengths - held.unstretched_lengths)
    eq = Equilibrium(u.copy(), q.copy(), lengths.copy(), tens, lengths < held.unstretched_lengths, np.zeros(6), 0,
                     w, 0)
    return PoseSolution(held, eq, offsets)
