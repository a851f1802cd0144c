"""Recursive least squares of load against displacement, ``y = k·x + c``, with exponential forgetting: the live
estimator's second, long-memory estimate of each branch (the first is the windowed fit of
:mod:`crane_stiffness.estimation.fit`). Units as there: x in m (or rad), y in N (or N·m), k in N/m (or N·m/rad).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from crane_stiffness.estimation.errors import DataError, ParameterError


@dataclass(frozen=True, slots=True)
class RlsResult:
    """State of a :class:`RecursiveLeastSquares` estimator.

    Attributes:
        stiffness: Estimated slope k, N/m (N·m/rad).
        intercept: Estimated intercept c, N (N·m).
        stderr: Approximate standard error of k (see :class:`RecursiveLeastSquares`).
        n: Samples seen since the last reset.
        effective_n: Sum of the forgetting weights, about ``1 / (1 − forgetting)`` in steady state.
    """

    stiffness: float
    intercept: float
    stderr: float
    n: int
    effective_n: float


class RecursiveLeastSquares:
    """Recursive least squares for ``y = k·x + c`` with exponential forgetting.

    Minimises ``Σ λ^(n−i) (y_i − k·x_i − c)²`` plus a weak prior (``initial`` with covariance
    ``initial_covariance·I``); λ = ``forgetting``, giving a memory of about ``1 / (1 − λ)`` samples. The update is
    written out for the 2×2 case in plain floats (a few µs per sample), with the covariance kept symmetric by
    construction.

    Covariance wind-up: during a hold x does not change, so forgetting would inflate the covariance without bound
    and the next sample would throw the estimate about. Forgetting is therefore suspended while the trace of the
    covariance would exceed its initial value (the estimator never becomes less certain than its prior).

    Standard error: ``stderr = sqrt(σ̂² · P₀₀ · W₂ / W)`` with ``W = Σλ^(n−i)``, ``W₂ = Σλ^(2(n−i))``
    and ``σ̂² = J / (W − 2·W₂/W)`` from the weighted residual cost J. This is the weighted-least-squares sandwich
    covariance under the assumption that the spread of x is about stationary over the memory; it is approximate
    while the load program sweeps a range.
    """

    def __init__(self, forgetting: float = 0.999, *, initial_covariance: float = 1e12,
                 initial: tuple[float, float] = (0.0, 0.0)) -> None:
        """Create the estimator.

        Args:
            forgetting: λ in (0, 1]; 1 means no forgetting (ordinary least squares).
            initial_covariance: Prior variance of k and c, > 0; large means an uninformative prior. The default
                suits x in metres (k up to ~1e6 N/m).
            initial: Prior (k, c).
        """
        forgetting = float(forgetting)
        if not 0.0 < forgetting <= 1.0:
            raise ParameterError('forgetting', forgetting, 'must be in (0, 1]')
        initial_covariance = float(initial_covariance)
        if not (math.isfinite(initial_covariance) and initial_covariance > 0.0):
            raise ParameterError('initial_covariance', initial_covariance, 'must be finite and > 0')
        if len(initial) != 2 or not all(math.isfinite(float(v)) for v in initial):
            raise ParameterError('initial', initial, 'must be two finite numbers (k, c)')
        self._lambda = forgetting
        self._p_init = initial_covariance
        self._initial = (float(initial[0]), float(initial[1]))
        self.reset()

    def reset(self) -> None:
        """Return to the prior."""
        self._k, self._c = self._initial
        self._p00 = self._p11 = self._p_init
        self._p01 = 0.0
        self._cost = 0.0
        self._w = 0.0
        self._w2 = 0.0
        self._n = 0

    @property
    def forgetting(self) -> float:
        """λ."""
        return self._lambda

    def add(self, x: float, y: float) -> None:
        """Update with one pair (x in m or rad, y in N or N·m). Raises DataError on NaN/Inf."""
        x = float(x)
        y = float(y)
        if not (math.isfinite(x) and math.isfinite(y)):
            raise DataError(f'x and y must be finite, got x={x!r}, y={y!r}')
        lam = self._lambda
        p00, p01, p11 = self._p00, self._p01, self._p11
        if (p00 + p11) / lam > 2.0 * self._p_init:
            lam = 1.0  # anti-wind-up, see the class docstring
        p00 /= lam
        p01 /= lam
        p11 /= lam
        # Measurement update with regressor φ = (x, 1): g = Pφ, gain g/den.
        g0 = p00 * x + p01
        g1 = p01 * x + p11
        den = 1.0 + x * g0 + g1
        error = y - (self._k * x + self._c)
        self._k += g0 * error / den
        self._c += g1 * error / den
        self._p00 = p00 - g0 * g0 / den
        self._p01 = p01 - g0 * g1 / den
        self._p11 = p11 - g1 * g1 / den
        self._cost = lam * self._cost + error * error / den
        self._w = lam * self._w + 1.0
        self._w2 = lam * lam * self._w2 + 1.0
        self._n += 1

    def result(self) -> RlsResult | None:
        """Current estimate, or None before 3 samples. stderr is NaN while the effective dof is < 1."""
        if self._n < 3:
            return None
        ratio = self._w2 / self._w
        dof = self._w - 2.0 * ratio
        stderr = math.nan
        if dof >= 1.0 and self._p00 > 0.0:
            stderr = math.sqrt(self._cost / dof * self._p00 * ratio)
        return RlsResult(stiffness=self._k, intercept=self._c, stderr=stderr, n=self._n, effective_n=self._w)
