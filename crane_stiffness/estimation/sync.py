"""Approximate time pairing of the force and displacement streams by their header stamps.

A small stand-in for ``message_filters.ApproximateTimeSynchronizer`` (not available here) for exactly two streams,
``'force'`` and ``'displacement'``. Samples are ``(stamp_s, value)`` with the stamp in seconds (header time, not
arrival time) and the value a float or an array of floats (e.g. a wrench [fx, fy, fz, mx, my, mz] in N and N·m),
checked for NaN/Inf; any other object (a message, a label) is passed through unchecked.

Pairing rule: two samples are paired when their stamps differ by at most ``slop`` and each is the other's nearest
remaining sample (mutual nearest neighbours); each sample is used at most once and pairs come out in stamp order.
Deciding "nearest" may need the next sample of a stream, so a pair is usually emitted one sample period late; a
pair whose next sample never comes is emitted once the other stream is ``max_age`` ahead, or by :meth:`flush`.

Bookkeeping per stream (see :class:`StreamCounters`):

- out of order: a stamp older than the last accepted stamp of its stream (equal stamps are accepted); dropped.
- non-finite: a NaN/Inf stamp or value; dropped (a NaN value still counts as a sample for dropout detection).
- stale: a stamp older than the newest stamp of the other stream by more than ``max_age``; dropped. A queued sample
  that falls that far behind its own stream can no longer be paired and is dropped as unmatched.
- dropout: a gap between consecutive stamps larger than ``dropout_factor`` times the expected period (given, or
  estimated online from the gaps); the sample itself is kept.
- unmatched: a sample discarded because no partner within ``slop`` can exist.
- discarded: a sample still queued when the pairing restarted (:meth:`ApproximateTimeSync.restart`).

Every sample pushed is accounted: received = paired + out_of_order + non_finite + stale + unmatched + discarded +
pending (dropouts are flagged, not dropped).

Every push is amortised O(1) (deques, each sample enters and leaves once).

:func:`pair_by_stamp` is the same pairing over whole recorded streams at once (numpy), for the offline analysis of a
session: it finds the pairs and the out-of-order and stale counts :class:`ApproximateTimeSync` would, given the
samples in their order of arrival.

Interpolated pairing (:class:`InterpolatingSync`, vectorised :func:`pair_by_interpolation`) is the other rule, for
streams at different rates: each sample of the slower stream paired with the faster stream linearly interpolated at
its stamp; the same admission rule and accounting.
"""
from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from crane_stiffness.estimation.errors import ParameterError, SyncError

FORCE = 'force'
DISPLACEMENT = 'displacement'
STREAMS = (FORCE, DISPLACEMENT)

# Weight of a new gap in the running estimate of a stream's period when none is given.
_PERIOD_EMA_ALPHA = 0.01


@dataclass(frozen=True, slots=True)
class Pair:
    """A force sample and a displacement sample whose stamps differ by at most ``slop``."""

    force_stamp_s: float
    force: Any
    displacement_stamp_s: float
    displacement: Any

    @property
    def stamp_s(self) -> float:
        """Mean of the two stamps, s."""
        return pair_stamp(self.force_stamp_s, self.displacement_stamp_s)


def pair_stamp(force_stamp_s: Any, displacement_stamp_s: Any) -> Any:
    """Stamp of a pair, s: the mean of its two stamps (floats, or element-wise arrays)."""
    return 0.5 * (force_stamp_s + displacement_stamp_s)


@dataclass(slots=True)
class StreamCounters:
    """Counters of one stream (module docstring gives the definitions)."""

    received: int = 0
    paired: int = 0
    out_of_order: int = 0
    non_finite: int = 0
    stale: int = 0
    dropouts: int = 0
    unmatched: int = 0
    discarded: int = 0


@dataclass(slots=True)
class SyncCounters:
    """Counters of both streams and the number of pairs emitted."""

    pairs: int = 0
    force: StreamCounters = field(default_factory=StreamCounters)
    displacement: StreamCounters = field(default_factory=StreamCounters)

    def total(self, name: str) -> int:
        """Sum of counter ``name`` (e.g. ``'stale'``) over both streams."""
        return int(getattr(self.force, name) + getattr(self.displacement, name))


def _is_finite(value: Any) -> bool:
    """False for a number or numeric array holding NaN/Inf; other objects are not checked."""
    if isinstance(value, (float, int)):
        return math.isfinite(value)
    try:
        return bool(np.isfinite(np.asarray(value, dtype=float)).all())
    except (TypeError, ValueError):
        return True


