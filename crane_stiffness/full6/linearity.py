"""Keeping a designed program where the crane's response is linear, and where the load cell reads: the lack of fit
the nonlinear model predicts for a program, and the design scaled down until it passes. Pure numpy.

**Why.** The identification (crane_stiffness.full6.identify) is never OK on a non-linear window: its lack-of-fit
statistic (the scatter of the step means about the fitted plane over what the sensors' noise explains, ≈ 1 for a
linear response) must pass its test. Loads up to half the slack margins (the safety factor) can bend the response
far more than the noise on a soft set-up (long wires, heavy platform), so a program designed on the slack rule alone
comes out WARN there; and a load beyond the load cell's full scale saturates its reading.

**The prediction.** For held wrenches w_k (k, 6) [N, N·m] with m_k pairs each, the model's deflections d_k =
solve_batch(w_k) (crane_stiffness.model, from the rest pose) are fitted by the plane d = C·w + offset weighted by
m_k; with r_k the residual of step k and Σ_e the noise covariance of one pair's residual
(:meth:`~crane_stiffness.full6.design.NoiseLevels.residual_covariance`), the statistic expected is

    1 + Σ_k m_k · r_kᵀ Σ_e⁻¹ r_k / (6·(k − 7)).

On the rig it came out lower than this (the measured noise within a step is larger than the white noise alone:
2.4 predicted against 1.4 measured, 23 against 9.9), so the prediction errs on the safe side.

**The scaled design** (:func:`linear_design`): peaks capped at ``full_scale`` (the load cell's full scale times a
fraction, per axis), then the D-optimal design scaled down, step by step, until the predicted statistic is at most
``max_lack_of_fit``: the even-order bend grows as the square of the load, the statistic's excess as its fourth
power, so each step scales the peaks by (target excess / predicted excess)^¼ (a little less).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.full6.design import LAB_NOISE, LoadDesign, NoiseLevels, d_optimal_design
from crane_stiffness.full6.errors import Full6InputError
from crane_stiffness.model import CraneGeometry

#: The default largest predicted lack-of-fit statistic of a design: the test flags ≈ 1.4 at p = 0.001 for 26 steps
#: (114 degrees of freedom), the statistic's own scatter is ±0.13 there, so 1.2 leaves about 4 % of sessions WARN
#: if the prediction were exact (on the rig it errs on the safe side).
MAX_LACK_OF_FIT = 1.2
#: Rounds of scaling before giving up (each brings the excess to the target to first order).
_ROUNDS = 8


def load_cell_full_scale() -> NDArray[np.float64]:
    """The simulated load cell's full scale (6,) [N, N·m]: ``load_cell.full_scale`` of the installed
    config/sensors.yaml (the rig's; a real sensor's is in its data sheet: give it instead)."""
    from crane_stiffness.params.files import config_path, load_params
    return np.asarray(load_params(config_path('sensors.yaml'), 'load_cell')['full_scale'], dtype=float)


def program_steps(design: LoadDesign) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The held wrenches (k, 6) of a design's program, its two zero baselines included, and the pairs each gives
    (k,) at the design's noise levels' pair rate after the settling time."""
    rate = design.noise.pair_rate_hz
    steps = np.vstack([np.zeros(6), design.steps, np.zeros(6)])
    pairs = np.full(len(steps), math.floor(rate * (design.hold_s - design.settle_s)), dtype=float)
    pairs[[0, -1]] = math.floor(rate * (design.baseline_s - design.settle_s))
    return steps, pairs


def predicted_lack_of_fit(geometry: CraneGeometry, steps: ArrayLike, pairs: ArrayLike,
                          noise: NoiseLevels = LAB_NOISE) -> float:
    """The lack-of-fit statistic the nonlinear model predicts (module docstring) for held wrenches ``steps``
    (k, 6) [N, N·m] with ``pairs`` (k,) pairs each; 1 for a linear response. Needs k >= 8 steps."""
    from crane_stiffness.full6.deflection import pose_deflection
    from crane_stiffness.model import rest_pose, solve_batch, tangent_stiffness
    w = np.asarray(steps, dtype=float).reshape(-1, 6)
    m = np.asarray(pairs, dtype=float).reshape(-1)
    if len(w) < 8 or m.shape != (len(w),) or not np.all(m > 0):
        raise Full6InputError('steps', len(w), 'must be at least 8 held wrenches, each with pairs > 0')
    rest = rest_pose(geometry)
    eq = solve_batch(geometry, w)
    d = pose_deflection(eq.displacement, eq.rotation, rest.displacement, rest.rotation)
    x = np.column_stack([w, np.ones(len(w))])
    root = np.sqrt(m)[:, None]
    coef, *_ = np.linalg.lstsq(x * root, d * root, rcond=None)
    r = d - x @ coef
    sigma = noise.residual_covariance(np.linalg.inv(tangent_stiffness(geometry, rest)))
    excess = float(np.sum(m * np.einsum('ki,ij,kj->k', r, np.linalg.inv(sigma), r)))
    return 1.0 + excess / (6 * (len(w) - 7))


@dataclass(frozen=True)
class LinearDesign:
    """A design kept linear: the design, its predicted lack of fit, and the factor its peaks were scaled by (1: the
    slack rule and the full scale alone set them)."""

    design: LoadDesign
    lack_of_fit: float
    scale: float


def linear_design(geometry: CraneGeometry, peaks: ArrayLike, *, full_scale: ArrayLike | None = None,
                  max_lack_of_fit: float = MAX_LACK_OF_FIT, noise: NoiseLevels = LAB_NOISE,
                  **design: float | int) -> LinearDesign:
    """The D-optimal design (crane_stiffness.full6.design.d_optimal_design, keywords ``design``) within ``peaks``
    (6,) [N, N·m] capped at ``full_scale`` (6,), scaled down until its predicted lack of fit is at most
    ``max_lack_of_fit`` (module docstring). Raises Full6InputError for a bad argument, SlackDesignError as the
    design does."""
    if not (math.isfinite(max_lack_of_fit) and max_lack_of_fit > 1.0):
        raise Full6InputError('max_lack_of_fit', max_lack_of_fit, 'must be a finite number > 1')
    p = np.asarray(peaks, dtype=float).reshape(6)
    if full_scale is not None:
        limit = np.asarray(full_scale, dtype=float).reshape(6)
        if not np.all(limit > 0.0):
            raise Full6InputError('full_scale', limit.tolist(), 'must be 6 numbers > 0 [N, N·m]')
        p = np.minimum(p, limit)
    scale = 1.0
    for _ in range(_ROUNDS):
        made = d_optimal_design(geometry, scale * p, noise=noise, **design)  # type: ignore[arg-type]
        lof = predicted_lack_of_fit(geometry, *program_steps(made), noise=noise)
        if lof <= max_lack_of_fit:
            return LinearDesign(made, lof, scale)
        scale *= 0.95 * ((max_lack_of_fit - 1.0) / (lof - 1.0)) ** 0.25
    raise Full6InputError('max_lack_of_fit', max_lack_of_fit, f'not reached in {_ROUNDS} rounds (predicted {lof:.3g} '
                          f'at {scale:.3g} of the peaks)')


__all__ = ['LinearDesign', 'MAX_LACK_OF_FIT', 'linear_design', 'load_cell_full_scale', 'predicted_lack_of_fit',
           'program_steps']
