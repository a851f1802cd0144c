"""Sample timing of the simulated sensors: a DAQ clock delivering buffers, and a zero-order hold of stamped inputs.

Pure Python/numpy, no ROS. Times are integer nanoseconds of the node clock (``Clock.now().nanoseconds``), so the
stamps of two sensors sampling at the same rate are bit-identical and pair exactly.

- :class:`SampleClock`: sample instants on the grid ``k · period`` of the clock (``period = round(1e9 / rate)`` ns).
  A timer asks at each tick for the instants since its previous tick (:meth:`SampleClock.due`), like a DAQ that
  delivers a buffer per interrupt. A backlog longer than ``max_backlog_s`` (the process stalled) is skipped and
  counted instead of being published as a late flood.
- :class:`StampedHold`: the input (the applied wrench, the platform pose) as a piecewise-constant signal. Each
  update takes effect at its header stamp, clamped into ``[last instant already read + 1 ns, arrival time]``: a
  zero stamp or one in the future (another clock) takes effect on arrival, and history already published is never
  rewritten. :meth:`StampedHold.read` gives the value in effect at each sample instant.
"""
from __future__ import annotations

import bisect
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.serde.stamps import NS_PER_S
from crane_stiffness.sim.errors import ParameterError


class SampleClock:
    """Sample instants ``k · period_ns`` (integer k) of a clock, handed out in bursts since the previous call."""

    def __init__(self, rate_hz: float, *, max_backlog_s: float = 0.5, start_after_ns: int | None = None) -> None:
        """Create the clock.

        Args:
            rate_hz: Sample rate, Hz, > 0 and at most 1 GHz.
            max_backlog_s: Longest stretch of samples delivered by one :meth:`due` call, s, > 0; older ones are
                skipped (counted in :attr:`skipped`).
            start_after_ns: First instant strictly after this time (e.g. the last instant of a clock being
                replaced); None: the first :meth:`due` call only starts the clock.
        """
        if isinstance(rate_hz, bool):
            raise ParameterError('rate_hz', rate_hz, 'must be a number')
        rate_hz = float(rate_hz)
        if not (math.isfinite(rate_hz) and 0.0 < rate_hz <= 1e9):
            raise ParameterError('rate_hz', rate_hz, 'must be finite, > 0 and <= 1e9 (Hz)')
        max_backlog_s = float(max_backlog_s)
        if not (math.isfinite(max_backlog_s) and max_backlog_s > 0.0):
            raise ParameterError('max_backlog_s', max_backlog_s, 'must be finite and > 0 (seconds)')
        self._period_ns = max(1, round(NS_PER_S / rate_hz))
        self._max_burst = max(1, math.ceil(max_backlog_s * NS_PER_S / self._period_ns))
        self._last_k: int | None = None if start_after_ns is None else int(start_after_ns) // self._period_ns
        self.skipped = 0

    @property
    def period_ns(self) -> int:
        """Sample period, ns (the rate rounded to a whole number of nanoseconds)."""
        return self._period_ns

    @property
    def last_ns(self) -> int | None:
        """Newest instant handed out (or the start), ns; None before the first :meth:`due` call."""
        return None if self._last_k is None else self._last_k * self._period_ns

    def due(self, now_ns: int) -> NDArray[np.int64]:
        """Instants after the previous call up to ``now_ns`` inclusive, ascending, int64 ns.

        The first call (without ``start_after_ns``) returns none and starts the clock at ``now_ns``. A clock that
        went backwards (simulated time restarted) restarts too.
        """
        k_now = int(now_ns) // self._period_ns
        if self._last_k is None or k_now < self._last_k:
            self._last_k = k_now
            return np.empty(0, dtype=np.int64)
        first = self._last_k + 1
        count = k_now - first + 1
        if count > self._max_burst:
            self.skipped += count - self._max_burst
            first = k_now - self._max_burst + 1
        self._last_k = k_now
        return np.arange(first, k_now + 1, dtype=np.int64) * self._period_ns


