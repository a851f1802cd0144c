"""The live view's Foxglove WebSocket server (the ``foxglove-sdk`` wheel) and the web page's HTTP server. No ROS:
the node (crane_stiffness.nodes.live_view) gives the channels' data, what to do on a (un)subscription and the
service handlers.

Channels: the ROS topics as foxglove_bridge offers them (schema encoding ``ros2msg``, message encoding ``cdr``, the
serialized message as received) and the derived channels (JSON). Services: ``std_srvs/srv/Trigger`` calls with a
JSON (``{}``) or CDR request; the response has the request's encoding (JSON ``{"success", "message"}``).
The page is plain files served from ``web/`` with ``config.json`` telling it the WebSocket port.
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
from foxglove import Channel, Context, MessageSchema, Schema, Service, ServiceSchema
from foxglove.websocket import Capability, ChannelView, Client, ServerListener

from crane_stiffness.view.errors import ViewError

WEB_DIR = Path(__file__).with_name('web')
#: The WebSocket subprotocol the SDK's server speaks (the page and clients ask for it).
SUBPROTOCOL = 'foxglove.sdk.v1'
TRIGGER = 'std_srvs/srv/Trigger'
#: What a Trigger call returns to the server: (success, message).
TriggerHandler = Callable[[], tuple[bool, str]]


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


class FoxgloveServer:
    """The WebSocket server, its channels and services. ``subscribe(topic, wanted)`` is called when the first
    client subscribes to a ROS channel and when the last one leaves it (on a server thread)."""

    def __init__(self, host: str, port: int, ros_topics: dict[str, tuple[str, str]],
                 derived: dict[str, tuple[str, dict[str, Any]]], services: dict[str, TriggerHandler],
                 subscribe: Callable[[str, bool], None], info: Callable[[str], Any],
                 warn: Callable[[str], Any]) -> None:
        """``ros_topics``: topic -> (type 'pkg/msg/Type', ros2msg definition); ``derived``: topic -> (schema
        name, JSON schema)."""
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
        request = MessageSchema(encoding='cdr', schema=Schema(name=f'{TRIGGER}_Request', encoding='ros2msg',
                                                              data=b''))
        response = MessageSchema(encoding='cdr', schema=Schema(name=f'{TRIGGER}_Response', encoding='ros2msg',
                                                               data=b'bool success\nstring message\n'))
        self.service_calls = 0
        service_list = [Service(name, schema=ServiceSchema(TRIGGER, request=request, response=response),
                                handler=functools.partial(self._call, handler))
                        for name, handler in services.items()]
        try:
            self.server = foxglove.start_server(
                name='crane_stiffness live_view', host=host, port=port, context=self.context,
                capabilities=[Capability.Services], supported_encodings=['json', 'cdr'], services=service_list,
                server_listener=self.listener)
        except Exception as exc:  # the SDK raises its own error type: say which address
            logger.removeHandler(self._log_forward)
            raise ViewError(f'cannot serve Foxglove WebSocket on {host}:{port}: {exc}') from exc

    @property
    def port(self) -> int:
        return self.server.port

    def _call(self, handler: TriggerHandler, request: Any) -> bytes:
        self.service_calls += 1
        success, message = handler()  # an exception becomes the client's serviceCallFailure
        return _trigger_response('cdr' if request.encoding == 'cdr' else 'json', success, message)

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
        self.server.stop()
        logging.getLogger('foxglove').removeHandler(self._log_forward)


#: The kinds of run the page knows: 'one_axis' (the force-displacement fit leads) and 'six_axis' (the 6×6 leads; no
#: one-axis verdict is shown).
RUNS = ('one_axis', 'six_axis')


class _PageHandler(http.server.SimpleHTTPRequestHandler):
    ws_port = 0
    run = 'one_axis'
    log_error_fn: Callable[[str], Any] = print

    def do_GET(self) -> None:  # noqa: N802 (the http.server name)
        if self.path.split('?')[0] == '/config.json':
            body = json.dumps({'ws_port': self.ws_port, 'subprotocol': SUBPROTOCOL, 'run': self.run}).encode()
            self.send_response(200)
            self.send_header('Content-Type', 'application/json')
            self.send_header('Content-Length', str(len(body)))
            self.end_headers()
            self.wfile.write(body)
            return
        super().do_GET()

    def end_headers(self) -> None:
        self.send_header('Cache-Control', 'no-store')
        super().end_headers()

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 (the http.server signature)
        pass  # one line per request would flood the node's log


class PageServer:
    """The page (``web/``) on ``http://host:port/`` in a thread of its own; ``config.json`` names ``ws_port`` and
    the kind of ``run`` (one of :data:`RUNS`: the page lays itself out for it from its first frame)."""

    def __init__(self, host: str, port: int, ws_port: int, run: str = 'one_axis') -> None:
        if run not in RUNS:
            raise ViewError(f'run {run!r}: expected one of {", ".join(RUNS)}')
        handler = type('Handler', (_PageHandler,), {'ws_port': ws_port, 'run': run})
        try:
            self.httpd = http.server.ThreadingHTTPServer((host, port), functools.partial(handler,
                                                                                         directory=str(WEB_DIR)))
        except OSError as exc:
            raise ViewError(f'cannot serve the page on {host}:{port}: {exc.strerror}') from exc
        self.httpd.daemon_threads = True
        self.thread = threading.Thread(target=self.httpd.serve_forever, name='live_view_http', daemon=True)
        self.thread.start()

    @property
    def port(self) -> int:
        return int(self.httpd.server_address[1])

    def stop(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
