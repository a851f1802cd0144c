"""The model's stiffness prediction with its uncertainty: the crane's measured inputs through the exact tangent
stiffness at the rest pose along one axis.

The measurement function is k_axis = f(a, b, h, W, d, E (or k), l0 offsets, centre-of-mass offset): the exact
tangent stiffness K at the rest pose under W (:func:`crane_stiffness.model.tangent_stiffness`,
:func:`~crane_stiffness.model.rest_pose`), then the stiffness along the axis with every other degree of freedom
free (:func:`~crane_stiffness.model.axis_stiffness`) [N/m for a force axis, N·m/rad for a moment axis]. It is
evaluated for many cranes at once by :func:`crane_stiffness.model.draws.rest_stiffness_draws` (compiled, ~30 µs a
crane), which serves both methods:

- the budget, by the GUM's law of propagation with central-difference sensitivities through the same function
  (2N + 1 cranes, one call), which says which input dominates;
- the distribution, by JCGM 101's adaptive Monte Carlo (batches of 10⁴ cranes), which gives the interval and
  validates the GUM's (JCGM 101 section 8).

The result is the GUM's :class:`~.budget.UncertaintyResult` with value = the point prediction (the nominal crane),
its ``monte_carlo`` holding the Monte Carlo result and the validation.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from crane_stiffness.model.draws import rest_stiffness_draws
from crane_stiffness.model.equilibrium import rest_pose
from crane_stiffness.model.geometry import CraneGeometry
from crane_stiffness.model.stiffness import axis_index, axis_stiffness, tangent_stiffness
from crane_stiffness.uncertainty.budget import DEFAULT_COVERAGE, DEFAULT_STEP, UncertaintyResult, combine
from crane_stiffness.uncertainty.crane_inputs import COM_OFFSETS, LENGTH_OFFSETS, crane_inputs, input_names
from crane_stiffness.uncertainty.errors import InputError, UncertaintyError
from crane_stiffness.uncertainty.inputs import InputQuantity
from crane_stiffness.uncertainty.montecarlo import DEFAULT_DIGITS, monte_carlo, with_monte_carlo


def draw_fields(geometry: CraneGeometry, columns: Mapping[str, Any], n: int) -> dict[str, Any]:
    """The arrays of :func:`~crane_stiffness.model.draws.rest_stiffness_draws` for ``n`` cranes whose inputs (names of
    :func:`.crane_inputs.input_names`) take the values ``columns`` (each (n,) or a scalar); the inputs not given,
    and the other offsets of a row given in part, keep ``geometry``'s values."""
    fields: dict[str, Any] = {name: columns[name] for name in
                              ('a', 'b', 'height', 'weight', 'wire_diameter', 'youngs_modulus', 'wire_stiffness')
                              if name in columns}
    if any(name in columns for name in LENGTH_OFFSETS):
        fields['length_offsets'] = np.stack([np.broadcast_to(columns.get(name, off), (n,)) for name, off in
                                             zip(LENGTH_OFFSETS, geometry.length_offsets)], axis=1)
    if any(name in columns for name in COM_OFFSETS):
        fields['com_offset'] = np.stack([np.broadcast_to(columns.get(name, off), (n,)) for name, off in
                                         zip(COM_OFFSETS, geometry.com_offset)], axis=1)
    return fields


def stiffness_function(geometry: CraneGeometry, axis: str, names: Sequence[str]) -> Callable[..., np.ndarray]:
    """f(x_1, …, x_N) → the rest stiffness along ``axis`` of the cranes with those inputs, vectorised: each x_i
    is a number or an array (M,) of the input ``names[i]`` (names of :func:`.crane_inputs.input_names`); returns
    (M,) [N/m or N·m/rad]."""
    direction = np.zeros(6)
    direction[axis_index(axis)] = 1.0
    names = tuple(names)
    known = input_names(geometry)
    for name in names:
        if name not in known:
            raise InputError('inputs', name, f'is not an input of this crane (inputs: {", ".join(known)})')

    def f(*values: Any) -> np.ndarray:
        if len(values) != len(names):
            raise UncertaintyError(f'the stiffness function takes {len(names)} inputs ({", ".join(names)}), '
                                   f'got {len(values)}')
        columns = {name: np.atleast_1d(np.asarray(v, dtype=float)) for name, v in zip(names, values)}
        k = rest_stiffness_draws(geometry, **draw_fields(geometry, columns, max(c.size for c in columns.values())))
        compliance = np.linalg.solve(k, np.broadcast_to(direction, (k.shape[0], 6))[..., None])[..., 0]
        return 1.0 / (compliance @ direction)

    return f