class StampedHold:
    """Zero-order hold of a vector signal updated by stamped messages (see the module docstring)."""

    def __init__(self, size: int, initial: ArrayLike | None = None) -> None:
        """Create the hold.

        Args:
            size: Length of the value vector, ≥ 1.
            initial: Value before the first update; None: no value (:meth:`read` marks those instants invalid).
        """
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 1:
            raise ParameterError('size', size, 'must be an integer >= 1')
        self._size = int(size)
        self._initial = None if initial is None else self._vector('initial', initial)
        self._times: list[int] = []
        self._values: list[NDArray[np.float64]] = []
        self._read_until = -1
        self.known_through_ns = -1  #: newest effective time of an update: the input is known up to here
        self.late = 0  #: updates stamped at or before an instant already read (they took effect later)

    def _vector(self, name: str, value: ArrayLike) -> NDArray[np.float64]:
        v = np.asarray(value, dtype=float).reshape(-1)
        if v.shape != (self._size,):
            raise ParameterError(name, value, f'must have {self._size} entries')
        return v

    @property
    def has_value(self) -> bool:
        """True once an update (or an initial value) is held."""
        return bool(self._values) or self._initial is not None

    @property
    def latest(self) -> NDArray[np.float64] | None:
        """The value of the newest update (or the initial value), a copy; None if there is none."""
        if self._values:
            return self._values[-1].copy()
        return None if self._initial is None else self._initial.copy()

    def update(self, value: ArrayLike, stamp_ns: int, now_ns: int) -> int:
        """Hold ``value`` from its stamp on (clamped, see the module docstring); returns the effective time, ns."""
        v = self._vector('value', value)
        stamp_ns = int(stamp_ns)
        now_ns = int(now_ns)
        t = stamp_ns if 0 < stamp_ns <= now_ns else now_ns
        if 0 < t <= self._read_until:
            self.late += 1
        t = max(t, self._read_until + 1)
        self.known_through_ns = max(self.known_through_ns, t)
        i = bisect.bisect_right(self._times, t)
        self._times.insert(i, t)
        self._values.insert(i, v)
        return t

    def read(self, times_ns: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Values in effect at ascending instants ``times_ns``.

        Returns:
            ``(values, valid)``: shape (n, size) and (n,); where no value was held yet, ``valid`` is False and the
            row is NaN.
        """
        times = np.asarray(times_ns, dtype=np.int64).reshape(-1)
        n = times.size
        out = np.full((n, self._size), np.nan)
        valid = np.zeros(n, dtype=bool)
        if n == 0:
            return out, valid
        held = np.zeros(n, dtype=bool)
        last = -1
        if self._times:
            idx = np.searchsorted(np.asarray(self._times, dtype=np.int64), times, side='right') - 1
            held = idx >= 0
            if held.any():
                out[held] = np.stack(self._values)[idx[held]]
            last = int(idx[-1])
        valid[held] = True
        if self._initial is not None:
            out[~held] = self._initial
            valid[~held] = True
        if last >= 0:  # later reads start after the newest instant: older entries are no longer needed
            del self._times[:last]
            del self._values[:last]
            self._initial = None
        self._read_until = max(self._read_until, int(times[-1]))
        return out, valid


class ReleaseGate:
    """Sample instants held back until the input in force at them is known (wall-clock time).

    A reading stamped t must be the input in force at t. On wall-clock time an update stamped before t may still be
    on its way when t has passed, so an instant is released only once an update at or after it has arrived
    (``known_through_ns``) or, failing that, once ``wait_ns`` of the clock has passed it: the stated longest wait,
    after which the held input is taken as in force (a later update stamped before it counts as late,
    :attr:`StampedHold.late`).
    """

    def __init__(self, wait_ns: int) -> None:
        if wait_ns < 0:
            raise ParameterError('wait_ns', wait_ns, 'must be >= 0')
        self.wait_ns = int(wait_ns)
        self._pending = np.empty(0, dtype=np.int64)

    @property
    def pending(self) -> int:
        """Instants held back now."""
        return int(self._pending.size)

    def add(self, times_ns: NDArray[np.int64]) -> None:
        """Instants that have passed (ascending, after those already added)."""
        if times_ns.size:
            self._pending = np.concatenate((self._pending, times_ns))

    def release(self, known_through_ns: int, now_ns: int) -> NDArray[np.int64]:
        """The instants whose input is known (at or before ``known_through_ns``) or waited for long enough."""
        limit = max(int(known_through_ns), int(now_ns) - self.wait_ns)
        n = int(np.searchsorted(self._pending, limit, side='right'))
        out, self._pending = self._pending[:n], self._pending[n:]
        return out
