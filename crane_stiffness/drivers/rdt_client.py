"""The RDT stream of one F/T sensor: a UDP receiver thread and the pipeline from datagrams to stamped SI wrenches.

- :class:`RdtReceiver` owns the socket. A background thread receives datagrams (blocking, so the GIL is free
  while it waits) with the kernel's arrival time (``SO_TIMESTAMPNS``, host realtime clock), and queues them for
  :meth:`RdtReceiver.drain`. :meth:`RdtReceiver.start` sends the stream request and raises a clear error when the
  address is wrong (does not resolve; ICMP port unreachable; no route) or the device stays silent. Once streaming,
  silence longer than ``timeout_s`` makes it send the request again every ``reconnect_interval_s`` until records
  flow again (the sensor was unplugged, rebooted, or another host took its stream); each new stream request is a
  new *generation*.
- :class:`RdtPipeline` turns drained datagrams into a :class:`Batch`: decode all records at once, account for
  lost / out-of-order / duplicate records (:class:`~.rdt.SequenceTracker`), stamp them from the sensor's sample
  counter (:class:`~.clock.CounterClock`), drop records with a status word of concern, convert counts to N and
  N·m, subtract the software tare and optionally average blocks of samples to a lower output rate.

No ROS here: ``crane_stiffness.nodes.netft`` publishes the batches.
"""
from __future__ import annotations

import errno
import math
import socket
import struct
import threading
import time
import urllib.error
import urllib.request
from collections import deque
from dataclasses import dataclass, field
import numpy as np
from numpy.typing import NDArray

from crane_stiffness.drivers import rdt
from crane_stiffness.drivers.clock import CounterClock
from crane_stiffness.drivers.errors import (DeviceAddressError, DeviceResponseError, DeviceSilentError,
                                            ParameterError)
from crane_stiffness.drivers.modbus import resolve

SO_TIMESTAMPNS = getattr(socket, 'SO_TIMESTAMPNS', 35)  # Linux value; the Python module does not export it
_TIMESPEC = struct.Struct('@qq')
#: Kernel receive buffer asked for: ~1 s of real-time records at 7 kHz (each datagram costs ~1 kB of buffer).
RECEIVE_BUFFER_BYTES = 8 * 1024 * 1024


def fetch_netftapi2(host: str, http_port: int = 80, timeout_s: float = 2.0) -> rdt.NetFtConfig:
    """Read an ATI box's calibration from ``http://host:http_port/netftapi2.xml``.

    Raises DeviceAddressError (nothing answers HTTP there), DeviceSilentError (no answer in time) or
    DeviceResponseError (an answer that is not a usable netftapi2.xml)."""
    url = f'http://{host}:{http_port}/netftapi2.xml'
    try:
        with urllib.request.urlopen(url, timeout=timeout_s) as response:
            text = response.read(1 << 20)
    except urllib.error.HTTPError as exc:
        raise DeviceResponseError(f'{url}: HTTP {exc.code} {exc.reason} (not an ATI Net F/T / Axia box? set '
                                  'counts_per_force and counts_per_torque)') from None
    except (TimeoutError, socket.timeout):
        raise DeviceSilentError(f'{url}: no answer within {timeout_s} s') from None
    except (urllib.error.URLError, OSError) as exc:
        reason = getattr(exc, 'reason', exc)
        raise DeviceAddressError(f'{url}: {reason} (wrong address, or the box serves no web page)') from None
    try:
        return rdt.parse_netftapi2(text)
    except DeviceResponseError as exc:
        raise DeviceResponseError(f'{url}: {exc}') from None


