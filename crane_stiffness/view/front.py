"""The live view's WebSocket front: the public port, where each connection is checked before it is used.

The ``foxglove-sdk`` server offers no hook into its handshake (its listener hears of subscriptions, not of
connections, and never sees a request's headers), so it listens on a private loopback port and this front stands
on the public one (``websockets``, an asyncio server on a thread of its own):

- at the handshake it refuses (HTTP 403) a ``Host`` or ``Origin`` the access policy (``view/access.py``) refuses,
  and (HTTP 401) a client without the token where connecting needs it (a server not on loopback);
- an accepted connection gets a connection of its own to the SDK's server, and the frames pass both ways as they
  are, except the service calls: the SDK's server offers none (whoever reaches its private port can only watch),
  the front advertises the services after the server's ``serverInfo`` (adding the ``services`` capability) and
  answers the calls (opcode 2) itself: with the token, by calling the handler; without it, with a
  ``serviceCallFailure`` and a ``status`` saying why, and a log line naming the client (address, Origin).

Frames are the Foxglove WebSocket protocol's: binary serviceCallRequest (opcode 2: u32 service id, u32 call id,
u32 encoding length, encoding, payload), serviceCallResponse (opcode 3, the same layout); JSON ``advertiseServices``,
``serviceCallFailure`` and ``status`` (level 0 info, 1 warning, 2 error).
"""
from __future__ import annotations

import asyncio
import json
import struct
import threading
from typing import Any, Callable, Mapping

from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.typing import Subprotocol

from crane_stiffness.view.access import AccessPolicy
from crane_stiffness.view.errors import ViewError

#: The WebSocket subprotocols the SDK's server speaks (the page asks for the first; Lichtblick for the second).
SUBPROTOCOLS = ('foxglove.sdk.v1', 'foxglove.websocket.v1')
#: A service call's handler: (request encoding, request payload) -> response payload; raising refuses the call
#: with the exception's text.
CallHandler = Callable[[str, bytes], bytes]
_START_TIMEOUT_S = 30.0
_ERROR = 2


def who(remote: Any, headers: Headers) -> str:
    """A client as the log names it: its address and the Origin it sent."""
    address = f'{remote[0]}:{remote[1]}' if isinstance(remote, tuple) and len(remote) >= 2 else str(remote)
    return f'{address} (Origin {headers.get("Origin", "none")})'


