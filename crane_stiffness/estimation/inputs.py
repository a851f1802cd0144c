"""The inputs of the live estimate before pairing: the checks every sensor sample passes (and their counters) and the
commanded load in effect at a stamp. Each is written for one sample at a time
(:class:`~crane_stiffness.estimation.live.LiveStiffness`) and for whole recorded streams at once (numpy, the offline
analysis of a session); the tests pin the two together.

Input checks (:func:`input_faults`, one definition for both): a sample is dropped when a number in it (its stamp
included) is NaN or Inf, else when its stamp is zero or negative, else when its stamp is ahead of its arrival time
by more than ``max_clock_skew_s`` (a clock skew: a sensor cannot measure the future, and one such stamp would hold
the pairing up until the clock caught up with it, an hour for a stamp an hour ahead), else when its value exceeds the
stream's limit in magnitude (an absurd reading). Each drop is counted under the first check it fails
(:data:`INPUT_CHECKS`). The arrival time is the node's clock when the message arrived (the middleware's reception
stamp) live, and the recorder's log time of the message offline (the nearest thing a bag holds: the recorder runs on
the same clock, a few ms apart). Stamps *behind* the clock are not checked: a late sample (a driver's burst, a
replayed bag) cannot hold the pairing up; it is at worst out of order or stale there.

Commands (:func:`command_inputs`, one definition for both): a command is dropped when its load or a time is NaN or
Inf; it holds from its header stamp, or from its arrival when the header stamp is zero (a publisher that does not
stamp). The load in effect at a stamp is that of the newest command stamped at or before it
(:class:`CommandHold` streaming, :class:`CommandSeries` vectorized). A command is *rejected* when it is absurd by the
shared rule (:mod:`crane_stiffness.contract.command_limits`, the crane model's own check) or when the model republished
it on
/crane/rejected_command: from its stamp until the next accepted command, pairs are not fitted.
"""
from __future__ import annotations

import bisect
from collections import deque
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: The input checks in the order they apply, named as the counters of the samples they drop.
INPUT_CHECKS = ('dropped_non_finite', 'dropped_zero_stamp', 'dropped_clock_skew', 'dropped_absurd')


def input_faults(finite: Any, stamp_s: Any, value: Any, limit: float, arrival_s: Any = math.nan,
                 max_ahead_s: float = math.inf) -> tuple[Any, Any, Any, Any]:
    """The input checks of one sample (a bool and floats) or, element-wise, of arrays of samples.

    Args:
        finite: every number of the sample, its stamp included, is finite.
        stamp_s: header stamp, s.
        value: the reading checked against ``limit`` (N or N·m, m or rad).
        limit: largest plausible magnitude of ``value``.
        arrival_s: when the sample arrived, s, on the clock of the stamps (NaN: unknown, not checked).
        max_ahead_s: largest lead of the stamp over ``arrival_s``, s (the ``max_clock_skew_s`` parameter).

    Returns:
        One flag per check of :data:`INPUT_CHECKS` (bools, or boolean arrays): set where the sample fails that check
        and none before it. A sample with no flag set is kept.
    """
    zero_stamp = finite & (stamp_s <= 0.0)
    stamped = finite & (stamp_s > 0.0)
    skew = stamped & (stamp_s - arrival_s > max_ahead_s)  # False where arrival_s is NaN
    absurd = stamped & (skew ^ True) & (abs(value) > limit)
    return finite ^ True, zero_stamp, skew, absurd  # x ^ True: not x, for a bool and element-wise alike


@dataclass
class InputCounters:
    """Counters of the live estimator's inputs, before pairing (the pairing's own counters are in
    :class:`~crane_stiffness.estimation.sync.SyncCounters`); the checks of :data:`INPUT_CHECKS` count their drops
    in the fields of those names."""

    force_received: int = 0
    displacement_received: int = 0
    command_received: int = 0
    dropped_non_finite: int = 0
    dropped_absurd: int = 0
    dropped_zero_stamp: int = 0
    dropped_clock_skew: int = 0
    dropped_malformed: int = 0
    force_dropped: int = 0          # force messages dropped by any input check (malformed included)
    displacement_dropped: int = 0   # displacement messages dropped by any input check (malformed included)
    command_dropped: int = 0        # NaN/Inf load or time: not used at all
    command_rejected: int = 0       # absurd by crane_stiffness.contract.command_limits: held as rejected
    command_used: int = 0           # held as accepted
    rejected_received: int = 0      # /crane/rejected_command messages (the model's rejections)
    late_rejections: int = 0        # rejected commands that arrived after pairs stamped under them were fitted
    pairs_fitted: int = 0
    pairs_rejected_command: int = 0  # paired while a rejected command was in force: not fitted
    pairs_non_finite: int = 0       # paired but refused by the fit (NaN/Inf; not reached after the input checks)
    fit_restarts: int = 0
    segments: int = 1               # fit segments (a new one at every restart, reset, re-zero or sensor restart)

    @property
    def dropped(self) -> int:
        return (self.dropped_non_finite + self.dropped_absurd + self.dropped_zero_stamp + self.dropped_clock_skew
                + self.dropped_malformed)


