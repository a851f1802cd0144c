"""Propagation of distributions by Monte Carlo (JCGM 101:2008), its adaptive procedure, and the vector form
(JCGM 102:2011) for several outputs at once.

Each input is drawn from its own distribution (:meth:`.inputs.InputQuantity.draws`); correlated inputs must be
normal (drawn jointly through the Cholesky factor of their correlation matrix, JCGM 101 6.4.8). The model is the same
callable as :func:`.budget.propagate` takes, called once per batch with numpy arrays (shape (M,)) in place of the
values, so it must be written with numpy operations; it returns an array (M,) (or (M, m) for the vector form).

Adaptive procedure (JCGM 101 7.9): batches of M = 10⁴ trials (at least 100/(1 − p)); after each batch h ≥ 2 the
standard deviations of the batch means, standard uncertainties and interval ends, each over √h, are compared with
the numerical tolerance δ of u(y) at ``significant_digits`` (u(y) = c × 10^l with c an n_dig-digit integer,
δ = 10^l / 2, 7.9.2); the run stops when twice each is <= δ. The result is computed from all h·M values: mean,
standard deviation, the probabilistically symmetric interval (7.7.1) and the shortest one (7.7.2).

Validation of the GUM uncertainty framework (JCGM 101 section 8): d_low = |y − U − y_low|, d_high =
|y + U − y_high| against δ from the GUM's u(y); both <= δ: "validated".

Seeded: pass ``seed`` (an int) or a numpy ``Generator``; the same seed gives the same result.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from crane_stiffness.uncertainty.budget import DEFAULT_COVERAGE, Correlations, UncertaintyResult, correlation_matrix
from crane_stiffness.uncertainty.errors import InputError, MonteCarloError
from crane_stiffness.uncertainty.inputs import InputQuantity

#: Trials per batch of the adaptive procedure (JCGM 101 7.9.4 a: M = max(10⁴, 100/(1 − p))).
BATCH = 10_000
#: Upper bound of the adaptive procedure's trials; reached, the result says converged = False.
MAX_TRIALS = 2_000_000
DEFAULT_DIGITS = 2


def numerical_tolerance(u: float, significant_digits: int = DEFAULT_DIGITS) -> float:
    """δ = 10^l / 2 where u = c × 10^l with c an integer of ``significant_digits`` digits (JCGM 101 7.9.2);
    e.g. u = 0.0253 at 2 digits: c = 25, l = −3, δ = 0.0005."""
    if significant_digits < 1:
        raise InputError('significant_digits', significant_digits, 'must be >= 1')
    if not math.isfinite(u) or u <= 0.0:
        raise InputError('u', u, 'the numerical tolerance needs a finite u > 0')
    exponent = math.floor(math.log10(u)) - (significant_digits - 1)
    if round(u / 10.0 ** exponent) >= 10 ** significant_digits:  # u rounds up to one more digit (9.96 → 10)
        exponent += 1
    return 0.5 * 10.0 ** exponent


def symmetric_interval(sorted_y: np.ndarray, coverage: float = DEFAULT_COVERAGE) -> tuple[float, float]:
    """The probabilistically symmetric coverage interval of sorted values (JCGM 101 7.7.1): y_(r), y_(r+q) with
    q = pM rounded, r = (M − q)/2 (rounded half up when not an integer), 1-based."""
    m = sorted_y.size
    q = int(coverage * m + 0.5)
    r = max(1, int(0.5 * (m - q) + 0.5))
    return float(sorted_y[r - 1]), float(sorted_y[min(r + q, m) - 1])


def interval_ends(y: np.ndarray, coverage: float = DEFAULT_COVERAGE) -> tuple[float, float]:
    """:func:`symmetric_interval` of values in any order, by partial sorting (O(M): the adaptive procedure's batches
    need only the two order statistics)."""
    m = y.size
    q = int(coverage * m + 0.5)
    r = max(1, int(0.5 * (m - q) + 0.5))
    low, high = r - 1, min(r + q, m) - 1
    part = np.partition(y, (low, high))
    return float(part[low]), float(part[high])


def shortest_interval(sorted_y: np.ndarray, coverage: float = DEFAULT_COVERAGE) -> tuple[float, float]:
    """The shortest coverage interval of sorted values (JCGM 101 7.7.2): y_(r*), y_(r*+q) with the least width."""
    m = sorted_y.size
    q = int(coverage * m + 0.5)
    if q >= m:
        return float(sorted_y[0]), float(sorted_y[-1])
    widths = sorted_y[q:] - sorted_y[:m - q]
    r = int(np.argmin(widths))
    return float(sorted_y[r]), float(sorted_y[r + q])


def draw_inputs(inputs: Sequence[InputQuantity], n: int, rng: np.random.Generator,
                correlations: Correlations | None = None) -> np.ndarray:
    """n joint draws of the inputs, shape (len(inputs), n). Correlated inputs must be normal with ν = ∞."""
    r = correlation_matrix(inputs, correlations)
    out = np.empty((len(inputs), n))
    correlated = [i for i in range(len(inputs)) if np.any(r[i, np.arange(len(inputs)) != i] != 0.0)]
    for i, q in enumerate(inputs):
        if i not in correlated:
            out[i] = q.draws(rng, n)
    if correlated:
        for i in correlated:
            q = inputs[i]
            if q.distribution != 'normal' or math.isfinite(q.dof):
                raise InputError(f'{q.name}.distribution', q.distribution,
                                 'a correlated input is drawn jointly normal: give it as normal with dof inf')
        sub = r[np.ix_(correlated, correlated)]
        try:
            chol = np.linalg.cholesky(sub)
        except np.linalg.LinAlgError:
            raise InputError('correlations', dict(correlations or {}),
                             'the correlation matrix must be positive definite') from None
        z = chol @ rng.standard_normal((len(correlated), n))
        for row, i in enumerate(correlated):
            out[i] = inputs[i].value + inputs[i].u * z[row]
    return out


def _rng(seed: int | np.random.Generator | None) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def _evaluate(function: Callable[..., Any], x: np.ndarray) -> np.ndarray:
    y = np.asarray(function(*x), dtype=float)
    if y.shape[:1] != (x.shape[1],):
        raise MonteCarloError(f'the model returned shape {y.shape} for {x.shape[1]} draws: it must take numpy '
                              f'arrays and return one value per draw')
    if not np.all(np.isfinite(y)):
        raise MonteCarloError(f'the model returned {int(np.sum(~np.isfinite(y)))} non-finite values of '
                              f'{y.size}: the inputs reach outside its domain')
    return y


@dataclass(frozen=True)
class MonteCarloResult:
    """The output's distribution as JCGM 101 summarises it: mean y, standard deviation u(y) (standard uncertainty),
    the probabilistically symmetric and the shortest coverage intervals for ``coverage``, the trials run, the
    numerical tolerance δ reached (None for a fixed number of trials) and whether the adaptive run settled."""

    mean: float
    u: float
    interval: tuple[float, float]
    shortest: tuple[float, float]
    coverage: float
    trials: int
    significant_digits: int
    delta: float
    converged: bool
    seed: int | None = None

    def to_dict(self) -> dict[str, Any]:
        return {'mean': self.mean, 'u': self.u, 'interval': list(self.interval), 'shortest': list(self.shortest),
                'coverage': self.coverage, 'trials': self.trials, 'significant_digits': self.significant_digits,
                'delta': self.delta, 'converged': self.converged, 'seed': self.seed}


def summarise(y: np.ndarray, coverage: float, significant_digits: int, converged: bool,
              seed: int | None) -> MonteCarloResult:
    """The result of a sample of the output (any order). Both intervals need only the tails of the sorted sample:
    the (1 − p)·M smallest and largest values, found by one partial sort (O(M)) and sorted alone; the same order
    statistics as a full sort, at a tenth of its cost (the hour's analysis draws ~10⁶ values per branch)."""
    m = int(y.size)
    q = int(coverage * m + 0.5)
    u = float(np.std(y, ddof=1))
    delta = numerical_tolerance(u, significant_digits) if u > 0.0 else 0.0
    if q >= m or 2 * (m - q) >= m:  # a tiny sample: sort it all
        sorted_y = np.sort(y)
        return MonteCarloResult(float(np.mean(y)), u, symmetric_interval(sorted_y, coverage),
                                shortest_interval(sorted_y, coverage), coverage, m, significant_digits, delta,
                                converged, seed)
    tail = m - q  # sorted positions [0, tail) and [q, m): every end either interval can have
    part = np.partition(y, (tail - 1, q))
    low, high = np.sort(part[:tail]), np.sort(part[q:])
    r = max(1, int(0.5 * tail + 0.5))  # symmetric_interval's order statistics r and r + q (1-based)
    symmetric = float(low[r - 1]), float(high[min(r + q, m) - 1 - q])
    widths = high - low  # y_(j+q) − y_(j), j = 0 … m − q − 1 (as shortest_interval, 0-based)
    j = int(np.argmin(widths))
    return MonteCarloResult(float(np.mean(y)), u, symmetric, (float(low[j]), float(high[j])), coverage, m,
                            significant_digits, delta, converged, seed)


def monte_carlo(function: Callable[..., Any], inputs: Sequence[InputQuantity], *,
                correlations: Correlations | None = None, coverage: float = DEFAULT_COVERAGE,
                significant_digits: int = DEFAULT_DIGITS, seed: int | np.random.Generator | None = 0,
                trials: int | None = None, batch: int = BATCH, max_trials: int = MAX_TRIALS) -> MonteCarloResult:
    """Monte Carlo propagation of the inputs' distributions through ``function`` (vectorised over draws).

    ``trials`` None runs the adaptive procedure of JCGM 101 7.9 at ``significant_digits``; a number runs that many
    trials (in batches). The same ``seed`` gives the same result.
    """
    inputs = list(inputs)
    if not inputs:
        raise InputError('inputs', [], 'need at least one input quantity')
    if not 0.0 < coverage < 1.0:
        raise InputError('coverage', coverage, 'a coverage probability must lie in (0, 1)')
    batch = max(int(batch), math.ceil(100.0 / (1.0 - coverage)))
    rng = _rng(seed)
    seed_value = seed if isinstance(seed, int) else None
    if trials is not None:
        if trials < 2:
            raise InputError('trials', trials, 'must be >= 2')
        parts = [_evaluate(function, draw_inputs(inputs, min(batch, trials - done), rng, correlations))
                 for done in range(0, trials, batch)]
        return summarise(np.concatenate(parts), coverage, significant_digits, True, seed_value)
    parts, stats = [], []
    shift = total = squares = 0.0  # running sums about the first batch's mean: u of all trials without concatenating
    while True:
        y = _evaluate(function, draw_inputs(inputs, batch, rng, correlations))
        parts.append(y)
        if len(parts) == 1:
            shift = float(np.mean(y))
        d = y - shift
        total += float(np.sum(d))
        squares += float(d @ d)
        stats.append((float(np.mean(y)), float(np.std(y, ddof=1)), *interval_ends(y, coverage)))
        h = len(parts)
        if h >= 2:
            m = h * batch
            u_all = math.sqrt(max(squares - total * total / m, 0.0) / (m - 1))
            if u_all == 0.0:
                break
            delta = numerical_tolerance(u_all, significant_digits)
            spread = np.std(np.array(stats), axis=0, ddof=1) / math.sqrt(h)  # of mean, u, low, high
            if 2.0 * float(spread.max()) <= delta:
                break
        if h * batch >= max_trials:
            return summarise(np.concatenate(parts), coverage, significant_digits, False, seed_value)
    return summarise(np.concatenate(parts), coverage, significant_digits, True, seed_value)


@dataclass(frozen=True)
class Validation:
    """JCGM 101 section 8: the GUM interval y ± U against the Monte Carlo one, at tolerance δ."""

    d_low: float
    d_high: float
    delta: float
    validated: bool

    def to_dict(self) -> dict[str, Any]:
        return {'d_low': self.d_low, 'd_high': self.d_high, 'delta': self.delta, 'validated': self.validated}


def validate_gum(gum: UncertaintyResult, mc: MonteCarloResult,
                 significant_digits: int = DEFAULT_DIGITS) -> Validation:
    """d_low = |y − U − y_low|, d_high = |y + U − y_high| (the Monte Carlo's probabilistically symmetric interval),
    δ from the GUM's u(y) at ``significant_digits``: validated when both are <= δ (JCGM 101 8.2)."""
    delta = numerical_tolerance(gum.u_c, significant_digits)
    d_low = abs(gum.interval[0] - mc.interval[0])
    d_high = abs(gum.interval[1] - mc.interval[1])
    return Validation(d_low, d_high, delta, d_low <= delta and d_high <= delta)


def with_monte_carlo(gum: UncertaintyResult, mc: MonteCarloResult,
                     significant_digits: int | None = None) -> UncertaintyResult:
    """The GUM result holding the Monte Carlo's dict and its validation (key 'validation')."""
    check = validate_gum(gum, mc, mc.significant_digits if significant_digits is None else significant_digits)
    return gum.with_monte_carlo({**mc.to_dict(), 'validation': check.to_dict()})


@dataclass(frozen=True)
class MultivariateResult:
    """Several outputs' joint distribution as JCGM 102 summarises it: the mean vector (m,) and the covariance
    matrix (m, m) of the outputs, in their units, from ``trials`` draws."""

    mean: np.ndarray
    covariance: np.ndarray
    trials: int

    @property
    def u(self) -> np.ndarray:
        """Standard uncertainties of the outputs, (m,)."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def correlation(self) -> np.ndarray:
        """Correlation matrix of the outputs, (m, m) (0 where an output has u = 0)."""
        u = self.u
        with np.errstate(divide='ignore', invalid='ignore'):
            r = self.covariance / np.outer(u, u)
        return np.where(np.outer(u, u) > 0.0, r, 0.0)

    def derived_uncertainty(self, gradient: Sequence[float]) -> float:
        """u(z) of a quantity z = g(outputs) to first order: √(∇gᵀ V ∇g) (JCGM 102 6.2), ∇g at the mean (m,)."""
        g = np.asarray(gradient, dtype=float).reshape(-1)
        if g.shape != self.mean.shape:
            raise InputError('gradient', list(g), f'needs one entry per output ({self.mean.size})')
        return math.sqrt(max(float(g @ self.covariance @ g), 0.0))

    def to_dict(self) -> dict[str, Any]:
        return {'mean': self.mean.tolist(), 'covariance': self.covariance.tolist(), 'trials': self.trials}


def monte_carlo_vector(function: Callable[..., Any], inputs: Sequence[InputQuantity], *,
                       correlations: Correlations | None = None, trials: int = 100_000, batch: int = BATCH,
                       seed: int | np.random.Generator | None = 0) -> MultivariateResult:
    """JCGM 102 Monte Carlo for a vector output: ``function`` takes the input arrays (M,) and returns (M, m) (for a
    matrix output, flatten it: e.g. the 36 entries of a 6×6 stiffness, row-major). Mean and covariance are
    accumulated over batches (sums of y and y yᵀ about the first batch's mean, so no cancellation)."""
    inputs = list(inputs)
    if trials < 2:
        raise InputError('trials', trials, 'must be >= 2')
    rng = _rng(seed)
    shift: np.ndarray | None = None
    total: np.ndarray | None = None
    cross: np.ndarray | None = None
    for done in range(0, trials, batch):
        y = _evaluate(function, draw_inputs(inputs, min(batch, trials - done), rng, correlations))
        y = y.reshape(y.shape[0], -1)
        if shift is None:
            shift = y.mean(axis=0)
            total = np.zeros(y.shape[1])
            cross = np.zeros((y.shape[1], y.shape[1]))
        assert total is not None and cross is not None
        d = y - shift
        total += d.sum(axis=0)
        cross += d.T @ d
    assert shift is not None and total is not None and cross is not None
    mean_d = total / trials
    covariance = (cross - trials * np.outer(mean_d, mean_d)) / (trials - 1)
    return MultivariateResult(shift + mean_d, 0.5 * (covariance + covariance.T), trials)
