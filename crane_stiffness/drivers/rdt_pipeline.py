"""The pipeline from an RDT sensor's datagrams to stamped SI wrenches.

:class:`RdtPipeline` turns the datagrams :meth:`~.rdt_client.RdtReceiver.drain` hands over into a :class:`Batch`:
decode all records at once, account for lost / out-of-order / duplicate records (:class:`~.rdt.SequenceTracker`),
stamp them from the sensor's sample counter (:class:`~.clock.CounterClock`), drop records with a status word of
concern, convert counts to N and N·m, subtract the software tare and optionally average blocks of samples to a lower
output rate. Pure numpy, no sockets and no ROS.

**After an outage** (a new stream request: the receiver's next *generation*) nothing received before the stream
stopped is delivered: the open averaging interval, records not yet handed over, and records of the old stream that
arrive only after the new request (in flight across the outage: recognised by their two counters keeping the old
stream's relation, ``ft_sequence − D·rdt_sequence`` with D the sample counter's step per record) are dropped and
counted (``records_stale_dropped``), and the software tare's readings are forgotten. The first record of the new
stream counts a stream restart; if its sample counter does not continue the old one (the device restarted: it
counts from its power-up again) the clock is restarted too (``clock_resets``). :attr:`RdtPipeline.last_restart`
says which, for people.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from crane_stiffness.drivers import rdt
from crane_stiffness.drivers.clock import CounterClock
from crane_stiffness.drivers.errors import DeviceSilentError, ParameterError

_MOD = 1 << 32
#: Records of the old stream still recognised as such after a new stream request [records].
STALE_WINDOW = 4096


@dataclass
class Batch:
    """Records ready to publish: stamps [ns, host clock] and wrenches [N, N·m] in the sensor frame, ascending."""

    stamps_ns: NDArray[np.int64]
    wrench: NDArray[np.float64]
    statuses: list[int] = field(default_factory=list)  # distinct non-zero status words seen in this batch

    def __len__(self) -> int:
        return int(self.stamps_ns.size)


class RdtPipeline:
    """Datagrams → :class:`Batch` (see the module docstring).

    ``publish_rate_hz`` 0 delivers every record; > 0 averages the records whose stamps fall in each interval
    k/publish_rate_hz of the host clock into one sample stamped at the mean of their stamps (7 kHz in, 1 kHz out:
    7 records each). ``drop_status_mask``: records whose status word has any of these bits set are counted and not
    delivered (0 = deliver everything).
    """

    def __init__(self, calibration: rdt.Calibration, sample_rate_hz: float, publish_rate_hz: float = 0.0,
                 tare_samples: int = 100, drop_status_mask: int = 0xFFFFFFFF,
                 clock: CounterClock | None = None) -> None:
        self.calibration = calibration
        self.clock = clock or CounterClock(sample_rate_hz)
        self.tracker = rdt.SequenceTracker()
        self.offset = np.zeros(6)                       # software tare [N, N·m]
        self._tared = False
        self._ring = np.zeros((1, 6))                   # last raw SI readings, for the software tare
        self._ring_next = self._ring_count = 0
        self._generation: int | None = None
        self._last_stamp = -1
        self.configure(publish_rate_hz, tare_samples, drop_status_mask)
        self.malformed_datagrams = 0
        self.status_records = 0                         # records with a non-zero status word
        self.dropped_status = 0                         # of those, not delivered (drop_status_mask)
        self.last_status = 0
        self.late_dropped = 0                           # arrived after newer records were delivered
        self.delivered_records = 0
        self.stream_resumes = 0                         # new streams after the first (after an outage)
        self.stale_dropped = 0                          # records from before an outage, not delivered after it
        self._stale_unseen = 0                          # of those, dropped before the sequence accounting saw them
        self._stale_outage = 0                          # of those, in the current outage
        self.last_restart = ''                          # the last restart, for people
        self._stream: list[int] | None = None           # this stream's first and last (rdt, ft) raw counters
        self._prev: list[int] | None = None             # the same of the stream before the outage
        self._starting = False                          # a new stream was requested: its first record not seen yet
        self._screen_left = 0                           # records of the new stream still checked for old ones
        self._out_stamps: list[NDArray[np.int64]] = []
        self._out_wrench: list[NDArray[np.float64]] = []

    def configure(self, publish_rate_hz: float, tare_samples: int, drop_status_mask: int) -> None:
        """Change the output rate, the tare length and the status mask; the stream's accounting, clock and tare
        stay (an open averaging interval is dropped)."""
        if not (isinstance(publish_rate_hz, (int, float)) and math.isfinite(publish_rate_hz) and publish_rate_hz >= 0):
            raise ParameterError('publish_rate_hz', publish_rate_hz, 'must be 0 (every record) or a rate > 0 [Hz]')
        if isinstance(tare_samples, bool) or not isinstance(tare_samples, int) or tare_samples < 1:
            raise ParameterError('tare_samples', tare_samples, 'must be an integer >= 1')
        if not isinstance(drop_status_mask, int) or not 0 <= drop_status_mask <= 0xFFFFFFFF:
            raise ParameterError('drop_status_mask', drop_status_mask, 'must be in 0..0xFFFFFFFF')
        self.publish_period_ns = round(1e9 / publish_rate_hz) if publish_rate_hz > 0 else 0
        self.drop_status_mask = drop_status_mask
        kept = self._recent()[-tare_samples:].copy()
        self._ring = np.zeros((tare_samples, 6))
        self._ring_next = self._ring_count = 0
        if kept.size:
            self._remember(kept)
        self._block_stamps: list[NDArray[np.int64]] = []
        self._block_wrench: list[NDArray[np.float64]] = []

    def process(self, datagrams: list[tuple[bytes, int, int]]) -> Batch:
        """Decode, account, stamp, convert, tare and (optionally) average ``datagrams`` from
        :meth:`RdtReceiver.drain`."""
        payloads: list[bytes] = []
        arrivals: list[int] = []
        counts: list[int] = []
        for data, t_ns, generation in datagrams:
            if len(data) % rdt.RECORD_SIZE or not data:
                self.malformed_datagrams += 1
                continue
            if generation != self._generation:
                if payloads:  # records of the old stream first
                    self._consume(payloads, arrivals, counts)
                    payloads, arrivals, counts = [], [], []
                if self._generation is not None:
                    self._stream_stopped()
                self._generation = generation
            payloads.append(data)
            arrivals.append(t_ns)
            counts.append(len(data) // rdt.RECORD_SIZE)
        if payloads:
            self._consume(payloads, arrivals, counts)
        return self._take()

    # --- outages --------------------------------------------------------------------------------------------

    def _stream_stopped(self) -> None:
        """A new stream was requested (the old one fell silent): drop what is held from the old one."""
        held = sum(b.shape[0] for b in self._block_stamps) + sum(b.shape[0] for b in self._out_stamps)
        self._block_stamps, self._block_wrench = [], []
        self._out_stamps, self._out_wrench = [], []
        self.stale_dropped += held
        self._ring_next = self._ring_count = 0           # the tare averages readings of the new stream only
        if self._stream is not None:
            self._prev, self._stream = self._stream, None
            self._stale_outage = held
        else:
            self._stale_outage += held
        self._starting = True
        self._screen_left = STALE_WINDOW if self._prev is not None else 0
        self.tracker.reset()                             # a new stream request restarts rdt_sequence

    def _of_previous_stream(self, seq: NDArray[np.int64], ft: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Records whose counters keep the previous stream's relation (ft − D·rdt within D + 1 of its last)."""
        assert self._prev is not None
        rdt0, ft0, rdt1, ft1 = self._prev
        step = max(1, round(((ft1 - ft0) % _MOD) / max(1, (rdt1 - rdt0) % _MOD)))
        d_rdt = (seq - rdt1 + _MOD // 2) % _MOD - _MOD // 2
        d_ft = (ft - ft1 + _MOD // 2) % _MOD - _MOD // 2
        return (np.abs(d_rdt) <= STALE_WINDOW) & (np.abs(d_ft - step * d_rdt) <= step + 1)

    def _stream_started(self, seq: int, ft: int, arrival_ns: int) -> None:
        """The first record of a new stream after an outage: count the restart, restart the clock if the
        device's sample counter started again."""
        self._starting = False
        if self._prev is None:
            return
        self.stream_resumes += 1
        ft_last = self._prev[3]
        if self.clock.continues(ft, arrival_ns):
            what = (f'stream restarted: the sample counter ran on ({(ft - ft_last) % _MOD} samples later, '
                    'clock kept)')
        else:
            self.clock.restart()
            what = (f'device restarted: its sample counter started again (ft_sequence {ft} after {ft_last}, '
                    f'rdt_sequence {seq}), clock reset')
        self.last_restart = f'{what}; {self._stale_outage} records from before the outage not published'

    def _consume(self, payloads: list[bytes], arrivals: list[int], counts: list[int]) -> None:
        records = rdt.decode_records(b''.join(payloads))
        arrival = np.asarray(arrivals, dtype=np.int64)
        if arrival.size != records.size:
            arrival = np.repeat(arrival, counts)
        if self._screen_left > 0 or self._starting:
            if self._screen_left > 0:  # in flight across the outage: the old stream's records
                self._screen_left -= records.size
                stale = self._of_previous_stream(records['rdt_sequence'].astype(np.int64),
                                                  records['ft_sequence'].astype(np.int64))
                if stale.any():
                    k = int(stale.sum())
                    self.stale_dropped += k
                    self._stale_unseen += k
                    self._stale_outage += k
                    records, arrival = records[~stale], arrival[~stale]
                    if records.size == 0:
                        return
            if self._starting:
                self._stream_started(int(records['rdt_sequence'][0]), int(records['ft_sequence'][0]),
                                     int(arrival[0]))
        first, last = records[0], records[-1]
        if self._stream is None:
            self._stream = [int(first['rdt_sequence']), int(first['ft_sequence']), 0, 0]
        self._stream[2:] = [int(last['rdt_sequence']), int(last['ft_sequence'])]
        n = records.size
        deliver, unwrapped = self.tracker.update(records['rdt_sequence'])
        in_order = self.tracker.in_order          # every record new and in order: nothing to select or sort
        stamps = self.clock.update(records['ft_sequence'], arrival)
        status = records['status']
        if not in_order:
            self.late_dropped += n - int(np.count_nonzero(deliver))  # late or duplicate
        if status.any():
            status = status.astype(np.int64)
            nonzero = status != 0
            self.status_records += int(nonzero.sum())
            self.last_status = int(status[nonzero][-1])
            bad = (status & self.drop_status_mask) != 0
            if bad.any():
                self.dropped_status += int((bad & deliver).sum())
                deliver = deliver & ~bad
                in_order = False
        if in_order:
            counts_delivered = records['counts']
        else:
            idx = np.flatnonzero(deliver)
            if idx.size == 0:
                return
            idx = idx[np.argsort(unwrapped[idx], kind='stable')]
            stamps, counts_delivered = stamps[idx], records['counts'][idx]
        stamps = self._monotonic(stamps)
        raw = self.calibration.to_si(counts_delivered)
        self._remember(raw)
        self._out_stamps.append(stamps)
        self._out_wrench.append(raw - self.offset if self._tared else raw)
        self.delivered_records += stamps.size

    def _monotonic(self, stamps: NDArray[np.int64]) -> NDArray[np.int64]:
        """Stamps never go backwards, nor closer than half a sample period: when the line moves down (a lower
        minimum came in, mostly in the first seconds) the step is taken up over the next samples instead of bunching
        them. s_i = max(model_i, s_(i-1) + g), with y_i = s_i - i·g a running maximum; computed relative to the first
        stamp (float64 near 1.7e18 ns would resolve only 256 ns)."""
        g = self.clock.period_ns / 2.0
        ok = self._last_stamp < 0 or stamps[0] - self._last_stamp >= g
        if ok and stamps.size > 1:
            ok = (stamps[1:] - stamps[:-1]).min() >= g
        if not ok:
            base = int(stamps[0])
            steps = np.arange(stamps.size) * g
            floor = float(self._last_stamp - base) + g if self._last_stamp >= 0 else -np.inf
            y = np.maximum.accumulate(np.maximum((stamps - base).astype(np.float64) - steps, floor))
            stamps = base + np.rint(y + steps).astype(np.int64)
        self._last_stamp = int(stamps[-1])
        return stamps

    def _remember(self, raw: NDArray[np.float64]) -> None:
        """Keep the newest raw readings in a ring of ``tare_samples`` rows, for the software tare."""
        ring = self._ring
        k = min(raw.shape[0], ring.shape[0])
        idx = (self._ring_next + np.arange(k)) % ring.shape[0]
        ring[idx] = raw[raw.shape[0] - k:]
        self._ring_next = int((self._ring_next + k) % ring.shape[0])
        self._ring_count = min(self._ring_count + k, ring.shape[0])

    def _recent(self) -> NDArray[np.float64]:
        """The remembered raw readings, oldest first, shape (tare_count, 6)."""
        if self._ring_count < self._ring.shape[0]:
            return self._ring[:self._ring_count]
        return np.roll(self._ring, -self._ring_next, axis=0)

    @property
    def latest_raw(self) -> NDArray[np.float64] | None:
        """The newest raw reading [N, N·m] before the software tare, or None."""
        if not self._ring_count:
            return None
        return self._ring[(self._ring_next - 1) % self._ring.shape[0]].copy()

    def _take(self) -> Batch:
        stamps = np.concatenate(self._out_stamps) if self._out_stamps else np.zeros(0, dtype=np.int64)
        wrench = np.concatenate(self._out_wrench) if self._out_wrench else np.zeros((0, 6))
        self._out_stamps, self._out_wrench = [], []
        statuses = [self.last_status] if self.last_status else []
        if self.publish_period_ns:
            stamps, wrench = self._average(stamps, wrench)
        return Batch(stamps, wrench, statuses)

    def _average(self, stamps: NDArray[np.int64], wrench: NDArray[np.float64]
                 ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Mean of the samples of each closed interval k·period; the newest interval stays open. Stamps ascend,
        so the intervals do too."""
        if stamps.size == 0:
            return stamps, wrench
        if self._block_stamps:
            stamps = np.concatenate(self._block_stamps + [stamps])
            wrench = np.concatenate(self._block_wrench + [wrench])
        blocks = stamps // self.publish_period_ns
        n_closed = int(np.searchsorted(blocks, blocks[-1]))   # samples before the newest (open) interval
        self._block_stamps, self._block_wrench = [stamps[n_closed:]], [wrench[n_closed:]]
        if n_closed == 0:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 6))
        b, s, w = blocks[:n_closed], stamps[:n_closed], wrench[:n_closed]
        starts = np.concatenate(([0], np.flatnonzero(b[1:] != b[:-1]) + 1))
        n = np.diff(np.append(starts, n_closed))
        mean_stamps = np.rint(np.add.reduceat(s - s[0], starts) / n).astype(np.int64) + s[0]
        mean_wrench = np.add.reduceat(w, starts, axis=0) / n[:, None]
        return mean_stamps, mean_wrench

    # --- tare -------------------------------------------------------------------------------------------------

    def tare(self) -> NDArray[np.float64]:
        """Software tare: subtract the mean of the last ``tare_samples`` raw readings from what follows. Returns
        the offset [N, N·m]; raises DeviceSilentError when nothing was received yet."""
        if not self._ring_count:
            raise DeviceSilentError('no reading received yet to tare on')
        self.offset = self._recent().mean(axis=0)
        self._tared = True
        return self.offset.copy()

    def clear_tare(self) -> None:
        """Forget the software tare (a hardware bias zeroes the device itself)."""
        self.offset = np.zeros(6)
        self._tared = False

    @property
    def tare_count(self) -> int:
        """Readings the next software tare would average."""
        return self._ring_count

    def counters(self) -> dict[str, int]:
        counts = self.tracker.as_dict()
        counts['records_received'] += self._stale_unseen
        counts['stream_restarts'] += self.stream_resumes
        return {**counts, 'records_stale_dropped': self.stale_dropped, 'records_delivered': self.delivered_records,
                'records_late_dropped': self.late_dropped, 'malformed_datagrams': self.malformed_datagrams,
                'status_records': self.status_records, 'status_dropped': self.dropped_status,
                'clock_resets': self.clock.resets}

