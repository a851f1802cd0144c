"""The law of propagation of uncertainty (GUM, JCGM 100:2008, 5.1.2 and 5.2.2) and the uncertainty budget.

For a measurement function y = f(x_1, …, x_N) the combined standard uncertainty is

    u_c²(y) = Σ c_i² u²(x_i) + 2 Σ_{i<j} c_i c_j u(x_i) u(x_j) r(x_i, x_j),      c_i = ∂f/∂x_i at the estimates,

the effective degrees of freedom follow Welch–Satterthwaite (G.2b), ν_eff = u_c⁴ / Σ (c_i u_i)⁴ / ν_i, the coverage
factor is Student's t for the coverage probability p (95 % by default) with ν_eff truncated to the next lower
integer, as G.4.1 says (k = t_0.975(16) = 2.12 for ν_eff = 16.7), and U = k u_c, interval y ± U.

The function is any Python callable taking the input values positionally, in the order of the inputs (the same
callable, written with numpy operations, serves :mod:`.montecarlo` with arrays). Sensitivity coefficients are
central finite differences with a step of 1 % of each input's u (small enough that the curvature over ±u/100 is
negligible, large enough that rounding in f is), or given analytically.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Mapping, Sequence

import numpy as np
# scipy.special, not scipy.stats (its ppf calls the same functions): 0.5 s less to import in every analysis, node and
# CLI call that states U (as crane_stiffness.estimation.fit).
from scipy import special

from crane_stiffness.uncertainty.errors import InputError, UncertaintyError
from crane_stiffness.uncertainty.inputs import InputQuantity, check_correlation

#: Finite-difference step as a fraction of each input's standard uncertainty.
DEFAULT_STEP = 1e-2
#: Coverage probability of U and the interval unless asked otherwise.
DEFAULT_COVERAGE = 0.95
#: The keys of :meth:`UncertaintyResult.to_dict`, exactly.
RESULT_KEYS = ('value', 'u_c', 'U', 'k', 'coverage', 'nu_eff', 'interval', 'budget', 'monte_carlo')

Correlations = Mapping[tuple[str, str], float]


@dataclass(frozen=True)
class BudgetRow:
    """One line of an uncertainty budget (GUM Table H.1's columns), in the input's unit; the contribution
    |c_i| u(x_i) is in the output's unit."""

    name: str
    value: float
    unit: str
    u: float
    distribution: str
    sensitivity: float
    contribution: float
    dof: float

    def to_dict(self) -> dict[str, Any]:
        """Plain values (dof ∞ as the float inf; JSON writers that refuse it get 'inf' from :func:`json_ready`)."""
        return {'name': self.name, 'value': self.value, 'unit': self.unit, 'u': self.u,
                'distribution': self.distribution, 'sensitivity': self.sensitivity,
                'contribution': self.contribution, 'dof': self.dof}


@dataclass(frozen=True)
class UncertaintyResult:
    """A measurement result as the GUM states it: y, u_c(y), U = k·u_c for ``coverage``, ν_eff and the interval
    y ± U, with the budget and, when one was run, the Monte Carlo result (JCGM 101) as its dict."""

    value: float
    u_c: float
    U: float
    k: float
    coverage: float
    nu_eff: float
    interval: tuple[float, float]
    budget: tuple[BudgetRow, ...] = ()
    monte_carlo: dict[str, Any] | None = field(default=None)

    @property
    def dominant(self) -> BudgetRow:
        """The budget row with the largest contribution |c_i| u(x_i)."""
        if not self.budget:
            raise UncertaintyError('this result has no budget rows')
        return max(self.budget, key=lambda row: row.contribution)

    def with_monte_carlo(self, monte_carlo: Mapping[str, Any] | None) -> UncertaintyResult:
        """A copy holding a Monte Carlo result's dict."""
        return replace(self, monte_carlo=None if monte_carlo is None else dict(monte_carlo))

    def to_dict(self) -> dict[str, Any]:
        """Keys exactly :data:`RESULT_KEYS`: value, u_c, U, k, coverage, nu_eff, interval [low, high], budget (a
        list of rows' dicts), monte_carlo (None or its dict)."""
        return {'value': self.value, 'u_c': self.u_c, 'U': self.U, 'k': self.k, 'coverage': self.coverage,
                'nu_eff': self.nu_eff, 'interval': [self.interval[0], self.interval[1]],
                'budget': [row.to_dict() for row in self.budget],
                'monte_carlo': None if self.monte_carlo is None else dict(self.monte_carlo)}


def json_ready(value: Any) -> Any:
    """A copy of a result dict with non-finite floats as strings ('inf'), for strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, Mapping):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    return value


def welch_satterthwaite(contributions: Sequence[float], dofs: Sequence[float], u_c: float | None = None) -> float:
    """ν_eff = u_c⁴ / Σ c_i⁴ / ν_i (GUM G.2b) from the contributions c_i = |c_i| u(x_i) [output unit]; u_c defaults
    to √Σ c_i². ∞ when every contribution with finite ν is zero."""
    c = np.asarray(contributions, dtype=float)
    nu = np.asarray(dofs, dtype=float)
    uc = math.sqrt(float(np.sum(c * c))) if u_c is None else float(u_c)
    finite = np.isfinite(nu) & (c != 0.0)
    denominator = float(np.sum(c[finite] ** 4 / nu[finite]))
    if denominator == 0.0:
        return math.inf
    return uc ** 4 / denominator


def coverage_factor(nu_eff: float, coverage: float = DEFAULT_COVERAGE) -> float:
    """k = t_{(1+p)/2}(ν) with ν = ν_eff truncated to the next lower integer (GUM G.4.1), at least 1; the normal
    quantile for ν = ∞ (1.960 for 95 %)."""
    if not 0.0 < coverage < 1.0:
        raise InputError('coverage', coverage, 'a coverage probability must lie in (0, 1)')
    q = 0.5 * (1.0 + coverage)
    if math.isinf(nu_eff):
        return float(special.ndtri(q))
    return float(special.stdtrit(max(1, math.floor(nu_eff)), q))


def correlation_matrix(inputs: Sequence[InputQuantity], correlations: Correlations | None) -> np.ndarray:
    """The (N, N) correlation matrix of the inputs from pairs {(name_i, name_j): r}, each checked (|r| <= 1, known
    names, no pair of an input with itself)."""
    names = [q.name for q in inputs]
    if len(set(names)) != len(names):
        raise InputError('inputs', names, 'every input needs a name of its own')
    index = {name: i for i, name in enumerate(names)}
    r = np.eye(len(inputs))
    for pair, value in (correlations or {}).items():
        field_name = f'correlation[{pair!r}]'
        if not (isinstance(pair, tuple) and len(pair) == 2):
            raise InputError(field_name, value, 'a correlation is keyed by a pair of input names')
        a, b = pair
        if a not in index or b not in index:
            raise InputError(field_name, value, f'names an input that is not given (inputs: {", ".join(names)})')
        if a == b:
            raise InputError(field_name, value, 'an input is fully correlated with itself; give pairs of two')
        rho = check_correlation(field_name, value)
        r[index[a], index[b]] = r[index[b], index[a]] = rho
    return r


def sensitivities(function: Callable[..., Any], inputs: Sequence[InputQuantity], *,
                  step: float = DEFAULT_STEP) -> np.ndarray:
    """c_i = ∂f/∂x_i at the estimates by central differences, step h_i = step · u(x_i) (an input known exactly,
    u = 0, gets h_i = step · 1e-6 · max(|x_i|, 1): its c_i is shown in the budget but contributes nothing)."""
    x = np.array([q.value for q in inputs], dtype=float)
    c = np.empty(len(inputs))
    for i, q in enumerate(inputs):
        h = step * q.u if q.u > 0.0 else step * 1e-6 * max(abs(q.value), 1.0)
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        c[i] = (float(function(*up)) - float(function(*down))) / (2.0 * h)
    if not np.all(np.isfinite(c)):
        bad = [q.name for q, ci in zip(inputs, c) if not math.isfinite(ci)]
        raise UncertaintyError(f'the measurement function is not finite around the estimates of {", ".join(bad)}')
    return c


def combine(value: float, inputs: Sequence[InputQuantity], c: Sequence[float] | np.ndarray, *,
            correlations: Correlations | None = None, coverage: float = DEFAULT_COVERAGE) -> UncertaintyResult:
    """The result from the output estimate y, the inputs and their sensitivity coefficients c_i (GUM 5.1.2,
    5.2.2). With correlations, ν_eff still uses the uncorrelated W–S formula with the correlated u_c (the GUM gives
    none for correlated inputs)."""
    c_arr = np.asarray(c, dtype=float).reshape(-1)
    if c_arr.shape != (len(inputs),):
        raise InputError('sensitivities', list(c_arr), f'need one per input ({len(inputs)})')
    u = np.array([q.u for q in inputs])
    r = correlation_matrix(inputs, correlations)
    cu = c_arr * u
    variance = float(cu @ r @ cu)
    u_c = math.sqrt(max(variance, 0.0))
    contributions = np.abs(cu)
    nu_eff = welch_satterthwaite(contributions, [q.dof for q in inputs], u_c)
    k = coverage_factor(nu_eff, coverage)
    big_u = k * u_c
    rows = tuple(BudgetRow(q.name, q.value, q.unit, q.u, q.distribution, float(ci), float(ct), q.dof)
                 for q, ci, ct in zip(inputs, c_arr, contributions))
    return UncertaintyResult(float(value), u_c, big_u, k, coverage, nu_eff, (value - big_u, value + big_u), rows)


def propagate(function: Callable[..., Any], inputs: Sequence[InputQuantity], *,
              correlations: Correlations | None = None, sensitivity: Sequence[float] | None = None,
              coverage: float = DEFAULT_COVERAGE, step: float = DEFAULT_STEP) -> UncertaintyResult:
    """GUM uncertainty framework: y = f(x), its budget, u_c, ν_eff, k and U for ``coverage``.

    Args:
        function: f, called as ``function(x_1, …, x_N)`` with the inputs' values in order; returns a number.
        inputs: the input quantities (names unique).
        correlations: {(name_i, name_j): r(x_i, x_j)} for correlated pairs (the rest are uncorrelated).
        sensitivity: the c_i when known analytically; else central differences with h_i = step · u(x_i).
        coverage: coverage probability p of U and the interval.
    """
    inputs = list(inputs)
    if not inputs:
        raise InputError('inputs', [], 'need at least one input quantity')
    value = float(function(*[q.value for q in inputs]))
    if not math.isfinite(value):
        raise UncertaintyError(f'the measurement function gives {value} at the estimates')
    c = sensitivities(function, inputs, step=step) if sensitivity is None else sensitivity
    return combine(value, inputs, c, correlations=correlations, coverage=coverage)
