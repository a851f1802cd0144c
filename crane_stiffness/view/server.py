"""The live view's Foxglove WebSocket server (the ``foxglove-sdk`` wheel) and the web page's HTTP server. No ROS:
the node (crane_stiffness.nodes.live_view) gives the channels' data, what to do on a (un)subscription and the
service handlers.

Channels: the ROS topics as foxglove_bridge offers them (schema encoding ``ros2msg``, message encoding ``cdr``, the
serialized message as received) and the derived channels (JSON). Services: ``std_srvs/srv/Trigger`` calls with a
JSON (``{}``) or CDR request; the response has the request's encoding (JSON ``{"success", "message"}``).
The page is plain files served from ``web/`` with ``config.json`` telling it the WebSocket port.

Who may use them is the access policy's to say (``view/access.py``): the SDK's server listens on a private loopback
port without services, behind the front (``view/front.py``) on the public port, which checks each handshake and
answers the service calls; the page's server refuses a foreign ``Host`` or ``Origin`` (HTTP 403).
"""
from __future__ import annotations

import functools
import http.server
import json
import logging
import threading
from pathlib import Path
from typing import Any, Callable

import foxglove
from foxglove import Channel, Context, Schema
from foxglove.websocket import ChannelView, Client, ServerListener

from crane_stiffness.view.access import AccessPolicy
from crane_stiffness.view.errors import ViewError
from crane_stiffness.view.front import SUBPROTOCOLS, WebSocketFront

WEB_DIR = Path(__file__).with_name('web')
#: The WebSocket subprotocol the page asks for.
SUBPROTOCOL = SUBPROTOCOLS[0]
TRIGGER = 'std_srvs/srv/Trigger'
#: A Trigger call for a client (its address and Origin in words) -> (success, message).
TriggerHandler = Callable[[str], tuple[bool, str]]


class _Listener(ServerListener):
    """Subscriptions of clients to ROS channels, counted per channel: the node subscribes to a ROS topic only while
    some client wants it (as foxglove_bridge does). Called on the server's threads."""

    def __init__(self, on_change: Callable[[str, bool], None]) -> None:
        self.on_change = on_change
        self.clients: dict[int, set[int]] = {}  # channel id -> client ids
        self.lock = threading.Lock()
        self.topics: dict[int, str] = {}  # ROS channel id -> topic

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        if channel.id not in self.topics:
            return
        with self.lock:
            ids = self.clients.setdefault(channel.id, set())
            first = not ids
            ids.add(client.id)
        if first:
            self.on_change(self.topics[channel.id], True)

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        if channel.id not in self.topics:
            return
        with self.lock:
            ids = self.clients.get(channel.id, set())
            ids.discard(client.id)
            last = not ids
        if last:
            self.on_change(self.topics[channel.id], False)


class _LogForward(logging.Handler):
    """The SDK's own log (client connects and leaves, invalid messages) into the node's log."""

    def __init__(self, info: Callable[[str], Any], warn: Callable[[str], Any]) -> None:
        super().__init__(logging.INFO)
        self.info, self.warn = info, warn

    def emit(self, record: logging.LogRecord) -> None:
        text = f'foxglove: {record.getMessage()}'
        # Two call sites: rclpy refuses a change of severity between calls from one line (raises ValueError).
        if record.levelno >= logging.WARNING:
            self.warn(text)
        else:
            self.info(text)


def _trigger_response(encoding: str, success: bool, message: str) -> bytes:
    if encoding == 'cdr':  # std_srvs/srv/Trigger_Response: bool, string (CDR little endian)
        text = message.encode('utf-8') + b'\0'
        return (b'\x00\x01\x00\x00' + bytes([1 if success else 0]) + b'\0' * 3 + len(text).to_bytes(4, 'little')
                + text)
    return json.dumps({'success': success, 'message': message}).encode('utf-8')


def _advertised(name: str) -> dict[str, Any]:
    """A Trigger service as the protocol advertises it (without its id)."""
    return {'type': TRIGGER,
            'request': {'encoding': 'cdr', 'schemaName': f'{TRIGGER}_Request', 'schemaEncoding': 'ros2msg',
                        'schema': ''},
            'response': {'encoding': 'cdr', 'schemaName': f'{TRIGGER}_Response', 'schemaEncoding': 'ros2msg',
                         'schema': 'bool success\nstring message\n'}}


