"""The delay between the force and displacement streams' stamps, estimated from the data, live and offline.

A sensor whose stamps run late against the other's (a DAQ that stamps on arrival, a filter) skews the pairs: the
displacement of the loading branch lags its force, the unloading branch leads it, and the two branches part. The
estimator corrects a known delay (``displacement_delay_s``) and estimates what is left from the data with
:func:`~crane_stiffness.estimation.offset.estimate_delay` (cross-correlation of where the load changes), WARNing
above ``max_stream_delay_s``.

Two forms of one rule, pinned together by test_estimator_wiring (``test_stream_delay_*``):

- :class:`StreamDelay`, streaming: the last ``delay_window_s`` of accepted samples, estimated again every quarter
  window while data flows and once when the streams pause; the last trusted estimate is kept through holds.
- :func:`stream_delay_of`, a whole recording: the same estimate over windows of ``delay_window_s`` where the load
  moves most (at most :data:`DELAY_WINDOWS` of them), the median of the trusted ones. A recording no longer than one
  window gives exactly the streaming estimate; an hour costs a few windows, not an FFT over every sample.

Pure Python, no ROS.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from crane_stiffness.estimation.errors import DataError, ParameterError
from crane_stiffness.estimation.inputs import Samples
from crane_stiffness.estimation.offset import DelayEstimate, estimate_delay
from crane_stiffness.estimation.sync import DISPLACEMENT, FORCE
from crane_stiffness.estimation.settings import DELAY_MAX_LAG_S, LiveSettings
from crane_stiffness.contract.status import status_value

#: Windows of a recording the offline estimate looks at (those where the load moves most).
DELAY_WINDOWS = 8


def _delay_problem(settings: LiveSettings, estimate: DelayEstimate | None) -> str:
    """The WARN reason for a trusted delay estimate whose remaining (uncorrected) part exceeds max_stream_delay_s,
    else ''. ``estimate`` is of the corrected stamps: what displacement_delay_s has not removed."""
    if estimate is None or not estimate.ok or abs(estimate.delay_s) <= settings.max_stream_delay_s:
        return ''
    total = estimate.delay_s + settings.displacement_delay_s
    return (f'displacement stamps {estimate.delay_s * 1e3:+.3g} ms late against force after correction (estimated '
            f'from the data, peak correlation {estimate.peak_correlation:.2f}) > max_stream_delay_s '
            f'{settings.max_stream_delay_s * 1e3:g} ms: loading and unloading are skewed; set displacement_delay_s '
            f'= {total:.6g}')


def _delay_values(settings: LiveSettings, estimate: DelayEstimate | None, attempt: DelayEstimate | None,
                  note: str) -> list[tuple[str, str]]:
    nan = math.nan
    residual = estimate.delay_s if estimate is not None else nan
    return [('stream_delay_s', status_value(residual + settings.displacement_delay_s)),
            ('stream_delay_residual_s', status_value(residual)),
            ('displacement_delay_s', status_value(settings.displacement_delay_s)),
            ('stream_delay_ok', str(estimate is not None and not _delay_problem(settings, estimate)).lower()),
            ('stream_delay_peak_correlation', status_value(estimate.peak_correlation if estimate is not None else nan)),
            ('stream_delay_note', note or (attempt.reason if attempt is not None else 'not estimated yet'))]


class StreamDelay:
    """The delay of the displacement stream's stamps against the force stream's, estimated live from the last
    ``delay_window_s`` of accepted samples (stamps already corrected by ``displacement_delay_s``) with
    :func:`~crane_stiffness.estimation.offset.estimate_delay`. :meth:`update` (from the slow timer) estimates again
    when there is new data: every quarter window while data flows, and once when the streams pause (the end of a
    load change). The last trusted estimate (``ok``: load changes to correlate) is kept through holds. The vectorised
    form over a whole recording is :func:`stream_delay_of`."""

    def __init__(self, settings: LiveSettings) -> None:
        self.settings = settings
        self.enabled = settings.delay_window_s > 0.0
        self._data: dict[str, deque[tuple[float, float]]] = {FORCE: deque(), DISPLACEMENT: deque()}  # (stamp, value)
        self._new = 0                # samples since the last estimate
        self._new_at_update = -1     # _new at the previous update: unchanged = the streams pause
        self._last_newest = -math.inf
        self.estimate: DelayEstimate | None = None   # last trusted estimate (ok)
        self.attempt: DelayEstimate | None = None    # last estimate made, trusted or not
        self.note = ''
        self.runs = 0

    def add(self, stream: str, stamp_s: float, value: float) -> None:
        """An accepted sample (stamp corrected, s; value in its unit): kept while within the window."""
        if not self.enabled:
            return
        q = self._data[stream]
        if q and stamp_s <= q[-1][0]:
            return  # out of order: the pairing counts it; the correlation needs increasing stamps
        q.append((stamp_s, value))
        horizon = stamp_s - self.settings.delay_window_s
        while q[0][0] < horizon:
            q.popleft()
        self._new += 1

    def update(self) -> DelayEstimate | None:
        """Estimate again if it is time (see the class docstring); returns the new estimate or None."""
        if not self.enabled or self._new == 0:
            return None
        f, d = self._data[FORCE], self._data[DISPLACEMENT]
        if not f or not d:
            return None
        newest = min(f[-1][0], d[-1][0])
        if newest - max(f[0][0], d[0][0]) < 4 * DELAY_MAX_LAG_S:
            return None  # too little overlap yet to search ±DELAY_MAX_LAG_S
        paused = self._new == self._new_at_update
        self._new_at_update = self._new
        if not paused and newest - self._last_newest < max(self.settings.delay_window_s / 4.0, 0.5):
            return None
        self._last_newest = newest
        self._new, self._new_at_update = 0, -1
        tf, yf = np.array(f).T
        td, yd = np.array(d).T
        try:
            result = estimate_delay(tf, yf, td, yd, max_lag_s=DELAY_MAX_LAG_S)
        except (DataError, ParameterError) as exc:
            self.note = f'not estimated: {exc}'
            return None
        self.runs += 1
        self.attempt = result
        self.note = ''
        if result.ok:
            self.estimate = result
        return result

    def problem(self) -> str:
        return _delay_problem(self.settings, self.estimate)

    def values(self) -> list[tuple[str, str]]:
        if not self.enabled:
            return [('stream_delay_note', 'not estimated (delay_window_s = 0)'),
                    ('displacement_delay_s', status_value(self.settings.displacement_delay_s))]
        return _delay_values(self.settings, self.estimate, self.attempt, self.note)


def _increasing(stamp: np.ndarray) -> np.ndarray:
    """Samples stamped after every earlier one (those :meth:`StreamDelay.add` keeps)."""
    if stamp.size == 0:
        return np.zeros(0, bool)
    before = np.maximum.accumulate(np.concatenate([[-np.inf], stamp[:-1]]))
    return stamp > before


def moving_windows(stamp: np.ndarray, value: np.ndarray, window_s: float, count: int) -> list[tuple[float, float]]:
    """The ``count`` windows ``[start, start + window_s)`` of consecutive windows over ``stamp`` [s] (increasing)
    in which ``value`` varies most (its standard deviation: a ramp or a step, not a hold's noise), in time order.
    One window holding everything, (−inf, inf), when the recording is no longer than ``window_s``."""
    if stamp.size == 0:
        return []
    if stamp[-1] - stamp[0] <= window_s:
        return [(-math.inf, math.inf)]  # all of it, as the streaming form holds it
    index = np.floor((stamp - stamp[0]) / window_s).astype(np.int64)
    n = int(index[-1]) + 1
    counts = np.bincount(index, minlength=n).astype(float)
    centred = value - value.mean()
    sums = np.bincount(index, centred, minlength=n)
    squares = np.bincount(index, centred * centred, minlength=n)
    with np.errstate(invalid='ignore', divide='ignore'):
        spread = np.where(counts > 1, squares / counts - (sums / counts) ** 2, -1.0)
    chosen = np.sort(np.argsort(-spread, kind='stable')[:count])
    return [(float(stamp[0] + k * window_s), float(stamp[0] + (k + 1) * window_s)) for k in chosen if spread[k] > 0]


def stream_delay_of(settings: LiveSettings, force: Samples, displacement: Samples
                    ) -> tuple[DelayEstimate | None, str, list[tuple[str, str]]]:
    """The delay between the streams over a whole recording (the vectorised form of :class:`StreamDelay`; samples
    that passed the input checks, displacement stamps already corrected by ``displacement_delay_s``): (the
    estimate or None, the WARN reason or '', the key/values the live input status reports).

    Estimated in the :data:`DELAY_WINDOWS` windows of ``delay_window_s`` where the force moves most
    (:func:`moving_windows`), each as the streaming form does; the estimate is the trusted window estimate with the
    median delay (all of its fields from that window), or the first window's reason why none could be trusted."""
    if settings.delay_window_s <= 0.0:
        return None, '', [('stream_delay_note', 'not estimated (delay_window_s = 0)'),
                          ('displacement_delay_s', status_value(settings.displacement_delay_s))]
    fi, di = _increasing(force.stamp), _increasing(displacement.stamp)
    tf, yf = force.stamp[fi], np.asarray(force.value[fi], dtype=float)
    td, yd = displacement.stamp[di], np.asarray(displacement.value[di], dtype=float)
    attempts: list[DelayEstimate] = []
    note = ''
    for start, end in moving_windows(tf, yf, settings.delay_window_s, DELAY_WINDOWS):
        a = slice(*np.searchsorted(tf, [start, end], side='right'))
        b = slice(*np.searchsorted(td, [start, end], side='right'))
        try:
            attempts.append(estimate_delay(tf[a], yf[a], td[b], yd[b], max_lag_s=DELAY_MAX_LAG_S))
        except (DataError, ParameterError) as exc:
            note = note or f'not estimated: {exc}'
    if not attempts and not note:
        note = 'not estimated: no force samples'
    trusted = sorted((e for e in attempts if e.ok), key=lambda e: e.delay_s)
    estimate = trusted[(len(trusted) - 1) // 2] if trusted else None
    attempt = estimate if estimate is not None else (attempts[0] if attempts else None)
    return estimate, _delay_problem(settings, estimate), _delay_values(settings, estimate, attempt,
                                                                        '' if attempt is not None else note)
