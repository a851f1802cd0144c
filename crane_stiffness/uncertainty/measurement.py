"""The measured stiffness of one axis with its GUM uncertainty budget: the fit's statistics (Type A) and the sensors'
declared calibrations (Type B) through the measurement function k = F/x.

The measurement function, with every correction written as a relative correction of the reading it acts on (its
estimate 0: nothing is corrected, only its uncertainty counted)::

    k = k_fit · (1 + δF_sensitivity + δF_nonlinearity + δF_misalignment + δF_cross)
              / ((1 + δx_sensitivity) (1 + δx_daq_gain) (1 + δx_linearity))

so each force correction enters with the sensitivity coefficient +k and each displacement correction with −k, and
the relative uncertainties add in quadrature; :func:`.budget.propagate` evaluates the coefficients through this very
function, so the budget's rows are real.

- **Type A**: k_fit and its standard error with its degrees of freedom. The analysis gives the fit of the hold means
  when there is one (n_holds − 2 degrees of freedom: a handful of nearly independent points, honest under coloured
  noise and drift, where the samples' own standard error, from thousands of correlated residuals, is far too small),
  else the fit of the samples.
- **Type B** from the certificates the sensor nodes declare (``calibration.*``, :mod:`crane_stiffness.sim.calibration`):
  the load cell's sensitivity on the fitted axis [% of reading]; the LVDT's sensitivity and its DAQ's gain [% of
  reading]; the load cell's nonlinearity and the LVDT's linearity [% FS], converted to the test's slope: the
  deviation from the best straight line, bounded by ±e (e = L × full scale, L the stated fraction), cannot change
  the slope over the range R the fit spans by more than e/R; and a smooth deviation curve (a sensor's
  characteristic: a cubic bounded by L over the stroke, Chebyshev's T3, has a slope of at most 3L in its middle
  half) changes the local sensitivity by at most :data:`SMOOTH_SLOPE_FACTOR` × L. The bound taken is the smaller,
  ±min(e/R, 3L): over the 74 µm a side-force test spans of a ±2.5 mm LVDT, e/R alone would be 8 % of k for a
  0.25 % linearity, which no smooth characteristic gives; the load cell's mounting misalignment [rad]: the two
  angles that tilt the fitted axis scale its reading by cos θ (an error up to 1 − cos θ_max, taken as
  ±(1 − cos θ_max) without correcting it), and a cross load (its ratio to the axis' load, 0 in a one-axis test)
  couples in by sin θ_max.
  Not counted: the load cell's cross-talk (acts on cross loads, absent in a one-axis test; the cross-coupling row
  covers them when given), hysteresis (the loading and unloading branches are fitted apart), zero drift and the
  DAQ's offset (a constant offset moves the intercept, not the slope; drift shows in the Type A of the hold means).

A component declared ``not_stated`` (or not declared at all) is left out and named: the result then says its
calibration part is statistical only for it, never a silent zero.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from crane_stiffness.contract.axes import AXES
from crane_stiffness.sim.calibration import PREFIX, Stated, stated_values
from crane_stiffness.uncertainty.budget import DEFAULT_COVERAGE, UncertaintyResult, json_ready, propagate
from crane_stiffness.uncertainty.errors import InputError
from crane_stiffness.uncertainty.inputs import InputQuantity
from crane_stiffness.uncertainty.montecarlo import DEFAULT_DIGITS, monte_carlo, with_monte_carlo

#: The inputs acting on the force (sensitivity +k), in the order of the measurement function.
#: How many times the stated (non)linearity [fraction of full scale] a smooth characteristic's local sensitivity
#: can depart from the best straight line's (a cubic bounded by 1 on [-1, 1], T3 = 4u³ − 3u, has |T3'| <= 3 on the
#: middle half of the stroke, where a test at rest works).
SMOOTH_SLOPE_FACTOR = 3.0
FORCE_INPUTS = ('load_cell_sensitivity', 'load_cell_nonlinearity', 'load_cell_misalignment', 'load_cell_cross_load')
#: The inputs acting on the displacement (sensitivity −k).
DISPLACEMENT_INPUTS = ('lvdt_sensitivity', 'lvdt_daq_gain', 'lvdt_linearity')
_DISTRIBUTION = {'normal': 'normal', 'rectangular': 'rectangular', 'triangular': 'triangular', 'u_shaped': 'arcsine'}


@dataclass(frozen=True)
class SlopeStatistics:
    """The Type A input: a fitted slope k_fit [N/m or N·m/rad], its standard error (same unit) and degrees of
    freedom (n − 2), and which fit it is ('hold means' or 'samples')."""

    stiffness: float
    stderr: float
    dof: float
    source: str


@dataclass(frozen=True)
class MeasuredStiffness:
    """The measured stiffness as the GUM states it (``result``), which fit gave its Type A, and the calibration
    components left out because they were not stated (each named with its sensor)."""

    result: UncertaintyResult
    type_a: str
    left_out: tuple[str, ...]
    counted: tuple[str, ...]

    @property
    def statistical_only(self) -> bool:
        """True when no calibration component was counted: the uncertainty is the fit's alone."""
        return not self.counted

    @property
    def calibration_statement(self) -> str:
        """What the calibration part holds, for a report: 'statistical only' named wherever a component is missing."""
        if not self.counted:
            return 'statistical only: no calibration declared by the sensors (the uncertainty is the fit\'s alone)'
        if self.left_out:
            return (f'calibration counted: {", ".join(self.counted)}; statistical only for '
                    f'{", ".join(self.left_out)} (not stated)')
        return f'calibration counted: {", ".join(self.counted)}'

    def to_dict(self) -> dict[str, Any]:
        """The result's dict (strict JSON: ∞ as 'inf') beside the notes."""
        return {'uncertainty': json_ready(self.result.to_dict()), 'type_a': self.type_a,
                'statistical_only': self.statistical_only, 'left_out': list(self.left_out),
                'counted': list(self.counted), 'calibration': self.calibration_statement}


