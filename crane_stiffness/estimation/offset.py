"""The time offset between the force and displacement streams, estimated from the data.

Two drivers stamp with different clocks and latencies and run at different rates (e.g. a 7 kHz F/T sensor and a
100 Hz Modbus LVDT). Pairing them, interpolated or by nearest stamp, is :mod:`crane_stiffness.estimation.sync`;
this module finds how far apart their clocks are. Pure numpy, no ROS.

:func:`estimate_delay` finds how much later one stream's stamps are than the other's for the same physical instant:
during load ramps and steps both streams change together, so the normalised cross-correlation of their time
derivatives (both resampled on one uniform grid and smoothed) peaks at the delay: smoothed over ``SMOOTH_S`` it has
one lobe, which says where (a ramp commanded in 10 ms steps would otherwise correlate again every 10 ms), and
smoothed to the slower stream's bandwidth it gives the peak within ``FINE_HALF_S`` of that lobe's; a parabola
through the peak refines it below the grid step, and a bounded least-squares search (the lag that makes
the slow stream the best straight-line function of the fast one at the shifted stamps) refines it further.
:func:`correct_stamps` applies it. The result says how sure it is (:attr:`DelayEstimate.ok`, ``reason``): without
load changes there is nothing to correlate, and it says so.

Sign convention: ``delay_s`` > 0 means stream ``b``'s stamps are late: the sample of ``b`` stamped ``s`` was taken
at ``s − delay_s`` (a displacement driver that stamps at the end of a slow request, say). Correct with
``correct_stamps(b_stamps, delay) = b_stamps − delay``.

Units: stamps in seconds (any common clock), values in the streams' own units (N, N·m, m). The live estimator uses
:func:`estimate_delay` and the stamp correction (estimation.stream_delay, displacement_delay_s).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.estimation.errors import DataError, ParameterError

__all__ = ['DelayEstimate', 'correct_stamps', 'estimate_delay', 'interpolate_at']


def _check_stream(name: str, t: ArrayLike, y: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.ndim != 1 or y.shape[:1] != t.shape:
        raise DataError(f'{name}: stamps must be 1-D and values have as many rows as stamps, got shapes '
                        f'{t.shape} and {y.shape}')
    if not (np.isfinite(t).all() and np.isfinite(y).all()):
        raise DataError(f'{name}: stamps and values must be finite; got NaN or Inf')
    if t.size > 1 and np.any(np.diff(t) <= 0):
        i = int(np.argmax(np.diff(t) <= 0))
        raise DataError(f'{name}: stamps must increase strictly; stamp {i + 1} = {t[i + 1]!r} s follows {t[i]!r} s')
    return t, y


def interpolate_at(t_fast: ArrayLike, y_fast: ArrayLike, t_query: ArrayLike,
                   max_gap_s: float = np.inf) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_]]:
    """The fast stream linearly interpolated at ``t_query`` [s].

    Args:
        t_fast: Strictly increasing stamps [s], shape (m,).
        y_fast: Values, shape (m,) or (m, k).
        t_query: Stamps to interpolate at [s], any order, shape (n,).
        max_gap_s: Largest distance between the two bracketing fast samples [s].

    Returns:
        (values, inside, gap_ok): values shape (n,) or (n, k) (NaN where not valid); ``inside``: the stamp lies
        within [t_fast[0], t_fast[-1]]; ``gap_ok``: its bracketing samples are at most ``max_gap_s`` apart. A value
        is valid where both hold.
    """
    t_fast, y_fast = _check_stream('fast stream', t_fast, y_fast)
    tq = np.asarray(t_query, dtype=float).ravel()
    if t_fast.size < 2:
        raise DataError(f'interpolation needs at least 2 fast samples, got {t_fast.size}')
    # Index of the right-hand bracket: t_fast[j-1] < tq <= t_fast[j] (a stamp on a sample uses the pair before it).
    j = np.searchsorted(t_fast, tq, side='left')
    inside = (tq >= t_fast[0]) & (tq <= t_fast[-1])
    j = np.clip(j, 1, t_fast.size - 1)
    t0, t1 = t_fast[j - 1], t_fast[j]
    gap_ok = (t1 - t0) <= max_gap_s
    w = (tq - t0) / (t1 - t0)
    y0, y1 = y_fast[j - 1], y_fast[j]
    wv = w if y_fast.ndim == 1 else w[:, None]
    values = y0 + wv * (y1 - y0)
    bad = ~(inside & gap_ok)
    if bad.any():
        values = values.copy()
        values[bad] = np.nan
    return values, inside, gap_ok


# --- time offset -----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class DelayEstimate:
    """How much later stream b's stamps are than stream a's (see the module docstring for the sign).

    Attributes:
        delay_s: The estimate [s] (after the least-squares refinement).
        xcorr_delay_s: The cross-correlation peak, parabola-refined [s].
        peak_correlation: Normalised correlation of the two derivative signals at the peak (−1..1).
        grid_s: Step of the common grid the correlation was computed on [s].
        max_lag_s: The lags searched: ±max_lag_s [s].
        samples: Grid points in the overlap of the two streams.
        ok: Whether the estimate can be trusted: a clear peak (``peak_correlation`` >= ``min_correlation``) inside
            the searched lags (not at their edge), with no second peak of the coarse correlation at
            ``MAX_RIVAL_PEAK`` of the highest.
        reason: Why not, when ``ok`` is False ('' otherwise).
    """

    delay_s: float
    xcorr_delay_s: float
    peak_correlation: float
    grid_s: float
    max_lag_s: float
    samples: int
    ok: bool
    reason: str = ''


def _median_period(t: NDArray[np.float64]) -> float:
    return float(np.median(np.diff(t)))


def _box(signal: NDArray[np.float64], width: int) -> NDArray[np.float64]:
    """Moving average over ``width`` points, centred as ``np.convolve(…, mode='same')`` (zeros beyond the ends), by
    a cumulative sum: O(n) whatever the width (a 25 ms box on a 0.1 ms grid is 250 points)."""
    if width <= 1:
        return signal
    n = signal.size
    csum = np.concatenate(([0.0], np.cumsum(signal)))
    start = np.arange(n) - width // 2  # first index of each window, as np.convolve 'same' has it
    lo = np.clip(start, 0, n)
    hi = np.clip(start + width, 0, n)
    return (csum[hi] - csum[lo]) / width


#: Peak correlation below which a delay estimate is not trusted. Peaks of 0.35–0.46 were seen to place a delay
#: anywhere within a load step's time: on the emulated drivers' rig the live estimate said 10.3 ms while the whole
#: recording gave 0.8 ms, and two moment sessions of a rig without delay gave 9.2–9.6 ms; a real delay among clear
#: load changes correlates at 0.9 and more (3 ms injected: 0.96).
MIN_PEAK_CORRELATION = 0.5
#: A second peak of the correlation at least this fraction of the highest, outside its lobe, makes the delay
#: ambiguous: a load commanded in steps at a fixed rate (the load programs' 100 Hz) makes the derivatives a pulse
#: train whose correlation repeats every period, and noise decides which repeat is highest (10 ms off).
MAX_RIVAL_PEAK = 0.8
#: The shortest smoothing before differentiating [s]: longer than the load programs' command period (100 Hz), so a
#: ramp commanded in steps differentiates to a plateau, not to a pulse train whose correlation repeats every 10 ms.
SMOOTH_S = 0.025
#: The fine peak is looked for within this of the coarse one [s]: under half the programs' 10 ms command period, so
#: a repeat of the fine correlation 10 ms away (a 500 Hz LVDT smooths over 2 ms only) is never taken for it.
FINE_HALF_S = 0.004


def estimate_delay(t_a: ArrayLike, y_a: ArrayLike, t_b: ArrayLike, y_b: ArrayLike, max_lag_s: float = 0.05,
                   grid_s: float | None = None, min_correlation: float = MIN_PEAK_CORRELATION,
                   refine: bool = True) -> DelayEstimate:
    """The delay of stream b's stamps against stream a's, from the data (both scalar streams, e.g. the force
    component fitted [N] and the displacement [m]; their units and scale do not matter, nor the sign of their
    relation).

    Args:
        t_a, y_a: Stream a: strictly increasing stamps [s] and values, shape (n,).
        t_b, y_b: Stream b, the same.
        max_lag_s: Delays searched: ±max_lag_s [s].
        grid_s: Step of the common grid [s]; default: the faster stream's median period, but at most a tenth of
            the slower stream's and at least 0.05 ms.
        min_correlation: Peak correlation below which the estimate is not ``ok`` (no load changes to go by).
        refine: Refine the correlation peak by least squares (see the module docstring).

    Returns:
        A :class:`DelayEstimate`. Raises DataError when the streams overlap too little (less than 4·max_lag_s)
        or a stream has fewer than 4 samples.
    """
    t_a, y_a = _check_stream('stream a', t_a, y_a)
    t_b, y_b = _check_stream('stream b', t_b, y_b)
    if y_a.ndim != 1 or y_b.ndim != 1:
        raise DataError('estimate_delay takes scalar streams (one component each)')
    if not max_lag_s > 0:
        raise ParameterError('max_lag_s', max_lag_s, 'must be > 0 [s]')
    if t_a.size < 4 or t_b.size < 4:
        raise DataError(f'each stream needs at least 4 samples, got {t_a.size} and {t_b.size}')
    start, end = max(t_a[0], t_b[0]), min(t_a[-1], t_b[-1])
    if end - start < 4 * max_lag_s:
        raise DataError(f'the streams overlap for {max(end - start, 0.0):.4g} s: at least 4·max_lag_s = '
                        f'{4 * max_lag_s:.4g} s needed')
    pa, pb = _median_period(t_a), _median_period(t_b)
    slow = max(pa, pb)
    if grid_s is None:
        grid_s = max(min(pa, pb, slow / 10.0), 5e-5)
    if not grid_s > 0:
        raise ParameterError('grid_s', grid_s, 'must be > 0 [s]')
    grid = np.arange(start, end, grid_s)
    ga = np.interp(grid, t_a, y_a)
    gb = np.interp(grid, t_b, y_b)
    # Both smoothed, then differentiated: what is left is where the load changes (ramps, steps), the same shape
    # in both streams, shifted by the delay. Twice: smoothed over at least SMOOTH_S (coarse: a ramp commanded in
    # steps is a plateau there, so the correlation has one lobe, which says where the delay is), and over the
    # slower stream's period (fine: the peak within that lobe, as sharp as the data allow).
    fine_width = max(int(round(slow / grid_s)), 1)
    max_lag = int(np.ceil(max_lag_s / grid_s))
    coarse = _correlation(ga, gb, max(int(round(SMOOTH_S / grid_s)), fine_width), max_lag)
    fine = _correlation(ga, gb, fine_width, max_lag)
    if coarse is None or fine is None:
        return DelayEstimate(float('nan'), float('nan'), 0.0, grid_s, max_lag_s, grid.size, False,
                             'a stream does not change in the overlap: nothing to correlate')
    lags, cc = coarse
    cut = (fine[1].size - cc.size) // 2  # the coarse one may search fewer lags on short data: the same lags
    c = fine[1][cut:cut + cc.size]
    # The relation may be inverted (a sign convention): take the strongest coarse peak of either sign.
    kc = int(np.argmax(np.abs(cc)))
    sign = 1.0 if cc[kc] >= 0 else -1.0
    half = max(int(round(FINE_HALF_S / grid_s)), 1)
    lo, hi = max(kc - half, 0), min(kc + half, lags.size - 1)
    k = lo + int(np.argmax(sign * c[lo:hi + 1]))
    peak = float(c[k])
    frac = 0.0
    if 0 < k < lags.size - 1:
        y0, y1, y2 = sign * c[k - 1], sign * c[k], sign * c[k + 1]
        denom = y0 - 2 * y1 + y2
        if y1 >= max(y0, y2) and denom < 0:  # a maximum: the parabola's vertex lies within half a step
            frac = 0.5 * (y0 - y2) / denom
    xcorr = float((lags[k] + frac) * grid_s)
    ok, reason = True, ''
    if abs(peak) < min_correlation:
        ok, reason = False, (f'peak correlation {abs(peak):.3f} < {min_correlation}: too little load change '
                             '(ramps or steps) to find the delay')
    elif kc in (0, lags.size - 1) or k in (0, lags.size - 1):
        ok, reason = False, f'the correlation peaks at the edge of ±{max_lag_s} s: the delay may be larger'
    else:
        rival = _rival_peak(sign * cc, kc)
        if rival is not None and sign * cc[rival] >= MAX_RIVAL_PEAK * abs(cc[kc]):
            ok, reason = False, (f'two correlation peaks of nearly equal height, at {lags[kc] * grid_s * 1e3:+.3g} '
                                 f'ms and {lags[rival] * grid_s * 1e3:+.3g} ms ({sign * cc[rival] / abs(cc[kc]):.2f} '
                                 'of the highest): the load changes repeat, the delay is ambiguous')
    delay = xcorr
    if refine and ok:
        delay = _refine(t_a, y_a, t_b, y_b, xcorr, max(10.0 * grid_s, slow / 2.0))
    return DelayEstimate(float(delay), xcorr, abs(peak), float(grid_s), float(max_lag_s), int(grid.size), ok,
                         reason)


def _correlation(ga: NDArray[np.float64], gb: NDArray[np.float64], width: int,
                 max_lag: int) -> tuple[NDArray[np.int64], NDArray[np.float64]] | None:
    """(lags, normalised correlation) of the derivatives of ga and gb (one grid) smoothed by a box of ``width``
    points, over lags ±max_lag grid steps (fewer when the data are short); None when a derivative is all zero.
    corr[L] = sum_i db[i + L]·da[i]: b lags a by L grid steps when the peak is at L > 0."""
    da = np.diff(_box(ga, width))
    db = np.diff(_box(gb, width))
    da, db = da[width:-width or None], db[width:-width or None]  # the box's edge effects
    da = da - da.mean()
    db = db - db.mean()
    na, nb = np.sqrt(da @ da), np.sqrt(db @ db)
    if na == 0 or nb == 0:
        return None
    n = da.size
    size = 1 << int(np.ceil(np.log2(2 * n)))
    corr = np.fft.irfft(np.fft.rfft(db, size) * np.conj(np.fft.rfft(da, size)), size)
    lag = min(max_lag, n - 1)
    lags = np.arange(-lag, lag + 1)
    return lags, corr[lags % size] / (na * nb)


def _rival_peak(s: NDArray[np.float64], k: int) -> int | None:
    """The highest local maximum of ``s`` outside the lobe of its maximum at ``k`` (where ``s`` stays above half
    of ``s[k]``), or None."""
    lo, hi = k, k
    while lo > 0 and s[lo - 1] > 0.5 * s[k]:
        lo -= 1
    while hi < s.size - 1 and s[hi + 1] > 0.5 * s[k]:
        hi += 1
    inner = np.arange(1, s.size - 1)
    is_max = (s[inner] >= s[inner - 1]) & (s[inner] >= s[inner + 1]) & ((inner < lo) | (inner > hi))
    candidates = inner[is_max]
    return int(candidates[np.argmax(s[candidates])]) if candidates.size else None


def _refine(t_a, y_a, t_b, y_b, guess: float, half_width: float) -> float:
    """The delay within guess ± half_width that makes the slow stream the best straight-line function of the fast
    one at the slow stream's shifted stamps (least squares over the slow samples). The fast stream is first
    averaged over the slow stream's period (a centred box: exact on ramps, no shift): interpolating its raw noise
    would make the sum of squares jump from one lag to the next."""
    from scipy.optimize import minimize_scalar

    pa, pb = _median_period(t_a), _median_period(t_b)
    a_slow = pa > pb
    t_fast, y_fast, t_slow, y_slow = (t_b, y_b, t_a, y_a) if a_slow else (t_a, y_a, t_b, y_b)
    width = max(int(round(max(pa, pb) / min(pa, pb))), 1)
    smooth = _box(y_fast, width)
    keep = slice(width, -width or None)  # the box's edges
    t_fast, smooth = t_fast[keep], smooth[keep]
    sign = -1.0 if a_slow else 1.0       # b late by d: a's sample at s is b's at s + d

    def sse(delay: float) -> float:
        x, inside, _ = interpolate_at(t_fast, smooth, t_slow - sign * delay)
        x, y = x[inside], y_slow[inside]
        design = np.column_stack([x, np.ones_like(x)])
        _, res, *_ = np.linalg.lstsq(design, y, rcond=None)
        return float(res[0]) / x.size if res.size else float('inf')

    result = minimize_scalar(sse, bounds=(guess - half_width, guess + half_width), method='bounded',
                             options={'xatol': 1e-6})
    return float(result.x)


def correct_stamps(stamps_s: ArrayLike | Iterable[float], delay_s: float) -> NDArray[np.float64]:
    """Stamps of the delayed stream moved to the instants their samples were taken: ``stamps − delay`` [s]."""
    if not np.isfinite(delay_s):
        raise ParameterError('delay_s', delay_s, 'must be finite [s]')
    return np.asarray(stamps_s, dtype=float) - float(delay_s)
