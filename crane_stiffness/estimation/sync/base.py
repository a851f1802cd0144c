"""What both pairing rules share: the stream names, a pair, the counters, the streaming base class (admission: out of
order, non-finite, stale; dropouts; the accounting) and the vectorised admission rule beside it."""
from __future__ import annotations

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


# ------------------------------------------------------------------------------------------------ vectorized --
def _in_order(stamp: np.ndarray) -> np.ndarray:
    """True where a stamp is not older than every stamp before it (arrival order), as ApproximateTimeSync."""
    ok = np.ones(stamp.size, bool)
    if stamp.size > 1:
        ok[1:] = stamp[1:] >= np.maximum.accumulate(stamp)[:-1]
    return ok


def left_ranks(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(np.searchsorted(b, a, 'left'), np.searchsorted(a, b, 'left'))`` of two ascending arrays, with one binary
    search: the number of ``b`` below each ``a`` and of ``a`` below each ``b`` (the second from the first by
    counting, O(n); the rig's streams hold millions of samples)."""
    unique_b = bool(b.size) and bool((np.diff(b) > 0).all())
    below_a = np.searchsorted(b, a, side='left')                 # #{b < a[i]}
    if unique_b and a.size:
        hit = below_a < b.size
        equal = np.zeros(a.size, np.int64)
        equal[hit] = b[below_a[hit]] == a[hit]
        not_above = below_a + equal                              # #{b <= a[i]} (b's values are unique)
        # a[i] < b[k] exactly when #{b <= a[i]} <= k: count the a's per value of not_above, cumulatively.
        below_b = np.cumsum(np.bincount(not_above, minlength=b.size + 1))[:b.size]
    else:
        below_b = np.searchsorted(a, b, side='left')
    return below_a, below_b


def _stale_both(force_stamp: np.ndarray, force_log: np.ndarray, disp_stamp: np.ndarray, disp_log: np.ndarray,
                max_age: float) -> tuple[np.ndarray, np.ndarray]:
    """For each stream, True where a sample is older than the other stream's newest stamp at its arrival by more
    than max_age."""
    f_at, d_at = left_ranks(force_log, disp_log)  # how many of the other stream had arrived before each sample

    def stale(stamp: np.ndarray, other_stamp: np.ndarray, arrived: np.ndarray) -> np.ndarray:
        if other_stamp.size == 0:
            return np.zeros(stamp.size, bool)
        newest = np.concatenate([[-np.inf], np.maximum.accumulate(other_stamp)])
        return stamp < newest[arrived] - max_age

    return stale(force_stamp, disp_stamp, f_at), stale(disp_stamp, force_stamp, d_at)


def _admitted(force_stamp: np.ndarray, force_log: np.ndarray, disp_stamp: np.ndarray, disp_log: np.ndarray,
              max_age: float) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """The vectorised form of ``_SyncBase._admit`` for inputs that passed the input checks: indices of the samples
    admitted per stream (in order, not stale) and the out-of-order and stale counts."""
    f_ok = _in_order(force_stamp)
    d_ok = _in_order(disp_stamp)
    f_stale, d_stale = _stale_both(force_stamp, force_log, disp_stamp, disp_log, max_age)
    f_stale &= f_ok
    d_stale &= d_ok
    counters = {'force_out_of_order': int((~f_ok).sum()), 'displacement_out_of_order': int((~d_ok).sum()),
                'force_stale': int(f_stale.sum()), 'displacement_stale': int(d_stale.sum())}
    return np.flatnonzero(f_ok & ~f_stale), np.flatnonzero(d_ok & ~d_stale), counters