def stated_component(params: Mapping[str, Any] | None, name: str, size: int, unit: str) -> Stated | None:
    """A component ``calibration.<name>`` as a sensor node declared it in its parameters, or None when it is not
    declared (the parameters are absent, as in a bag of an older recorder) or declared ``not_stated``."""
    if not params:
        return None
    key = PREFIX + name
    if key not in params:
        return None
    distribution = params.get(key + '_distribution', 'normal')
    if distribution == 'not_stated':
        return None
    if distribution not in _DISTRIBUTION:
        raise InputError(key + '_distribution', distribution, f'must be one of {", ".join(_DISTRIBUTION)}, '
                                                              'not_stated')
    k = params.get(key + '_k', 2.0)
    if isinstance(k, bool) or not isinstance(k, (int, float)) or not math.isfinite(k) or k <= 0:
        raise InputError(key + '_k', k, 'a coverage factor must be a finite number > 0')
    return Stated(name, stated_values(key, params[key], size), distribution, float(k), unit)


def _relative(name: str, stated: Stated, index: int, scale: float) -> InputQuantity:
    """A relative correction (estimate 0) from a stated component's entry ``index``, times ``scale`` (its unit to
    a fraction of the slope)."""
    value = float(stated.value[index]) * scale
    if stated.distribution == 'normal':
        return InputQuantity.expanded(name, 0.0, value, stated.k, unit='1')
    return InputQuantity.bounded(name, 0.0, value, _DISTRIBUTION[stated.distribution], unit='1')


def _bound(stated: Stated, index: int) -> float:
    """The bound of a stated entry: its half-width, or a normal one's U (≈ 95 %)."""
    return float(stated.value[index])


def _positive(value: float | None) -> float | None:
    """A usable span or scale: finite and > 0, else None (the component it converts is then left out)."""
    if value is None or not math.isfinite(value) or value <= 0.0:
        return None
    return float(value)