@dataclass(frozen=True)
class Samples:
    """The samples of one recorded stream that passed the input checks, in order of arrival."""

    stamp: np.ndarray
    """Header stamps, s."""
    arrival_ns: np.ndarray
    """Arrival (log) times, ns."""
    value: np.ndarray


def checked_samples(stamp_s: np.ndarray, arrival_ns: np.ndarray, value: np.ndarray, finite: np.ndarray,
                    limit: float, max_ahead_s: float = math.inf) -> tuple[Samples, dict[str, int]]:
    """The samples of a recorded stream that pass the input checks (:func:`input_faults`, the arrival being the
    log time ``arrival_ns``), and how many each check dropped (keys :data:`INPUT_CHECKS`)."""
    faults = input_faults(finite, stamp_s, value, limit, np.asarray(arrival_ns) * 1e-9, max_ahead_s)
    keep = ~(faults[0] | faults[1] | faults[2] | faults[3])
    counts = {name: int(failed.sum()) for name, failed in zip(INPUT_CHECKS, faults)}
    return Samples(stamp_s[keep], arrival_ns[keep], value[keep]), counts


def command_inputs(stamp_s: Any, arrival_s: Any, load: Any) -> tuple[Any, Any]:
    """The check and the stamp of one command (floats) or, element-wise, of arrays of commands.

    Returns:
        (usable, stamp): usable when the load and both times are finite; stamp, s, from which the command holds:
        its header stamp, or its arrival where the header stamp is zero.
    """
    usable = np.isfinite(load) & np.isfinite(stamp_s) & np.isfinite(arrival_s)
    return usable, np.where(stamp_s > 0.0, stamp_s, arrival_s)


class CommandHold:
    """The commanded load in effect at a stamp: updates kept in stamp order, read at increasing stamps.

    An update is accepted (``reason`` None) or rejected (``reason`` says why): a rejected command holds, like any
    other, until the next update, and :meth:`entry` reports it. Of updates with equal stamps a rejection comes last
    (the model's rejection of a command stamps it with the command's own stamp), the rest in order of arrival.
    """

    MAX_HELD = 10_000  # commands kept while no pair reads them (100 s at 100 Hz)

    def __init__(self) -> None:
        self._keys: list[tuple[float, int]] = []  # (stamp, 1 if rejected else 0)
        self._loads: list[float] = []
        self._reasons: list[str | None] = []

    def __bool__(self) -> bool:
        return bool(self._keys)

    def add(self, stamp_s: float, load: float, reason: str | None = None, *, from_model: bool = False) -> None:
        """An update from ``stamp_s`` (s): the load (N or N·m; NaN for the model's rejection, which has none) and,
        for a rejected command, the reason; ``from_model``: a rejection by the model (ordered after a command of the
        same stamp)."""
        key = (stamp_s, 1 if from_model else 0)
        i = bisect.bisect_right(self._keys, key)
        self._keys.insert(i, key)
        self._loads.insert(i, load)
        self._reasons.insert(i, reason)
        if len(self._keys) > self.MAX_HELD:
            del self._keys[0], self._loads[0], self._reasons[0]

    def entry(self, stamp_s: float) -> tuple[float, str | None] | None:
        """(load, rejection reason or None) of the newest update stamped at or before ``stamp_s``; None before the
        first one."""
        i = bisect.bisect_right(self._keys, (stamp_s, 2)) - 1  # 2: after both ranks of equal stamps
        if i < 0:
            return None
        if i > 0:  # reads come at increasing stamps: drop what can no longer be in effect
            del self._keys[:i], self._loads[:i], self._reasons[:i]
        return self._loads[0], self._reasons[0]

    def at(self, stamp_s: float) -> float | None:
        """Load of the newest update stamped at or before ``stamp_s``; None before the first one."""
        got = self.entry(stamp_s)
        return None if got is None else got[0]


