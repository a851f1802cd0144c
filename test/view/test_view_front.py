"""The live view's WebSocket front (crane_stiffness.view.front) without ROS: the view's servers in this process with a
Trigger handler of the test's, and clients that break the rules: a service call split into fragments (answered
with the token, refused without), an unmasked frame and an over-long one (the connection closed, the server goes on),
a request that is no handshake (400); and its frame helpers on known bytes."""
from __future__ import annotations

import re
import socket
import struct
from typing import Iterator

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from crane_stiffness.view.access import AccessPolicy
from crane_stiffness.view.wsframes import frame, frame_bounds, parse_head, unmask
from crane_stiffness.view.server import FoxgloveServer
from helpers.foxglove_client import PATIENCE_S, FoxgloveClient

SERVICE = '/load_cell/tare'


@pytest.fixture
def server() -> Iterator[tuple[FoxgloveServer, list[str], list[str]]]:
    """(the servers, the handler's calls, the warnings logged)."""
    calls: list[str] = []
    warnings: list[str] = []

    def tare(caller: str) -> tuple[bool, str]:
        calls.append(caller)
        return True, 'tared'
    fs = FoxgloveServer('127.0.0.1', 0, {}, {'/live_view/xy': ('X', {'type': 'object'})}, {SERVICE: tare},
                        lambda *_: None, lambda *_: None, warnings.append, AccessPolicy('127.0.0.1'))
    try:
        yield fs, calls, warnings
    finally:
        fs.stop()


def _call_frame(service_id: int, call_id: int) -> bytes:
    return struct.pack('<BIII', 2, service_id, call_id, 4) + b'json{}'


def test_a_fragmented_call_is_read_whole(server):
    fs, calls, _ = server
    for token, answered in ((fs.policy.token, True), (None, False)):
        client = FoxgloveClient(fs.port, token=token)
        try:
            whole = _call_frame(client.services[SERVICE]['id'], 9)
            client.ws.send([whole[:3], whole[3:11], whole[11:]])  # three frames: binary, continuation, final
            assert client.poll_until(lambda: 9 in client.responses or 9 in client.failures)
        finally:
            client.close()
        if answered:
            assert client.responses[9] == ('json', b'{"success": true, "message": "tared"}')
        else:
            assert 'no token' in client.failures[9]
    # the handler is told who calls: the client's address and its Origin (this client sends none)
    assert len(calls) == 1 and re.fullmatch(r'127\.0\.0\.1:\d+ \(Origin none\)', calls[0]), calls


def test_an_unmasked_or_overlong_frame_closes_the_connection(server):
    fs, calls, warnings = server
    for bad in (frame(2, _call_frame(1, 1)),  # unmasked: only a server may send that
                bytes([0x82, 0xFF]) + (1 << 30).to_bytes(8, 'big') + b'\0' * 4):  # a 1 GiB frame announced
        client = FoxgloveClient(fs.port, token=fs.policy.token)
        try:
            client.ws.socket.sendall(bad)
            with pytest.raises(ConnectionClosed):  # the front closes it: reading ends there
                while True:
                    client.ws.recv(timeout=PATIENCE_S)
        finally:
            client.close()
    assert any('an unmasked frame from the client' in w for w in warnings), warnings
    assert any('a frame of 1073741824 bytes from the client' in w for w in warnings), warnings
    assert calls == []
    # the server goes on serving
    client = FoxgloveClient(fs.port, token=fs.policy.token)
    try:
        assert client.call(SERVICE, 'json', b'{}', 4)[0] == 'json'
    finally:
        client.close()
    assert len(calls) == 1 and calls[0].startswith('127.0.0.1:')


def test_no_handshake_is_a_bad_request(server):
    fs, _, warnings = server
    for request in (b'hello\r\n\r\n', b'GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n',
                    b'GET / HTTP/1.1\r\nHost: a\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n'
                    b'Sec-WebSocket-Key: x\r\n\r\n'):
        with socket.create_connection(('127.0.0.1', fs.port), timeout=PATIENCE_S) as sock:
            sock.sendall(request)
            reply = b''
            while chunk := sock.recv(4096):
                reply += chunk
        assert reply.startswith(b'HTTP/1.1 400 Bad Request'), (request, reply)
    assert fs.front.refused_connections == 3
    with connect(f'ws://127.0.0.1:{fs.port}', subprotocols=['foxglove.sdk.v1'], open_timeout=PATIENCE_S) as ws:
        assert b'serverInfo' in ws.recv(timeout=PATIENCE_S, decode=False)


def test_frame_helpers():
    assert frame(1, b'hi') == b'\x81\x02hi'
    assert frame(2, bytes(300))[:4] == b'\x82\x7e\x01\x2c'
    assert frame(2, bytes(70000))[:10] == b'\x82\x7f' + (70000).to_bytes(8, 'big')
    # RFC 6455, 5.7: a masked "Hello" from a client
    masked = bytes.fromhex('818537fa213d7f9f4d5158')
    opcode, start, end, fin, mask = frame_bounds(masked, 0)
    assert (opcode, start, end, fin, mask) == (1, 6, 11, True, bytes.fromhex('37fa213d'))
    assert unmask(masked[start:end], mask) == b'Hello'
    assert frame_bounds(masked[:10], 0) is None and frame_bounds(b'\x81', 0) is None
    assert frame_bounds(b'\x01\x03Hel\x80\x02lo', 5) == (0, 7, 9, True, b'')  # the continuation after a fragment
    method, path, headers = parse_head(b'GET /?token=a HTTP/1.1\r\nHost: x:1\r\nX-A: 1\r\nx-a: 2\r\n\r\n')
    assert (method, path, headers) == ('GET', '/?token=a', {'host': ['x:1'], 'x-a': ['1', '2']})
    for bad in (b'GET /\r\n\r\n', b'GET / HTTP/1.1\r\nno colon\r\n\r\n', b'GET / HTTP/1.1\r\n Host: x\r\n\r\n'):
        with pytest.raises(ValueError):
            parse_head(bad)
