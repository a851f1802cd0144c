"""The live view's WebSocket front: the public port, where each connection is checked before it is used.

The ``foxglove-sdk`` server offers no hook into its handshake (its listener hears of subscriptions, not of
connections, and never sees a request's headers), so it listens on a private loopback port and this front stands
on the public one (stdlib asyncio, on a thread of its own):

- at the handshake it refuses (HTTP 403) a ``Host`` or ``Origin`` the access policy (``view/access.py``) refuses,
  and (HTTP 401) a client without the token where connecting needs it (a server not on loopback);
- an accepted connection gets a connection of its own to the SDK's server (the client's handshake passed on, its
  key, version and subprotocols, without extensions: the frames stay uncompressed and readable), and the frames
  pass both ways as bytes: from the server in whole frames, unread but for their headers (the front costs little
  however fast the channels are); from the client read, to find the service calls. The SDK's server offers no
  services (whoever reaches its private port can only watch): the front advertises them after the server's
  ``serverInfo`` (adding the ``services`` capability) and answers the calls (opcode 2) itself: with the token, by
  calling the handler; without it, with a ``serviceCallFailure`` and a ``status`` saying why, and a log line naming
  the client (address, Origin).

Frames (RFC 6455) are read and made by ``view/wsframes.py``. The Foxglove WebSocket protocol's messages: binary
serviceCallRequest (opcode 2: u32 service id, u32 call id, u32 encoding length, encoding, payload),
serviceCallResponse (opcode 3, the same layout); JSON ``advertiseServices``, ``serviceCallFailure`` and ``status``
(level 0 info, 1 warning, 2 error).
"""
from __future__ import annotations

import asyncio
import json
import struct
import threading
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from crane_stiffness.view.access import AccessPolicy
from crane_stiffness.view.errors import ViewError
from crane_stiffness.view.wsframes import announced_length, frame, frame_bounds, parse_head, unmask

#: The WebSocket subprotocols the SDK's server speaks (the page asks for the first; Lichtblick for the second).
SUBPROTOCOLS = ('foxglove.sdk.v1', 'foxglove.websocket.v1')
#: A service call's handler: (request encoding, request payload, the caller: the client's address and Origin in
#: words, :func:`who`) -> response payload; raising refuses the call with the exception's text.
CallHandler = Callable[[str, bytes, str], bytes]
_TIMEOUT_S = 60.0  # for a handshake to arrive or be answered: only a stuck peer takes this long
_MAX_HEAD = 16 * 1024  # bytes of a handshake request or response
_MAX_CLIENT_MESSAGE = 1 << 20  # bytes of one client message (subscriptions, calls): a bigger one closes it
_HIGH_WATER = 4 << 20  # bytes unsent to a client above which the server's side is not read
_TEXT, _BINARY, _CONTINUATION = 1, 2, 0
_ERROR = 2
_SERVER_INFO = b'{"op":"serverInfo"'
_REASONS = {400: 'Bad Request', 401: 'Unauthorized', 403: 'Forbidden'}


class _Closed(Exception):
    """A peer broke the protocol (an unmasked client frame, a message too long): the connection is closed."""


def _one(headers: dict[str, list[str]], name: str) -> str | None:
    """The first value of header ``name`` (lower case), or None."""
    values = headers.get(name)
    return values[0] if values else None


def who(peer: Any, origin: str | None) -> str:
    """A client as the log names it: its address and the Origin it sent."""
    address = f'{peer[0]}:{peer[1]}' if isinstance(peer, tuple) and len(peer) >= 2 else str(peer)
    return f'{address} (Origin {origin or "none"})'


