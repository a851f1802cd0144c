"""The loads a multi-axis program may hold: every wrench inside the slack margin of its direction, with a safety
factor.

**Slack factor of a wrench.** For a wrench w (6,) = [fx, fy, fz, mx, my, mz] (N, N·m, fixed frame, z down; the
force at the geometry's load point, the couple about the platform centre, both fixed in space), load the crane from
its rest pose along s·w, s from 0 up, on the nonlinear model: the slack factor is the s at which the first wire goes
slack (crane_stiffness.design.margins, kernel :func:`crane_stiffness.model.inverse.slack_margin`; ``inf`` when no
wire goes slack up to :data:`FACTOR_CAP`). It is the slack margin of w's direction divided by |w|, with no need to
weigh newtons against newton-metres, and it scales exactly: the factor of t·w is factor(w)/t.

**The rule.** A program may hold w only if ``factor(w) >= safety_factor`` (default :data:`DEFAULT_SAFETY_FACTOR` =
2: the load could double before a wire goes slack; the wires' tensions are nearly affine in the load, so each keeps
about half its rest tension or more). The straight path between two consecutive steps (the load program jumps, the
model and an actuator follow the straight line) is checked at :data:`TRANSITION_POINTS`; the paths from and to zero
are rays along the steps themselves, covered by the steps' own factors. :func:`check_steps` refuses a program that
breaks the rule, naming the step, the direction and the wire (:class:`~crane_stiffness.full6.errors.SlackDesignError`).

**The admissible set of a fold-over design.** Six wires hold six degrees of freedom, so the wire tensions change
affinely with the load to first order: t(w) ≈ t0 + A·w (A = ∂t/∂w, (6, 6), :func:`tension_rates`). A design that
holds both w and −w (fold-over) with the safety factor then keeps ``|A·w| <= t0 / safety_factor`` wire by wire: with
the box of peak loads ``|w_j| <= peak_j`` a convex polytope. :func:`admissible_vertices` lists its vertices (the
D-optimal design of a first-order model is supported on them) and moves each onto the nonlinear rule.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.contract.axes import AXES
from crane_stiffness.design.margins import RTOL, XTOL
from crane_stiffness.full6.errors import Full6InputError, SlackDesignError
from crane_stiffness.model import CraneGeometry, Equilibrium, rest_pose, solve_batch
from crane_stiffness.model.equilibrium import geometry_arrays
from crane_stiffness.model.geometry import WIRE_NAMES
from crane_stiffness.model.inverse import slack_margin

DEFAULT_SAFETY_FACTOR = 2.0
#: Fractions of the way from one step to the next at which the straight transition is checked.
TRANSITION_POINTS = (0.25, 0.5, 0.75)
#: Slack factors are computed up to this value; beyond it a direction counts as never slackening (inf).
FACTOR_CAP = 1000.0
#: Vertices of the linearised polytope are moved onto factor = safety_factor·(1 + DESIGN_CLEARANCE): on the lab
#: model the straight transition between two vertices on one face dips below their factor by up to 4e-5 of it (the
#: tensions are not quite affine in the load), and the transitions must keep the rule too.
DESIGN_CLEARANCE = 1e-3
#: The paper's names of wires 1..6 (overhead vertex, platform vertex).
PAPER_WIRES = ('AD', 'BD', 'BE', 'CE', 'CF', 'AF')
# Relative step of the central differences of the tension rates (of each axis' peak load).
_RATE_STEP = 1e-2


def wire_label(wire: int) -> str:
    """'wire_4 (CE)' for index 3; for −1 'no wire (the platform loses equilibrium first)'."""
    if wire < 0:
        return 'no wire (the platform loses equilibrium first)'
    return f'{WIRE_NAMES[wire]} ({PAPER_WIRES[wire]})'


def _format_wrench(w: NDArray[np.float64]) -> str:
    return ', '.join(f'{name} {value + 0.0:+.4g} {"N" if i < 3 else "N·m"}'
                     for i, (name, value) in enumerate(zip(AXES, w)))


def _format_direction(d: NDArray[np.float64]) -> str:
    return '(' + ', '.join(f'{name} {value + 0.0:+.3f}' for name, value in zip(AXES, d)) + ')'


@dataclass(frozen=True)
class SlackFactors:
    """Slack factors of n wrenches: factor (n,) [-] (inf: none up to FACTOR_CAP; 0: a wire slack at rest), the
    wire that goes slack first (n,) (index 0..5, −1 for none or a lost equilibrium)."""

    factor: NDArray[np.float64]
    wire: NDArray[np.int64]


def _rest(geometry: CraneGeometry, equilibrium: Equilibrium | None) -> Equilibrium:
    eq = rest_pose(geometry) if equilibrium is None else equilibrium
    if np.any(eq.load):
        raise Full6InputError('equilibrium.load', eq.load.tolist(),
                              'slack factors start from the rest pose under the weight alone (load 0)')
    return eq


def slack_factors(geometry: CraneGeometry, wrenches: ArrayLike, *,
                  equilibrium: Equilibrium | None = None) -> SlackFactors:
    """The slack factor of each wrench (n, 6) [N, N·m] from the rest pose (``equilibrium``, default
    :func:`crane_stiffness.model.rest_pose`). A zero wrench has factor inf."""
    w = np.ascontiguousarray(np.asarray(wrenches, dtype=float).reshape(-1, 6))
    if not np.all(np.isfinite(w)):
        raise Full6InputError('wrenches', w.tolist(), 'every component must be finite')
    eq = _rest(geometry, equilibrium)
    arr = geometry_arrays(geometry)
    u = np.ascontiguousarray(eq.displacement, dtype=float)
    q = np.ascontiguousarray(eq.rotation, dtype=float)
    l_ref = float(arr.l0.max())
    factor = np.full(w.shape[0], math.inf)
    wire = np.full(w.shape[0], -1, dtype=np.int64)
    for i, row in enumerate(w):
        if not np.any(row):
            continue
        s, k, _ = slack_margin(*arr.args(), u, q, row, FACTOR_CAP, RTOL, XTOL, arr.lc, l_ref)
        factor[i], wire[i] = s, k
    return SlackFactors(factor, wire)


def _refuse(step: int, n: int, w: NDArray[np.float64], factor: float, wire: int, safety_factor: float,
            transition: float | None) -> SlackDesignError:
    direction = w / np.linalg.norm(w)
    where = (f'step {step + 1} of {n}' if transition is None else
             f'the transition from step {step + 1} to step {step + 2} of {n}, {transition:.0%} of the way,')
    if factor == 0.0:
        why = f'{wire_label(wire)} is slack at the rest pose already'
    elif factor < 1.0:
        why = (f'it would slacken {wire_label(wire)}: along its direction that wire goes slack at {factor:.4g} times '
               f'this wrench')
    else:
        why = (f'it comes too close to slack: along its direction {wire_label(wire)} goes slack at {factor:.4g} '
               f'times this wrench, less than the safety factor {safety_factor:g}')
    message = (f'{where} (wrench {_format_wrench(w)}; direction {_format_direction(direction)}, the unit vector of '
               f'the wrench in N and N·m) is refused: {why}')
    return SlackDesignError(message, step=step, wrench=w.copy(), direction=direction, wire=wire,
                            wire_name=wire_label(wire), factor=factor, safety_factor=safety_factor,
                            transition=transition is not None)


def check_steps(geometry: CraneGeometry, steps: ArrayLike, safety_factor: float = DEFAULT_SAFETY_FACTOR, *,
                equilibrium: Equilibrium | None = None) -> SlackFactors:
    """The slack factors of a program's held wrenches (n, 6) [N, N·m] in play order, or
    :class:`~crane_stiffness.full6.errors.SlackDesignError` for the first step (then the first transition) whose
    factor is below ``safety_factor`` (module docstring: the rule). Returns the steps' :class:`SlackFactors`."""
    if not (math.isfinite(safety_factor) and safety_factor >= 1.0):
        raise Full6InputError('safety_factor', safety_factor, 'must be a finite number >= 1')
    w = np.asarray(steps, dtype=float).reshape(-1, 6)
    eq = _rest(geometry, equilibrium)
    held = slack_factors(geometry, w, equilibrium=eq)
    n = w.shape[0]
    for i in range(n):
        if held.factor[i] < safety_factor:
            raise _refuse(i, n, w[i], float(held.factor[i]), int(held.wire[i]), safety_factor, None)
    if n > 1:
        t = np.asarray(TRANSITION_POINTS)
        path = ((1.0 - t)[None, :, None] * w[:-1, None, :] + t[None, :, None] * w[1:, None, :]).reshape(-1, 6)
        between = slack_factors(geometry, path, equilibrium=eq)
        for c in np.flatnonzero(between.factor < safety_factor)[:1]:
            i, j = divmod(int(c), len(TRANSITION_POINTS))
            raise _refuse(i, n, path[c], float(between.factor[c]), int(between.wire[c]), safety_factor,
                          float(t[j]))
    return held


