"""When a stiffness fit may be called OK: the rules the live estimator and ``analyze`` share. Pure numpy, no ROS.

A measurement tool never calls a meaningless number OK. Two checks, each worded for people:

- :func:`fit_problems`: a branch fit is not a stiffness when its slope is not positive, when its 95 % interval
  contains zero, or when its scatter is far beyond what the sensors' noise explains (:func:`scatter_ratio`).
- :func:`axis_problem`: the fitted axis must be the axis the commands load. Fitting fy while the program moves mz
  fits noise against noise; a program that moves another component beside the fitted one is combined loading.

:func:`noise_std` estimates a sensor's white noise from the data themselves (second differences, median based, so
a ramp does not count at all and a step between samples barely does): the live estimator applies it to its branch
windows at its slow refresh, ``analyze`` to each branch's pairs; both call the same functions (the scatter check
here, and the displacement noise the fits count: ``LiveSettings.displacement_noise_of``).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from crane_stiffness.contract.axes import AXES

#: |Δ| of a command component below this counts as "does not move" [N or N·m] (commands are exact program values).
MOVE_TOLERANCE = 1e-9
#: median(|d|) of a normal variable d with unit standard deviation.
_MEDIAN_ABS_NORMAL = 0.6744897501960817


def noise_std(values: ArrayLike) -> float:
    """White-noise standard deviation of a series sampled in order, from its second differences
    ``d = v[i+1] − 2·v[i] + v[i−1]`` (σ·√6 for white noise, exactly 0 for a ramp): ``median(|d|) / (0.6745·√6)``;
    NaN with fewer than 3 values. Units of ``values``.

    Second, not first, differences: a load program's ramps move the displacement by a few noise levels per sample at
    1 kHz, and a first difference would count that motion as noise (and the errors-in-variables fit would then
    over-correct); the median keeps the steps between holds out."""
    v = np.asarray(values, dtype=float)
    if v.size < 3:
        return math.nan
    d2 = v[2:] - 2.0 * v[1:-1] + v[:-2]
    return float(np.median(np.abs(d2))) / (_MEDIAN_ABS_NORMAL * math.sqrt(6.0))


def scatter_ratio(displacement: ArrayLike, force: ArrayLike, stiffness: float, residual_rms: float) -> float:
    """The fit's residual rms over what the noise of both sensors explains, ``sqrt(σ_F² + k²·σ_x²)`` with σ from
    :func:`noise_std` of each series (pairs in stamp order). About 1 for a good linear fit; NaN when unknown."""
    sf, sx = noise_std(force), noise_std(displacement)
    expected = math.sqrt(sf * sf + (stiffness * sx) ** 2)
    if not (math.isfinite(expected) and math.isfinite(residual_rms)) or expected <= 0.0:
        return math.nan
    return residual_rms / expected


def fit_problems(stiffness: float, ci95_low: float, ci95_high: float, scatter: float,
                 max_scatter_ratio: float) -> list[str]:
    """Why a branch fit is not a stiffness one can sign (empty: none of these): a slope that is not positive, a
    95 % interval containing zero, a scatter ``max_scatter_ratio`` times or more what the sensors' noise explains."""
    problems = []
    if not stiffness > 0.0:
        problems.append(f'slope {stiffness:.4g} is not positive: not a stiffness')
    if ci95_low <= 0.0 <= ci95_high:
        problems.append(f'its 95 % interval {ci95_low:.4g} .. {ci95_high:.4g} contains zero')
    if math.isfinite(scatter) and scatter > max_scatter_ratio:
        problems.append(f'scatter {scatter:.3g} x what the sensors\' noise explains (> max_scatter_ratio '
                        f'{max_scatter_ratio:g})')
    return problems


def moved_axes(low: Sequence[float] | np.ndarray, high: Sequence[float] | np.ndarray) -> list[str]:
    """The wrench components whose commanded value moved (``high − low`` > MOVE_TOLERANCE), in AXES order."""
    return [axis for axis, lo, hi in zip(AXES, low, high) if hi - lo > MOVE_TOLERANCE]


def axis_problem(fitted: str, low: Sequence[float] | np.ndarray, high: Sequence[float] | np.ndarray) -> str:
    """'' when the commands (componentwise range ``low`` .. ``high`` over the fit segment) load the fitted axis
    alone (or load nothing yet); else the problem, naming both axes."""
    moved = moved_axes(low, high)
    if not moved or moved == [fitted]:
        return ''
    if fitted not in moved:
        return (f'fitting {fitted}, but the commands load {" ".join(moved)} and {fitted} does not move: set '
                f'force_axis (and the displacement sensor) to the loaded axis')
    others = [a for a in moved if a != fitted]
    return f'fitting {fitted}, but the commands also move {" ".join(others)}: combined loading'


class CommandRange:
    """Componentwise range of the commanded wrench since the last :meth:`reset` (streaming form; the offline form
    is ``np.min``/``np.max`` over the commands of the fit segment)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.low = np.full(6, np.inf)
        self.high = np.full(6, -np.inf)

    def add(self, wrench: Sequence[float]) -> None:
        w = np.asarray(wrench, dtype=float)
        if np.isfinite(w).all():
            np.minimum(self.low, w, out=self.low)
            np.maximum(self.high, w, out=self.high)

    def problem(self, fitted: str) -> str:
        return axis_problem(fitted, self.low, self.high) if np.isfinite(self.low).all() else ''