@dataclass(frozen=True)
class CommandSeries:
    """The usable commands of a recording in stamp order (:class:`CommandHold` for whole streams at once)."""

    stamp: np.ndarray
    """Stamps from which each command holds, s, ascending (commands of equal stamps in order of arrival, a
    rejection last)."""
    value: np.ndarray
    """Commanded loads, N or N·m (NaN for a rejection by the model)."""
    first_arrival_ns: int
    """Arrival (log) time of the first usable command, ns."""
    rejected: np.ndarray | None = None
    """True for a rejected command (absurd, or rejected by the model); None: none is."""
    arrival_ns: np.ndarray | None = None
    """Arrival (log) time of each, ns (known when ``rejected`` is)."""

    @classmethod
    def of(cls, stamp_s: np.ndarray, arrival_ns: np.ndarray, load: np.ndarray, absurd: np.ndarray | None = None,
           rejected_stamp_s: np.ndarray | None = None,
           rejected_arrival_ns: np.ndarray | None = None) -> CommandSeries | None:
        """The usable commands (:func:`command_inputs`) of arrays in order of arrival; None without one.

        ``absurd``: per command, True where :func:`crane_stiffness.contract.command_limits.command_faults` rejects it.
        ``rejected_stamp_s``, ``rejected_arrival_ns``: the model's rejections (/crane/rejected_command)."""
        usable, stamp = command_inputs(stamp_s, arrival_ns * 1e-9, load)
        rej = np.zeros(stamp.shape, bool) if absurd is None else np.asarray(absurd, bool)
        stamp, value, arrival, rej = stamp[usable], np.asarray(load, float)[usable], arrival_ns[usable], rej[usable]
        model = np.zeros(stamp.size, np.int8)  # 1: a rejection by the model
        if rejected_stamp_s is not None and rejected_stamp_s.size:
            assert rejected_arrival_ns is not None  # the model's rejections come with both arrays
            r_ok, r_stamp = command_inputs(rejected_stamp_s, rejected_arrival_ns * 1e-9,
                                           np.zeros(rejected_stamp_s.size))
            n = int(r_ok.sum())
            stamp = np.concatenate([stamp, r_stamp[r_ok]])
            value = np.concatenate([value, np.full(n, np.nan)])
            arrival = np.concatenate([arrival, rejected_arrival_ns[r_ok]])
            rej = np.concatenate([rej, np.ones(n, bool)])
            model = np.concatenate([model, np.ones(n, np.int8)])
        if stamp.size == 0:
            return None
        # Key (stamp, rejected by the model, arrival) as CommandHold orders its updates (the model's rejections of
        # equal stamps last; absurd commands are held as rejected but ordered as commands).
        order = np.lexsort((arrival, model, stamp))
        any_rejected = bool(rej.any())
        return cls(stamp[order], value[order], int(arrival.min()), rej[order] if any_rejected else None,
                   arrival[order] if any_rejected else None)

    def at(self, stamp_s: np.ndarray, arrival_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The load in effect at each stamp for a reader at the given arrival times: (load, held); held is False
        where no command was stamped at or before the stamp, or none had arrived yet (load is then meaningless)."""
        k = np.searchsorted(self.stamp, stamp_s, side='right') - 1
        held = (k >= 0) & (arrival_ns >= self.first_arrival_ns)
        return self.value[np.maximum(k, 0)], held

    def rejected_at(self, stamp_s: np.ndarray, arrival_ns: np.ndarray) -> np.ndarray:
        """True where the command in effect at each stamp is a rejected one that had arrived by the reader's arrival
        time (a rejection the live estimator had not received yet did not stop it fitting)."""
        if self.rejected is None:
            return np.zeros(np.shape(stamp_s), bool)
        assert self.arrival_ns is not None  # known when rejected is (of)
        k = np.searchsorted(self.stamp, stamp_s, side='right') - 1
        kk = np.maximum(k, 0)
        return (k >= 0) & self.rejected[kk] & (self.arrival_ns[kk] <= arrival_ns)


# ------------------------------------------------------------------------------------------ stream health --
#: Gaps between consecutive stamps kept to estimate a stream's sample period (their median).
RECENT_GAPS = 256
# Weight of a new delivery gap in the running estimate of a stream's delivery period.
_DELIVERY_ALPHA = 0.1


def received_fraction(count: int, first_s: float, newest_s: float, period_s: float) -> float:
    """Fraction of a stream's samples that arrived: ``count`` in-order samples against the number its own stamps say
    were sent from ``first_s`` to ``newest_s`` (s) at one per ``period_s`` (s); at most 1, NaN when unknown."""
    if count < 2 or not (period_s > 0.0) or not math.isfinite(newest_s - first_s):
        return math.nan
    expected = round((newest_s - first_s) / period_s) + 1
    return min(1.0, count / expected)


class StreamHealth:
    """Is a sensor stream alive, and how many of its samples arrive (streaming; :func:`stream_health_of` is the
    same over a whole recorded stream).

    Counts the in-order samples (a stamp not older than every earlier one) that passed the input checks, the first
    and newest stamps and the last :data:`RECENT_GAPS` positive gaps between them (their median is the sample period
    unless one is given): :meth:`received_fraction`. Live it also keeps when the newest sample arrived and the
    *delivery* period (a running mean of the gaps between arrivals more than half a sample period apart: the sample
    period, or the burst period of a driver that publishes in bursts): a stream is silent (:meth:`silent_for`) when
    nothing arrived for more than ``dropout_factor`` times the larger of the two.
    """

    def __init__(self, period_s: float | None = None) -> None:
        self.given_period = period_s
        self.count = 0
        self.first = math.nan
        self.newest = math.nan
        self.gaps: deque[float] = deque(maxlen=RECENT_GAPS)
        self.arrival = math.nan     # arrival of the newest sample, s (node clock)
        self.delivery = math.nan    # delivery period, s
        self.sequence: int | None = None  # the publisher's sequence number of the newest sample (None: unknown)
        self._batch_period = math.nan  # period() as of a while ago: a median per sample would cost ~100 µs
        self._since_median = 0

    def add(self, stamp_s: float, arrival_s: float = math.nan) -> None:
        """A sample that passed the input checks, stamped ``stamp_s`` and arrived at ``arrival_s`` (s)."""
        if self.count == 0:
            self.first = self.newest = stamp_s
            self.count = 1
        elif stamp_s >= self.newest:
            gap = stamp_s - self.newest
            if gap > 0.0:
                self.gaps.append(gap)
            self.newest = stamp_s
            self.count += 1
        if math.isfinite(arrival_s):
            if math.isfinite(self.arrival):
                gap = arrival_s - self.arrival
                self._since_median += 1
                if self._since_median >= 64 or math.isnan(self._batch_period):
                    self._batch_period = self.period()
                    self._since_median = 0
                period = self._batch_period
                if gap > 0.5 * (period if math.isfinite(period) else 0.0) and gap > 0.0:
                    self.delivery = gap if math.isnan(self.delivery) else \
                        self.delivery + _DELIVERY_ALPHA * (gap - self.delivery)
            self.arrival = max(arrival_s, self.arrival) if math.isfinite(self.arrival) else arrival_s

    def period(self) -> float:
        """Sample period, s: the given one, else the median of the recent gaps (NaN before two samples)."""
        if self.given_period:
            return self.given_period
        return float(np.median(self.gaps)) if self.gaps else math.nan

    def received_fraction(self) -> float:
        return received_fraction(self.count, self.first, self.newest, self.period())

    def silence_limit(self, dropout_factor: float) -> float:
        """Longest silence that is not a dead stream, s (NaN while unknown or with detection off)."""
        if not dropout_factor:
            return math.nan
        period = self.period()
        if math.isfinite(self.delivery):
            period = max(period, self.delivery) if math.isfinite(period) else self.delivery
        return dropout_factor * period

    def silent_for(self, now_s: float) -> float:
        """Time since the newest sample arrived, s (NaN before the first or without arrival times)."""
        return now_s - self.arrival


@dataclass(frozen=True)
class HealthSummary:
    """:class:`StreamHealth`'s counts over a whole recorded stream (:func:`stream_health_of`)."""

    count: int
    first: float
    newest: float
    period: float

    @property
    def received_fraction(self) -> float:
        return received_fraction(self.count, self.first, self.newest, self.period)


def stream_health_of(stamp_s: np.ndarray, period_s: float | None = None) -> HealthSummary:
    """:class:`StreamHealth`'s count, first and newest stamp and period at the end of a stream of samples that passed
    the input checks, in order of arrival (vectorized)."""
    stamp = np.asarray(stamp_s, dtype=float)
    if stamp.size == 0:
        return HealthSummary(0, math.nan, math.nan, period_s or math.nan)
    ok = np.ones(stamp.size, bool)
    ok[1:] = stamp[1:] >= np.maximum.accumulate(stamp)[:-1]
    kept = stamp[ok]
    gaps = np.diff(kept)
    gaps = gaps[gaps > 0.0][-RECENT_GAPS:]
    period = period_s if period_s else (float(np.median(gaps)) if gaps.size else math.nan)
    return HealthSummary(int(ok.sum()), float(kept[0]), float(kept[-1]), period)
