"""live_view: the rig live, for people watching a test (a thin adapter around crane_stiffness.view).

Serves, on ``host`` (127.0.0.1 by default; 0.0.0.0 opens it to the lab network):

- a Foxglove WebSocket server on ``port`` (the ``foxglove-sdk`` wheel): the rig's topics (``topics``) with their
  ROS 2 schemas (ros2msg, cdr) as foxglove_bridge offers them, each subscribed in ROS only while a client listens;
  the derived channels under /live_view/ (JSON, at ``rate_hz`` while a client listens): ``xy`` (the current fit
  segment's fitted pairs, force vs displacement, decimated to at most ``max_points`` for display), ``fit_lines``
  (each branch's line and 95 % band), ``prediction`` (the model's stiffness as a line), ``estimate``, ``status``
  (the estimator's, as text and level), ``wires``, ``scene`` (``foxglove.SceneUpdate``: the crane with its
  deflection × ``deflection_scale``, and the measured compliance ellipsoid when there is a 6×6 fit) and
  ``stiffness6`` (the six-axis estimator's K against the model's tangent, K2 and the status: sent only once that
  estimator has published); and the Trigger services ``services`` (tare, estimator reset, recording
  start/stop), forwarded to the ROS services of the same name;
- the page (crane_stiffness/view/web) on ``http_port``, which talks to the same WebSocket server.

Reads /stiffness/fitted_pairs and /stiffness/fit_lines (the estimator's pairs and fit lines: nothing is refitted
here), /stiffness/estimate_values (the estimate, and the prediction of the fitted axis), /stiffness/estimate (the
statuses, the fitted axis and its unit), /crane/wire_states,
/crane/platform_pose and /crane/applied_wrench, /stiffness6/stiffness, /stiffness6/stiffness_expanded (its U),
/stiffness6/compliance and /stiffness6/status (latched); the geometry from the geometry.* parameters (the crane file).
The high-rate inputs are taken serialized and only the newest is decoded, at ``rate_hz``. Port 0 takes a free port;
the addresses are logged at start (``live view: page http://…/?token=…, Foxglove ws://…``).

Access (crane_stiffness.view.access; docs/live_view.md, "Security"): both servers refuse a foreign ``Host`` or
``Origin`` (the page's own origin and ``allowed_origins`` pass); every service call needs the token (``token``, or a
new one at each start), and so does connecting at all when ``host`` is not a loopback address. The token is in the
page's logged address and written (0600) to ``token_file``.
"""
from __future__ import annotations

import math
import os
import threading
from pathlib import Path
from typing import Any, Callable

import numpy as np

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from crane_stiffness.contract import stiffness6_layout, topics
from crane_stiffness.model import CraneGeometry
from crane_stiffness.rosnode.qos import KEPT_QOS, LATCHED_QOS, RELIABLE_QOS, rclpy_qos
from crane_stiffness.rosnode.control_callers import CallAnnouncer
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.session_qos import message_class
from crane_stiffness.rosnode.parameters import Params, check
from crane_stiffness.rosnode.messages import stamp_to_s
from crane_stiffness.params.geometry import GEOMETRY_PARAMS, geometry_from_params
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.full6.reference import reference_at_rest
from crane_stiffness.view import plot, stiffness6
from crane_stiffness.view.access import AccessPolicy, default_token_file, write_token_file
from crane_stiffness.view.msgdefs import definition
from crane_stiffness.view.scene import SCENE_SCHEMA, SLACK_TENSION_N, CraneState, scene_update
from crane_stiffness.view.errors import ViewError
from crane_stiffness.view.server import FoxgloveServer, PageServer

PREFIX = '/live_view/'
#: The ROS topics offered by default: every rig topic, the model status, /diagnostics and the view topics.
DEFAULT_TOPICS = [*topics.RIG_TOPICS, topics.MODEL_STATUS, topics.DIAGNOSTICS, *topics.VIEW_TOPICS]
DEFAULT_SERVICES = ['/load_cell/tare', '/stiffness_estimator/reset', '/session_recorder/start',
                    '/session_recorder/stop']
_TYPES = {**topics.RIG_TOPICS, **topics.VIEW_TOPICS, topics.MODEL_STATUS: 'std_msgs/msg/String',
          topics.DIAGNOSTICS: 'diagnostic_msgs/msg/DiagnosticArray'}