class RdtReceiver:
    """One RDT stream from ``host:port`` (see the module docstring). Use as a context manager or start/stop."""

    def __init__(self, host: str, port: int = rdt.RDT_PORT, command: str = 'realtime', timeout_s: float = 0.5,
                 reconnect_interval_s: float = 1.0) -> None:
        """Args:
            host: The sensor's address or name.
            port: Its RDT port (49152 on every ATI and OnRobot device).
            command: 'realtime' (0x0002, one record per datagram) or 'buffered' (0x0003, several per datagram).
            timeout_s: Silence after which the stream counts as lost [s].
            reconnect_interval_s: Interval between stream requests while it is lost [s].
        """
        if command not in rdt.STREAM_COMMANDS:
            raise ParameterError('command', command, f'must be one of {", ".join(rdt.STREAM_COMMANDS)}')
        if isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536:
            raise ParameterError('port', port, 'must be in 1..65535')
        for name, v in (('timeout_s', timeout_s), ('reconnect_interval_s', reconnect_interval_s)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ParameterError(name, v, 'must be a finite number > 0 [s]')
        self.host, self.port, self.command = host, port, command
        self.timeout_s, self.reconnect_interval_s = float(timeout_s), float(reconnect_interval_s)
        self.datagrams = 0          # received since start
        self.requests = 0           # stream requests sent
        self.reconnects = 0         # stream requests sent after the stream was lost
        self.refused = 0            # ICMP port-unreachable replies (nothing listening)
        self.generation = 0         # +1 per stream request
        self.streaming = False      # records arrived within timeout_s
        self.last_error = ''
        self.kernel_timestamps = False
        self._sock: socket.socket | None = None
        self._pending: deque[tuple[bytes, int, int]] = deque()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._running = False
        self._last_rx = 0.0
        self._last_request = 0.0
        self._first = threading.Event()

    @property
    def where(self) -> str:
        return f'{self.host}:{self.port}'

    # --- life cycle -------------------------------------------------------------------------------------------

    def start(self, wait_s: float = 2.0) -> None:
        """Open the socket, request the stream and wait up to ``wait_s`` for the first record.

        Raises DeviceAddressError (the address does not resolve, nothing listens there, no route) or
        DeviceSilentError (the device sends nothing)."""
        address = resolve(self.host, self.port, socket.SOCK_DGRAM)
        family = socket.AF_INET6 if ':' in address else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        for option in (getattr(socket, 'SO_RCVBUFFORCE', None), socket.SO_RCVBUF):
            if option is None:
                continue
            try:
                sock.setsockopt(socket.SOL_SOCKET, option, RECEIVE_BUFFER_BYTES)
                break
            except OSError:  # SO_RCVBUFFORCE needs CAP_NET_ADMIN; SO_RCVBUF is capped at net.core.rmem_max
                continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            self.kernel_timestamps = True
        except OSError:
            self.kernel_timestamps = False
        sock.settimeout(0.05)
        try:
            sock.connect((address, self.port))  # only the sensor's datagrams reach this socket
        except OSError as exc:
            sock.close()
            raise DeviceAddressError(f'RDT device {self.where}: {exc.strerror or exc}') from None
        self._sock = sock
        self._running = True
        self._first.clear()
        self._send_request()
        self._thread = threading.Thread(target=self._receive_loop, name=f'rdt-{self.where}', daemon=True)
        self._thread.start()
        if not self._first.wait(wait_s):
            refused, error = self.refused, self.last_error
            self.stop()
            if refused:
                raise DeviceAddressError(f'no RDT device at {self.where}: port unreachable (nothing listens there: '
                                         'wrong address or port?)')
            if error:
                raise DeviceAddressError(f'no RDT device at {self.where}: {error}')
            raise DeviceSilentError(f'RDT device {self.where} sent no record within {wait_s} s of a '
                                    f'{self.command} stream request (wrong address, device off, or its RDT '
                                    'interface disabled?)')

    def stop(self) -> None:
        """Ask the device to stop streaming, stop the thread and close the socket."""
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._sock is not None:
            try:
                self._sock.send(rdt.encode_request(rdt.CMD_STOP))
            except OSError:
                pass
            self._sock.close()
            self._sock = None
        self.streaming = False

    def __enter__(self) -> RdtReceiver:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # --- commands ---------------------------------------------------------------------------------------------

    def _send_request(self, new_stream: bool = True) -> None:
        if new_stream:
            self.generation += 1
        self.requests += 1
        self._last_request = time.monotonic()
        self._send(rdt.encode_request(rdt.STREAM_COMMANDS[self.command]))

    def _send(self, data: bytes) -> None:
        assert self._sock is not None  # started: stop() closes it only after the receive thread ended
        try:
            self._sock.send(data)
        except ConnectionRefusedError:
            self.refused += 1
        except OSError as exc:  # no route, network down: reported, retried
            self.last_error = exc.strerror or str(exc)

    def bias(self) -> None:
        """Send the hardware bias command (0x0042): the device zeroes its readings on the current load."""
        if self._sock is None:
            raise DeviceSilentError(f'RDT device {self.where}: not started')
        self._send(rdt.encode_request(rdt.CMD_BIAS))

    # --- receiving --------------------------------------------------------------------------------------------

    def _receive_loop(self) -> None:
        sock = self._sock
        assert sock is not None  # start() connects it before it starts this thread
        cmsg_size = socket.CMSG_SPACE(_TIMESPEC.size)
        pending = self._pending
        while self._running:
            try:
                data, ancillary, _, _ = sock.recvmsg(65536, cmsg_size)
            except socket.timeout:
                self._check_silence()
                continue
            except ConnectionRefusedError:  # ICMP port unreachable for our request: nothing listens (yet)
                self.refused += 1
                self.streaming = False
                self._check_silence()
                continue
            except OSError as exc:
                if exc.errno in (errno.EBADF, errno.ENOTSOCK):
                    return
                self.last_error = exc.strerror or str(exc)
                self.streaming = False
                time.sleep(0.05)
                self._check_silence()
                continue
            t_ns = 0
            for level, kind, payload in ancillary:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(payload) >= _TIMESPEC.size:
                    sec, nsec = _TIMESPEC.unpack_from(payload)
                    t_ns = sec * 1_000_000_000 + nsec
            if t_ns == 0:
                t_ns = time.time_ns()
            pending.append((data, t_ns, self.generation))  # deque.append is atomic
            self.datagrams += 1
            self._last_rx = time.monotonic()
            if not self.streaming:
                self.streaming = True
                self._first.set()

    def _check_silence(self) -> None:
        now = time.monotonic()
        if self.streaming and now - self._last_rx > self.timeout_s:
            self.streaming = False
        if not self.streaming and now - self._last_request >= self.reconnect_interval_s and self._first.is_set():
            self.reconnects += 1
            self._send_request()
        elif not self._first.is_set() and now - self._last_request >= min(0.5, self.reconnect_interval_s):
            self._send_request(new_stream=False)  # the first request (or the device's first answer) may be lost

    def drain(self) -> list[tuple[bytes, int, int]]:
        """The datagrams received since the last call: ``(payload, arrival_ns, generation)``, in arrival order."""
        out = []
        pending = self._pending
        while pending:
            out.append(pending.popleft())
        return out


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
                    self.tracker.reset()  # a new stream request restarts rdt_sequence
                    self.clock.reset()
                self._generation = generation
            payloads.append(data)
            arrivals.append(t_ns)
            counts.append(len(data) // rdt.RECORD_SIZE)
        if payloads:
            self._consume(payloads, arrivals, counts)
        return self._take()

    def _consume(self, payloads: list[bytes], arrivals: list[int], counts: list[int]) -> None:
        records = rdt.decode_records(b''.join(payloads))
        n = records.size
        arrival = np.asarray(arrivals, dtype=np.int64)
        if arrival.size != n:
            arrival = np.repeat(arrival, counts)
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
        return {**self.tracker.as_dict(), 'records_delivered': self.delivered_records,
                'records_late_dropped': self.late_dropped, 'malformed_datagrams': self.malformed_datagrams,
                'status_records': self.status_records, 'status_dropped': self.dropped_status,
                'clock_resets': self.clock.resets}

