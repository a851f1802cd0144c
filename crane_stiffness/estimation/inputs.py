"""The inputs of the live estimate before pairing: the checks every sensor sample passes (and their counters) and the
commanded load in effect at a stamp. Each is written for one sample at a time
(:class:`~crane_stiffness.estimation.live.LiveStiffness`) and for whole recorded streams at once (numpy, the offline
analysis of a session); the tests pin the two together.

Input checks (:func:`input_faults`, one definition for both): a sample is dropped when a number in it (its stamp
included) is NaN or Inf, else when its stamp is zero or negative, else when its value exceeds the stream's limit in
magnitude (an absurd reading). Each drop is counted under the first check it fails (:data:`INPUT_CHECKS`).

Commands (:func:`command_inputs`, one definition for both): a command is dropped when its load or a time is NaN or
Inf; it holds from its header stamp, or from its arrival when the header stamp is zero (a publisher that does not
stamp). The load in effect at a stamp is that of the newest command stamped at or before it
(:class:`CommandHold` streaming, :class:`CommandSeries` vectorized).
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass
from typing import Any

import numpy as np

#: The input checks in the order they apply, named as the counters of the samples they drop.
INPUT_CHECKS = ('dropped_non_finite', 'dropped_zero_stamp', 'dropped_absurd')


def input_faults(finite: Any, stamp_s: Any, value: Any, limit: float) -> tuple[Any, Any, Any]:
    """The input checks of one sample (a bool and floats) or, element-wise, of arrays of samples.

    Args:
        finite: every number of the sample, its stamp included, is finite.
        stamp_s: header stamp, s.
        value: the reading checked against ``limit`` (N or N·m, m or rad).
        limit: largest plausible magnitude of ``value``.

    Returns:
        One flag per check of :data:`INPUT_CHECKS` (bools, or boolean arrays): set where the sample fails that check
        and none before it. A sample with no flag set is kept.
    """
    zero_stamp = finite & (stamp_s <= 0.0)
    absurd = finite & (stamp_s > 0.0) & (abs(value) > limit)
    return finite ^ True, zero_stamp, absurd  # finite ^ True: not finite, for a bool and element-wise alike


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
    dropped_malformed: int = 0
    command_dropped: int = 0
    pairs_fitted: int = 0
    fit_restarts: int = 0

    @property
    def dropped(self) -> int:
        return self.dropped_non_finite + self.dropped_absurd + self.dropped_zero_stamp + self.dropped_malformed


@dataclass(frozen=True)
class Samples:
    """The samples of one recorded stream that passed the input checks, in order of arrival."""

    stamp: np.ndarray
    """Header stamps, s."""
    arrival_ns: np.ndarray
    """Arrival (log) times, ns."""
    value: np.ndarray


def checked_samples(stamp_s: np.ndarray, arrival_ns: np.ndarray, value: np.ndarray, finite: np.ndarray,
                    limit: float) -> tuple[Samples, dict[str, int]]:
    """The samples of a recorded stream that pass the input checks (:func:`input_faults`), and how many each check
    dropped (keys :data:`INPUT_CHECKS`)."""
    faults = input_faults(finite, stamp_s, value, limit)
    keep = ~(faults[0] | faults[1] | faults[2])
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
    """The commanded load in effect at a stamp: updates kept in stamp order, read at increasing stamps."""

    def __init__(self) -> None:
        self._stamps: list[float] = []
        self._loads: list[float] = []

    def __bool__(self) -> bool:
        return bool(self._stamps)

    MAX_HELD = 10_000  # commands kept while no pair reads them (100 s at 100 Hz)

    def add(self, stamp_s: float, load: float) -> None:
        i = bisect.bisect_right(self._stamps, stamp_s)
        self._stamps.insert(i, stamp_s)
        self._loads.insert(i, load)
        if len(self._stamps) > self.MAX_HELD:
            del self._stamps[0]
            del self._loads[0]

    def at(self, stamp_s: float) -> float | None:
        """Load of the newest update stamped at or before ``stamp_s``; None before the first one."""
        i = bisect.bisect_right(self._stamps, stamp_s) - 1
        if i < 0:
            return None
        if i > 0:  # reads come at increasing stamps: drop what can no longer be in effect
            del self._stamps[:i]
            del self._loads[:i]
        return self._loads[0]


@dataclass(frozen=True)
class CommandSeries:
    """The usable commands of a recording in stamp order (:class:`CommandHold` for whole streams at once)."""

    stamp: np.ndarray
    """Stamps from which each command holds, s, ascending (commands of equal stamps in order of arrival)."""
    value: np.ndarray
    """Commanded loads, N or N·m."""
    first_arrival_ns: int
    """Arrival (log) time of the first usable command, ns."""

    @classmethod
    def of(cls, stamp_s: np.ndarray, arrival_ns: np.ndarray, load: np.ndarray) -> CommandSeries | None:
        """The usable commands (:func:`command_inputs`) of arrays in order of arrival; None without one."""
        usable, stamp = command_inputs(stamp_s, arrival_ns * 1e-9, load)
        if not usable.any():
            return None
        order = np.argsort(stamp[usable], kind='stable')
        return cls(stamp[usable][order], load[usable][order], int(arrival_ns[usable].min()))

    def at(self, stamp_s: np.ndarray, arrival_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The load in effect at each stamp for a reader at the given arrival times: (load, held); held is False
        where no command was stamped at or before the stamp, or none had arrived yet (load is then meaningless)."""
        k = np.searchsorted(self.stamp, stamp_s, side='right') - 1
        held = (k >= 0) & (arrival_ns >= self.first_arrival_ns)
        return self.value[np.maximum(k, 0)], held
