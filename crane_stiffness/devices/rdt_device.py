"""An RDT device on this machine: serves a wrench the way an ATI Net F/T / OnRobot HEX does, over UDP.

:class:`RdtDevice` runs a thread that answers RDT requests (stream real-time or buffered, stop, bias) on
``host:port`` (port 0 picks a free port; :attr:`RdtDevice.port` says which). Its internal sample counter
(``ft_sequence``) runs at ``sample_rate_hz`` × (1 + ``clock_ppm``·1e-6) from the moment it starts, like a sensor's
since power-up; while a client streams, every due sample is sent as one record (real-time) or in datagrams of
``records_per_packet`` (buffered), with ``rdt_sequence`` counting from 1 per stream request. The reading comes from
``source()``: the current wrench [N, N·m], called once per send burst (with ``batch=True``: ``source(n)`` returns
the n samples of the burst, shape (n, 6), e.g. with independent noise), converted to counts with ``calibration``
(minus the bias the 0x0042 command captured). Optionally it serves ``/netftapi2.xml`` over HTTP like an ATI box.

Fault injection for tests: ``drop`` (a predicate on rdt_sequence: that record is never sent), ``reorder_every``
(every n-th datagram is held back and sent after the next one), ``status`` (the status word of every record),
``silent`` (receive requests but send nothing). :meth:`stop` then :meth:`start` is a power cycle on the same port;
:meth:`power_cycle` does both with the records a real outage leaves in flight: the last datagrams sent before the
power-down reach the client only after the device is back (a switch or the host's socket still held them), before
the device answers a new stream request.
Pure Python, no ROS; for 127.0.0.1 (any address can be given, for a test's own network namespace).
"""
from __future__ import annotations

import socket
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike

from crane_stiffness.drivers import rdt
from crane_stiffness.drivers.errors import ParameterError, ProtocolError