class _Stream:
    """Queue and timing state of one stream."""

    __slots__ = ('queue', 'last', 'period', 'period_fixed', 'counters')

    def __init__(self, period: float | None, counters: StreamCounters) -> None:
        self.queue: deque[tuple[float, Any]] = deque()
        self.last = -math.inf  # newest in-order stamp: a lower bound of every future stamp
        self.period = period
        self.period_fixed = period is not None
        self.counters = counters


class _SyncBase:
    """What both pairings share: the streams' timing state, the counters and the admission rule of a sample
    (non-finite, out of order, stale; dropouts counted)."""

    def __init__(self, *, max_age: float, expected_period: float | Mapping[str, float] | None,
                 dropout_factor: float | None, max_queue: int, min_age: float = 0.0, min_age_name: str = '') -> None:
        max_age = float(max_age)
        if not (math.isfinite(max_age) and max_age >= min_age):
            rule = f'>= {min_age_name} = {min_age}' if min_age_name else '>= 0'
            raise ParameterError('max_age', max_age, f'must be finite and {rule} (seconds)')
        if dropout_factor is not None:
            dropout_factor = float(dropout_factor)
            if not (math.isfinite(dropout_factor) and dropout_factor > 1.0):
                raise ParameterError('dropout_factor', dropout_factor, 'must be finite and > 1, or None')
        if isinstance(max_queue, bool) or not isinstance(max_queue, int) or max_queue < 1:
            raise ParameterError('max_queue', max_queue, 'must be an integer >= 1')
        if expected_period is None or isinstance(expected_period, Mapping):
            periods = dict(expected_period or {})
            unknown = set(periods) - set(STREAMS)
            if unknown:
                raise ParameterError('expected_period', periods, f'keys must be among {", ".join(STREAMS)}')
        else:
            periods = {name: expected_period for name in STREAMS}
        for name, period in periods.items():
            if period is not None and not (math.isfinite(float(period)) and float(period) > 0.0):
                raise ParameterError(f'expected_period[{name}]', period, 'must be finite and > 0 (seconds)')
        self._max_age = max_age
        self._dropout_factor = dropout_factor
        self._max_queue = max_queue
        self._periods = {name: (None if periods.get(name) is None else float(periods[name])) for name in STREAMS}
        self._index = {FORCE: 0, DISPLACEMENT: 1}
        self.reset()

    def reset(self) -> None:
        """Empty the queues and zero the counters."""
        self._counters = SyncCounters()
        self._new_streams()

    def _new_streams(self) -> None:
        self._streams = (_Stream(self._periods[FORCE], self._counters.force),
                         _Stream(self._periods[DISPLACEMENT], self._counters.displacement))

    def restart(self) -> None:
        """Start pairing afresh (a new fit segment, a reset): the queued samples are discarded (counted), the
        streams' newest stamps and estimated periods forgotten; the counters go on."""
        for old in self._streams:
            old.counters.discarded += len(old.queue)
        self._new_streams()

    def carry_counters(self, previous: _SyncBase) -> None:
        """Go on counting where ``previous`` (replaced by this one on a settings change) stopped; its queued samples
        count as discarded."""
        previous.restart()
        self._counters = previous._counters
        self._streams[0].counters = self._counters.force
        self._streams[1].counters = self._counters.displacement

    @property
    def counters(self) -> SyncCounters:
        """A snapshot of the counters."""
        c = self._counters
        return SyncCounters(pairs=c.pairs, force=replace(c.force), displacement=replace(c.displacement))

    def pending(self, stream: str) -> int:
        """Samples of ``stream`` held: waiting for a partner (or, interpolated, kept to interpolate between)."""
        return len(self._streams[self._stream_index(stream)].queue)

    def period(self, stream: str) -> float | None:
        """Expected (given or estimated) sample period of ``stream``, s; None before two samples."""
        return self._streams[self._stream_index(stream)].period

    def _stream_index(self, stream: str) -> int:
        try:
            return self._index[stream]
        except KeyError:
            raise SyncError(f'stream = {stream!r}: must be one of {", ".join(STREAMS)}') from None

    def push(self, stream: str, stamp_s: float, value: Any) -> list[Pair]:
        """Add one sample; returns the pairs completed by it (often none, sometimes more than one)."""
        i = self._stream_index(stream)
        own = self._streams[i]
        stamp_s = float(stamp_s)
        if not self._admit(own, self._streams[1 - i], stamp_s, value):
            return []
        return self._take(i, own, stamp_s, value)

    def _take(self, i: int, own: _Stream, stamp_s: float, value: Any) -> list[Pair]:
        """An admitted sample of stream ``i``: queue it, return the pairs it completes (per pairing rule)."""
        raise NotImplementedError

    def _enqueue(self, own: _Stream, stamp_s: float, value: Any) -> None:
        """Queue a sample; past ``max_queue`` the oldest is dropped as unmatched."""
        own.queue.append((stamp_s, value))
        if len(own.queue) > self._max_queue:
            own.queue.popleft()
            own.counters.unmatched += 1

    def _admit(self, own: _Stream, other: _Stream, stamp_s: float, value: Any) -> bool:
        """Count a sample and apply the admission rule (module docstring): False if it is dropped (counted)."""
        counters = own.counters
        counters.received += 1
        if not math.isfinite(stamp_s):
            counters.non_finite += 1
            return False
        if stamp_s < own.last:
            counters.out_of_order += 1
            return False
        if own.last != -math.inf:
            gap = stamp_s - own.last
            if own.period is None:
                own.period = gap if gap > 0.0 else None
            elif self._dropout_factor is not None and gap > self._dropout_factor * own.period:
                counters.dropouts += 1
            elif not own.period_fixed:
                own.period += _PERIOD_EMA_ALPHA * (gap - own.period)
        own.last = stamp_s
        if not _is_finite(value):
            counters.non_finite += 1
            return False
        if stamp_s < other.last - self._max_age:
            counters.stale += 1
            return False
        return True


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