@dataclass
class _Connection:
    """One client's connection: where its frames go, what the front holds back."""

    writer: asyncio.StreamWriter
    name: str
    authenticated: bool
    info_seen: bool = False  # the server's serverInfo went by (the services advertised after it)
    down_fragmented: bool = False  # a fragmented message of the server's is being passed on
    held: list[bytes] = field(default_factory=list)  # the front's frames waiting for it to end
    parts: list[tuple[bytes, bytes, bytes]] = field(default_factory=list)  # a fragmented client message: (frame,
    # payload, mask)

    def send(self, data: bytes) -> None:
        """A frame of the front's own, between two of the server's whole messages."""
        if self.down_fragmented:
            self.held.append(data)
        elif not self.writer.is_closing():
            self.writer.write(data)


class _Downstream(asyncio.Protocol):
    """The connection to the SDK's server for one client: its handshake answer (``answer``), then its frames to the
    client as they arrive, from the transport's callback (no task woken per read: the fast channels' path). Reading
    pauses while the client's socket has more than ``_HIGH_WATER`` bytes unsent (a slow client: the SDK's server
    then drops its oldest data messages, as it does for a slow client of its own)."""

    def __init__(self, front: WebSocketFront) -> None:
        loop = asyncio.get_running_loop()
        self.front = front
        self.answer: asyncio.Future[bytes] = loop.create_future()
        self.closed: asyncio.Future[None] = loop.create_future()
        self.buf = bytearray()
        self.conn: _Connection | None = None
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        self.buf += data
        if self.conn is not None:
            self._pass()
        elif not self.answer.done():
            end = self.buf.find(b'\r\n\r\n')
            if end >= 0:
                self.answer.set_result(bytes(self.buf[:end + 4]))
                del self.buf[:end + 4]  # frames sent right after it wait here for attach()
            elif len(self.buf) > _MAX_HEAD:
                self.answer.set_exception(ConnectionError('no handshake answer from the view\'s server'))

    def attach(self, conn: _Connection) -> None:
        """From now on the frames go to ``conn``."""
        self.conn = conn
        self._pass()

    def _pass(self) -> None:
        assert self.conn is not None and self.transport is not None
        self.front._pass_down(self.buf, self.conn)
        client = self.conn.writer.transport
        if client.get_write_buffer_size() > _HIGH_WATER and not self.transport.is_closing():
            self.transport.pause_reading()
            asyncio.get_running_loop().call_later(0.005, self._resume)

    def _resume(self) -> None:
        assert self.conn is not None and self.transport is not None
        if self.transport.is_closing() or self.conn.writer.is_closing():
            return
        if self.conn.writer.transport.get_write_buffer_size() > _HIGH_WATER // 2:
            asyncio.get_running_loop().call_later(0.005, self._resume)
        else:
            self.transport.resume_reading()

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.answer.done():
            self.answer.set_exception(ConnectionError('the view\'s server closed the connection'))
        if not self.closed.done():
            self.closed.set_result(None)


