"""The RDT stream of one F/T sensor: a UDP receiver thread (the pipeline from its datagrams to stamped SI wrenches is
:mod:`.rdt_pipeline`).

- :class:`RdtReceiver` owns the socket. A background thread receives datagrams (blocking, so the GIL is free
  while it waits) with the kernel's arrival time (``SO_TIMESTAMPNS``, host realtime clock), and queues them for
  :meth:`RdtReceiver.drain`. :meth:`RdtReceiver.start` sends the stream request and raises a clear error when the
  address is wrong (does not resolve; ICMP port unreachable; no route) or the device stays silent. Once streaming,
  silence longer than ``timeout_s`` makes it send the request again every ``reconnect_interval_s`` until records
  flow again (the sensor was unplugged, rebooted, or another host took its stream); each new stream request is a
  new *generation*.

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

from crane_stiffness.drivers import rdt
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