def measured_stiffness(slope: SlopeStatistics, axis: str, *, load_cell: Mapping[str, Any] | None = None,
                       lvdt: Mapping[str, Any] | None = None, force_span: float | None = None,
                       displacement_span: float | None = None, cross_load_ratio: float = 0.0,
                       unit: str = 'N/m', coverage: float = DEFAULT_COVERAGE, monte_carlo_run: bool = False,
                       seed: int | None = 0, significant_digits: int = DEFAULT_DIGITS) -> MeasuredStiffness:
    """The stiffness along ``axis`` with its budget (see the module docstring).

    Args:
        slope: the Type A input (k_fit, its standard error, dof, which fit).
        axis: fx … mz, the load cell's axis fitted.
        load_cell: the load cell node's parameters (``calibration.*`` and ``full_scale`` [N, N·m] per axis), None
            when not recorded.
        lvdt: the LVDT node's parameters (``calibration.*`` and ``range_m`` [m]), None when not recorded.
        force_span: the load's range the fit spans, max − min [N or N·m] (converts the nonlinearity in % FS).
        displacement_span: the displacement's range the fit spans [m or rad] (converts the linearity in % FS).
        cross_load_ratio: largest load on the other axes of the same kind over the axis' largest load (0 in a
            one-axis test), for the misalignment's cross-coupling.
        unit: the stiffness' unit for the budget.
        monte_carlo_run: also propagate the distributions by JCGM 101's adaptive Monte Carlo through the same
            measurement function (the calibration effects drawn from their declared distributions, the Type A as
            the scaled and shifted t of JCGM 101 6.4.9 with ν = n − 2), seeded with ``seed``, at
            ``significant_digits``; the result's ``monte_carlo`` then holds it and the GUM's validation (section 8).
    """
    if axis not in AXES:
        raise InputError('axis', axis, f'must be one of {", ".join(AXES)}')
    for field, value in (('slope.stiffness', slope.stiffness), ('slope.stderr', slope.stderr)):
        if not math.isfinite(value):
            raise InputError(field, value, 'must be finite (a fit of at least three points)')
    if not math.isfinite(cross_load_ratio) or cross_load_ratio < 0.0:
        raise InputError('cross_load_ratio', cross_load_ratio, 'must be a finite number >= 0')
    i = AXES.index(axis)
    inputs = [InputQuantity('stiffness_fit', slope.stiffness, slope.stderr, 'normal', slope.dof, unit)]
    counted: list[str] = []
    left_out: list[str] = []

    def add(name: str, quantity: InputQuantity | None) -> None:
        if quantity is None:
            left_out.append(name)
        else:
            inputs.append(quantity)
            counted.append(name)

    # The load cell: sensitivity [% of reading], nonlinearity [% FS], misalignment [rad].
    sens = stated_component(load_cell, 'sensitivity', 6, '% of reading')
    add('load_cell_sensitivity', None if sens is None else _relative('load_cell_sensitivity', sens, i, 1e-2))
    nonlin = stated_component(load_cell, 'nonlinearity', 6, '% FS')
    full_scale = np.atleast_1d(np.asarray((load_cell or {}).get('full_scale', [math.inf] * 6), dtype=float))
    fs = _positive(float(full_scale[i if full_scale.size == 6 else 0]))
    span = _positive(force_span)
    add('load_cell_nonlinearity', None if nonlin is None or fs is None or span is None else
        _relative('load_cell_nonlinearity', nonlin, i, 1e-2 * min(fs / span, SMOOTH_SLOPE_FACTOR)))
    misalignment = stated_component(load_cell, 'misalignment', 3, 'rad')
    if misalignment is None:
        add('load_cell_misalignment', None)
    else:
        tilt = [_bound(misalignment, j) for j in range(3) if j != i % 3]
        theta = math.hypot(*tilt)
        add('load_cell_misalignment', InputQuantity.bounded('load_cell_misalignment', 0.0, 1.0 - math.cos(theta),
                                                            'rectangular', unit='1'))
        if cross_load_ratio > 0.0:
            add('load_cell_cross_load', InputQuantity.bounded('load_cell_cross_load', 0.0,
                                                              cross_load_ratio * math.sin(theta), 'rectangular',
                                                              unit='1'))
    # The LVDT channel: sensitivity and DAQ gain [% of reading], linearity [% of the half stroke].
    for name in ('sensitivity', 'daq_gain'):
        stated = stated_component(lvdt, name, 1, '% of reading')
        add(f'lvdt_{name}', None if stated is None else _relative(f'lvdt_{name}', stated, 0, 1e-2))
    linearity = stated_component(lvdt, 'linearity', 1, '% FS')
    stroke = np.asarray((lvdt or {}).get('range_m', [-math.inf, math.inf]), dtype=float)
    half_stroke = _positive(float(np.max(np.abs(stroke))) if stroke.size else None)
    x_span = _positive(displacement_span)
    add('lvdt_linearity', None if linearity is None or half_stroke is None or x_span is None else
        _relative('lvdt_linearity', linearity, 0, 1e-2 * min(half_stroke / x_span, SMOOTH_SLOPE_FACTOR)))
    names = [q.name for q in inputs]
    function = stiffness_function(names)
    result = propagate(function, inputs, coverage=coverage)
    if monte_carlo_run:
        mc = monte_carlo(function, inputs, coverage=coverage, significant_digits=significant_digits, seed=seed)
        result = with_monte_carlo(result, mc, significant_digits)
    return MeasuredStiffness(result, slope.source, tuple(left_out), tuple(counted))


def stiffness_function(names: Sequence[str]) -> Any:
    """The measurement function over the inputs ``names`` (the first 'stiffness_fit', then any of
    :data:`FORCE_INPUTS` and :data:`DISPLACEMENT_INPUTS`): k = k_fit (1 + Σ δF) / Π (1 + δx)."""
    names = tuple(names)
    force = [j for j, n in enumerate(names) if n in FORCE_INPUTS]
    displacement = [j for j, n in enumerate(names) if n in DISPLACEMENT_INPUTS]
    unknown = [n for n in names[1:] if n not in FORCE_INPUTS + DISPLACEMENT_INPUTS]
    if not names or names[0] != 'stiffness_fit' or unknown:
        raise InputError('inputs', list(names), "must be 'stiffness_fit' then inputs of "
                                                f'{", ".join(FORCE_INPUTS + DISPLACEMENT_INPUTS)}')

    def k(*x: Any) -> Any:
        numerator = 1.0 + sum(x[j] for j in force)
        denominator = 1.0
        for j in displacement:
            denominator = denominator * (1.0 + x[j])
        return x[0] * numerator / denominator

    return k


__all__ = ['DISPLACEMENT_INPUTS', 'FORCE_INPUTS', 'MeasuredStiffness', 'SMOOTH_SLOPE_FACTOR', 'SlopeStatistics',
           'measured_stiffness',
           'stated_component', 'stiffness_function']