# ------------------------------------------------------------------------------------------------ vectorized --
def _nearest(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Index of the nearest element of sorted ``b`` for each of ``a``; ties go to the earlier (lower) index."""
    j = np.searchsorted(b, a, side='left')  # b[j - 1] < a <= b[j]
    padded = np.concatenate([[-np.inf], b, [np.inf]])  # padded[j] = b[j - 1], padded[j + 1] = b[j]
    pick = np.where(padded[j + 1] - a < a - padded[j], j, j - 1)
    if b.size > 1 and not (np.diff(b) > 0).all():
        pick = np.searchsorted(b, b[pick], side='left')  # the first of equal stamps
    return pick


def _in_order(stamp: np.ndarray) -> np.ndarray:
    """True where a stamp is not older than every stamp before it (arrival order), as ApproximateTimeSync."""
    ok = np.ones(stamp.size, bool)
    if stamp.size > 1:
        ok[1:] = stamp[1:] >= np.maximum.accumulate(stamp)[:-1]
    return ok


def _stale(stamp: np.ndarray, log: np.ndarray, other_stamp: np.ndarray, other_log: np.ndarray,
           max_age: float) -> np.ndarray:
    """True where a sample is older than the other stream's newest stamp at its arrival by more than max_age."""
    if other_stamp.size == 0:
        return np.zeros(stamp.size, bool)
    newest = np.concatenate([[-np.inf], np.maximum.accumulate(other_stamp)])
    return stamp < newest[np.searchsorted(other_log, log, side='left')] - max_age


def _admitted(force_stamp: np.ndarray, force_log: np.ndarray, disp_stamp: np.ndarray, disp_log: np.ndarray,
              max_age: float) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """The vectorised form of ``_SyncBase._admit`` for inputs that passed the input checks: indices of the samples
    admitted per stream (in order, not stale) and the out-of-order and stale counts."""
    f_ok = _in_order(force_stamp)
    d_ok = _in_order(disp_stamp)
    f_stale = _stale(force_stamp, force_log, disp_stamp, disp_log, max_age) & f_ok
    d_stale = _stale(disp_stamp, disp_log, force_stamp, force_log, max_age) & d_ok
    counters = {'force_out_of_order': int((~f_ok).sum()), 'displacement_out_of_order': int((~d_ok).sum()),
                'force_stale': int(f_stale.sum()), 'displacement_stale': int(d_stale.sum())}
    return np.flatnonzero(f_ok & ~f_stale), np.flatnonzero(d_ok & ~d_stale), counters


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
    nf = _nearest(f, d)
    nd = _nearest(d, f)
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