def axis_peaks(geometry: CraneGeometry, safety_factor: float = DEFAULT_SAFETY_FACTOR, *,
               equilibrium: Equilibrium | None = None) -> NDArray[np.float64]:
    """The largest load (6,) [N, N·m] each axis may hold alone, of either sign, under the rule: the smaller slack
    margin of +axis and −axis divided by ``safety_factor`` (inf for an axis no wire goes slack along)."""
    unit = np.vstack([np.eye(6), -np.eye(6)])
    f = slack_factors(geometry, unit, equilibrium=equilibrium).factor
    return np.minimum(f[:6], f[6:]) / safety_factor


def tension_rates(geometry: CraneGeometry, scale: ArrayLike, *,
                  equilibrium: Equilibrium | None = None) -> NDArray[np.float64]:
    """A = ∂t/∂w (6 wires, 6 axes) at the rest pose [N/N, N/(N·m)], by central differences of the nonlinear model
    at ±1 % of ``scale`` (6,) [N, N·m] (the peak loads) per axis."""
    s = np.asarray(scale, dtype=float).reshape(6)
    eq = _rest(geometry, equilibrium)
    if np.any(eq.wire_tensions <= 0.0):
        slack = int(np.argmin(eq.wire_tensions))
        raise Full6InputError('geometry', geometry.to_dict(),
                              f'{wire_label(slack)} is slack at the rest pose: no load keeps a safety factor')
    h = _RATE_STEP * s
    plus = solve_batch(geometry, np.diag(h)).wire_tensions
    minus = solve_batch(geometry, -np.diag(h)).wire_tensions
    return ((plus - minus) / (2.0 * h[:, None])).T


