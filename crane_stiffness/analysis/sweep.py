"""The paper's parametric studies, as arrays (no plotting here; see :mod:`.figures`).

- :func:`stiffness_vs_weight`: stiffness to a small load along one axis against W for several heights (Figs. 10, 13).
- :func:`force_displacement`: load–displacement curves of the nonlinear model beside the linearized model, the
  W = 0 elastic-only model and a single-wire pendulum carrying W/6 (Figs. 5–9).

Displacements along an axis: for fx, fy, fz the platform centre's motion [m] from the loaded rest pose; for mx, my,
mz the rotation [rad] from that pose, as a rotation vector in the fixed frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np

from crane_stiffness.model import (CraneGeometry, Equilibrium, ModelError, axis_index, directional_stiffness,
                                   elastic_stiffness, paper_stiffness, rest_pose, single_wire_pendulum_stiffness,
                                   solve_equilibrium, tangent_stiffness)

Progress = Callable[[Iterable], Iterable]


def _identity(it: Iterable) -> Iterable:
    return it


def unit(axis: str) -> np.ndarray:
    """The unit load vector (6,) of an axis name."""
    d = np.zeros(6)
    d[axis_index(axis)] = 1.0
    return d


def displacement_along(axis: str, eq: Equilibrium, rest: Equilibrium) -> float:
    """Displacement [m] or rotation [rad] of ``eq`` from ``rest`` along the axis."""
    i = axis_index(axis)
    if i < 3:
        return float(eq.displacement[i] - rest.displacement[i])
    rel = eq.rotation @ rest.rotation.T
    angle = np.arccos(np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0))
    vec = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    scale = 0.5 if angle < 1e-9 else angle / (2.0 * np.sin(angle))
    return float(vec[i - 3] * scale)


@dataclass(frozen=True)
class StiffnessRow:
    """One point of a stiffness-against-weight study. Stiffness in N/m (force axes) or N·m/rad (moment axes)."""

    height: float
    l0: float
    weight: float
    tangent: float   # exact tangent of the nonlinear model at the loaded rest pose
    paper: float     # eq. (18) with the implicit h_w
    elastic: float   # eq. (28): W = 0, wires as bilateral springs


def stiffness_vs_weight(base: CraneGeometry, axis: str, heights: Sequence[float] | np.ndarray,
                        weights: Sequence[float] | np.ndarray, progress: Progress = _identity) -> list[StiffnessRow]:
    """Stiffness to a small load along ``axis`` for every (height, weight) pair (the paper's Figs. 10 and 13)."""
    d = unit(axis)
    cases = [(h, w) for h in heights for w in weights]
    rows = []
    for h, w in progress(cases):
        g = base.replace(height=float(h), weight=float(w))
        eq = rest_pose(g)
        rows.append(StiffnessRow(g.height, g.l0, g.weight,
                                 directional_stiffness(tangent_stiffness(g, eq), d),
                                 directional_stiffness(paper_stiffness(g), d),
                                 directional_stiffness(elastic_stiffness(g), d)))
    return rows


def slack_threshold(geometry: CraneGeometry, axis: str, upper: float | None = None, rtol: float = 1e-4) -> float:
    """Smallest load along ``axis`` at which a wire goes slack (loading quasi-statically from rest) [N or N·m].

    Bisection on the load with warm-started equilibria; ``upper`` defaults to 2·W (forces) or 2·W·max(a, b)
    (moments). Returns ``inf`` if no wire goes slack up to ``upper`` (or the load path ends first).
    """
    d = unit(axis)
    if upper is None:
        upper = 2.0 * geometry.weight * (1.0 if axis_index(axis) < 3 else max(geometry.a, geometry.b))

    def slack_at(value: float) -> bool:
        try:
            return bool(solve_equilibrium(geometry, load=value * d).slack.any())
        except ModelError:
            return True  # the path ended: the wires gave up before this load
    if not slack_at(upper):
        return float('inf')
    lo, hi = 0.0, upper
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if slack_at(mid) else (mid, hi)
    return hi


@dataclass(frozen=True)
class ForceDisplacement:
    """Load–displacement curves along one axis (arrays of equal length).

    Attributes:
        axis: the load axis (fx … mz).
        load: applied load [N or N·m].
        nonlinear: displacement of the nonlinear model with slack wires [m or rad].
        linear: load / K_dir of eq. (18).
        elastic: load / K_dir of eq. (28) (W = 0, bilateral springs).
        pendulum: load / ((W/6)/h_w), a single wire carrying W/6 (force axes fx, fy only; NaN otherwise).
        slack_wires: number of slack wires at each load.
    """

    axis: str
    load: np.ndarray
    nonlinear: np.ndarray
    linear: np.ndarray
    elastic: np.ndarray
    pendulum: np.ndarray
    slack_wires: np.ndarray

    def columns(self) -> dict[str, np.ndarray]:
        return {'load': self.load, 'nonlinear': self.nonlinear, 'linear': self.linear, 'elastic': self.elastic,
                'pendulum': self.pendulum, 'slack_wires': self.slack_wires}


def force_displacement(geometry: CraneGeometry, axis: str, max_load: float, points: int = 41,
                       progress: Progress = _identity) -> ForceDisplacement:
    """Curves of Figs. 5–9: load along ``axis`` from 0 to ``max_load`` in ``points`` steps, quasi-statically."""
    if points < 2:
        raise ValueError(f'points = {points}: need at least 2')
    d = unit(axis)
    loads = np.linspace(0.0, float(max_load), int(points))
    rest = rest_pose(geometry)
    path: list[Equilibrium] = []
    for value in progress(loads):  # quasi-static: each load warm-starts from the previous equilibrium
        path.append(solve_equilibrium(geometry, load=value * d, initial=path[-1] if path else None))
    nonlinear = np.array([displacement_along(axis, eq, rest) for eq in path])
    k_lin = directional_stiffness(paper_stiffness(geometry), d)
    k_el = directional_stiffness(elastic_stiffness(geometry), d)
    if axis in ('fx', 'fy') and geometry.weight > 0:
        pend = loads / single_wire_pendulum_stiffness(geometry)
    else:
        pend = np.full_like(loads, np.nan)
    return ForceDisplacement(axis, loads, nonlinear, loads / k_lin, loads / k_el, pend,
                             np.array([int(eq.slack.sum()) for eq in path]))

