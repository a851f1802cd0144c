"""Interpolated pairing: :class:`InterpolatingSync` (streaming) and :func:`pair_by_interpolation` (whole recorded
streams, numpy), side by side; the tests pin them together."""
from __future__ import annotations

import bisect
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from crane_stiffness.estimation.errors import ParameterError
from crane_stiffness.estimation.sync.base import (FORCE, STREAMS, Pair, _admitted,
                                                  _Stream, _SyncBase)

class InterpolatingSync(_SyncBase):
    """Pairs each sample of the slower stream with the faster stream linearly interpolated at its stamp.

    Two drivers at different rates (a 1 kHz F/T sensor, a 100 Hz Modbus LVDT) rarely stamp the same instant: the
    nearest fast sample is up to half its period away from the slow sample, on a ramp a force error of half a
    period's load change. Here each *slow* sample (stamp ``t``) is paired with the *fast* stream ``fast``
    interpolated at ``t`` between its two samples ``t0 < t <= t1`` (consecutive admitted samples); the pair's
    stamps are both ``t``. The admission rule is :class:`ApproximateTimeSync`'s (non-finite, out of order, stale,
    dropouts), so is the accounting (``received = paired + out_of_order + non_finite + stale + unmatched +
    discarded + pending`` per stream). Counted as unmatched: a slow sample with no fast sample before it, one whose
    bracket is more than ``max_gap`` wide (a dropout of the fast stream: nothing is invented across it), one that
    waited for a later fast sample while its own stream went ``max_age`` further (the fast stream stalled). A fast
    sample counts as paired once it has been one end of a pair's bracket (it may serve several pairs), as unmatched
    if it was kept and never served; it is kept while a non-stale slow sample could still need it (``pending``).

    :func:`pair_by_interpolation` is the same over whole recorded streams (numpy); the tests pin the two together.

    Example::

        sync = InterpolatingSync('force', max_gap=0.005, max_age=0.1)   # 1 kHz force, 100 Hz LVDT
        for pair in sync.push('displacement', 0.0103, 2.1e-5):
            estimator.add(pair.stamp_s, pair.force, pair.displacement)
    """

    def __init__(self, fast: str, *, max_gap: float, max_age: float = 0.5,
                 expected_period: float | Mapping[str, float] | None = None,
                 dropout_factor: float | None = 3.0, max_queue: int = 100_000) -> None:
        """Create the synchroniser.

        Args:
            fast: The stream interpolated: ``'force'`` or ``'displacement'`` (the faster one).
            max_gap: Widest bracket of fast samples interpolated across, s, > 0.
            max_age: Staleness limit and latency bound, s, > 0.
            expected_period, dropout_factor, max_queue: As for :class:`ApproximateTimeSync`.
        """
        if fast not in STREAMS:
            raise ParameterError('fast', fast, f'must be one of {", ".join(STREAMS)}')
        max_gap = float(max_gap)
        if not (math.isfinite(max_gap) and max_gap > 0.0):
            raise ParameterError('max_gap', max_gap, 'must be finite and > 0 (seconds)')
        self.fast = fast
        self._max_gap = max_gap
        super().__init__(max_age=max_age, expected_period=expected_period, dropout_factor=dropout_factor,
                         max_queue=max_queue)
        if not self._max_age > 0.0:
            raise ParameterError('max_age', self._max_age, 'must be > 0 (seconds)')

    def _new_streams(self) -> None:
        super()._new_streams()
        self._fast_i = self._index[self.fast]
        # Fast history as lists from _start on (bisect needs a list; the retired head is cut off now and then). The
        # fast _Stream's queue is not used: pending() of the fast stream is the history's length.
        self._ft: list[float] = []
        self._fy: list[Any] = []
        self._used: list[bool] = []
        self._start = 0

    def pending(self, stream: str) -> int:
        if self._stream_index(stream) == self._fast_i:
            return len(self._ft) - self._start
        return super().pending(stream)

    def restart(self) -> None:
        fast = self._streams[self._fast_i].counters
        used = sum(self._used[self._start:])
        fast.paired += used
        fast.discarded += len(self._ft) - self._start - used
        super().restart()

    def _take(self, i: int, own: _Stream, stamp_s: float, value: Any) -> list[Pair]:
        # A slow sample waits for a fast one at or after its stamp; a fast one may complete waiting slow samples.
        if i == self._fast_i:
            self._ft.append(stamp_s)
            self._fy.append(value)
            self._used.append(False)
            pairs = self._drain()
            self._retire(stamp_s)
            return pairs
        self._enqueue(own, stamp_s, value)
        return self._drain()

    def flush(self) -> list[Pair]:
        """The streams ended: slow samples still waiting for a later fast sample cannot be bracketed (unmatched)."""
        slow = self._streams[1 - self._fast_i]
        slow.counters.unmatched += len(slow.queue)
        slow.queue.clear()
        return []

    def _drain(self) -> list[Pair]:
        slow = self._streams[1 - self._fast_i]
        queue, counters = slow.queue, slow.counters
        ft, fy, used, lo = self._ft, self._fy, self._used, self._start
        pairs: list[Pair] = []
        force_fast = self._fast_i == 0
        while queue and len(ft) > lo and queue[0][0] <= ft[-1]:
            t, value = queue.popleft()
            j = bisect.bisect_left(ft, t, lo)  # ft[j-1] < t <= ft[j]
            if j == lo or ft[j] - ft[j - 1] > self._max_gap:
                counters.unmatched += 1  # no fast sample before it, or a dropout of the fast stream around it
                continue
            t0, t1 = ft[j - 1], ft[j]
            y0 = fy[j - 1]
            x = y0 + (t - t0) / (t1 - t0) * (fy[j] - y0)
            used[j - 1] = used[j] = True
            pairs.append(Pair(t, x, t, value) if force_fast else Pair(t, value, t, x))
        # The latency bound: a slow sample that waited while its own stream went max_age further (the fast stream
        # stalled) is given up.
        while queue and queue[0][0] < slow.last - self._max_age:
            queue.popleft()
            counters.unmatched += 1
        if pairs:
            self._counters.pairs += len(pairs)
            counters.paired += len(pairs)
        return pairs

    def _retire(self, newest: float) -> None:
        """Drop fast samples no admissible slow sample can need: a slow sample stamped before ``newest − max_age``
        is stale, so only the samples from there on and the one before them are kept."""
        ft, used = self._ft, self._used
        fast = self._streams[self._fast_i].counters
        limit = newest - self._max_age
        lo = self._start
        while len(ft) - lo > 2 and (ft[lo + 1] < limit or len(ft) - lo > self._max_queue):
            if used[lo]:
                fast.paired += 1
            else:
                fast.unmatched += 1
            lo += 1
        self._start = lo
        if lo > 4096 and lo > len(ft) // 2:
            del ft[:lo], self._fy[:lo], used[:lo]
            self._start = 0