def point_prediction(geometry: CraneGeometry, axis: str) -> float:
    """The nominal crane's rest stiffness along ``axis`` (what ``crane-stiffness stiffness`` prints as the exact
    tangent) [N/m or N·m/rad]."""
    return axis_stiffness(tangent_stiffness(geometry, rest_pose(geometry)), axis)


def predict_stiffness(geometry: CraneGeometry, axis: str = 'fy', *,
                      uncertainty: Mapping[str, Mapping[str, Any]] | None = None,
                      inputs: Sequence[InputQuantity] | None = None, seed: int | None = 0,
                      significant_digits: int = DEFAULT_DIGITS, trials: int | None = None,
                      coverage: float = DEFAULT_COVERAGE, monte_carlo_run: bool = True,
                      step: float = DEFAULT_STEP) -> UncertaintyResult:
    """The model's rest stiffness along ``axis`` with its uncertainty, budget and (by default) Monte Carlo.

    Args:
        geometry: the crane (its values are the inputs' estimates).
        axis: fx … mz.
        uncertainty: {input: flat form} overriding the defaults (:func:`.crane_inputs.crane_inputs`), e.g. what
            :func:`.crane_inputs.load_uncertainty_file` read.
        inputs: the input quantities themselves instead (names of :func:`.crane_inputs.input_names`).
        seed: the Monte Carlo's seed (same seed, same result).
        significant_digits: the adaptive Monte Carlo's numerical tolerance (JCGM 101 7.9.2) and its validation's.
        trials: a fixed number of Monte Carlo trials instead of the adaptive procedure.
        monte_carlo_run: False gives the GUM result alone (the budget: 2N + 1 cranes, milliseconds).
    """
    axis_index(axis)
    quantities = list(inputs) if inputs is not None else crane_inputs(geometry, uncertainty)
    names = [q.name for q in quantities]
    f = stiffness_function(geometry, axis, names)
    x = np.array([q.value for q in quantities])
    h = np.array([step * q.u if q.u > 0.0 else step * 1e-6 * max(abs(q.value), 1.0) for q in quantities])
    n = len(quantities)
    points = np.repeat(x[:, None], 2 * n + 1, axis=1)
    points[np.arange(n), 1 + np.arange(n)] += h       # column 1 + i: x_i + h_i
    points[np.arange(n), 1 + n + np.arange(n)] -= h   # column 1 + n + i: x_i − h_i
    y = f(*points)
    value = float(y[0])
    c = (y[1:1 + n] - y[1 + n:]) / (2.0 * h)
    if not (math.isfinite(value) and np.all(np.isfinite(c))):
        raise UncertaintyError(f'the prediction along {axis} is not finite near the estimates')
    gum = combine(value, quantities, c, coverage=coverage)
    if not monte_carlo_run:
        return gum
    mc = monte_carlo(f, quantities, coverage=coverage, significant_digits=significant_digits, seed=seed,
                     trials=trials)
    return with_monte_carlo(gum, mc, significant_digits)


def agreement_U(result: UncertaintyResult) -> tuple[float, str]:
    """The prediction's expanded uncertainty for E_n, and where it comes from: the GUM's U, unless its Monte Carlo
    ran and did not validate the GUM interval (JCGM 101 8.2: the Monte Carlo's interval is then the one that means
    95 %), then the larger distance from the prediction to an end of the Monte Carlo's probabilistically symmetric
    interval. The lab model's budget is mostly one rectangular input (the wire's modulus), so y ± 1.96·u reaches past
    its distribution's 95 %: over 200 drawn cranes ± U covered the true tangent 0.985 of the time, the Monte Carlo's
    interval 0.965 (docs/uncertainty.md, Coverage)."""
    mc = result.monte_carlo or {}
    if not mc or (mc.get('validation') or {}).get('validated', True):
        return float(result.U), 'GUM'
    low, high = (float(v) for v in mc['interval'])
    return max(result.value - low, high - result.value, 0.0), 'Monte Carlo (JCGM 101; the GUM interval not validated)'