class WebSocketFront:
    """The front on ``host:port`` before the SDK's server on ``127.0.0.1:upstream_port``. ``services``: name ->
    (advertised service as the protocol's JSON without ``id``, handler); ``info``/``warn``: the node's log."""

    def __init__(self, host: str, port: int, upstream_port: int, policy: AccessPolicy,
                 services: Mapping[str, tuple[dict[str, Any], CallHandler]], info: Callable[[str], Any],
                 warn: Callable[[str], Any]) -> None:
        self.policy = policy
        self.upstream_port = upstream_port
        self.info, self.warn = info, warn
        self.by_id = {i: (name, entry[1]) for i, (name, entry) in enumerate(services.items(), start=1)}
        advertised = {'op': 'advertiseServices', 'services': [
            {'id': i, 'name': name, **entry[0]} for i, (name, entry) in enumerate(services.items(), start=1)]}
        self.advertised = frame(_TEXT, json.dumps(advertised).encode())
        self.service_calls = 0  # answered by a handler (a success or its failure)
        self.refused_calls = 0  # refused for want of the token
        self.refused_connections = 0
        self.connections: set[asyncio.StreamWriter] = set()
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, name='live_view_ws_front', daemon=True)
        self.thread.start()
        try:
            self.server = asyncio.run_coroutine_threadsafe(
                asyncio.start_server(self._handle, host, port, limit=_MAX_HEAD), self.loop).result(_TIMEOUT_S)
        except OSError as exc:
            self._stop_loop()
            raise ViewError(f'cannot serve the Foxglove WebSocket on {host}:{port}: {exc.strerror}') from exc

    @property
    def port(self) -> int:
        return int(self.server.sockets[0].getsockname()[1])

    # --- the handshake ---
    async def _handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.connections.add(writer)
        upstream: asyncio.Transport | None = None
        try:
            try:
                head = await asyncio.wait_for(reader.readuntil(b'\r\n\r\n'), _TIMEOUT_S)
                method, path, headers = parse_head(head)
            except (asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError, ValueError) as exc:
                self.refused_connections += 1
                self.warn(f'live view: WebSocket from {who(writer.get_extra_info("peername"), None)} refused: '
                          f'no valid handshake ({type(exc).__name__})')
                await self._refuse(writer, 400, 'no valid WebSocket handshake')
                return
            origins = headers.get('origin', [])
            name = who(writer.get_extra_info('peername'), origins[0] if origins else None)
            status, reason = self._check(method, path, headers)
            if status:
                self.refused_connections += 1
                self.warn(f'live view: WebSocket from {name} refused: {reason}')
                await self._refuse(writer, status, reason)
                return
            authenticated = self.policy.token_ok(self.policy.presented_token(
                path, _one(headers, 'authorization')))
            up, down = await asyncio.get_running_loop().create_connection(
                lambda: _Downstream(self), '127.0.0.1', self.upstream_port)
            upstream = up
            up.write(self._upstream_request(headers))
            answer = await asyncio.wait_for(asyncio.shield(down.answer), _TIMEOUT_S)
            writer.write(answer)  # 101 with the accept key of the client's key, the subprotocol chosen
            if not answer.startswith(b'HTTP/1.1 101'):
                status_line = answer.split(b'\r\n', 1)[0].decode('latin-1')
                self.warn(f'live view: WebSocket client {name}: the view\'s server refused it: {status_line}')
                await writer.drain()
                return
            self.info(f'live view: WebSocket client {name} connected '
                      f'({"with the token" if authenticated else "without the token: watching only"})')
            conn = _Connection(writer, name, authenticated)
            down.attach(conn)
            pump = asyncio.create_task(self._up(reader, up, conn))
            await asyncio.wait({pump, down.closed}, return_when=asyncio.FIRST_COMPLETED)
            pump.cancel()
            # a peer gone mid-write (ConnectionResetError) ends the pump: nothing more to say
            await asyncio.gather(pump, return_exceptions=True)
        except (OSError, asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError) as exc:
            self.warn(f'live view: WebSocket client {who(writer.get_extra_info("peername"), None)}: {exc!r}')
        finally:
            self.connections.discard(writer)
            writer.close()
            if upstream is not None:
                upstream.close()

    def _check(self, method: str, path: str, headers: dict[str, list[str]]) -> tuple[int, str]:
        """(0, '') for a handshake that may go on, else (HTTP status, why)."""
        for single in ('host', 'origin', 'authorization', 'sec-websocket-key'):
            if len(headers.get(single, [])) > 1:
                return 400, f'more than one {single} header'
        if (method != 'GET' or 'websocket' not in ','.join(headers.get('upgrade', [])).lower()
                or not headers.get('sec-websocket-key')):
            return 400, 'not a WebSocket handshake'
        origin = _one(headers, 'origin')
        reason = (self.policy.host_refusal(_one(headers, 'host'))
                  or self.policy.origin_refusal(origin))
        if reason:
            return 403, reason
        if not self.policy.open_to_read and not self.policy.token_ok(self.policy.presented_token(
                path, _one(headers, 'authorization'))):
            return 401, 'the token is needed to connect (the server is not on loopback)'
        return 0, ''

    def _upstream_request(self, headers: dict[str, list[str]]) -> bytes:
        """The client's handshake for the SDK's server: its key, version and subprotocols; no extensions (the frames
        must stay readable), no token, no Origin."""
        lines = ['GET / HTTP/1.1', f'Host: 127.0.0.1:{self.upstream_port}', 'Upgrade: websocket',
                 'Connection: Upgrade', f'Sec-WebSocket-Key: {headers["sec-websocket-key"][0]}',
                 f'Sec-WebSocket-Version: {(headers.get("sec-websocket-version") or ["13"])[0]}']
        if headers.get('sec-websocket-protocol'):
            lines.append(f'Sec-WebSocket-Protocol: {", ".join(headers["sec-websocket-protocol"])}')
        return ('\r\n'.join(lines) + '\r\n\r\n').encode('latin-1')

    @staticmethod
    async def _refuse(writer: asyncio.StreamWriter, status: int, reason: str) -> None:
        body = (reason + '\n').encode('utf-8')
        writer.write(f'HTTP/1.1 {status} {_REASONS[status]}\r\nContent-Type: text/plain; charset=utf-8\r\n'
                     f'Content-Length: {len(body)}\r\nConnection: close\r\n\r\n'.encode() + body)
        await writer.drain()

    # --- the frames ---
    def _pass_down(self, buf: bytearray, conn: _Connection) -> None:
        """The server's whole frames in ``buf`` to the client (taken out of ``buf``); after ``serverInfo``, the
        services."""
        out, pos = [], 0
        while (found := frame_bounds(buf, pos)) is not None:
            opcode, start, end, fin, _mask = found
            if not conn.info_seen and opcode == _TEXT and fin and buf.startswith(_SERVER_INFO, start):
                conn.info_seen = True
                out.append(self._server_info(bytes(buf[start:end])))
            else:
                if opcode in (_TEXT, _BINARY, _CONTINUATION):
                    conn.down_fragmented = not fin
                out.append(bytes(buf[pos:end]))  # a data or a control frame (ping, pong, close), as it came
            pos = end
        del buf[:pos]
        if not out or conn.writer.is_closing():
            return
        conn.writer.write(b''.join(out))
        if conn.held and not conn.down_fragmented:
            held, conn.held = conn.held, []
            conn.writer.write(b''.join(held))

    def _server_info(self, payload: bytes) -> bytes:
        if not self.by_id:
            return frame(_TEXT, payload)
        info = json.loads(payload)
        info['capabilities'] = [*info.get('capabilities', []), 'services']
        return frame(_TEXT, json.dumps(info).encode()) + self.advertised

    async def _up(self, reader: asyncio.StreamReader, upstream: asyncio.Transport, conn: _Connection) -> None:
        """The client's frames to the server, but the service calls, answered here."""
        buf = bytearray()
        try:
            while chunk := await reader.read(1 << 16):
                buf += chunk
                out, pos = [], 0
                while (found := frame_bounds(buf, pos)) is not None:
                    opcode, start, end, fin, mask = found
                    if not mask:
                        raise _Closed('an unmasked frame from the client')
                    if end - start > _MAX_CLIENT_MESSAGE:
                        raise _Closed(f'a frame of {end - start} bytes from the client')
                    out.extend(self._from_client(conn, opcode, fin, bytes(buf[pos:end]), buf[start:end], mask))
                    pos = end
                announced = announced_length(buf, pos)
                if announced is not None and announced > _MAX_CLIENT_MESSAGE:  # refused before it is read
                    raise _Closed(f'a frame of {announced} bytes from the client')
                del buf[:pos]
                if out and not upstream.is_closing():
                    upstream.write(b''.join(out))  # a client's few messages: the server reads them at once
        except _Closed as exc:
            self.warn(f'live view: WebSocket client {conn.name} closed: {exc}')

    def _from_client(self, conn: _Connection, opcode: int, fin: bool, raw: bytes, payload: bytearray,
                     mask: bytes) -> list[bytes]:
        """What of one client frame goes on to the server (a service call is handled here instead)."""
        if opcode == _CONTINUATION and conn.parts:
            conn.parts.append((raw, bytes(payload), mask))
            if sum(len(p[1]) for p in conn.parts) > _MAX_CLIENT_MESSAGE:
                raise _Closed('a message too long from the client')
            if not fin:
                return []
            parts, conn.parts = conn.parts, []
            first = parts[0][0][0] & 0x0F
            if first == _BINARY:
                message = b''.join(unmask(p, m) for _raw, p, m in parts)
                if message[:1] == b'\x02':
                    self._service_call(conn, message)
                    return []
            return [p[0] for p in parts]
        if opcode in (_TEXT, _BINARY) and not fin:
            conn.parts = [(raw, bytes(payload), mask)]
            return []
        if opcode == _BINARY and payload and payload[0] ^ mask[0] == 2:
            self._service_call(conn, unmask(payload, mask))
            return []
        return [raw]  # any other frame: the server's to read (and to refuse)

    def _service_call(self, conn: _Connection, message: bytes) -> None:
        try:
            service_id, call_id, length = struct.unpack_from('<III', message, 1)
            if 13 + length > len(message):
                raise ValueError('the encoding runs past the message')
            encoding = message[13:13 + length].decode('utf-8')
        except (struct.error, UnicodeDecodeError, ValueError) as exc:
            conn.send(_status(f'invalid service call request: {exc}'))
            return
        payload = message[13 + length:]
        service = self.by_id.get(service_id, (f'#{service_id}',))[0]
        if not conn.authenticated:
            self.refused_calls += 1
            self.warn(f'live view: service call {service} from {conn.name} refused: no token')
            text = (f'service {service}: refused, this connection has no token (connect with ?token=... as the '
                    f'live view printed it)')
            conn.send(_failure(service_id, call_id, text) + _status(text))
            return
        if service_id not in self.by_id:
            conn.send(_failure(service_id, call_id, f'no service with id {service_id}'))
            return
        if encoding not in ('json', 'cdr'):
            conn.send(_failure(service_id, call_id, f'service {service}: encoding {encoding!r}: expected json or '
                                                    'cdr'))
            return
        # the handler waits for the ROS service: on a thread, so the frames keep flowing meanwhile
        asyncio.get_running_loop().create_task(self._answer(conn, service_id, call_id, encoding, payload))

    async def _answer(self, conn: _Connection, service_id: int, call_id: int, encoding: str, payload: bytes) -> None:
        self.service_calls += 1
        try:
            response = await asyncio.to_thread(self.by_id[service_id][1], encoding, payload, conn.name)
        except Exception as exc:  # noqa: BLE001 (any failure of the call is the client's to read)
            conn.send(_failure(service_id, call_id, str(exc)))
            return
        enc = encoding.encode()
        conn.send(frame(_BINARY, struct.pack('<BIII', 3, service_id, call_id, len(enc)) + enc + response))

    # --- stop ---
    def stop(self) -> None:
        """Close the server and its connections, then the loop's thread."""
        async def close() -> None:
            self.server.close()
            for writer in list(self.connections):
                writer.close()
            await self.server.wait_closed()
        try:
            asyncio.run_coroutine_threadsafe(close(), self.loop).result(_TIMEOUT_S)
        finally:
            self._stop_loop()

    def _stop_loop(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(_TIMEOUT_S)
        self.loop.close()


def _failure(service_id: int, call_id: int, message: str) -> bytes:
    return frame(_TEXT, json.dumps({'op': 'serviceCallFailure', 'serviceId': service_id, 'callId': call_id,
                                    'message': message}).encode())


def _status(message: str) -> bytes:
    return frame(_TEXT, json.dumps({'op': 'status', 'level': _ERROR, 'message': message}).encode())