@dataclass
class InterpolationResult:
    """Pairs found by :func:`pair_by_interpolation`: per pair the slow sample's index (into the slow arrays given),
    the right-hand fast sample of its bracket (its index; the pair can form once it has arrived), the stamp [s]
    and the interpolated fast value; and the counters of :class:`InterpolatingSync` (out of order, stale, slow
    samples unmatched)."""

    slow_index: np.ndarray
    fast_index: np.ndarray
    stamp: np.ndarray
    fast_value: np.ndarray
    counters: dict[str, int]


def pair_by_interpolation(force_stamp: np.ndarray, force_log: np.ndarray, disp_stamp: np.ndarray,
                          disp_log: np.ndarray, fast: str, fast_value: np.ndarray, max_gap: float,
                          max_age: float) -> InterpolationResult:
    """Pair two streams exactly as :class:`InterpolatingSync`, vectorized.

    Inputs are in arrival order (log time ascending) and already passed the input checks; ``fast_value`` holds the
    values of the ``fast`` stream (shape (n,) or (n, k)). Out-of-order and stale samples are dropped as the
    synchroniser drops them; each remaining slow sample at ``t`` pairs with the fast samples ``t0 < t <= t1``
    around it (``np.searchsorted``) when ``t1 − t0 <= max_gap``. The synchroniser's latency bound for a stalled
    fast stream is not modelled (it matters only when the fast stream stops for longer than ``max_age``), and a
    slow sample after the last fast one is left out, as it is still waiting live.
    """
    if fast not in STREAMS:
        raise ParameterError('fast', fast, f'must be one of {", ".join(STREAMS)}')
    f_idx, d_idx, counters = _admitted(force_stamp, force_log, disp_stamp, disp_log, max_age)
    fast_idx, slow_idx = (f_idx, d_idx) if fast == FORCE else (d_idx, f_idx)
    fast_stamp, slow_stamp = (force_stamp, disp_stamp) if fast == FORCE else (disp_stamp, force_stamp)
    tf = fast_stamp[fast_idx]
    ts = slow_stamp[slow_idx]
    j = np.searchsorted(tf, ts, side='left')  # tf[j-1] < ts <= tf[j]
    inside = (j >= 1) & (j < tf.size)
    jc = np.clip(j, 1, max(tf.size - 1, 1))
    if tf.size >= 2:
        t0, t1 = tf[jc - 1], tf[jc]
        ok = inside & (t1 - t0 <= max_gap)
    else:
        ok = np.zeros(ts.size, bool)
    keep = np.flatnonzero(ok)
    jk = jc[keep]
    y = np.asarray(fast_value, dtype=float)[fast_idx]
    t0, t1 = tf[jk - 1], tf[jk]
    w = (ts[keep] - t0) / (t1 - t0)
    y0, y1 = y[jk - 1], y[jk]
    x = y0 + (w if y.ndim == 1 else w[:, None]) * (y1 - y0)
    waiting = int(np.count_nonzero(j >= tf.size))
    slow = 'displacement' if fast == FORCE else 'force'
    counters.update(pairs=int(keep.size), **{f'{slow}_unmatched': int(ts.size - keep.size - waiting),
                                            f'{slow}_waiting': waiting})
    return InterpolationResult(slow_idx[keep], fast_idx[jk], ts[keep], x, counters)
