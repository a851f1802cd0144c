"""A Foxglove WebSocket client for the live view tests, written from the protocol (the ``foxglove.sdk.v1``
subprotocol): JSON control messages (serverInfo, advertise, advertiseServices, subscribe, status) and binary frames
(opcode 1 messageData: u32 subscription id, u64 log time, payload; 2 serviceCallRequest: u32 service id, u32 call
id, u32 encoding length, encoding, payload; 3 serviceCallResponse, the same layout). Imports no rclpy.

The connection neither pings nor stops reading: the tests check what the server sends, not how fast it answers a
keepalive ping, and a client that reads from the socket only in :meth:`FoxgloveClient.poll` (websockets' default
``max_queue``) would leave the server's frames, pongs included, unread between two polls. A test waits for what it
needs with :meth:`FoxgloveClient.poll_until`, under a deadline only a hung server exceeds.
"""
from __future__ import annotations

import json
import struct
import time
from typing import Any, Callable

from websockets.sync.client import ClientConnection, connect
from websockets.typing import Origin

from helpers import PATIENCE_S  # re-exported: the view tests import it from here

SUBPROTOCOL = 'foxglove.sdk.v1'


class FoxgloveClient:
    """One connection: what the server advertised, and the messages of the subscribed channels by topic."""

    def __init__(self, port: int, host: str = '127.0.0.1', timeout_s: float = PATIENCE_S, *, token: str | None = None,
                 origin: str | None = None) -> None:
        """``token``: sent as ``?token=`` (the view's service calls need it); ``origin``: an Origin header, as a
        browser's page sends it (None: none, as a tool's client)."""
        query = f'/?token={token}' if token is not None else ''
        # no keepalive pings (ping_interval=None), and the receiving thread buffers every frame (max_queue=None)
        # instead of pausing until the test reads: the connection stays up however long the test looks away
        self.ws: ClientConnection = connect(f'ws://{host}:{port}{query}', subprotocols=[SUBPROTOCOL],
                                            origin=Origin(origin) if origin else None,
                                            open_timeout=timeout_s, max_size=None, max_queue=None,
                                            ping_interval=None, legacy=True)
        self.server_info: dict[str, Any] = {}
        self.channels: dict[str, dict[str, Any]] = {}  # topic -> advertised channel
        self.services: dict[str, dict[str, Any]] = {}  # name -> advertised service
        self.statuses: list[dict[str, Any]] = []
        self.messages: dict[str, list[bytes]] = {}  # topic -> payloads, oldest first
        self.responses: dict[int, tuple[str, bytes]] = {}  # call id -> (encoding, payload)
        self.failures: dict[int, str] = {}  # call id -> message
        self._subscriptions: dict[int, str] = {}
        self.poll_until(lambda: bool(self.server_info and self.channels and self.services), timeout_s)

    def poll(self, duration_s: float) -> None:
        """Receive for ``duration_s``."""
        end = time.monotonic() + duration_s
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return
            try:
                frame = self.ws.recv(timeout=left)
            except TimeoutError:
                return
            self._handle(frame)

    def poll_until(self, condition: Callable[[], bool], timeout_s: float = PATIENCE_S) -> bool:
        """Receive until ``condition()`` holds (checked every 50 ms) or ``timeout_s`` passed; whether it holds."""
        deadline = time.monotonic() + timeout_s
        while not condition():
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self.poll(min(left, 0.05))
        return True

    def _handle(self, frame: str | bytes) -> None:
        if isinstance(frame, str):
            msg = json.loads(frame)
            op = msg.get('op')
            if op == 'serverInfo':
                self.server_info = msg
            elif op == 'advertise':
                self.channels.update({c['topic']: c for c in msg['channels']})
            elif op == 'advertiseServices':
                self.services.update({s['name']: s for s in msg['services']})
            elif op == 'status':
                self.statuses.append(msg)
            elif op == 'serviceCallFailure':
                self.failures[msg['callId']] = msg['message']
            return
        op = frame[0]
        if op == 1:
            sub_id, _log_time = struct.unpack_from('<IQ', frame, 1)
            topic = self._subscriptions.get(sub_id)
            if topic is not None:
                self.messages.setdefault(topic, []).append(bytes(frame[13:]))
        elif op == 3:
            _service, call, length = struct.unpack_from('<III', frame, 1)
            self.responses[call] = (frame[13:13 + length].decode(), bytes(frame[13 + length:]))

    def subscribe(self, *topics: str) -> None:
        subs = []
        for topic in topics:
            sub_id = len(self._subscriptions) + 1
            self._subscriptions[sub_id] = topic
            subs.append({'id': sub_id, 'channelId': self.channels[topic]['id']})
        self.ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subs}))

    def json_messages(self, topic: str) -> list[dict[str, Any]]:
        return [json.loads(p) for p in self.messages.get(topic, [])]

    def call(self, service: str, encoding: str, payload: bytes, call_id: int, timeout_s: float = PATIENCE_S
             ) -> tuple[str, bytes]:
        """Call an advertised service; (encoding, payload) of the response (AssertionError on a failure)."""
        self.call_raw(self.services[service]['id'], encoding, payload, call_id)
        self.poll_until(lambda: call_id in self.responses or call_id in self.failures, timeout_s)
        assert call_id not in self.failures, f'{service}: {self.failures[call_id]}'
        assert call_id in self.responses, f'{service}: no answer in {timeout_s:g} s'
        return self.responses[call_id]

    def call_raw(self, service_id: int, encoding: str, payload: bytes, call_id: int) -> None:
        enc = encoding.encode()
        self.ws.send(struct.pack('<BIII', 2, service_id, call_id, len(enc)) + enc + payload)

    def close(self) -> None:
        self.ws.close()