class FoxgloveServer:
    """The WebSocket server, its channels and services: the SDK's server on a private loopback port, the front
    (:class:`WebSocketFront`) on ``host:port``, both under ``policy``. ``subscribe(topic, wanted)`` is called when
    the first client subscribes to a ROS channel and when the last one leaves it (on a server thread)."""

    def __init__(self, host: str, port: int, ros_topics: dict[str, tuple[str, str]],
                 derived: dict[str, tuple[str, dict[str, Any]]], services: dict[str, TriggerHandler],
                 subscribe: Callable[[str, bool], None], info: Callable[[str], Any],
                 warn: Callable[[str], Any], policy: AccessPolicy | None = None) -> None:
        """``ros_topics``: topic -> (type 'pkg/msg/Type', ros2msg definition); ``derived``: topic -> (schema
        name, JSON schema); ``policy``: who may connect and call (None: a new one for ``host``, a new token)."""
        self.policy = policy if policy is not None else AccessPolicy(host)
        self.context = Context()
        self.listener = _Listener(subscribe)
        self._log_forward = _LogForward(info, warn)
        logger = logging.getLogger('foxglove')
        logger.setLevel(logging.INFO)
        logger.addHandler(self._log_forward)
        logger.propagate = False
        self.ros: dict[str, Channel] = {}
        for topic, (msg_type, text) in ros_topics.items():
            channel = Channel(topic, schema=Schema(name=msg_type, encoding='ros2msg', data=text.encode('utf-8')),
                              message_encoding='cdr', context=self.context)
            self.ros[topic] = channel
            self.listener.topics[channel.id()] = topic
        self.derived = {topic: Channel(topic, schema=Schema(name=name, encoding='jsonschema',
                                                            data=json.dumps(schema).encode('utf-8')),
                                       message_encoding='json', context=self.context)
                        for topic, (name, schema) in derived.items()}
        try:
            # no services here: whoever reaches this private port can only watch; the front answers the calls
            self.server = foxglove.start_server(
                name='crane_stiffness live_view', host='127.0.0.1', port=0, context=self.context,
                supported_encodings=['json', 'cdr'], server_listener=self.listener)
        except Exception as exc:  # the SDK raises its own error type: say which address
            logger.removeHandler(self._log_forward)
            raise ViewError(f'cannot serve Foxglove WebSocket on 127.0.0.1 (private port): {exc}') from exc
        calls = {name: (_advertised(name), functools.partial(self._call, handler))
                 for name, handler in services.items()}
        try:
            self.front = WebSocketFront(host, port, self.server.port, self.policy, calls, info, warn)
        except ViewError:
            self.server.stop()
            logger.removeHandler(self._log_forward)
            raise

    @property
    def port(self) -> int:
        """The public port (the front's)."""
        return self.front.port

    @property
    def service_calls(self) -> int:
        return self.front.service_calls

    @staticmethod
    def _call(handler: TriggerHandler, encoding: str, _payload: bytes, caller: str) -> bytes:
        success, message = handler(caller)  # an exception becomes the client's serviceCallFailure
        return _trigger_response(encoding, success, message)

    def log_json(self, topic: str, message: dict[str, Any], log_time_ns: int) -> bool:
        """Send ``message`` on a derived channel if a client listens; True if sent."""
        channel = self.derived[topic]
        if not channel.has_sinks():
            return False
        channel.log(json.dumps(message, allow_nan=False).encode('utf-8'), log_time=log_time_ns)
        return True

    def wanted(self, topic: str) -> bool:
        """Whether some client listens on derived channel ``topic``."""
        return self.derived[topic].has_sinks()

    def stop(self) -> None:
        self.front.stop()
        self.server.stop()
        logging.getLogger('foxglove').removeHandler(self._log_forward)


#: The kinds of run the page knows: 'one_axis' (the force-displacement fit leads) and 'six_axis' (the 6×6 leads; no
#: one-axis verdict is shown).
RUNS = ('one_axis', 'six_axis')


class _PageHandler(http.server.SimpleHTTPRequestHandler):
    ws_port = 0
    run = 'one_axis'
    policy: AccessPolicy
    warn: Callable[[str], Any] = print

    def do_GET(self) -> None:  # noqa: N802 (the http.server name)
        if self._refused():
            return
        if self.path.split('?')[0] == '/config.json':
            body = json.dumps({'ws_port': self.ws_port, 'subprotocol': SUBPROTOCOL, 'run': self.run}).encode()
            self.send_response(200)
            self.send_header('Content-Type', 'application/json')
            self.send_header('Content-Length', str(len(body)))
            self.end_headers()
            self.wfile.write(body)
            return
        super().do_GET()

    def do_HEAD(self) -> None:  # noqa: N802 (the http.server name)
        if not self._refused():
            super().do_HEAD()

    def _refused(self) -> bool:
        """Refuse (403) a request whose Host or Origin the policy refuses; whether it was."""
        reason = self.policy.host_refusal(self.headers.get('Host')) or self.policy.origin_refusal(
            self.headers.get('Origin'))
        if reason is None:
            return False
        self.warn(f'live view: page request from {self.client_address[0]}:{self.client_address[1]} (Origin '
                  f'{self.headers.get("Origin", "none")}) refused: {reason}')
        self.send_error(403, 'Forbidden', reason)
        return True

    def end_headers(self) -> None:
        self.send_header('Cache-Control', 'no-store')
        super().end_headers()

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (the http.server signature)
        pass  # one line per request would flood the node's log


class PageServer:
    """The page (``web/``) on ``http://host:port/`` in a thread of its own; ``config.json`` names ``ws_port`` and
    the kind of ``run`` (one of :data:`RUNS`: the page lays itself out for it from its first frame)."""

    def __init__(self, host: str, port: int, ws_port: int, run: str = 'one_axis', policy: AccessPolicy | None = None,
                 warn: Callable[[str], Any] = print) -> None:
        """``policy``: the Host and Origin checks (None: a new one for ``host``, allowing this page's origin)."""
        if run not in RUNS:
            raise ViewError(f'run {run!r}: expected one of {", ".join(RUNS)}')
        self.policy = policy if policy is not None else AccessPolicy(host)
        handler = type('Handler', (_PageHandler,), {'ws_port': ws_port, 'run': run, 'policy': self.policy,
                                                    'warn': staticmethod(warn)})
        try:
            self.httpd = http.server.ThreadingHTTPServer((host, port), functools.partial(handler,
                                                                                         directory=str(WEB_DIR)))
        except OSError as exc:
            raise ViewError(f'cannot serve the page on {host}:{port}: {exc.strerror}') from exc
        self.httpd.daemon_threads = True
        if not self.policy.page_port:  # port 0: the page's origin is known once bound
            self.policy.page_port = self.port
        self.thread = threading.Thread(target=self.httpd.serve_forever, name='live_view_http', daemon=True)
        self.thread.start()

    @property
    def port(self) -> int:
        return int(self.httpd.server_address[1])

    def stop(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
