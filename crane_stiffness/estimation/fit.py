"""Straight-line fits of load against displacement with errors in both variables: batch and sliding window, side by
side (:class:`WindowedLeastSquares` gives :func:`fit_line`'s result on its window; the tests pin them together).

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
It is NaN when a half has no spread in x beyond its noise (the full fit's rule, ``SXX >= Sxx / 2``: a window
mostly one hold has halves split by noise alone) or ``k_lower`` is 0.

Errors in both variables: both sensors are noisy. Ordinary least squares of y on x attenuates the slope by the
reliability ratio ``Sxx_true / Sxx``, i.e. by about ``(σx / sd x)²`` (a 1 µm-noise LVDT over a stroke of 10 µm
standard deviation: 1 % low). Given the displacement's white-noise standard deviation ``x_noise`` = σx (from the
sensor's specification, or estimated from the data with :func:`crane_stiffness.estimation.quality.noise_std`), the
fits use the method-of-moments estimator with known measurement-error variance (Fuller, *Measurement Error Models*,
1987, §1.2)::

    k = Sxy / (Sxx − (n − 1)·σx²)

with centred sums ``Sxx, Sxy`` of the observed pairs, and its variance (Fuller's theorem 1.2.1), which counts both
noises: the force's through the residuals and the displacement's through them and the correction terms::

    Var k = s_vv / SXX + (n − 1)·(σx²·s_vv + k²·σx⁴) / SXX²,   SXX = Sxx − (n − 1)·σx²,
    s_vv = Σ (y − ȳ − k·(x − x̄))² / (n − 2).

With ``x_noise`` = 0 both are the ordinary least-squares formulas, to the bit. There is no fit when the spread of x
is not well above its noise, ``SXX < Sxx / 2`` (:data:`MIN_RELIABILITY`: least squares would be low by more than
half; a window inside one hold has ``SXX`` ≈ 0 of either sign, and a slope of noise against noise is no stiffness).
The intercept's standard error is the first-order ``sqrt(s_vv/n + x̄²·Var k)``.
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

#: The least reliability ratio SXX / Sxx (the share of the displacement's spread that is not noise) a fit needs.
MIN_RELIABILITY = 0.5


def hidden_by_noise(sxx: Any, n: Any, x_noise: Any) -> Any:
    """The rule for every slope here: True where the displacement's spread is not well beyond its noise,
    ``Sxx − (n − 1)·x_noise² < MIN_RELIABILITY·Sxx`` (centred sum ``sxx`` of n points; arrays broadcast)."""
    return sxx - (n - 1) * np.asarray(x_noise, dtype=float) ** 2 < MIN_RELIABILITY * sxx


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
        x_noise: Standard deviation of the displacement's white noise counted in the fit, units of x (0: ordinary
            least squares; see the module docstring).
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
    x_noise: FloatOrArray


def _scalar_or_array(value: NDArray[np.float64]) -> FloatOrArray:
    return float(value) if value.ndim == 0 else value


def _assemble(n: int, xm: Any, ym: Any, sxx: Any, sxy: Any, syy: Any, sse: Any, nonlinearity: Any,
              x_noise: Any) -> LineFit:
    """Build a LineFit from centred sums of the observed pairs and the ordinary least-squares ``sse``, counting the
    displacement noise ``x_noise`` (module docstring; needs ``Sxx − (n − 1)·x_noise² > 0``); works element-wise on
    floats or arrays."""
    xm, ym, sxx, sxy, syy, sse, x_noise = (np.asarray(v, dtype=float) for v in (xm, ym, sxx, sxy, syy, sse,
                                                                                 x_noise))
    x_var = x_noise * x_noise
    sxx_true = sxx - (n - 1) * x_var
    k = sxy / sxx_true
    c = ym - k * xm
    dof = n - 2
    # residuals about the corrected line: the least-squares SSE plus what moving the slope off its minimum adds
    sse = sse + sxx * (k - sxy / sxx) ** 2
    s2 = sse / dof
    var_k = s2 / sxx_true + (n - 1) * (x_var * s2 + k * k * x_var * x_var) / (sxx_true * sxx_true)
    stderr = np.sqrt(var_k)
    intercept_stderr = np.sqrt(s2 / n + xm * xm * var_k)
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
        x_noise=_scalar_or_array(x_noise),
    )


def _assemble_scalar(n: int, xm: float, ym: float, sxx: float, sxy: float, syy: float, sse: float,
                     nonlinearity: float, x_noise: float) -> LineFit:
    """:func:`_assemble` for Python floats (``Sxx − (n − 1)·x_noise²`` > 0, n ≥ 3): the same operations in the same
    order, so the same bits, at a tenth of the cost (the live estimator calls it for every published estimate)."""
    xm, ym, sxx, sxy, syy, sse = float(xm), float(ym), float(sxx), float(sxy), float(syy), float(sse)
    x_noise = float(x_noise)
    x_var = x_noise * x_noise
    sxx_true = sxx - (n - 1) * x_var
    k = sxy / sxx_true
    c = ym - k * xm
    dof = n - 2
    sse = sse + sxx * (k - sxy / sxx) ** 2
    s2 = sse / dof
    var_k = s2 / sxx_true + (n - 1) * (x_var * s2 + k * k * x_var * x_var) / (sxx_true * sxx_true)
    stderr = math.sqrt(var_k)
    intercept_stderr = math.sqrt(s2 / n + xm * xm * var_k)
    half_width = t_quantile(dof) * stderr
    r2 = min(sxy * sxy / (sxx * syy) if syy > 0.0 else 0.0, 1.0)
    return LineFit(stiffness=k, intercept=c, stderr=stderr, intercept_stderr=intercept_stderr,
                   ci95_low=k - half_width, ci95_high=k + half_width, r2=r2, n=n,
                   residual_rms=math.sqrt(sse / n), nonlinearity=float(nonlinearity), x_noise=x_noise)


def _slopes(x: NDArray[np.float64], y: NDArray[np.float64], x_noise: Any = 0.0) -> NDArray[np.float64]:
    """Slopes along the last axis counting the displacement noise ``x_noise`` (module docstring); NaN where x has no
    spread beyond it."""
    dx = x - x.mean(axis=-1, keepdims=True)
    sxx = np.einsum('...i,...i->...', dx, dx)
    sxy = np.einsum('...i,...i->...', dx, y - y.mean(axis=-1, keepdims=True))
    scale = np.abs(x).max(axis=-1)
    flat = sxx <= x.shape[-1] * (_ZERO_SPREAD_REL * scale) ** 2
    true_sxx = sxx - (x.shape[-1] - 1) * np.asarray(x_noise, dtype=float) ** 2
    # The full fit's rule: no slope without spread well beyond the noise. A half of a window that is mostly one
    # hold (the rig at rest before a program) is split by its noise alone; its corrected slope was anything.
    flat = flat | ~(true_sxx > 0.0) | hidden_by_noise(sxx, x.shape[-1], x_noise)
    sxx = true_sxx
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(flat, np.nan, sxy / np.where(flat, 1.0, sxx))


def split_half_nonlinearity(x: ArrayLike, y: ArrayLike, stiffness: ArrayLike, intercept: ArrayLike,
                            x_noise: ArrayLike = 0.0) -> FloatOrArray:
    """Nonlinearity indicator ``1 − k_upper / k_lower`` of points (x, y) along the last axis.

    The halves are split at the median of ``|stiffness·x + intercept|`` (the full fit's load magnitude); see the
    module docstring; each half's slope counts the displacement noise ``x_noise`` as the full fit does. Needs at
    least 3 points; returns NaN where a half has no spread or ``k_lower`` is 0.
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
    noise = np.asarray(x_noise, dtype=float)
    k_lower = _slopes(np.take_along_axis(x, lower, axis=-1), np.take_along_axis(y, lower, axis=-1), noise)
    k_upper = _slopes(np.take_along_axis(x, upper, axis=-1), np.take_along_axis(y, upper, axis=-1), noise)
    with np.errstate(invalid='ignore', divide='ignore'):
        ratio = 1.0 - k_upper / k_lower
    return _scalar_or_array(np.where(np.isfinite(ratio), ratio, np.nan))


def _x_noise(x_noise: ArrayLike, batch_shape: tuple[int, ...]) -> NDArray[np.float64]:
    """``x_noise`` checked (finite, ≥ 0) and broadcast to the batch's shape."""
    noise = np.asarray(x_noise, dtype=float)
    if not (np.isfinite(noise).all() and (noise >= 0.0).all()):
        raise ParameterError('x_noise', x_noise, 'must be finite and >= 0 (standard deviation, units of x)')
    try:
        return np.broadcast_to(noise, batch_shape)
    except ValueError:
        raise ParameterError('x_noise', f'shape {noise.shape}', f'must broadcast to the batch shape {batch_shape}') \
            from None


def fit_line(x: ArrayLike, y: ArrayLike, *, x_noise: ArrayLike = 0.0) -> LineFit:
    """Fit of ``y = k·x + c`` with errors in both variables, standard errors and a 95 % interval for k.

    Args:
        x: Displacements, m (or rad); shape (n,) or (..., n) for a batch of independent fits along the last axis.
        y: Loads, N (or N·m); broadcast against x.
        x_noise: Standard deviation of the displacement's white noise, units of x; a float, or an array of the
            batch's shape ``x.shape[:-1]``. 0 (the default): ordinary least squares. See the module docstring.

    Returns:
        A :class:`LineFit`; its fields are floats for 1-D input, arrays of shape ``x.shape[:-1]`` for a batch.

    Raises:
        DataError: Fewer than 3 points (the error estimate needs n − 2 ≥ 1), NaN/Inf values, or no spread in x
            (beyond its noise; in any fit of a batch).
        ParameterError: ``x_noise`` negative, not finite, or not of the batch's shape.
    """
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    if x.ndim == 0:
        raise DataError('x and y must be arrays of at least 3 points, got scalars')
    n = x.shape[-1]
    if n < 3:
        raise DataError(f'a line fit with an error estimate needs at least 3 points, got {n}')
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise DataError('x and y must be finite; got NaN or Inf')
    noise = _x_noise(x_noise, x.shape[:-1])
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
    hidden = hidden_by_noise(sxx, n, noise)
    if np.any(hidden):
        where = '' if hidden.ndim == 0 else f' in fit(s) {np.argwhere(hidden).tolist()[:5]}'
        raise DataError(f'x has no spread beyond its noise{where} ((n - 1)·x_noise² > Sxx / 2): no stiffness in it')
    k_ols = sxy / sxx
    residual = dy - k_ols[..., None] * dx
    sse = np.einsum('...i,...i->...', residual, residual)
    k = sxy / (sxx - (n - 1) * noise * noise)
    nonlinearity = split_half_nonlinearity(x, y, k, ym - k * xm, noise)
    return _assemble(n, xm, ym, sxx, sxy, syy, sse, nonlinearity, noise)


def fit_or_none(x: np.ndarray | Sequence[float], y: ArrayLike, x_noise: float = 0.0) -> LineFit | None:
    """:func:`fit_line`, or None when there is nothing to fit (fewer than 3 points, no spread in x beyond its noise,
    NaN/Inf)."""
    if len(x) < 3:
        return None
    try:
        return fit_line(x, y, x_noise=x_noise)
    except DataError:
        return None


class WindowedLeastSquares:
    """Least-squares line over the last ``window`` (x, y) pairs, updated in O(1) per sample.

    Running sums are kept about a reference point (x₀, y₀) near the data, and recomputed exactly from the buffer
    every ``recompute_every`` updates (default: ``window``) with the reference moved to the buffer mean, so the
    rounding error of adding and removing samples cannot build up. The amortised cost stays O(1).

    :meth:`result` equals :func:`fit_line` on the same window (and the same ``x_noise``) to rounding error. Its
    nonlinearity indicator needs a partition of the window, O(window) per call; pass ``nonlinearity=False`` to skip
    it (NaN).
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

    def result(self, nonlinearity: bool | None = None, x_noise: float = 0.0) -> LineFit | None:
        """Fit of the current window, or None with fewer than 3 pairs or no spread in x (beyond its noise).

        ``nonlinearity``: compute the indicator (partitions the window) — None: as chosen at construction.
        ``x_noise``: standard deviation of the displacement's white noise counted in the fit, units of x, ≥ 0
        (:func:`fit_line`).
        """
        n = self._n
        if n < 3:
            return None
        sxx = self._sxx - self._sx * self._sx / n
        if sxx <= _ZERO_SPREAD_REL * self._sxx or sxx <= 0.0:
            return None
        x_noise = float(x_noise)
        if not (x_noise >= 0.0 and math.isfinite(x_noise)):
            raise ParameterError('x_noise', x_noise, 'must be finite and >= 0 (standard deviation, units of x)')
        if hidden_by_noise(sxx, n, x_noise):
            return None  # no spread beyond the noise
        sxy = self._sxy - self._sx * self._sy / n
        syy = max(self._syy - self._sy * self._sy / n, 0.0)
        sse = max(syy - sxy * sxy / sxx, 0.0)  # clipped: rounding can make a perfect fit slightly negative
        xm = self._x0 + self._sx / n
        ym = self._y0 + self._sy / n
        indicator = math.nan
        if self._nonlinearity if nonlinearity is None else nonlinearity:
            x, y = self.data()
            k = sxy / (sxx - (n - 1) * x_noise * x_noise)
            # 1-D window: already a float
            indicator = float(split_half_nonlinearity(x, y, k, ym - k * xm, x_noise))
        return _assemble_scalar(n, xm, ym, sxx, sxy, syy, sse, indicator, x_noise)