class WebSocketFront:
    """The front on ``host:port`` before the SDK's server on ``127.0.0.1:upstream_port``. ``services``: name ->
    (advertised service as the protocol's JSON without ``id``, handler); ``info``/``warn``: the node's log."""

    def __init__(self, host: str, port: int, upstream_port: int, policy: AccessPolicy,
                 services: Mapping[str, tuple[dict[str, Any], CallHandler]], info: Callable[[str], Any],
                 warn: Callable[[str], Any]) -> None:
        self.policy = policy
        self.upstream = f'ws://127.0.0.1:{upstream_port}'
        self.info, self.warn = info, warn
        self.by_id = {i: (name, entry[1]) for i, (name, entry) in enumerate(services.items(), start=1)}
        self.advertised = json.dumps({'op': 'advertiseServices', 'services': [
            {'id': i, 'name': name, **entry[0]} for i, (name, entry) in enumerate(services.items(), start=1)]})
        self.service_calls = 0  # answered by a handler (a success or its failure)
        self.refused_calls = 0  # refused for want of the token
        self.refused_connections = 0
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, name='live_view_ws_front', daemon=True)
        self.thread.start()
        try:
            self.server: Server = asyncio.run_coroutine_threadsafe(self._start(host, port), self.loop).result(
                _START_TIMEOUT_S)
        except OSError as exc:
            self._stop_loop()
            raise ViewError(f'cannot serve the Foxglove WebSocket on {host}:{port}: {exc.strerror}') from exc

    async def _start(self, host: str, port: int) -> Server:
        # No compression (the frames pass as they are) nor keepalive pings (a client of a loaded machine that
        # answers late stays connected, as with the SDK's server); no size limit (a scene may be large).
        return await serve(self._handle, host, port, process_request=self._check,
                           subprotocols=[Subprotocol(p) for p in SUBPROTOCOLS], compression=None,
                           max_size=None, ping_interval=None, server_header=None)

    @property
    def port(self) -> int:
        return int(self.server.sockets[0].getsockname()[1])

    # --- the handshake ---
    def _check(self, connection: ServerConnection, request: Request) -> Response | None:
        """Refuse the handshake (a response) or let it go on (None)."""
        reason = (self.policy.host_refusal(request.headers.get('Host'))
                  or self.policy.origin_refusal(request.headers.get('Origin')))
        status = 403
        if reason is None and not self.policy.open_to_read and not self._authenticated(request):
            reason, status = 'the token is needed to connect (the server is not on loopback)', 401
        if reason is None:
            return None
        self.refused_connections += 1
        self.warn(f'live view: WebSocket from {who(connection.remote_address, request.headers)} refused: {reason}')
        return connection.respond(status, reason + '\n')

    def _authenticated(self, request: Request) -> bool:
        return self.policy.token_ok(self.policy.presented_token(request.path, request.headers.get('Authorization')))

    # --- a connection ---
    async def _handle(self, client: ServerConnection) -> None:
        request = client.request
        assert request is not None  # the handshake is done
        authenticated = self._authenticated(request)
        name = who(client.remote_address, request.headers)
        self.info(f'live view: WebSocket client {name} connected '
                  f'({"with the token" if authenticated else "without the token: watching only"})')
        try:
            async with connect(self.upstream, subprotocols=[client.subprotocol] if client.subprotocol else None,
                               compression=None, max_size=None, ping_interval=None, open_timeout=60) as upstream:
                tasks = {asyncio.create_task(self._down(upstream, client)),
                         asyncio.create_task(self._up(client, upstream, authenticated, name))}
                _done, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
                for task in pending:
                    task.cancel()
                await asyncio.gather(*pending, return_exceptions=True)
        except (OSError, ConnectionClosed, TimeoutError) as exc:
            self.warn(f'live view: WebSocket client {name}: the view\'s server did not take it: {exc}')

    async def _down(self, upstream: ClientConnection, client: ServerConnection) -> None:
        """The SDK server's frames to the client; after ``serverInfo``, the services."""
        try:
            async for frame in upstream:
                if isinstance(frame, str) and frame.startswith('{"op":"serverInfo"') and self.by_id:
                    info = json.loads(frame)
                    info['capabilities'] = [*info.get('capabilities', []), 'services']
                    await client.send(json.dumps(info))
                    await client.send(self.advertised)
                    continue
                await client.send(frame)
        except ConnectionClosed:
            pass

    async def _up(self, client: ServerConnection, upstream: ClientConnection, authenticated: bool,
                  name: str) -> None:
        """The client's frames to the SDK's server, but service calls, answered here."""
        try:
            async for frame in client:
                if isinstance(frame, bytes) and frame[:1] == b'\x02':
                    await self._service_call(client, frame, authenticated, name)
                else:
                    await upstream.send(frame)
        except ConnectionClosed:
            pass

    async def _service_call(self, client: ServerConnection, frame: bytes, authenticated: bool, name: str) -> None:
        try:
            service_id, call_id, length = struct.unpack_from('<III', frame, 1)
            encoding = frame[13:13 + length].decode('utf-8')
            if 13 + length > len(frame):
                raise ValueError('the encoding runs past the frame')
        except (struct.error, UnicodeDecodeError, ValueError) as exc:
            await self._status(client, f'invalid service call request: {exc}')
            return
        payload = frame[13 + length:]
        if not authenticated:
            self.refused_calls += 1
            service = self.by_id.get(service_id, (f'#{service_id}',))[0]
            self.warn(f'live view: service call {service} from {name} refused: no token')
            text = (f'service {service}: refused, this connection has no token (connect with ?token=... as the '
                    f'live view printed it)')
            await self._failure(client, service_id, call_id, text)
            await self._status(client, text)
            return
        if service_id not in self.by_id:
            await self._failure(client, service_id, call_id, f'no service with id {service_id}')
            return
        service, handler = self.by_id[service_id]
        if encoding not in ('json', 'cdr'):
            await self._failure(client, service_id, call_id, f'service {service}: encoding {encoding!r}: expected '
                                'json or cdr')
            return
        # the handler waits for the ROS service: on a thread, so the frames keep flowing meanwhile
        asyncio.create_task(self._answer(client, service_id, call_id, encoding, payload, handler))

    async def _answer(self, client: ServerConnection, service_id: int, call_id: int, encoding: str,
                      payload: bytes, handler: CallHandler) -> None:
        self.service_calls += 1
        try:
            response = await asyncio.to_thread(handler, encoding, payload)
        except Exception as exc:  # noqa: BLE001 (any failure of the call is the client's to read)
            await self._failure(client, service_id, call_id, str(exc))
            return
        enc = encoding.encode()
        try:
            await client.send(struct.pack('<BIII', 3, service_id, call_id, len(enc)) + enc + response)
        except ConnectionClosed:
            pass

    @staticmethod
    async def _failure(client: ServerConnection, service_id: int, call_id: int, message: str) -> None:
        try:
            await client.send(json.dumps({'op': 'serviceCallFailure', 'serviceId': service_id, 'callId': call_id,
                                          'message': message}))
        except ConnectionClosed:
            pass

    @staticmethod
    async def _status(client: ServerConnection, message: str) -> None:
        try:
            await client.send(json.dumps({'op': 'status', 'level': _ERROR, 'message': message}))
        except ConnectionClosed:
            pass

    # --- stop ---
    def stop(self) -> None:
        """Close the server and its connections, then the loop's thread."""
        async def close() -> None:
            self.server.close()
            await self.server.wait_closed()
        try:
            asyncio.run_coroutine_threadsafe(close(), self.loop).result(_START_TIMEOUT_S)
        finally:
            self._stop_loop()

    def _stop_loop(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(_START_TIMEOUT_S)
        self.loop.close()
