"""Who may use the live view, with real clients: the live_view node (real rclpy, DDS on loopback) beside a node
offering the Trigger service ``/session_recorder/stop`` (counting its calls: the rig's side), and

- raw WebSocket handshakes and HTTP requests: a foreign ``Origin`` or ``Host`` refused (403) at the handshake, by the
  WebSocket front and by the page's server alike; the page's own origin and an ``allowed_origins`` one accepted;
- Foxglove protocol clients: without the token a client may watch but its call is refused (a serviceCallFailure and
  a status, the service never called), with the token (``?token=`` or ``Authorization: Bearer``) it is called;
- headless Chromium: a page of another origin (a second local HTTP server) can neither open the WebSocket, even
  knowing the token, nor call a service, while the view's own page, opened at its address with the token, connects.
"""
from __future__ import annotations

import base64
import functools
import http.client
import json
import os
import socket
import threading
import time
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any, Iterator

import pytest
from rclpy.serialization import serialize_message
from std_srvs.srv import Trigger

from helpers.browser import PATIENCE_S, Browser
from helpers.foxglove_client import FoxgloveClient
from helpers.view_rig import ViewRig

SERVICE = '/session_recorder/stop'


class _Rig(ViewRig):
    """The view rig with the service a foreign page wants to call, counting its calls."""

    def __init__(self, ctx: Any, **params: Any) -> None:
        super().__init__(ctx, 'access_test_rig', **params)
        self.calls = 0
        self.pub.create_service(Trigger, SERVICE, self._stop)

    def _stop(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.calls += 1
        response.success, response.message = True, 'bag closed'
        return response

    @property
    def ws_port(self) -> int:
        assert self.view.foxglove is not None
        return self.view.foxglove.port

    @property
    def http_port(self) -> int:
        assert self.view.page is not None
        return self.view.page.port

    @property
    def token(self) -> str:
        assert self.view.foxglove is not None
        return self.view.foxglove.policy.token


@pytest.fixture
def rig(rclpy_context) -> Iterator[_Rig]:
    with _Rig(rclpy_context, allowed_origins='https://app.foxglove.dev') as r:
        yield r


def _handshake(port: int, host: str, origin: str | None = None, path: str = '/') -> tuple[int, str]:
    """A WebSocket opening handshake written by hand (any Host and Origin): (HTTP status, the response's text)."""
    lines = [f'GET {path} HTTP/1.1', f'Host: {host}', 'Upgrade: websocket', 'Connection: Upgrade',
             f'Sec-WebSocket-Key: {base64.b64encode(os.urandom(16)).decode()}', 'Sec-WebSocket-Version: 13',
             'Sec-WebSocket-Protocol: foxglove.sdk.v1']
    if origin is not None:
        lines.append(f'Origin: {origin}')
    with socket.create_connection(('127.0.0.1', port), timeout=PATIENCE_S) as sock:
        sock.sendall(('\r\n'.join(lines) + '\r\n\r\n').encode())
        reply = b''
        while b'\r\n\r\n' not in reply:
            chunk = sock.recv(4096)
            if not chunk:
                break
            reply += chunk
        if not reply.startswith(b'HTTP/1.1 101'):  # the refusal's body says why
            sock.settimeout(5.0)
            try:
                while chunk := sock.recv(4096):
                    reply += chunk
            except TimeoutError:
                pass
    text = reply.decode('latin-1')
    return int(text.split(' ', 2)[1]), text


def _page_request(port: int, path: str, headers: dict[str, str]) -> tuple[int, bytes]:
    connection = http.client.HTTPConnection('127.0.0.1', port, timeout=PATIENCE_S)
    try:
        connection.putrequest('GET', path, skip_host=True)
        for key, value in headers.items():
            connection.putheader(key, value)
        connection.endheaders()
        reply = connection.getresponse()
        return reply.status, reply.read()
    finally:
        connection.close()


def test_foreign_origin_and_host_refused_at_the_handshake(rig):
    ws, page = rig.ws_port, rig.http_port
    own = f'http://127.0.0.1:{page}'
    # the WebSocket: the page's own origin, a tool without Origin and an allowed web app connect (101) ...
    for origin in (own, f'http://localhost:{page}', None, 'https://app.foxglove.dev'):
        status, text = _handshake(ws, f'127.0.0.1:{ws}', origin)
        assert status == 101, (origin, text)
    # ... a foreign page does not, with the token or without, nor a request naming a foreign Host (DNS rebinding)
    for host, origin, path in ((f'127.0.0.1:{ws}', 'http://evil.example', '/'),
                               (f'127.0.0.1:{ws}', 'http://evil.example', f'/?token={rig.token}'),
                               (f'127.0.0.1:{ws}', f'http://127.0.0.1:{page + 1}', '/'),
                               (f'evil.example:{ws}', None, f'/?token={rig.token}'),
                               (f'evil.example:{ws}', f'http://evil.example:{page}', '/')):
        status, text = _handshake(ws, host, origin, path)
        assert status == 403, (host, origin, text)
        assert ('Origin' if 'evil' not in host else 'Host') in text.split('\r\n\r\n', 1)[1], text
    assert rig.view.foxglove is not None and rig.view.foxglove.front.refused_connections == 5
    # the page's server: the same checks, 403
    assert _page_request(page, '/config.json', {'Host': f'127.0.0.1:{page}'})[0] == 200
    assert _page_request(page, '/', {'Host': f'localhost:{page}', 'Origin': own})[0] == 200
    status, body = _page_request(page, '/config.json', {'Host': f'evil.example:{page}'})
    assert status == 403 and b'is not a name or address this server listens on' in body, body
    status, body = _page_request(page, '/config.json', {'Host': f'127.0.0.1:{page}',
                                                        'Origin': 'http://evil.example'})
    assert status == 403 and b'nor in allowed_origins' in body, body
    status, _ = _page_request(page, '/index.html', {})  # no Host at all (HTTP/1.0 style): the check cannot be made
    assert status == 403


def test_a_service_call_needs_the_token(rig):
    request = serialize_message(Trigger.Request())
    _wait_for_service(rig)
    watcher = FoxgloveClient(rig.ws_port, origin=f'http://127.0.0.1:{rig.http_port}')
    try:
        # it may watch: the channels and the services are advertised to it ...
        assert '/live_view/xy' in watcher.channels and SERVICE in watcher.services
        # ... but not call one: refused with a failure and a status, the service never called
        watcher.call_raw(watcher.services[SERVICE]['id'], 'cdr', request, 11)
        assert watcher.poll_until(lambda: 11 in watcher.failures and bool(watcher.statuses))
        assert 'no token' in watcher.failures[11] and 'no token' in watcher.statuses[-1]['message']
        assert watcher.statuses[-1]['level'] == 2
        wrong = FoxgloveClient(rig.ws_port, token=rig.token[:-1] + ('x' if rig.token[-1] != 'x' else 'y'))
        try:
            wrong.call_raw(wrong.services[SERVICE]['id'], 'json', b'{}', 12)
            assert wrong.poll_until(lambda: 12 in wrong.failures) and 'no token' in wrong.failures[12]
        finally:
            wrong.close()
    finally:
        watcher.close()
    assert rig.calls == 0
    # with the token, in the URL (the page, Foxglove, Lichtblick) or as a bearer header (tools): called
    client = FoxgloveClient(rig.ws_port, token=rig.token)
    try:
        encoding, payload = client.call(SERVICE, 'json', b'{}', 1)
        assert (encoding, json.loads(payload)) == ('json', {'success': True, 'message': 'bag closed'})
    finally:
        client.close()
    assert rig.calls == 1
    from websockets.sync.client import connect
    with connect(f'ws://127.0.0.1:{rig.ws_port}', subprotocols=['foxglove.sdk.v1'], open_timeout=PATIENCE_S,
                 additional_headers={'Authorization': f'Bearer {rig.token}'}) as tool:
        services = _services(tool)
        tool.send(b'\x02' + services[SERVICE].to_bytes(4, 'little') + (3).to_bytes(4, 'little')
                  + (3).to_bytes(4, 'little') + b'cdr' + request)
        deadline = time.monotonic() + PATIENCE_S
        while True:
            frame = tool.recv(timeout=max(0.1, deadline - time.monotonic()))
            if isinstance(frame, bytes) and frame[0] == 3:
                break
    assert frame[5:9] == (3).to_bytes(4, 'little') and rig.calls == 2
    assert rig.view.foxglove is not None and rig.view.foxglove.front.refused_calls == 2


def _services(ws: Any) -> dict[str, int]:
    """Read until the server advertised its services: name -> id."""
    deadline = time.monotonic() + PATIENCE_S
    while time.monotonic() < deadline:
        frame = ws.recv(timeout=PATIENCE_S)
        if isinstance(frame, str) and json.loads(frame).get('op') == 'advertiseServices':
            return {s['name']: s['id'] for s in json.loads(frame)['services']}
    raise AssertionError('no advertiseServices')


def _wait_for_service(rig: _Rig) -> None:
    """Until the view's client of the service sees the rig's server (DDS discovery)."""
    client = rig.view.trigger_clients[SERVICE]
    deadline = time.monotonic() + PATIENCE_S
    while not client.service_is_ready():
        assert time.monotonic() < deadline, f'{SERVICE} not discovered'
        time.sleep(0.05)


#: The foreign page: tries the view's WebSocket twice (with the token it somehow knows, and without) and, were a
#: connection to open, calls the service; it writes what happened into the DOM for the test to read.
EVIL_PAGE = """<!DOCTYPE html><html><body><pre id="log"></pre><script>
const log = (s) => { document.getElementById('log').textContent += s + '\\n'; };
const params = new URLSearchParams(location.search);
function attempt(name, url) {
  return new Promise((resolve) => {
    const ws = new WebSocket(url, ['foxglove.sdk.v1']);
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => log(name + ': open');
    ws.onmessage = (e) => {
      if (typeof e.data !== 'string') return;
      const msg = JSON.parse(e.data);
      if (msg.op === 'advertiseServices') {
        const id = msg.services.find((s) => s.name === '/session_recorder/stop').id;
        const enc = new TextEncoder().encode('json'), body = new TextEncoder().encode('{}');
        const frame = new DataView(new ArrayBuffer(13 + enc.length + body.length));
        frame.setUint8(0, 2); frame.setUint32(1, id, true); frame.setUint32(5, 1, true);
        frame.setUint32(9, enc.length, true);
        new Uint8Array(frame.buffer).set(enc, 13); new Uint8Array(frame.buffer).set(body, 13 + enc.length);
        ws.send(frame.buffer); log(name + ': called');
      }
      if (msg.op === 'serviceCallFailure') log(name + ': call failed');
    };
    ws.onclose = (e) => { log(name + ': closed ' + e.code); resolve(); };
  });
}
(async () => {
  await attempt('with token', `ws://127.0.0.1:${params.get('port')}/?token=${params.get('token')}`);
  await attempt('without token', `ws://127.0.0.1:${params.get('port')}/`);
  try {
    const r = await fetch(`http://127.0.0.1:${params.get('http_port')}/config.json`);
    log('config: ' + r.status);
  } catch (e) { log('config: blocked'); }
  document.body.dataset.done = 'yes';
})();
</script></body></html>
"""


class _EvilHandler(SimpleHTTPRequestHandler):
    def log_message(self, *args: Any) -> None:
        pass


@pytest.fixture
def evil_site(tmp_path) -> Iterator[str]:
    """Another origin on this machine: an HTTP server of the foreign page, as any site the operator opens."""
    site = tmp_path / 'evil'
    site.mkdir()
    (site / 'index.html').write_text(EVIL_PAGE)
    server = ThreadingHTTPServer(('127.0.0.1', 0), functools.partial(_EvilHandler, directory=str(site)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f'http://127.0.0.1:{server.server_address[1]}'
    finally:
        server.shutdown()
        server.server_close()


def test_a_page_of_another_origin_cannot_use_the_view_in_chromium(rig, evil_site, chromium_path, tmp_path):
    _wait_for_service(rig)
    browser = Browser(chromium_path, tmp_path / 'chromium.log')
    try:
        browser.open(f'{evil_site}/?port={rig.ws_port}&http_port={rig.http_port}&token={rig.token}')
        browser.wait_for("document.body?.dataset.done === 'yes'")
        evil_log = browser.evaluate("document.getElementById('log').textContent")
        # the view's own page at its address with the token still connects and watches
        browser.open(f'http://127.0.0.1:{rig.http_port}/?token={rig.token}')
        browser.wait_for("document.getElementById('connection')?.textContent === 'connected'")
        browser.wait_for("document.body?.dataset.run === 'one_axis'")
    finally:
        browser.close()
    lines = evil_log.split('\n')
    assert 'with token: open' not in lines and 'without token: open' not in lines, evil_log
    assert not any('called' in line for line in lines), evil_log
    assert 'with token: closed 1006' in lines and 'without token: closed 1006' in lines, evil_log  # refused
    assert 'config: blocked' in lines or 'config: 403' in lines, evil_log
    assert rig.calls == 0
    front = rig.view.foxglove.front if rig.view.foxglove is not None else None
    assert front is not None and front.refused_connections >= 2 and front.refused_calls == 0
    assert Path(tmp_path / 'chromium.log').exists()