#: The derived channels the Foxglove server offers: channel -> (schema name, JSON schema). What the shipped layouts
#: (foxglove/*.json) may read besides ``topics``.
DERIVED_CHANNELS: dict[str, tuple[str, dict[str, Any]]] = {
    **{PREFIX + name: (schema['title'], schema) for name, schema in plot.SCHEMAS.items()},
    PREFIX + 'scene': ('foxglove.SceneUpdate', SCENE_SCHEMA),
    PREFIX + 'stiffness6': (stiffness6.SCHEMA['title'], stiffness6.SCHEMA),
}
#: The parameters read once, at start.
_AT_START = ('host', 'port', 'http_port', 'topics', 'services', 'six_axis_program', 'token', 'token_file',
             'allowed_origins', 'allowed_hosts')
_NO_EVENTS = SubscriptionEventCallbacks(use_default_callbacks=False)
#: Every derived channel is sent at least this often (ns), changed or not.
RESEND_NS = 1_000_000_000

PARAMS = (
    ParamSpec('host', '127.0.0.1', "address both servers listen on: 127.0.0.1 = this machine only; 0.0.0.0 = every "
              "interface (the lab network) [-]"),
    ParamSpec('port', 8765, 'Foxglove WebSocket port (0: any free port, logged) [-]', low=0, high=65535),
    ParamSpec('http_port', 8080, 'port of the page (0: any free port, logged) [-]', low=0, high=65535),
    ParamSpec('rate_hz', 15.0, 'rate of the derived channels (plot, estimate, status, scene) [Hz]', above=0.0,
              at_most=100.0),
    ParamSpec('max_points', 500, 'most force-displacement points shown per segment (decimated for display; the '
              'estimator fits every pair) [-]', low=2, high=100000),
    ParamSpec('deflection_scale', 200.0, "the platform's displacement and rotation are drawn this many times larger "
              'in the 3D scene [-]', above=0.0),
    ParamSpec('six_axis_program', False, 'the rig plays a six-axis program (the rig sets it, '
              'crane_stiffness.launcher.rig_description): the page leads with the 6x6 and shows no one-axis verdict; '
              'it also does once a 6x6 fit is published [-]'),
    ParamSpec('topics', DEFAULT_TOPICS, 'ROS topics offered to Foxglove clients (types from the rig contract) [-]'),
    ParamSpec('services', DEFAULT_SERVICES, 'std_srvs/Trigger services offered through the WebSocket [-]'),
    ParamSpec('token', '', 'secret every service call through the WebSocket must present (and every connection, '
              'when host is not a loopback address); empty: a new random one at each start, shown in the page\'s '
              'logged address and written to token_file [-]', rule='empty or at least 16 printable characters '
              'without spaces'),
    ParamSpec('token_file', '', 'file the token is written to, readable by its owner only (0600), for tools; empty: '
              '$ROS_HOME (else ~/.ros)/crane_stiffness/live_view_<port>.token, removed at exit [-]'),
    ParamSpec('allowed_origins', '', 'web origins besides the page\'s own that may open the WebSocket and fetch '
              'the page, comma-separated (e.g. https://app.foxglove.dev for the Foxglove web app) [-]',
              rule='each scheme://host[:port], http or https, no path'),
    ParamSpec('allowed_hosts', '', 'host names a request\'s Host header may name besides localhost, this '
              'machine\'s name and the addresses the servers listen on, comma-separated (a DNS name of the lab PC) '
              '[-]', rule='each a host name or address'),
    ParamSpec('service_timeout_s', 5.0, 'longest wait for a forwarded service call [s]', above=0.0),
    *GEOMETRY_PARAMS,
)


def _validate(values: dict[str, Any]) -> CraneGeometry:
    for topic in values['topics']:
        check(topic in _TYPES, 'topics', topic, f'must be one of {", ".join(sorted(_TYPES))}')
    for name in values['services']:
        check(name.startswith('/'), 'services', name, 'must be an absolute service name')
    AccessPolicy(values['host'], token=values['token'] or 'x' * 16, allowed_origins=values['allowed_origins'],
                 allowed_hosts=values['allowed_hosts'])  # raises ViewError (a ValueError) naming the field
    return geometry_from_params(values)  # raises GeometryError (a ValueError) naming the field



def _port_hint(exc: ViewError, parameter: str, argument: str) -> ViewError:
    """A server that cannot listen says which parameter (and launch argument) chooses its port: 'Address already in
    use' alone left a lab guessing which of the rig's ports another program had taken."""
    if 'cannot serve' not in str(exc):
        return exc
    return ViewError(f'{exc} (parameter {parameter}; ros2 launch: {argument}:=...): another program has the port, '
                     f'or it is not free on this host: set {parameter} to a free one')


