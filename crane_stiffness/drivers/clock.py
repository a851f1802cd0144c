"""A device's sample counter mapped to host time: stamps from the counter, not from arrival times.

A sensor that numbers its samples (RDT's ``ft_sequence``) fixes their spacing exactly, but its oscillator runs at
its own rate (tens of ppm off) and its counter has an unknown origin. Every record also has an arrival time on the
host, which is the sample instant plus a delay: a constant transport part and a jitter that is never negative (the
network, the kernel, a descheduled receiver). So the sample instants lie on the **lower envelope** of the points
(counter, arrival time): :class:`CounterClock` keeps, for bins of ``bin_s`` of counter time over the last
``window_s``, the point of least delay, and fits a line through those minima (robustly: bins whose minimum lies
well above the line, e.g. a bin spent in a congestion, are dropped and the line refitted). The slope tracks the
oscillator's rate error (drift), the intercept the origin. Stamps are then

    stamp = t0 + (c − c0)·period + a + b·(c − c0)        [ns, host clock]

which carries the constant part of the delay (unobservable from one direction; microseconds on a LAN) but none of
the jitter. Until three bins are complete the line is flat through the least delay seen so far.

The counter is unwrapped (32-bit rollover). A step of more than ``max_step_s`` (the device restarted, or a stream
from another device) restarts the clock (:attr:`resets`). After a stream stopped, :meth:`continues` says whether a
record of the new stream is on the same counter (the device kept running) or not (it restarted: :meth:`restart`).
Pure numpy, no ROS. Times are integer nanoseconds of the host clock the arrival times come from.
"""
from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.drivers.errors import ParameterError
from crane_stiffness.serde.stamps import NS_PER_S

_MOD = 1 << 32
_HALF = 1 << 31


