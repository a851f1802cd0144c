"""Slack margin per load direction: how large a force (or couple), along a given direction, slackens the first wire.

Found on the nonlinear model by continuation from the equilibrium at the pose (load s·d, s from 0 up), with
Newton's method on s for the onset of each wire — not by the linearisation (kernel
:func:`crane_stiffness.model._pose_kernels.slack_margin`). A force is applied at the geometry's load point, a
couple about the platform centre, both fixed in space (fixed frame, z down: an upward force has a negative z
component). Margins are in N (forces) or N·m (couples); ``inf`` where no wire goes slack up to the cap (a downward
pull only stretches the wires).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from crane_stiffness.design.errors import DesignInputError
from crane_stiffness.model import Equilibrium
from crane_stiffness.model.equilibrium import geometry_arrays
from crane_stiffness.model.inverse import slack_margin
from crane_stiffness.model.geometry import CraneGeometry

#: Relative tolerance on a margin and pose tolerance of the corrector [m].
RTOL = 1e-12
XTOL = 1e-13
#: Default cap: forces up to CAP·W [N], couples up to CAP·W·max(a, b) [N·m].
CAP = 10.0
KINDS = ('force', 'moment')
_GOLDEN = math.pi * (3.0 - math.sqrt(5.0))


def sphere_directions(n: int) -> np.ndarray:
    """n unit directions (n, 3) spread evenly over the sphere and mapped onto themselves by a 120° turn about z.

    The crane's symmetry is threefold, so a direction set with the same symmetry makes the minimum over directions
    repeat exactly under that turn. n % 3 == 1 adds the upward pole (0, 0, −1), n % 3 == 2 both poles; the rest
    come in triples on an equal-area spiral."""
    if n < 1:
        raise DesignInputError('directions', n, 'must be >= 1')
    poles = [np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 1.0])][:n % 3]
    m = n // 3
    out = list(poles)
    sector = 2.0 * math.pi / 3.0
    for i in range(m):
        z = 1.0 - 2.0 * (i + 0.5) / m
        rho = math.sqrt(max(0.0, 1.0 - z * z))
        phi = (i * _GOLDEN) % sector
        for j in range(3):
            a = phi + j * sector
            out.append(np.array([rho * math.cos(a), rho * math.sin(a), z]))
    return np.array(out).reshape(n, 3)


def circle_directions(n: int, plane: str = 'xy') -> np.ndarray:
    """n unit directions (n, 3) evenly around a circle in the xy (horizontal), xz or yz plane, from the first
    axis towards the second (angle = 2πi/n)."""
    if n < 3:
        raise DesignInputError('points', n, 'must be >= 3')
    if plane not in ('xy', 'xz', 'yz'):
        raise DesignInputError('plane', plane, "must be 'xy', 'xz' or 'yz'")
    ang = 2.0 * math.pi * np.arange(n) / n
    out = np.zeros((n, 3))
    i, j = ('xyz'.index(plane[0]), 'xyz'.index(plane[1]))
    out[:, i] = np.cos(ang)
    out[:, j] = np.sin(ang)
    return out


def load_directions(directions: np.ndarray, kind: str) -> np.ndarray:
    """6-vectors (n, 6) [F; M] of unit force or couple directions (n, 3)."""
    if kind not in KINDS:
        raise DesignInputError('kind', kind, f'must be one of {KINDS}')
    d = np.asarray(directions, dtype=float).reshape(-1, 3)
    norm = np.linalg.norm(d, axis=1)
    if not np.all(norm > 0) or not np.all(np.isfinite(norm)):
        raise DesignInputError('directions', d.tolist(), 'must be finite and non-zero')
    out = np.zeros((d.shape[0], 6))
    first = 0 if kind == 'force' else 3
    out[:, first:first + 3] = d / norm[:, None]
    return out


@dataclass(frozen=True)
class Margins:
    """Slack margins along directions (n, 3) of one kind: margin (n,) [N or N·m], the wire that goes slack first
    (index 0..5, −1 for none), and the kernel's status per direction (FOUND, NONE, LIMIT_POINT, SLACK_AT_START)."""

    kind: str
    directions: np.ndarray
    margin: np.ndarray
    wire: np.ndarray
    status: np.ndarray

    @property
    def smallest(self) -> tuple[float, int]:
        """(smallest margin, index of its direction)."""
        i = int(np.argmin(self.margin))
        return float(self.margin[i]), i


def slack_margins(geometry: CraneGeometry, equilibrium: Equilibrium, directions, kind: str = 'force', *,
                  cap: float = CAP, rtol: float = RTOL) -> Margins:
    """Slack margin along each direction (n, 3) from ``equilibrium`` (under no external load) of ``geometry``."""
    if np.any(equilibrium.load):
        raise DesignInputError('equilibrium.load', equilibrium.load.tolist(),
                               'margins start from an equilibrium under the weight alone (load 0)')
    dirs = load_directions(directions, kind)
    arr = geometry_arrays(geometry)
    s_max = cap * geometry.weight * (1.0 if kind == 'force' else arr.lc)
    u = np.ascontiguousarray(equilibrium.displacement, dtype=float)
    q = np.ascontiguousarray(equilibrium.rotation, dtype=float)
    n = dirs.shape[0]
    margin, wire, status = np.empty(n), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    l_ref = float(arr.l0.max())
    for c in range(n):
        margin[c], wire[c], status[c] = slack_margin(*arr.args(), u, q, dirs[c], s_max, rtol, XTOL, arr.lc,
                                                        l_ref)
    return Margins(kind, dirs[:, :3] if kind == 'force' else dirs[:, 3:], margin, wire, status)