def admissible_vertices(geometry: CraneGeometry, peaks: ArrayLike, safety_factor: float = DEFAULT_SAFETY_FACTOR, *,
                        equilibrium: Equilibrium | None = None) -> NDArray[np.float64]:
    """Vertices (m, 6) [N, N·m] of the fold-over admissible polytope ``|A·w| <= t0/safety_factor``,
    ``|w_j| <= peaks_j`` (module docstring), one of each ± pair (its first non-zero component positive), each
    scaled down where needed so that both it and its opposite keep the nonlinear rule with DESIGN_CLEARANCE."""
    p = np.asarray(peaks, dtype=float).reshape(6)
    if not np.all(np.isfinite(p) & (p > 0.0)):
        raise Full6InputError('peaks', p.tolist(), 'every axis needs a finite peak load > 0 (N, N·m): the design '
                              'must load all six axes')
    eq = _rest(geometry, equilibrium)
    rates = tension_rates(geometry, p, equilibrium=eq)
    bound = eq.wire_tensions / safety_factor
    # |g_r·w| <= 1 for the 12 rows: six wires, six axes.
    g = np.vstack([rates / bound[:, None], np.diag(1.0 / p)])
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=6)))
    found = []
    for rows in itertools.combinations(range(12), 6):
        sub = g[list(rows)]
        if abs(np.linalg.det(sub * p)) < 1e-9:
            continue
        points = signs @ np.linalg.inv(sub).T
        inside = np.all(np.abs(points @ g.T) <= 1.0 + 1e-9, axis=1)
        found.append(points[inside])
    vertices = np.vstack(found) / p
    first = vertices[np.arange(len(vertices)), np.argmax(np.abs(vertices) > 1e-9, axis=1)]
    vertices = vertices[first > 0.0]
    vertices = np.unique(np.round(vertices, 9), axis=0) * p
    both = slack_factors(geometry, np.vstack([vertices, -vertices]), equilibrium=eq).factor
    factor = np.minimum(both[:len(vertices)], both[len(vertices):])
    shrink = np.minimum(1.0, factor / (safety_factor * (1.0 + DESIGN_CLEARANCE)))
    return vertices * shrink[:, None]


__all__ = ['DEFAULT_SAFETY_FACTOR', 'DESIGN_CLEARANCE', 'FACTOR_CAP', 'PAPER_WIRES', 'SlackFactors',
           'TRANSITION_POINTS', 'admissible_vertices', 'axis_peaks', 'check_steps', 'slack_factors',
           'tension_rates', 'wire_label']