class LiveViewNode(Node):
    """Subscribes to the rig, serves the view (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('live_view', **kwargs)
        self.lock = threading.Lock()  # the wanted ROS topics, set on the server's threads
        self.wanted: dict[str, bool] = {}
        self.ros_subs: dict[str, Subscription] = {}
        self.counters = {'forwarded': 0, 'derived_sent': 0, 'service_calls': 0, 'subscriptions_changed': 0,
                         'service_calls_refused': 0, 'connections_refused': 0}
        self.foxglove: FoxgloveServer | None = None
        self.page: PageServer | None = None
        self.token_file: Path | None = None
        self.token_removable = False
        self.timer: Timer | None = None
        self.settings: dict[str, Any] = {}
        self.points: plot.PointBuffer | None = None
        self.latest: dict[str, Any] = {}  # serialized newest message per high-rate input topic
        self.fit_lines: list[float] | None = None
        self.prediction = float('nan')  # the estimator's (its values' prediction: always of its own axis)
        self.axis: tuple[str, str] | None = None  # (fitted axis, stiffness unit) from the estimator's status
        self.statuses: list[tuple[str, int, str]] = []
        self.uncertainty: dict[str, dict[str, str]] = {}  # each branch status's key/values: its U and E_n
        # the six-axis estimator's newest K and C data, and status (level, message, key-values); None: not yet
        self.k6: list[float] | None = None
        self.k6_expanded: list[float] | None = None  # K with its U (/stiffness6/stiffness_expanded)
        self.c6: list[float] | None = None
        self.status6: tuple[int, str, dict[str, str]] | None = None
        self.tangent6: Any = None  # the model's K at rest for self.geometry, computed at the first 6x6 message
        self.dirty: set[str] = set()
        self.resent_ns = 0  # when every derived channel was last sent (a client that joined since gets them all)
        self.trigger_clients = {name: self.create_client(Trigger, name) for name in DEFAULT_SERVICES}
        self.announcer = CallAnnouncer(self)  # names the WebSocket client of each call (control events)
        self.params = Params(self, PARAMS, _validate, self._apply)
        self.create_subscription(Float64MultiArray, topics.FITTED_PAIRS, self._on_pairs, RELIABLE_QOS)
        self.create_subscription(Float64MultiArray, topics.FIT_LINES, self._on_fit_lines, RELIABLE_QOS)
        self.create_subscription(DiagnosticArray, topics.STIFFNESS_ESTIMATE, self._on_estimate, KEPT_QOS)
        self.create_subscription(Float64MultiArray, topics.STIFFNESS6, self._on_k6, LATCHED_QOS)
        self.create_subscription(Float64MultiArray, topics.STIFFNESS6_EXPANDED, self._on_k6_expanded, LATCHED_QOS)
        self.create_subscription(Float64MultiArray, topics.COMPLIANCE6, self._on_c6, LATCHED_QOS)
        self.create_subscription(DiagnosticArray, topics.STIFFNESS6_STATUS, self._on_status6, LATCHED_QOS)
        for topic, msg_type in ((topics.STIFFNESS_VALUES, Float64MultiArray), (topics.WIRE_STATES, JointState),
                                (topics.PLATFORM_POSE, PoseStamped), (topics.APPLIED_WRENCH, WrenchStamped)):
            self.create_subscription(msg_type, topic, self._keeper(topic, msg_type), RELIABLE_QOS, raw=True,
                                     event_callbacks=_NO_EVENTS)

    # --- parameters, servers ---
    def _apply(self, geometry: CraneGeometry, values: dict[str, Any]) -> None:
        self.geometry = geometry
        self.tangent6 = None  # the tangent of this geometry: computed again when next needed
        if self.points is None or values['max_points'] != self.settings.get('max_points'):
            self.points = plot.PointBuffer(values['max_points'])
        if values['rate_hz'] != self.settings.get('rate_hz'):
            if self.timer is not None:
                self.destroy_timer(self.timer)
            self.timer = self.create_timer(1.0 / values['rate_hz'], self._tick)
        for name in values['services']:
            if name not in self.trigger_clients:
                self.trigger_clients[name] = self.create_client(Trigger, name)
        if self.foxglove is None:
            self._start_servers(values)
        elif any(values[k] != self.settings[k] for k in _AT_START):
            self.get_logger().warn(f'{", ".join(_AT_START)} take effect at the next start')
        self.dirty.update(('xy', 'scene', 'stiffness6'))
        self.settings = values

    def _start_servers(self, values: dict[str, Any]) -> None:
        prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
        ros = {topic: (_TYPES[topic], definition(_TYPES[topic], prefixes)) for topic in values['topics']}
        derived = dict(DERIVED_CHANNELS)
        services = {name: self._caller(name) for name in values['services']}
        logger = self.get_logger()
        host = values['host']
        policy = AccessPolicy(host, page_port=values['http_port'], token=values['token'],
                              allowed_origins=values['allowed_origins'], allowed_hosts=values['allowed_hosts'])
        try:
            self.foxglove = FoxgloveServer(host, values['port'], ros, derived, services, self._want, logger.info,
                                           logger.warn, policy)
        except ViewError as exc:
            raise _port_hint(exc, 'port', 'view_port') from None
        try:
            try:
                self.page = PageServer(host, values['http_port'], self.foxglove.port,
                                       'six_axis' if values['six_axis_program'] else 'one_axis', policy, logger.warn)
            except ViewError as exc:  # e.g. a device emulator given http_port:=8080, the page's default
                raise _port_hint(exc, 'http_port', 'view_http_port') from None
            self.token_file = (Path(values['token_file']) if values['token_file']
                               else default_token_file(self.foxglove.port))
            write_token_file(self.token_file, policy.token)
        except (ValueError, OSError):
            self.close()
            raise
        self.token_removable = not values['token_file']
        shown = '127.0.0.1' if host in ('0.0.0.0', '::', '') else host
        ws_shown = f'[{shown}]' if ':' in shown else shown
        access = ('watching open on loopback, service calls need the token' if policy.open_to_read
                  else 'every connection needs the token')
        logger.info(f'live view: page {policy.page_url(shown, self.page.port)} , Foxglove ws://{ws_shown}:'
                    f'{self.foxglove.port}/?token={policy.token} ({len(ros)} ROS topics, {len(derived)} derived '
                    f'channels, {len(services)} services; listening on {host}; {access}; token in {self.token_file})')

    def close(self) -> None:
        """Stop both servers and remove a token file of our naming (run() calls it at exit; twice does no harm)."""
        if self.page is not None:
            self.page.stop()
            self.page = None
        if self.foxglove is not None:
            self.counters['service_calls'] = self.foxglove.service_calls
            self.counters['service_calls_refused'] = self.foxglove.front.refused_calls
            self.counters['connections_refused'] = self.foxglove.front.refused_connections
            self.foxglove.stop()
            self.foxglove = None
        if self.token_file is not None and self.token_removable:
            self.token_file.unlink(missing_ok=True)

    # --- ROS topics offered, subscribed while a client listens ---
    def _want(self, topic: str, wanted: bool) -> None:
        """A server thread: the first client subscribed to ``topic`` or the last left it (handled by _tick)."""
        with self.lock:
            self.wanted[topic] = wanted

    def _update_subscriptions(self) -> None:
        with self.lock:
            changes, self.wanted = self.wanted, {}
        for topic, wanted in changes.items():
            if wanted and topic not in self.ros_subs:
                qos = topics.TOPIC_QOS.get(topic)
                profile = rclpy_qos(qos) if qos is not None else rclpy_qos(topics.RELIABLE, 100)
                self.ros_subs[topic] = self.create_subscription(message_class(_TYPES[topic]), topic,
                                                                self._forwarder(topic), profile, raw=True,
                                                                event_callbacks=_NO_EVENTS)
            elif not wanted and topic in self.ros_subs:
                self.destroy_subscription(self.ros_subs.pop(topic))
            self.counters['subscriptions_changed'] += 1

    def _forwarder(self, topic: str):
        assert self.foxglove is not None
        channel = self.foxglove.ros[topic]
        clock = self.get_clock()

        def forward(data: bytes) -> None:
            channel.log(data, log_time=clock.now().nanoseconds)
            self.counters['forwarded'] += 1
        return forward

    # --- inputs of the derived channels ---
    def _keeper(self, topic: str, msg_type: Any):
        def keep(data: bytes) -> None:
            self.latest[topic] = (data, msg_type)
            self.dirty.add(topic)
        return keep

    def _newest(self, topic: str) -> Any:
        entry = self.latest.get(topic)
        return None if entry is None else deserialize_message(entry[0], entry[1])

    def _on_pairs(self, msg: Float64MultiArray) -> None:
        assert self.points is not None
        try:
            self.points.add(msg.data)
        except ValueError as exc:  # not rows of PAIR_FIELDS (a foreign publisher): said, not fatal
            self.get_logger().warn(f'live view: {topics.FITTED_PAIRS} ignored: {exc}', throttle_duration_sec=5.0)
            return
        self.dirty.add('xy')

    def _on_fit_lines(self, msg: Float64MultiArray) -> None:
        self.fit_lines = list(msg.data)
        self.dirty.add('fit_lines')

    def _on_estimate(self, msg: DiagnosticArray) -> None:
        self.statuses = [(s.name, s.level[0] if isinstance(s.level, bytes) else int(s.level), s.message)
                         for s in msg.status]
        # each branch's U and E_n (the estimate channel carries them beside the values' repeatability interval)
        self.uncertainty = plot.branch_uncertainty([(s.name, {kv.key: kv.value for kv in s.values})
                                                    for s in msg.status])
        self.dirty.add('estimate')
        for s in msg.status:  # the fitted axis and its unit, from the first branch status that names them
            values = {kv.key: kv.value for kv in s.values}
            if 'axis' in values and 'unit' in values:
                self.axis = (values['axis'], values['unit'])
                break
        self.dirty.add('status')

    def _on_k6(self, msg: Float64MultiArray) -> None:
        self.k6 = list(msg.data)
        self.dirty.update(('stiffness6', 'scene'))

    def _on_k6_expanded(self, msg: Float64MultiArray) -> None:
        self.k6_expanded = list(msg.data)
        self.dirty.add('stiffness6')

    def _on_c6(self, msg: Float64MultiArray) -> None:
        self.c6 = list(msg.data)
        self.dirty.add('scene')

    def _on_status6(self, msg: DiagnosticArray) -> None:
        for s in msg.status[:1]:  # one status: 'stiffness6_estimator: 6x6'
            level = s.level[0] if isinstance(s.level, bytes) else int(s.level)
            self.status6 = (level, s.message, {kv.key: kv.value for kv in s.values})
            self.dirty.add('stiffness6')

    # --- outputs ---
    def _tick(self) -> None:
        self._update_subscriptions()
        fox = self.foxglove
        now = self.get_clock().now().nanoseconds
        if now - self.resent_ns >= RESEND_NS:  # the slow channels too, for clients that joined since
            self.resent_ns = now
            self.dirty.update(('status', 'fit_lines', 'scene', 'stiffness6', *self.latest))
        if fox is None or not self.dirty:
            return
        dirty, self.dirty = self.dirty, set()
        sent = 0
        try:
            sent += self._send_plot(fox, dirty, now)
            if 'status' in dirty and self.statuses:
                sent += fox.log_json(PREFIX + 'status', plot.status_message(self.statuses, self.axis), now)
            values = (self._newest(topics.STIFFNESS_VALUES) if dirty & {topics.STIFFNESS_VALUES, 'estimate'}
                      and fox.wanted(PREFIX + 'estimate') else None)
            if values is not None:  # the values' k and repeatability, the status's U and E_n
                sent += fox.log_json(PREFIX + 'estimate', plot.estimate_message(values.data, self.uncertainty), now)
            sent += self._send_crane(fox, dirty, now)
            sent += self._send_stiffness6(fox, dirty, now)
        except ValueError as exc:  # a message of the wrong shape (a foreign publisher): said, not fatal
            self.get_logger().warn(f'live view: cannot show an input: {exc}', throttle_duration_sec=5.0)
        self.counters['derived_sent'] += sent

    def _send_plot(self, fox: FoxgloveServer, dirty: set[str], now: int) -> int:
        assert self.points is not None
        sent = 0
        if topics.STIFFNESS_VALUES in dirty:  # the prediction line: the estimator's prediction, of its own axis
            values = self._newest(topics.STIFFNESS_VALUES)
            prediction = plot.estimate_message(values.data)['loading']['prediction']
            prediction = math.nan if prediction is None else prediction
            if not (prediction == self.prediction or math.isnan(prediction) and math.isnan(self.prediction)):
                self.prediction = prediction
                dirty.add('fit_lines')
        if ('xy' in dirty or 'fit_lines' in dirty) and fox.wanted(PREFIX + 'xy'):
            sent += fox.log_json(PREFIX + 'xy', self.points.message(self.fit_lines, self.prediction), now)
        if 'fit_lines' in dirty or 'xy' in dirty:
            if self.fit_lines is not None and 'fit_lines' in dirty:
                sent += fox.log_json(PREFIX + 'fit_lines', plot.fit_lines_message(self.fit_lines), now)
            rows = self.points.rows
            x_range = (float(rows[:, 1].min()), float(rows[:, 1].max())) if len(rows) else None
            sent += fox.log_json(PREFIX + 'prediction',
                                 plot.prediction_message(self.prediction, self.fit_lines, x_range), now)
        return sent

    def _send_crane(self, fox: FoxgloveServer, dirty: set[str], now: int) -> int:
        if not dirty & {topics.WIRE_STATES, topics.PLATFORM_POSE, topics.APPLIED_WRENCH, 'scene'}:
            return 0
        wires = self._newest(topics.WIRE_STATES)
        if wires is None:
            return 0
        sent = fox.log_json(PREFIX + 'wires', plot.wires_message(wires.name, wires.position, wires.effort,
                                                                 SLACK_TENSION_N), now)
        if not fox.wanted(PREFIX + 'scene'):
            return sent
        pose, wrench = self._newest(topics.PLATFORM_POSE), self._newest(topics.APPLIED_WRENCH)
        p = pose.pose if pose is not None else None
        state = CraneState(
            position=(p.position.x, p.position.y, p.position.z) if p else (0.0, 0.0, 0.0),
            orientation=(p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w) if p else
            (0.0, 0.0, 0.0, 1.0),
            tensions=list(wires.effort),
            force=(wrench.wrench.force.x, wrench.wrench.force.y, wrench.wrench.force.z) if wrench else (0.0,) * 3,
            stamp_s=stamp_to_s(wires.header.stamp))
        scene = scene_update(self.geometry, state, self.settings['deflection_scale'], self._compliance())
        return sent + fox.log_json(PREFIX + 'scene', scene, now)

    def _compliance(self) -> Any:
        """The measured translational compliance (3, 3) [m/N] of the newest 6x6 fit (its K inverted when no C came
        yet), or None without a fit."""
        if self.k6 is None:
            return None
        if self.c6 is not None:
            return stiffness6_layout.decode(self.c6)[0, :3, :3]
        k = stiffness6_layout.decode(self.k6)[0]
        return np.linalg.inv(k)[:3, :3] if np.all(np.isfinite(k)) and np.linalg.cond(k) < 1e12 else None

    def _send_stiffness6(self, fox: FoxgloveServer, dirty: set[str], now: int) -> int:
        """The 6x6 channel, once the six-axis estimator published something (never on a rig without it)."""
        if 'stiffness6' not in dirty or (self.k6 is None and self.status6 is None):
            return 0
        if not fox.wanted(PREFIX + 'stiffness6'):
            return 0
        if self.tangent6 is None:
            self.tangent6 = reference_at_rest(self.geometry).tangent
        message = stiffness6.stiffness6_message(self.k6, self.tangent6, self.status6,
                                                stiffness6.expanded_uncertainty(self.k6, self.k6_expanded))
        return int(fox.log_json(PREFIX + 'stiffness6', message, now))

    # --- services through the bridge ---
    def _caller(self, name: str) -> Callable[[str], tuple[bool, str]]:
        return lambda caller: self._call(name, caller)

    def _call(self, name: str, caller: str) -> tuple[bool, str]:
        """A server thread: call the ROS Trigger service ``name`` for the WebSocket client ``caller`` (its address
        and Origin) and wait for its answer. The call is announced first (a control event naming the client, every
        reader's acknowledgement awaited: crane_stiffness.contract.control_events), so the node serving it can say
        who stopped, tared or reset it."""
        client = self.trigger_clients[name]
        if not client.service_is_ready():
            raise RuntimeError(f'service {name} is not available (is its node running?)')
        if not self.announcer.announce(name, f"the live view's WebSocket client {caller}"):
            self.get_logger().warn(f'service {name}: the control event naming {caller} was not acknowledged in time')
        done = threading.Event()
        future = client.call_async(Trigger.Request())
        future.add_done_callback(lambda _: done.set())
        if not done.wait(self.settings['service_timeout_s']):
            raise RuntimeError(f'service {name}: no answer in {self.settings["service_timeout_s"]:g} s')
        response = future.result()
        self.get_logger().info(f'service {name} called through the WebSocket by {caller}: success={response.success}, '
                               f'{response.message}')
        return bool(response.success), str(response.message)


def main(args=None) -> int:
    return run(LiveViewNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