class CounterClock:
    """Host-time stamps for a sample counter running at ``rate_hz`` nominal (see the module docstring)."""

    def __init__(self, rate_hz: float, *, bin_s: float = 0.5, window_s: float = 30.0, max_step_s: float = 2.0,
                 counter_bits: int = 32) -> None:
        """Create the clock.

        Args:
            rate_hz: Nominal rate of the counter [Hz], > 0 (RDT: the internal sample rate, e.g. 7000).
            bin_s: Counter time per bin of the lower envelope [s]; longer bins find a lower minimum each.
            window_s: Span of the bins the line is fitted to [s]; longer windows average more but follow a
                changing drift (temperature) more slowly.
            max_step_s: Largest counter step between consecutive records that is taken as the same stream [s].
            counter_bits: Width of the counter (wraps at 2**counter_bits); 32 for RDT.
        """
        for name, v in (('rate_hz', rate_hz), ('bin_s', bin_s), ('window_s', window_s), ('max_step_s', max_step_s)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ParameterError(name, v, 'must be a finite number > 0')
        if window_s < 3 * bin_s:
            raise ParameterError('window_s', window_s, f'must be at least 3 bins of bin_s = {bin_s} s')
        if counter_bits != 32:
            raise ParameterError('counter_bits', counter_bits, 'only 32-bit counters are supported')
        self.rate_hz = float(rate_hz)
        self.period_ns = NS_PER_S / self.rate_hz
        self.bin_counts = max(1, round(bin_s * self.rate_hz))
        self.window_bins = max(3, round(window_s / bin_s))
        self.max_step = max(2, round(max_step_s * self.rate_hz))
        self.resets = 0
        self._start()

    def _start(self) -> None:
        self._raw_last: int | None = None     # last raw counter value seen
        self._unwrapped_last = 0              # its unwrapped value
        self._t0: int | None = None           # arrival time of the origin record [ns]
        self._bins: OrderedDict[int, tuple[int, float]] = OrderedDict()  # bin -> (x at min, residual min)
        self._a = 0.0                         # intercept [ns]
        self._b = 0.0                         # slope [ns per count]
        self._fitted_bins = 0                 # complete bins behind the current line
        self._fitted_until: int | None = None  # newest of them
        self._min_residual = math.inf

    def reset(self) -> None:
        """Forget everything: the next record is a new origin (not counted; see :meth:`restart`)."""
        self._start()

    def restart(self) -> None:
        """The device's counter started again: forget everything and count a reset (:attr:`resets`)."""
        if self._t0 is not None:
            self.resets += 1
        self._start()

    def continues(self, counter: int, arrival_ns: int, tolerance_s: float = 0.25) -> bool:
        """Whether a record (raw ``counter``, arrived at ``arrival_ns`` [ns, host clock]) lies on this clock's
        counter: a step forwards of at most ``max_step_s`` from the last record, and the line stamps it no later
        than its arrival and no more than ``tolerance_s`` [s] before it. A counter that started again after a power
        cycle fails (a step backwards, or a stamp seconds before the arrival). True before the first record."""
        if self._raw_last is None or self._t0 is None:
            return True
        step = (int(counter) - self._raw_last + _HALF) % _MOD - _HALF
        if not 0 < step <= self.max_step:
            return False
        stamp = int(self._stamps(np.array([self._unwrapped_last + step - self._x0]))[0])
        late_ns = int(arrival_ns) - stamp
        return -0.001 * NS_PER_S <= late_ns <= tolerance_s * NS_PER_S

    @property
    def skew_ppm(self) -> float:
        """Estimated rate error of the counter against the host clock [ppm]: > 0 = the device clock runs slow
        (its samples are further apart in host time than nominal)."""
        return self._b / self.period_ns * 1e6

    @property
    def fitted(self) -> bool:
        """True once the line is fitted through at least three complete bins (drift tracked)."""
        return self._fitted_bins >= 3

    def _unwrap(self, raw: NDArray[np.int64]) -> tuple[NDArray[np.int64], int]:
        """Unwrapped counters of ``raw`` and the index of the first step too large to belong to the stream (or
        len(raw))."""
        prev = raw[0] if self._raw_last is None else self._raw_last
        steps = np.empty(raw.size, dtype=np.int64)
        steps[0] = raw[0] - prev
        np.subtract(raw[1:], raw[:-1], out=steps[1:])
        steps += _HALF
        steps %= _MOD
        steps -= _HALF
        cut = raw.size
        if steps.max() > self.max_step or steps.min() < -self.max_step:
            cut = int(np.flatnonzero(np.abs(steps) > self.max_step)[0])
        base = self._unwrapped_last if self._raw_last is not None else 0
        unwrapped = base + np.cumsum(steps[:cut])
        return unwrapped, cut

    def update(self, counter: ArrayLike, arrival_ns: ArrayLike) -> NDArray[np.int64]:
        """Stamps [ns] for records with device counters ``counter`` (arrival order) that arrived at ``arrival_ns``
        (host clock; records of one datagram share its arrival time). Updates the envelope first, so each stamp
        uses everything known up to its batch."""
        raw = np.asarray(counter, dtype=np.int64) % _MOD
        arrival = np.broadcast_to(np.asarray(arrival_ns, dtype=np.int64), raw.shape)
        if raw.size == 0:
            return np.zeros(0, dtype=np.int64)
        unwrapped, cut = self._unwrap(raw)
        if cut < raw.size:
            head = self._update_unwrapped(raw[:cut], unwrapped, arrival[:cut]) if cut else np.zeros(0, np.int64)
            self.resets += 1
            self._start()
            return np.concatenate([head, self.update(raw[cut:], arrival[cut:])])
        return self._update_unwrapped(raw, unwrapped, arrival)

    def _update_unwrapped(self, raw: NDArray[np.int64], unwrapped: NDArray[np.int64],
                          arrival: NDArray[np.int64]) -> NDArray[np.int64]:
        if self._t0 is None:
            self._t0 = int(arrival[0])
            self._x0 = int(unwrapped[0])
        self._raw_last = int(raw[-1])
        self._unwrapped_last = int(unwrapped[-1])
        x = unwrapped - self._x0
        residual = (arrival - self._t0).astype(np.float64) - x * self.period_ns
        self._add_to_bins(x, residual)
        return self._stamps(x)

    def stamp(self, counter_unwrapped_offset: ArrayLike) -> NDArray[np.int64]:
        """Stamps [ns] of counter values given as offsets from the origin record (for tests and diagnostics)."""
        return self._stamps(np.asarray(counter_unwrapped_offset, dtype=np.int64))

    def _stamps(self, x: NDArray[np.int64]) -> NDArray[np.int64]:
        assert self._t0 is not None  # set by the first update: stamps count from its origin record
        offset = x * self.period_ns + self._a + self._b * x
        return self._t0 + np.rint(offset).astype(np.int64)

    def _add_to_bins(self, x: NDArray[np.int64], residual: NDArray[np.float64]) -> None:
        bins = x // self.bin_counts
        first, last = int(bins.min()), int(bins.max())
        if first == last:  # the common case: a batch within one bin
            i = int(residual.argmin())
            minima = [(first, i)]
        else:
            order = np.lexsort((residual, bins))           # by bin, then residual: first of each bin is its minimum
            sorted_bins = bins[order]
            head = np.ones(order.size, dtype=bool)
            head[1:] = sorted_bins[1:] != sorted_bins[:-1]
            minima = [(int(bins[i]), i) for i in order[head].tolist()]
        opened = False
        for key, i in minima:
            held = self._bins.get(key)
            if held is None:
                opened = True
            if held is None or residual[i] < held[1]:
                self._bins[key] = (int(x[i]), float(residual[i]))
        if opened and len(self._bins) > 1 and next(reversed(self._bins)) != max(self._bins):
            self._bins = OrderedDict(sorted(self._bins.items()))  # a late record opened an older bin
        while len(self._bins) > self.window_bins + 1:
            self._bins.popitem(last=False)
        complete = len(self._bins) - 1                  # the newest bin may still fill
        if complete >= 3:
            if opened and (complete != self._fitted_bins or self._newest_complete() != self._fitted_until):
                self._fit()
        else:
            self._min_residual = min(self._min_residual, float(residual.min()))
            self._a, self._b = self._min_residual, 0.0

    def _newest_complete(self) -> int:
        return list(self._bins)[-2]

    def _fit(self) -> None:
        items = list(self._bins.values())[:-1]
        xs = np.array([p[0] for p in items], dtype=np.float64)
        rs = np.array([p[1] for p in items])
        keep = np.ones(xs.size, dtype=bool)
        for _ in range(2):
            b, a = np.polyfit(xs[keep], rs[keep], 1)
            above = rs - (a + b * xs)
            spread = max(float(np.median(np.abs(above[keep] - np.median(above[keep])))), 1000.0)  # ≥ 1 µs
            new_keep = above < 4.0 * spread
            if new_keep.sum() < 3 or np.array_equal(new_keep, keep):
                break
            keep = new_keep
        self._a, self._b = float(a), float(b)
        self._fitted_bins = len(items)
        self._fitted_until = self._newest_complete()