class RdtDevice:
    """Emulated RDT F/T sensor (see the module docstring). A context manager: ``with RdtDevice(src) as dev:``."""

    def __init__(self, source: Callable[..., ArrayLike], *, host: str = '127.0.0.1', port: int = 0,
                 sample_rate_hz: float = 7000.0, calibration: rdt.Calibration = rdt.Calibration(1e6, 1e6),
                 records_per_packet: int = 1, clock_ppm: float = 0.0, start_counter: int = 0,
                 http_port: int | None = None, drop: Callable[[int], bool] | None = None, reorder_every: int = 0,
                 status: int = 0, burst_interval_s: float = 0.0005, batch: bool = False) -> None:
        """Args:
            source: Returns the current wrench [Fx Fy Fz N, Tx Ty Tz N·m] in the sensor frame.
            host, port: Where to listen for requests (port 0: a free port).
            sample_rate_hz: Internal sample rate, the rate of ft_sequence [Hz].
            calibration: Counts per N and per N·m.
            records_per_packet: Records per datagram in buffered mode (0x0003) (real-time always sends one).
            clock_ppm: Rate error of the device's oscillator [ppm]; > 0 runs fast.
            start_counter: ft_sequence at start (e.g. close to 2**32 to test the wrap).
            http_port: Serve /netftapi2.xml on this port (0: a free one); None: no HTTP.
            drop, reorder_every, status: Fault injection (see the module docstring).
            burst_interval_s: How often the thread sends what is due [s].
            batch: Call ``source(n)`` for the n samples of a burst instead of ``source()`` once.
        """
        if not callable(source):
            raise ParameterError('source', source, 'must be a callable returning 6 numbers')
        if not (sample_rate_hz > 0 and np.isfinite(sample_rate_hz)):
            raise ParameterError('sample_rate_hz', sample_rate_hz, 'must be a finite number > 0 [Hz]')
        if isinstance(records_per_packet, bool) or not isinstance(records_per_packet, int) or not (
                1 <= records_per_packet <= 40):
            raise ParameterError('records_per_packet', records_per_packet, 'must be an integer in 1..40')
        self.source = source
        self.batch = bool(batch)
        self.host, self.port = host, port
        self.sample_rate_hz = float(sample_rate_hz)
        self.calibration = calibration
        self.records_per_packet = records_per_packet
        self.clock_ppm = float(clock_ppm)
        self.start_counter = int(start_counter)
        self.http_port = http_port
        self.drop = drop
        self.reorder_every = int(reorder_every)
        self.status = int(status)
        self.silent = False
        self.burst_interval_s = float(burst_interval_s)
        self.bias_counts = np.zeros(6, dtype=np.int64)
        self.requests: list[tuple[int, int]] = []   # (command, sample_count) received, oldest first
        self.bad_requests = 0
        self.records_sent = 0
        self.records_dropped = 0
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._http: ThreadingHTTPServer | None = None
        self._running = False
        # Stream state, set by each stream request:
        self._leftover = b''                 # buffered: records short of a full datagram
        self._hold = 0                       # datagrams to hold back as in flight at the next power-down
        self._held_event = threading.Event()
        self.in_flight: list[tuple[bytes, tuple]] = []  # (datagram, client) held across the power cycle
        self.power_cycles = 0
        self._remaining: int | None = None   # records left of a counted request; None: endless

    # --- life cycle -------------------------------------------------------------------------------------------

    def start(self) -> RdtDevice:
        """Bind and start serving (a power-up: ft_sequence starts at ``start_counter``, no client, no bias)."""
        if self._running:
            return self
        sock = socket.socket(socket.AF_INET6 if ':' in self.host else socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((self.host, self.port))
        sock.settimeout(self.burst_interval_s)
        self._sock = sock
        self.port = sock.getsockname()[1]
        self.bias_counts = np.zeros(6, dtype=np.int64)
        self._client: tuple | None = None
        self._t0 = time.monotonic()
        self._running = True
        in_flight, self.in_flight = self.in_flight, []
        for packet, client in in_flight:  # records sent before the power-down, arriving only now
            try:
                sock.sendto(packet, client)
            except OSError:
                pass
        self._thread = threading.Thread(target=self._loop, name=f'rdt-device-{self.port}', daemon=True)
        self._thread.start()
        if self.http_port is not None and self._http is None:
            self._start_http()
        return self

    def stop(self) -> None:
        """Stop serving and close the port (a power-down)."""
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self._http is not None:
            self._http.shutdown()
            self._http.server_close()
            self._http = None

    #: Longest power_cycle waits for a running stream and for the datagrams it holds in flight [s].
    HOLD_WAIT_S = 10.0

    def power_cycle(self, off_s: float, in_flight: int = 0) -> int:
        """Power down for ``off_s`` seconds and up again on the same port, as a real sensor does when its supply
        drops: its sample counter (ft_sequence) starts again at ``start_counter``, the stream and the bias are
        gone (the client must request the stream again, rdt_sequence counts from 1), and the last ``in_flight``
        datagrams sent before the power-down reach the client only after the power-up (up to ``HOLD_WAIT_S`` is
        waited for a stream to run and for them, so a busy machine does not skip the case). Blocks for ``off_s``;
        returns the datagrams held in flight."""
        deadline = time.monotonic() + self.HOLD_WAIT_S
        while in_flight and not self.streaming and time.monotonic() < deadline:
            time.sleep(0.005)  # a client re-requesting its stream (it timed out on a busy machine)
        if in_flight and self.streaming:
            self._held_event.clear()
            self._hold = int(in_flight)
            self._held_event.wait(max(0.0, deadline - time.monotonic()))
        self.stop()
        self._hold = 0
        self._held_event.clear()
        self.power_cycles += 1
        time.sleep(off_s)
        held = len(self.in_flight)
        self.start()
        return held

    def __enter__(self) -> RdtDevice:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    @property
    def streaming(self) -> bool:
        """True while a client has a stream running."""
        return self._client is not None

    def counter_now(self) -> int:
        """The internal sample counter now (unwrapped)."""
        elapsed = time.monotonic() - self._t0
        return self.start_counter + int(elapsed * self.sample_rate_hz * (1.0 + self.clock_ppm * 1e-6))

    # --- HTTP: /netftapi2.xml -----------------------------------------------------------------------------------

    def _start_http(self) -> None:
        assert self.http_port is not None  # start() serves HTTP only when given a port
        xml = rdt.netftapi2_xml(self.calibration, self.sample_rate_hz, self.sample_rate_hz).encode()

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 (http.server's name)
                if self.path.split('?')[0] != '/netftapi2.xml':
                    self.send_error(404)
                    return
                self.send_response(200)
                self.send_header('Content-Type', 'text/xml')
                self.send_header('Content-Length', str(len(xml)))
                self.end_headers()
                self.wfile.write(xml)

            def log_message(self, *args) -> None:
                pass

        self._http = ThreadingHTTPServer((self.host, self.http_port), Handler)
        self._http.daemon_threads = True
        self.http_port = self._http.server_address[1]
        threading.Thread(target=self._http.serve_forever, name='rdt-device-http', daemon=True).start()

    # --- serving ----------------------------------------------------------------------------------------------

    def _loop(self) -> None:
        sock = self._sock
        assert sock is not None  # start() binds it before it starts this thread
        held: bytes | None = None      # a datagram held back to reorder
        datagrams = 0
        while self._running:
            if self._held_event.is_set():  # in flight and about to lose power: nothing more goes out
                time.sleep(self.burst_interval_s)
                continue
            try:
                data, peer = sock.recvfrom(64)
                self._on_request(data, peer)
                continue  # handle every queued request before sending
            except socket.timeout:
                pass
            except OSError:
                if not self._running:
                    return
            client = self._client
            if client is None:
                self._sent_until = self.counter_now()
                continue
            now = self.counter_now()
            first = self._sent_until + 1
            if now < first:
                continue
            if now - first > int(self.sample_rate_hz):  # more than 1 s behind (stalled): skip, as a device would
                first = now - int(self.sample_rate_hz)
            ft = np.arange(first, now + 1, dtype=np.int64)
            self._sent_until = now
            if self.silent:
                continue
            rdt_seq = self._rdt_next + np.arange(ft.size, dtype=np.int64)
            self._rdt_next += ft.size
            if self._remaining is not None:
                ft, rdt_seq = ft[:self._remaining], rdt_seq[:self._remaining]
                self._remaining -= ft.size
            if self.batch:
                counts = self.calibration.to_counts(np.asarray(self.source(ft.size), dtype=float).reshape(-1, 6))
            else:
                counts = self.calibration.to_counts(np.asarray(self.source(), dtype=float).reshape(1, 6))
            counts = counts - self.bias_counts
            keep = np.ones(ft.size, dtype=bool)
            if self.drop is not None:
                keep = np.array([not self.drop(int(s)) for s in rdt_seq], dtype=bool)
                self.records_dropped += int((~keep).sum())
            per = self.records_per_packet if client[1] == rdt.CMD_BUFFERED else 1
            counts = np.broadcast_to(counts, (ft.size, 6))
            payload = rdt.encode_records(rdt_seq[keep], ft[keep], self.status, counts[keep])
            step = per * rdt.RECORD_SIZE
            if per > 1:  # a buffered stream sends full datagrams only, as the device's output buffer does
                payload = self._leftover + payload
                full = len(payload) // step * step
                payload, self._leftover = payload[:full], payload[full:]
            for i in range(0, len(payload), step):
                packet = payload[i:i + step]
                if self._hold and not self._held_event.is_set():
                    # The last datagrams before the power-down: in flight (they may span several passes of this
                    # loop: a quick loop has one datagram at a time). Nothing goes out after them.
                    self.in_flight.append((packet, client[0]))
                    if len(self.in_flight) >= self._hold:
                        self._held_event.set()
                    continue
                if self._held_event.is_set():
                    break
                datagrams += 1
                try:
                    if self.reorder_every and held is None and datagrams % self.reorder_every == 0:
                        held = packet
                        continue
                    sock.sendto(packet, client[0])
                    if held is not None:
                        sock.sendto(held, client[0])
                        held = None
                except OSError:
                    pass  # the client went away: a device keeps streaming into the void until told to stop
            self.records_sent += int(keep.sum())
            if self._remaining == 0:
                self._client = None

    def _on_request(self, data: bytes, peer: tuple) -> None:
        try:
            command, count = rdt.decode_request(data)
        except ProtocolError:
            self.bad_requests += 1
            return
        self.requests.append((command, count))
        if command in (rdt.CMD_REALTIME, rdt.CMD_BUFFERED):
            self._client = (peer, command)
            self._rdt_next = 1
            self._leftover = b''
            self._remaining = count if count else None
            self._sent_until = self.counter_now()
        elif command == rdt.CMD_STOP:
            self._client = None
        elif command == rdt.CMD_BIAS:
            reading = self.source(1) if self.batch else self.source()
            self.bias_counts = self.calibration.to_counts(np.asarray(reading, dtype=float).reshape(-1, 6)[-1])
