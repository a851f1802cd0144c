"""Straight-line fits of load against displacement: batch, sliding window and recursive.

The model fitted everywhere is ``y = k·x + c`` with

- ``x``: displacement along the loaded axis, m (or rad for a moment test),
- ``y``: load along the same axis, N (or N·m),
- ``k``: stiffness, N/m (or N·m/rad); ``c``: intercept, N (or N·m), which absorbs a tare or zero error.

Axes and signs are those of the paper's fixed frame (z down); the caller projects the wrench and the displacement
on the loaded axis before fitting. Nothing here knows about ROS or about time other than as a label.

Nonlinearity indicator (:func:`fit_line`, :class:`WindowedLeastSquares`): the points are split at the median of
the fitted load magnitude ``|k·x + c|`` into a lower and an upper half (they share the middle point when n is
odd); a line is fitted to each half and ``nonlinearity = 1 − k_upper / k_lower``. It is about 0 for a straight
line, positive when the curve softens at larger loads (the slack-wire bend of the paper's Fig. 9: equal load steps
give growing displacement steps), negative when it stiffens. The split uses the fitted load, a function of x,
rather than the measured y, because selecting points on the noisy response would bias both half slopes low.
It is NaN when a half has no spread in x or ``k_lower`` is 0.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray
# scipy.special, not scipy.stats (its ppf calls the same functions): 0.2 s to import instead of 0.5 s, in every
# node and CLI call that fits.
from scipy import special

from crane_stiffness.estimation.errors import DataError, ParameterError

#: A float for a single fit, an array for a batch of fits (leading axes of the input).
FloatOrArray = Union[float, NDArray[np.float64]]

# Relative size below which the spread of x counts as zero (a few hundred ulps of the data's magnitude).
_ZERO_SPREAD_REL = 1e-12


def t_quantile(dof: int, confidence: float = 0.95) -> float:
    """Two-sided Student-t quantile for ``dof`` degrees of freedom, e.g. 4.303 for dof=2 at 95 %.

    Exact (scipy, cached) up to 1000 degrees of freedom; above that the Cornish–Fisher expansion in 1/dof, whose
    error there is below 1e-9: a live fit over a growing window would otherwise call scipy once per new pair.
    """
    if dof <= 1000:
        return _t_quantile_exact(int(dof), confidence)
    z = _normal_quantile(confidence)
    v = float(dof)
    return z + (z ** 3 + z) / (4 * v) + (5 * z ** 5 + 16 * z ** 3 + 3 * z) / (96 * v * v) \
        + (3 * z ** 7 + 19 * z ** 5 + 17 * z ** 3 - 15 * z) / (384 * v ** 3)


@lru_cache(maxsize=2048)
def _t_quantile_exact(dof: int, confidence: float) -> float:
    return float(special.stdtrit(dof, 0.5 + confidence / 2.0))


@lru_cache(maxsize=16)
def _normal_quantile(confidence: float) -> float:
    return float(special.ndtri(0.5 + confidence / 2.0))


@dataclass(frozen=True, slots=True)
class LineFit:
    """Result of an ordinary least-squares fit ``y = stiffness·x + intercept``: the one record of a line fit (the live
    :class:`~crane_stiffness.estimation.estimator.Estimate` extends it; the offline analysis reports it as it is).

    Units follow the inputs: stiffness in N/m (N·m/rad), intercept in N (N·m). Fields are floats for one fit and
    arrays over the leading axes for a batch (:func:`fit_line` with 2-D or higher input).

    Attributes:
        stiffness: Slope k.
        intercept: Intercept c.
        stderr: Standard error of k, ``sqrt(s² / Σ(x − x̄)²)`` with ``s² = SSE / (n − 2)``.
        intercept_stderr: Standard error of c.
        ci95_low: Lower end of the 95 % confidence interval of k, ``k − t(0.975, n − 2)·stderr``.
        ci95_high: Upper end of that interval.
        r2: Coefficient of determination; 0 when y has no spread (as :func:`scipy.stats.linregress`).
        n: Number of points.
        residual_rms: ``sqrt(SSE / n)``, in the units of y.
        nonlinearity: ``1 − k_upper / k_lower`` (see the module docstring); > 0 means softening.
    """

    stiffness: FloatOrArray
    intercept: FloatOrArray
    stderr: FloatOrArray
    intercept_stderr: FloatOrArray
    ci95_low: FloatOrArray
    ci95_high: FloatOrArray
    r2: FloatOrArray
    n: int
    residual_rms: FloatOrArray
    nonlinearity: FloatOrArray


def _scalar_or_array(value: NDArray[np.float64]) -> FloatOrArray:
    return float(value) if value.ndim == 0 else value


def _assemble(n: int, xm: Any, ym: Any, sxx: Any, sxy: Any, syy: Any, sse: Any, nonlinearity: Any) -> LineFit:
    """Build a LineFit from centred sums; works element-wise on floats or arrays."""
    xm, ym, sxx, sxy, syy, sse = (np.asarray(v, dtype=float) for v in (xm, ym, sxx, sxy, syy, sse))
    k = sxy / sxx
    c = ym - k * xm
    dof = n - 2
    s2 = sse / dof
    stderr = np.sqrt(s2 / sxx)
    intercept_stderr = np.sqrt(s2 * (1.0 / n + xm * xm / sxx))
    half_width = t_quantile(dof) * stderr
    with np.errstate(invalid='ignore', divide='ignore'):
        # r = Sxy / sqrt(Sxx·Syy) is better conditioned than 1 − SSE/Syy for a nearly perfect fit.
        r2 = np.where(syy > 0.0, sxy * sxy / (sxx * np.where(syy > 0.0, syy, 1.0)), 0.0)
    r2 = np.minimum(r2, 1.0)
    return LineFit(
        stiffness=_scalar_or_array(k),
        intercept=_scalar_or_array(c),
        stderr=_scalar_or_array(stderr),
        intercept_stderr=_scalar_or_array(intercept_stderr),
        ci95_low=_scalar_or_array(k - half_width),
        ci95_high=_scalar_or_array(k + half_width),
        r2=_scalar_or_array(r2),
        n=n,
        residual_rms=_scalar_or_array(np.sqrt(sse / n)),
        nonlinearity=_scalar_or_array(np.asarray(nonlinearity, dtype=float)),
    )


def _assemble_scalar(n: int, xm: float, ym: float, sxx: float, sxy: float, syy: float, sse: float,
                     nonlinearity: float) -> LineFit:
    """:func:`_assemble` for Python floats (sxx > 0, n ≥ 3): the same operations in the same order, so the same
    bits, at a tenth of the cost (the live estimator calls it for every published estimate)."""
    xm, ym, sxx, sxy, syy, sse = float(xm), float(ym), float(sxx), float(sxy), float(syy), float(sse)
    k = sxy / sxx
    c = ym - k * xm
    dof = n - 2
    s2 = sse / dof
    stderr = math.sqrt(s2 / sxx)
    intercept_stderr = math.sqrt(s2 * (1.0 / n + xm * xm / sxx))
    half_width = t_quantile(dof) * stderr
    r2 = min(sxy * sxy / (sxx * syy) if syy > 0.0 else 0.0, 1.0)
    return LineFit(stiffness=k, intercept=c, stderr=stderr, intercept_stderr=intercept_stderr,
                   ci95_low=k - half_width, ci95_high=k + half_width, r2=r2, n=n,
                   residual_rms=math.sqrt(sse / n), nonlinearity=float(nonlinearity))


def _slopes(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """OLS slopes along the last axis; NaN where x has no spread."""
    dx = x - x.mean(axis=-1, keepdims=True)
    sxx = np.einsum('...i,...i->...', dx, dx)
    sxy = np.einsum('...i,...i->...', dx, y - y.mean(axis=-1, keepdims=True))
    scale = np.abs(x).max(axis=-1)
    flat = sxx <= x.shape[-1] * (_ZERO_SPREAD_REL * scale) ** 2
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(flat, np.nan, sxy / np.where(flat, 1.0, sxx))


def split_half_nonlinearity(x: ArrayLike, y: ArrayLike, stiffness: ArrayLike,
                            intercept: ArrayLike) -> FloatOrArray:
    """Nonlinearity indicator ``1 − k_upper / k_lower`` of points (x, y) along the last axis.

    The halves are split at the median of ``|stiffness·x + intercept|`` (the full fit's load magnitude); see the
    module docstring. Needs at least 3 points; returns NaN where a half has no spread or ``k_lower`` is 0.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    n = x.shape[-1]
    m = (n + 1) // 2
    fitted = np.abs(np.asarray(stiffness, dtype=float)[..., None] * x + np.asarray(intercept, dtype=float)[..., None])
    # The halves are sets: a partition around the median (O(n)) finds them; a full sort of a branch of an hour's
    # pairs (millions) was most of the offline fits' time.
    lower = np.argpartition(fitted, m - 1, axis=-1)[..., :m]
    upper = np.argpartition(fitted, n - m, axis=-1)[..., n - m:]
    k_lower = _slopes(np.take_along_axis(x, lower, axis=-1), np.take_along_axis(y, lower, axis=-1))
    k_upper = _slopes(np.take_along_axis(x, upper, axis=-1), np.take_along_axis(y, upper, axis=-1))
    with np.errstate(invalid='ignore', divide='ignore'):
        ratio = 1.0 - k_upper / k_lower
    return _scalar_or_array(np.where(np.isfinite(ratio), ratio, np.nan))


def fit_line(x: ArrayLike, y: ArrayLike) -> LineFit:
    """Ordinary least-squares fit of ``y = k·x + c`` with standard errors and a 95 % interval for k.

    Args:
        x: Displacements, m (or rad); shape (n,) or (..., n) for a batch of independent fits along the last axis.
        y: Loads, N (or N·m); broadcast against x.

    Returns:
        A :class:`LineFit`; its fields are floats for 1-D input, arrays of shape ``x.shape[:-1]`` for a batch.

    Raises:
        DataError: Fewer than 3 points (the error estimate needs n − 2 ≥ 1), NaN/Inf values, or no spread in x
            (in any fit of a batch).
    """
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    if x.ndim == 0:
        raise DataError('x and y must be arrays of at least 3 points, got scalars')
    n = x.shape[-1]
    if n < 3:
        raise DataError(f'a line fit with an error estimate needs at least 3 points, got {n}')
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise DataError('x and y must be finite; got NaN or Inf')
    xm = x.mean(axis=-1)
    ym = y.mean(axis=-1)
    # Centre before forming sums of squares so an offset in x or y (e.g. an un-zeroed LVDT) costs no precision.
    dx = x - xm[..., None]
    dy = y - ym[..., None]
    sxx = np.einsum('...i,...i->...', dx, dx)
    sxy = np.einsum('...i,...i->...', dx, dy)
    syy = np.einsum('...i,...i->...', dy, dy)
    flat = sxx <= n * (_ZERO_SPREAD_REL * np.abs(x).max(axis=-1)) ** 2
    if np.any(flat):
        where = '' if flat.ndim == 0 else f' in fit(s) {np.argwhere(flat).tolist()[:5]}'
        raise DataError(f'x has zero spread{where}: all displacements equal, the slope is undefined')
    k = sxy / sxx
    residual = dy - k[..., None] * dx
    sse = np.einsum('...i,...i->...', residual, residual)
    nonlinearity = split_half_nonlinearity(x, y, k, ym - k * xm)
    return _assemble(n, xm, ym, sxx, sxy, syy, sse, nonlinearity)


def fit_or_none(x: np.ndarray | Sequence[float], y: ArrayLike) -> LineFit | None:
    """:func:`fit_line`, or None when there is nothing to fit (fewer than 3 points, no spread in x, NaN/Inf)."""
    if len(x) < 3:
        return None
    try:
        return fit_line(x, y)
    except DataError:
        return None


class WindowedLeastSquares:
    """Least-squares line over the last ``window`` (x, y) pairs, updated in O(1) per sample.

    Running sums are kept about a reference point (x₀, y₀) near the data, and recomputed exactly from the buffer
    every ``recompute_every`` updates (default: ``window``) with the reference moved to the buffer mean, so the
    rounding error of adding and removing samples cannot build up. The amortised cost stays O(1).

    :meth:`result` equals :func:`fit_line` on the same window to rounding error. Its nonlinearity indicator
    needs a sort of the window, O(window·log window) per call; pass ``nonlinearity=False`` to skip it (NaN).
    """

    def __init__(self, window: int, *, recompute_every: int | None = None, nonlinearity: bool = True) -> None:
        """Create an empty window.

        Args:
            window: Number of most recent pairs kept, ≥ 3.
            recompute_every: Updates between exact recomputations of the sums, ≥ 1; default ``window``.
            nonlinearity: Compute the nonlinearity indicator in :meth:`result`.
        """
        if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 3:
            raise ParameterError('window', window, 'must be an integer >= 3')
        if recompute_every is None:
            recompute_every = int(window)
        if isinstance(recompute_every, bool) or not isinstance(recompute_every, (int, np.integer)) \
                or recompute_every < 1:
            raise ParameterError('recompute_every', recompute_every, 'must be an integer >= 1')
        self._window = int(window)
        self._recompute_every = int(recompute_every)
        self._nonlinearity = bool(nonlinearity)
        self._xbuf = np.empty(self._window)
        self._ybuf = np.empty(self._window)
        self.reset()

    def reset(self) -> None:
        """Forget all samples."""
        self._head = 0  # slot of the next write; the oldest sample once the buffer is full
        self._n = 0
        self._x0 = 0.0
        self._y0 = 0.0
        self._sx = self._sy = self._sxx = self._sxy = self._syy = 0.0
        self._updates = 0

    @property
    def window(self) -> int:
        """Capacity of the window (pairs)."""
        return self._window

    def __len__(self) -> int:
        return self._n

    def add(self, x: float, y: float) -> None:
        """Append one pair, dropping the oldest once ``window`` pairs are held. Raises DataError on NaN/Inf."""
        x = float(x)
        y = float(y)
        if not (math.isfinite(x) and math.isfinite(y)):
            raise DataError(f'x and y must be finite, got x={x!r}, y={y!r}')
        if self._n == 0:
            self._x0, self._y0 = x, y
        head = self._head
        if self._n == self._window:
            dx = self._xbuf[head] - self._x0
            dy = self._ybuf[head] - self._y0
            self._sx -= dx
            self._sy -= dy
            self._sxx -= dx * dx
            self._sxy -= dx * dy
            self._syy -= dy * dy
        else:
            self._n += 1
        self._xbuf[head] = x
        self._ybuf[head] = y
        self._head = (head + 1) % self._window
        dx = x - self._x0
        dy = y - self._y0
        self._sx += dx
        self._sy += dy
        self._sxx += dx * dx
        self._sxy += dx * dy
        self._syy += dy * dy
        self._updates += 1
        if self._updates >= self._recompute_every:
            self._recompute()

    def _recompute(self) -> None:
        """Exact sums from the buffer about its mean (bounds the drift of the running sums)."""
        x, y = self.data()
        self._x0 = float(x.mean())
        self._y0 = float(y.mean())
        dx = x - self._x0
        dy = y - self._y0
        self._sx = float(dx.sum())
        self._sy = float(dy.sum())
        self._sxx = float(dx @ dx)
        self._sxy = float(dx @ dy)
        self._syy = float(dy @ dy)
        self._updates = 0

    def data(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Copies of the held (x, y) pairs, oldest first."""
        if self._n < self._window:
            return self._xbuf[:self._n].copy(), self._ybuf[:self._n].copy()
        order = np.r_[self._head:self._window, 0:self._head]
        return self._xbuf[order], self._ybuf[order]

    def result(self, nonlinearity: bool | None = None) -> LineFit | None:
        """Fit of the current window, or None with fewer than 3 pairs or no spread in x.

        ``nonlinearity``: compute the indicator (sorts the window) — None: as chosen at construction.
        """
        n = self._n
        if n < 3:
            return None
        sxx = self._sxx - self._sx * self._sx / n
        if sxx <= _ZERO_SPREAD_REL * self._sxx or sxx <= 0.0:
            return None
        sxy = self._sxy - self._sx * self._sy / n
        syy = max(self._syy - self._sy * self._sy / n, 0.0)
        sse = max(syy - sxy * sxy / sxx, 0.0)  # clipped: rounding can make a perfect fit slightly negative
        xm = self._x0 + self._sx / n
        ym = self._y0 + self._sy / n
        indicator = math.nan
        if self._nonlinearity if nonlinearity is None else nonlinearity:
            x, y = self.data()
            k = sxy / sxx
            indicator = float(split_half_nonlinearity(x, y, k, ym - k * xm))  # 1-D window: already a float
        return _assemble_scalar(n, xm, ym, sxx, sxy, syy, sse, indicator)


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
