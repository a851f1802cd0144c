"""Pairing by nearest stamps: :class:`ApproximateTimeSync` (streaming) and :func:`pair_by_stamp` (whole recorded
streams, numpy), side by side; ``test/estimation/test_sync.py`` pins them together."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from crane_stiffness.estimation.errors import ParameterError
from crane_stiffness.estimation.sync.base import (Pair, _admitted, left_ranks,
                                                  _Stream, _SyncBase)

class ApproximateTimeSync(_SyncBase):
    """Pairs the ``'force'`` and ``'displacement'`` streams by approximate stamp (see the module docstring).

    Example::

        sync = ApproximateTimeSync(slop=1e-4, expected_period=2e-4)
        for pair in sync.push('force', 0.0102, wrench):
            estimator.add(pair.stamp_s, pair.force[1], pair.displacement)
    """

    def __init__(self, slop: float, *, max_age: float = 0.5,
                 expected_period: float | Mapping[str, float] | None = None,
                 dropout_factor: float | None = 3.0, max_queue: int = 100_000) -> None:
        """Create the synchroniser.

        Args:
            slop: Largest stamp difference of a pair, s, ≥ 0.
            max_age: Staleness limit and latency bound, s, ≥ slop.
            expected_period: Sample period of the streams, s, > 0: one value for both or a mapping per stream
                name. None: estimated online from the gaps.
            dropout_factor: A gap larger than this many periods counts as a dropout, > 1; None disables.
            max_queue: Cap on queued samples per stream (oldest discarded as unmatched), ≥ 1.
        """
        slop = float(slop)
        if not (math.isfinite(slop) and slop >= 0.0):
            raise ParameterError('slop', slop, 'must be finite and >= 0 (seconds)')
        self._slop = slop
        super().__init__(max_age=max_age, expected_period=expected_period, dropout_factor=dropout_factor,
                         max_queue=max_queue, min_age=slop, min_age_name='slop')

    def _take(self, i: int, own: _Stream, stamp_s: float, value: Any) -> list[Pair]:
        self._enqueue(own, stamp_s, value)
        return self._match(flush=False)

    def flush(self) -> list[Pair]:
        """Emit every pair still possible without waiting for more samples, then drop what cannot pair.

        For the end of an offline run; the synchroniser can keep receiving afterwards.
        """
        pairs = self._match(flush=True)
        for stream in self._streams:
            stream.counters.unmatched += len(stream.queue)
            stream.queue.clear()
        return pairs

    def _match(self, flush: bool) -> list[Pair]:
        pairs: list[Pair] = []
        fs, ds = self._streams
        fq, dq = fs.queue, ds.queue
        slop = self._slop
        while fq and dq:
            tf = fq[0][0]
            td = dq[0][0]
            if tf < td - slop:  # later displacements are later still: no partner can come
                fq.popleft()
                fs.counters.unmatched += 1
                continue
            if td < tf - slop:
                dq.popleft()
                ds.counters.unmatched += 1
                continue
            # Within slop. The later head's nearest partner is the earlier head (queues are sorted); pair if the
            # earlier head is also the later head's nearest, i.e. the next sample on the earlier head's stream
            # is not closer.
            if tf <= td:
                decision = self._earlier_is_nearest(fs, td, td - tf, flush)
            else:
                decision = self._earlier_is_nearest(ds, tf, tf - td, flush)
            if decision is None:
                break  # wait for the next sample on the earlier head's stream
            if not decision:
                continue  # the earlier head was dropped as dominated
            f_stamp, f_value = fq.popleft()
            d_stamp, d_value = dq.popleft()
            pairs.append(Pair(f_stamp, f_value, d_stamp, d_value))
        if pairs:
            self._counters.pairs += len(pairs)
            fs.counters.paired += len(pairs)
            ds.counters.paired += len(pairs)
        self._discard_unpairable(fs, ds)
        self._discard_unpairable(ds, fs)
        return pairs

    def _earlier_is_nearest(self, earlier: _Stream, later_stamp: float, distance: float,
                            flush: bool) -> bool | None:
        """True: pair the heads. False: the earlier head was dominated and dropped. None: undecided yet."""
        queue = earlier.queue
        if len(queue) > 1:
            if abs(queue[1][0] - later_stamp) < distance:
                # The next sample is closer to the later head, and to every later sample too: drop this one.
                queue.popleft()
                earlier.counters.unmatched += 1
                return False
            return True
        # No next sample yet; every future stamp is >= earlier.last.
        if flush or earlier.last - later_stamp >= distance:
            return True
        if self._streams[0] is earlier:
            newest_other = self._streams[1].last
        else:
            newest_other = self._streams[0].last
        if newest_other - queue[0][0] > self._max_age:
            return True  # waited long enough: bound the latency
        return None

    def _discard_unpairable(self, own: _Stream, other: _Stream) -> None:
        """Drop queued samples of ``own`` that no current or future sample of ``other`` can pair with."""
        queue = own.queue
        if not queue:
            return
        # A partner would need a stamp >= head - slop; future stamps of other are >= other.last, and ones more
        # than max_age behind own.last are stale on arrival.
        limit = own.last - self._max_age - self._slop
        if not other.queue:
            limit = max(limit, other.last - self._slop)
        while queue and queue[0][0] < limit:
            queue.popleft()
            own.counters.unmatched += 1


def _nearest(a: np.ndarray, b: np.ndarray, j: np.ndarray | None = None) -> np.ndarray:
    """Index of the nearest element of sorted ``b`` for each of ``a``; ties go to the earlier (lower) index.
    ``j``: ``np.searchsorted(b, a, 'left')`` if known."""
    if j is None:
        j = np.searchsorted(b, a, side='left')  # b[j - 1] < a <= b[j]
    padded = np.concatenate([[-np.inf], b, [np.inf]])  # padded[j] = b[j - 1], padded[j + 1] = b[j]
    pick = np.where(padded[j + 1] - a < a - padded[j], j, j - 1)
    if b.size > 1 and not (np.diff(b) > 0).all():
        pick = np.searchsorted(b, b[pick], side='left')  # the first of equal stamps
    return pick


@dataclass
class PairResult:
    """Indices of paired samples (into the arrays given) and the counters of the live synchroniser."""

    force_index: np.ndarray
    displacement_index: np.ndarray
    counters: dict[str, int]


def _match_known(sync: ApproximateTimeSync, force: list[float], displacement: list[float]) -> list[tuple[int, int]]:
    """``sync``'s matching of two short sorted stamp lists whose samples are all known (as at a flush), from empty
    queues: (force index, displacement index) of each pair."""
    fs, ds = sync._streams
    fs.queue.clear()
    ds.queue.clear()
    fs.queue.extend(zip(force, range(len(force))))
    ds.queue.extend(zip(displacement, range(len(displacement))))
    return [(p.force, p.displacement) for p in sync._match(flush=True)]


def pair_by_stamp(force_stamp: np.ndarray, force_log: np.ndarray, disp_stamp: np.ndarray, disp_log: np.ndarray,
                  slop: float, max_age: float) -> PairResult:
    """Pair two streams exactly as :class:`ApproximateTimeSync`, vectorized.

    Inputs are in arrival order (log time ascending) and already passed the input checks. Out-of-order samples
    (older than an earlier stamp of their stream) and stale ones (see :func:`_stale`) are dropped. Of the rest:

    1. mutual nearest neighbours within ``slop`` (ties to the earlier sample), found with ``np.searchsorted`` over
       the whole arrays. Every such pair is also a pair of the synchroniser, and when it forms, everything before
       it on both streams is settled: each is a point where the synchroniser's state is known.
    2. Between two consecutive such pairs the synchroniser's own matching rule is replayed on the few samples left
       over (none at all when both sensors sample on one clock, as on the rig; a handful around a dropout).

    The synchroniser's latency bound for a stalled stream (waiting at most ``max_age``) is not modelled: it matters
    only when a stream stops for longer than ``max_age``. The last pair is included even though the live
    synchroniser emits it only when a later sample arrives.
    """
    f_idx, d_idx, counters = _admitted(force_stamp, force_log, disp_stamp, disp_log, max_age)
    if f_idx.size == 0 or d_idx.size == 0:
        counters.update(pairs=0, force_unmatched=int(f_idx.size), displacement_unmatched=int(d_idx.size),
                        replayed_stretches=0)
        return PairResult(np.zeros(0, np.int64), np.zeros(0, np.int64), counters)
    f = force_stamp[f_idx]
    d = disp_stamp[d_idx]
    if f.size == d.size and np.array_equal(f, d) and (f.size < 2 or bool((np.diff(f) > 0).all())):
        # Both sensors on one clock grid and nothing lost: every sample is its partner's nearest, at 0 s.
        nf = nd = np.arange(f.size)
    else:
        j_f, j_d = left_ranks(f, d)
        nf = _nearest(f, d, j_f)
        nd = _nearest(d, f, j_d)
    mutual = (nd[nf] == np.arange(f.size)) & (np.abs(f - d[nf]) <= slop)
    af = np.flatnonzero(mutual)          # anchors: positions in f and d of the mutual pairs
    ad = nf[mutual]
    # Stretches with samples left over between anchors (and before the first / after the last).
    bf = np.concatenate([[-1], af, [f.size]])
    bd = np.concatenate([[-1], ad, [d.size]])
    gaps = np.flatnonzero((np.diff(bf) > 1) | (np.diff(bd) > 1))
    extra_f: list[int] = []
    extra_d: list[int] = []
    replay = ApproximateTimeSync(slop, max_age=slop)
    for g in gaps.tolist():
        f0, f1 = int(bf[g]) + 1, int(bf[g + 1])  # the stretch, and the closing anchor (if any) at f1/d1
        d0, d1 = int(bd[g]) + 1, int(bd[g + 1])
        fs = f[f0:min(f1 + 1, f.size)].tolist()
        ds = d[d0:min(d1 + 1, d.size)].tolist()
        for i, j in _match_known(replay, fs, ds):
            if f0 + i < f1 and d0 + j < d1:  # the closing anchor pairs as found above
                extra_f.append(f0 + i)
                extra_d.append(d0 + j)
    if extra_f:
        pf = np.concatenate([af, np.asarray(extra_f, dtype=np.int64)])
        pd = np.concatenate([ad, np.asarray(extra_d, dtype=np.int64)])
        order = np.argsort(pf, kind='stable')
        af, ad = pf[order], pd[order]
    fi = f_idx[af]
    di = d_idx[ad]
    counters.update(pairs=int(fi.size), force_unmatched=int(f_idx.size - fi.size),
                    displacement_unmatched=int(d_idx.size - fi.size), replayed_stretches=int(gaps.size))
    return PairResult(fi, di, counters)


# ----------------------------------------------------------------------------------------------- interpolated --
