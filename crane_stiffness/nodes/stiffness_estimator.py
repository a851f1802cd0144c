"""stiffness_estimator: live stiffness from load and displacement (a thin adapter around estimation.live).

Subscribes (sensor QoS: best effort, so reliable and best-effort publishers both match)
  /load_cell/wrench (WrenchStamped; the ``force_axis`` component is fitted, N or N·m),
  /lvdt/displacement (PointStamped, point.x in m) or, with ``displacement_type: float64``, a std_msgs/Float64
  channel in volts converted by ``displacement_gain`` [m/V] and ``displacement_offset`` [m] and stamped with its
  reception time;
and (reliable) /crane/wrench_command for the load branch, /crane/rejected_command (commands the crane model
rejected: no pair is fitted while one is in force, nor while an absurd command is), (transient local)
/crane/predicted_stiffness (the model's 6×6 tangent: the prediction is its stiffness along this estimator's own
``force_axis``, crane_stiffness.model.axis_stiffness, whatever axis the model's /crane/predicted_axis_stiffness
follows; so the prediction beside an estimate is always of the fitted axis, in its unit).
Pairs samples by header stamp, fits loading and unloading branches apart (windowed LS + RLS) and publishes
  /stiffness/estimate_values (Float64MultiArray, rows loading, unloading × columns VALUE_FIELDS) and
  /stiffness/stiffness (Float64, loading branch) once per batch of queued messages that changed it (a sensor
  buffer is one estimate: the newest pair's stamp is its age), and
  /stiffness/estimate (DiagnosticArray: one status per branch plus an input status with the counters) and again
  /stiffness/stiffness at ``diagnostics_rate_hz``. A part that has not begun (a branch without an estimate yet, the
  inputs before each stream's first sample) is published as level OK with a message starting 'waiting: '
  (crane_stiffness.contract.status.WAITING).
For the live view (not recorded by default): /stiffness/fitted_pairs (Float64MultiArray, every pair fitted, rows ×
PAIR_FIELDS, gathered for PAIRS_PERIOD_S) and /stiffness/fit_lines (Float64MultiArray, each branch's window as a line
with its 95 % band, rows × FIT_LINE_FIELDS, at ``diagnostics_rate_hz``).
Inputs are judged at every report: a stream silent for more than ``dropout_factor`` delivery periods (and at least
``min_silence_s``) makes the input status ERROR and both branches STALE; a stream that lost more than
``max_loss_fraction`` of its samples, or a
rejected command in force, makes them WARN. A sensor publisher whose sequence numbers start again (a restarted
sensor, which zeroes itself) or a new publisher on a sensor topic starts a new fit segment (the old window is
dropped), named in every status; so does a re-zero without a restart: a change of the latched zero epoch on
/lvdt/zero or /load_cell/tare (std_msgs/Float64, the sensor's zero/tare count; the first value starts none, nor does
one before any reading; without these topics a re-zero goes unseen).
The wrench is moved from the sensor's frame to the platform centre in crane_base (``sensor_rotation``,
``sensor_position``, ``sensor_reaction``; frames.SensorMount) before the ``force_axis`` component is taken; the
displacement stamps are corrected by ``displacement_delay_s``; the remaining delay between the streams is estimated
from the recent data (``delay_window_s``) and reported in the input status (stream_delay_*), WARN above
``max_stream_delay_s``.
Each branch's status states the expanded uncertainty U (GUM, k ≈ 2, 95 %) of its k beside the fit's statistical
interval (the repeatability), and E_n against the model: U from the window's fit and the load cell's and the LVDT's
declared calibrations (their ``calibration.*`` parameters, read from ``load_cell_nodes`` and ``lvdt_nodes`` over ROS at
start and when they change: crane_stiffness.rosnode.estimator_references; "statistical only" while none is
declared), the model's U from ``model_node``'s geometry and ``uncertainty_file`` (GUM linear law, computed once);
|E_n| > 1 is WARN (estimation.live_uncertainty).
Service ~/reset (std_srvs/Trigger) starts afresh: fits, branch tracker, pairing queues, commands held, stream health
(the counters go on). Plug in a real driver by remapping the input topics.
"""
from __future__ import annotations

from functools import partial
from typing import Any, Callable, cast

import numpy as np

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PointStamped, WrenchStamped
from rclpy.clock import ROSClock
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.time import Time
from rclpy.subscription import Subscription
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from crane_stiffness.contract import topics
from crane_stiffness.model.stiffness import axis_stiffness
from crane_stiffness.serde import CdrError, decode_float64, decode_stamped, stamp_seconds
from crane_stiffness.estimation.branch import BRANCHES
from crane_stiffness.estimation.fit_lines import FIT_LINE_FIELDS
from crane_stiffness.estimation.live import PAIR_FIELDS, VALUE_FIELDS, LiveStiffness
from crane_stiffness.estimation.settings import DISPLACEMENT_TYPE_PARAM, ESTIMATOR_PARAMS, LiveSettings
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.contract.status import wire_level
from crane_stiffness.estimation.sync import DISPLACEMENT, FORCE
from crane_stiffness.rosnode.qos import KEPT_QOS, LATCHED_QOS, RELIABLE_QOS, sensor_qos, stream_qos
from crane_stiffness.rosnode.sim_time import PeriodicOutput, SimTimeParticipant, uses_sim_time
from crane_stiffness.rosnode.control_callers import ServiceCallers
from crane_stiffness.rosnode.diagnostics import Diagnostics
from crane_stiffness.rosnode.estimator_references import EstimatorReferences
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.messages import stamp_to_s
from crane_stiffness.rosnode.parameters import Params

__all__ = ['VALUE_FIELDS', 'PARAMS', 'StiffnessEstimatorNode', 'main']

# rclpy's SingleThreadedExecutor adds QoS-event handlers to every wait set for each publisher and subscription with
# default callbacks (a few µs each per wait). The high-rate endpoints below go without: a best-effort volatile
# subscription matches every publisher, and a reliable volatile publisher every volatile subscriber.
_NO_EVENTS_SUB = SubscriptionEventCallbacks(use_default_callbacks=False)
_NO_EVENTS_PUB = PublisherEventCallbacks(use_default_callbacks=False)
#: Most queued sensor messages handled by one callback (see ``_take_queued``).
MAX_BATCH = 400
#: The fitted pairs are gathered this long before they are published (s): ~20 messages a second for the live view,
#: not one per batch beside /stiffness/estimate_values.
PAIRS_PERIOD_S = 0.05


def _take_queued(subscription) -> tuple[Any, dict] | None:
    """The next (message, message info) already queued on ``subscription``, or None.

    rclpy's executors take one message per subscription per wait (~0.2 ms for the SingleThreadedExecutor here): a DAQ
    burst of N samples on two topics would cost up to 2N waits. Taking what is queued within one callback (the call
    the SingleThreadedExecutor's own ``_take_subscription`` makes) handles a burst for the price of one wait; at 1 kHz
    it roughly halves the node's CPU and keeps the newest sample's latency at 2-3 ms.
    """
    with subscription.handle:
        return subscription.handle.take_message(subscription.msg_type, subscription.raw)

#: The node's parameters: the live estimator's settings (declared once, in estimation.settings), and the node's own.
PARAMS = (
    DISPLACEMENT_TYPE_PARAM,
    *ESTIMATOR_PARAMS,
    ParamSpec('diagnostics_rate_hz', 5.0, 'rate of /stiffness/estimate and of the nonlinearity update [Hz]',
              above=0.0),
    ParamSpec('load_cell_nodes', ['/load_cell', '/netft'], "nodes whose declared calibration (calibration.*, "
              "full_scale) counts in each branch's U: the first that answers is read, at start and when it changes; "
              "read at start [-]"),
    ParamSpec('lvdt_nodes', ['/lvdt', '/modbus_lvdt'], "nodes whose declared calibration (calibration.*, range_m) "
              "counts in each branch's U, as load_cell_nodes; read at start [-]"),
    ParamSpec('model_node', '/crane_model', "node whose geometry.* (the crane file) the model prediction's U is "
              "computed from, once; '' = no E_n; read at start [-]"),
    ParamSpec('uncertainty_file', 'uncertainty_lab.yaml', "the crane inputs' uncertainties for the prediction's U "
              '(a file of config/ or a path) [-]', rule='a readable uncertainty file'),
)


def _validate(values: dict[str, Any]) -> LiveSettings:
    """The settings of the live core (each value was checked against its declared rule by Params)."""
    return LiveSettings.from_params(values)  # ValueError naming the parameter; checks what the fits would


class StiffnessEstimatorNode(Node):
    """Feeds decoded messages to LiveStiffness and publishes what it returns."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('stiffness_estimator', **kwargs)
        # Built with the start-up settings by the first _apply (Params, below): the methods assert it is set.
        self.core: LiveStiffness | None = None
        self.settings: dict[str, Any] = {}
        self.sub_displacement: Subscription | None = None  # created by _apply, for the displacement_type
        self.drained: list = []  # (subscription, handler) taken from in turn: command, force, displacement
        self.timer: PeriodicOutput | None = None
        self.last_stiffness = float('nan')
        self.changed = False  # new pairs fitted since the last /stiffness/estimate_values
        self.pub_values = self.create_publisher(Float64MultiArray, topics.STIFFNESS_VALUES, KEPT_QOS,
                                                event_callbacks=_NO_EVENTS_PUB)
        self.pub_stiffness = self.create_publisher(Float64, topics.STIFFNESS, LATCHED_QOS,
                                                   event_callbacks=_NO_EVENTS_PUB)
        self.pub_estimate = self.create_publisher(DiagnosticArray, topics.STIFFNESS_ESTIMATE, LATCHED_QOS,
                                                  event_callbacks=_NO_EVENTS_PUB)
        self.pub_pairs = self.create_publisher(Float64MultiArray, topics.FITTED_PAIRS, RELIABLE_QOS,
                                               event_callbacks=_NO_EVENTS_PUB)
        self.pub_lines = self.create_publisher(Float64MultiArray, topics.FIT_LINES, RELIABLE_QOS,
                                               event_callbacks=_NO_EVENTS_PUB)
        self.pairs_published_s = 0.0  # node clock of the last /stiffness/fitted_pairs
        n = len(VALUE_FIELDS)
        self.values_msg = Float64MultiArray()  # reused: the layout is set once
        self.values_msg.layout.dim = [
            MultiArrayDimension(label='branch', size=len(BRANCHES), stride=len(BRANCHES) * n),
            MultiArrayDimension(label='field', size=n, stride=n)]
        # On simulated time the streams are reliable and the clock waits for this node (stage 3): nothing is lost,
        # and what arrives is held until the watermark says every input up to it is in (_drain_all).
        self.sim_time = uses_sim_time(self)
        self.held: list[tuple[bool, Callable[..., None], Any]] = []  # simulated time: (is a command, handler, msg)
        self.sub_command = self.create_subscription(WrenchStamped, topics.WRENCH_COMMAND,
                                                    self._held_until_watermark(self._on_command, command=True),
                                                    stream_qos(RELIABLE_QOS, self.sim_time))
        self.sub_rejected = self.create_subscription(WrenchStamped, topics.REJECTED_COMMAND,
                                                     self._held_until_watermark(self._on_rejected, command=True),
                                                     stream_qos(RELIABLE_QOS, self.sim_time))
        self.publisher_counts: dict[str, int] = {}  # matched publishers per sensor stream at the last report
        # The sensor streams are taken serialized and decoded here (serde.cdr): a quarter of the CPU per message.
        self.sub_force = self.create_subscription(WrenchStamped, topics.LOAD_CELL_WRENCH,
                                                  self._then_drain(self._on_force), sensor_qos(self.sim_time),
                                                  event_callbacks=_NO_EVENTS_SUB, raw=True)
        self.tangent: np.ndarray | None = None  # the model's newest 6x6 tangent (/crane/predicted_stiffness)
        self.references: EstimatorReferences | None = None  # (created once the settings are: below)
        self.params = Params(self, PARAMS, _validate, self._apply)  # subscribes the displacement
        self.create_subscription(Float64MultiArray, topics.PREDICTED_STIFFNESS, self._on_tangent, LATCHED_QOS)
        for stream, topic in ((DISPLACEMENT, topics.LVDT_ZERO), (FORCE, topics.LOAD_CELL_TARE)):
            self.create_subscription(Float64, topic, partial(self._on_zero_epoch, stream), LATCHED_QOS)
        self.create_service(Trigger, '~/reset', self._srv_reset)
        self.callers = ServiceCallers(self)  # who resets (the live view names its client)
        self.diagnostics = Diagnostics(self, self._diagnostics_report)
        self.references = EstimatorReferences(
            self, {'load_cell': self.settings['load_cell_nodes'], 'lvdt': self.settings['lvdt_nodes'],
                   'model': [self.settings['model_node']]}, lambda: self.core,
            lambda: self.settings['uncertainty_file'])
        self.sim = SimTimeParticipant(self, 3, self.sim_report, drain=self._drain_all,
                                      inputs=[topics.WRENCH_COMMAND, topics.REJECTED_COMMAND, topics.LOAD_CELL_WRENCH,
                                              topics.LVDT_DISPLACEMENT])
        for pub in (self.pub_values, self.pub_stiffness, self.pub_estimate, self.pub_pairs, self.pub_lines):
            self.sim.counted(pub)  # (the recorder, a stage above, waits for them and logs them in their step)

    def sim_report(self, t_ns: int) -> None:
        """Simulated time: every input up to ``t_ns`` has been handled (drained before this call). Held while the
        calibrations and the model's geometry are being read (EstimatorReferences.holds): the same U in every run."""
        if self.references is not None and self.references.holds(t_ns, self.sim_report):
            return
        if self.timer is not None:
            self.timer.at_watermark(t_ns)
        self.sim.report(t_ns)

    def _diagnostics_report(self) -> tuple[int, str, list[tuple[str, str]]]:
        assert self.core is not None
        level, message, pairs = self.core.input_report('diagnostics', self._now_s())
        return wire_level(level), message, pairs

    @property
    def counters(self) -> dict[str, int]:
        """Every message accounted (what ``run`` prints at exit): the input counters and the pairing's, per stream
        (see LiveStiffness.accounting)."""
        assert self.core is not None
        return self.core.accounting()

    def _now_ns(self) -> int:
        """The node's time [ns]: on simulated time the last watermark handled (PeriodicOutput.now_ns)."""
        return self.timer.now_ns() if self.timer is not None else self.get_clock().now().nanoseconds

    def _now_s(self) -> float:
        return self._now_ns() * 1e-9

    def _apply(self, settings: LiveSettings, values: dict[str, Any]) -> None:
        first = self.core is None
        if self.core is None:  # the start: segment 1 is fitted with these settings (not a change of parameters)
            self.core = LiveStiffness(settings)
            self.core.record_pairs = True  # for /stiffness/fitted_pairs
        if first or self.core.configure(settings):
            where = 'at the platform centre' if settings.force_row() is None else 'moved to the platform centre'
            self.get_logger().info(f'fitting {settings.force_axis}: window {settings.window} pairs, pairing '
                                   f'{settings.pairing_text()}, branch from {settings.branch_source}, wrench {where}, '
                                   f'displacement stamps - {settings.displacement_delay_s:g} s, '
                                   f'{settings.noise_text()}')
        if values['displacement_type'] != self.settings.get('displacement_type'):
            if self.sub_displacement is not None:
                self.destroy_subscription(self.sub_displacement)
            msg_type, handle = ((Float64, self._on_volts) if values['displacement_type'] == 'float64'
                                else (PointStamped, self._on_point))
            self.sub_displacement = self.create_subscription(msg_type, topics.LVDT_DISPLACEMENT,
                                                             self._then_drain(handle),
                                                             sensor_qos(self.sim_time),
                                                             event_callbacks=_NO_EVENTS_SUB, raw=True)
            self.drained = [(self.sub_command, self._on_command), (self.sub_rejected, self._on_rejected),
                            (self.sub_force, self._on_force), (self.sub_displacement, handle)]
            self.publisher_counts.pop(DISPLACEMENT, None)
        if values['diagnostics_rate_hz'] != self.settings.get('diagnostics_rate_hz'):
            if self.timer is None:  # (on simulated time: at the watermarks, see sim_report)
                self.timer = PeriodicOutput(self, 1.0 / values['diagnostics_rate_hz'], self._publish_estimate,
                                            self.sim_time)
            else:
                self.timer.set_period(1.0 / values['diagnostics_rate_hz'])
        self.settings = values
        self._set_prediction()  # force_axis may have changed: the prediction follows it
        if self.references is not None:
            self.references.update_prediction()  # (computed again only for a new axis or uncertainty file)

    # --- inputs: a message (sensors: serialized) and, when taken by _drain, its message info ---
    def _decode(self, data: bytes, count: int, stream: str) -> tuple[float, tuple[float, ...]] | None:
        """(stamp in s, the floats) of a stamped message, or None: counted as malformed."""
        assert self.core is not None
        try:
            sec, nanosec, values = decode_stamped(data, count)
        except CdrError:
            self.core.add_malformed(stream)
            return None
        return stamp_seconds(sec, nanosec), values

    @staticmethod
    def _sequence(info: dict | None) -> int | None:
        """The publisher's sequence number of a message (it starts at 1 for every new publisher), if known."""
        seq = (info or {}).get('publication_sequence_number') or 0
        return seq if 0 < seq < 2**63 else None  # 0 or all ones: not supported by the middleware

    def _on_force(self, data: bytes, info: dict | None = None) -> None:
        assert self.core is not None
        self.sim.received(topics.LOAD_CELL_WRENCH)
        sample = self._decode(data, 6, FORCE)
        if sample is not None and self.core.add_force(sample[0], sample[1], self._sensor_arrival_s(info),
                                                      self._sequence(info)):
            self.changed = True

    def _on_point(self, data: bytes, info: dict | None = None) -> None:
        assert self.core is not None
        self.sim.received(topics.LVDT_DISPLACEMENT)
        sample = self._decode(data, 3, DISPLACEMENT)
        if sample is not None and self.core.add_displacement(sample[0], sample[1][0], self._sensor_arrival_s(info),
                                                             self._sequence(info)):
            self.changed = True

    def _on_volts(self, data: bytes, info: dict | None = None) -> None:
        assert self.core is not None
        self.sim.received(topics.LVDT_DISPLACEMENT)
        try:
            volts = decode_float64(data)
        except CdrError:
            self.core.add_malformed(DISPLACEMENT)
            return
        if self.core.add_volts(self._arrival_s(info), volts, self._sequence(info)):
            self.changed = True

    def _on_command(self, msg: WrenchStamped, info: dict | None = None) -> None:
        assert self.core is not None
        self.sim.received(topics.WRENCH_COMMAND)
        f, m = msg.wrench.force, msg.wrench.torque
        self.core.add_command(stamp_to_s(msg.header.stamp), (f.x, f.y, f.z, m.x, m.y, m.z),
                              self._arrival_s(info))

    def _on_rejected(self, msg: WrenchStamped, info: dict | None = None) -> None:
        assert self.core is not None
        self.sim.received(topics.REJECTED_COMMAND)
        f, m = msg.wrench.force, msg.wrench.torque
        self.core.add_rejected(stamp_to_s(msg.header.stamp), (f.x, f.y, f.z, m.x, m.y, m.z), self._arrival_s(info))

    def _sensor_arrival_s(self, info: dict | None) -> float:
        """A sensor sample's arrival for the clock-skew check, s; NaN (not judged) while the node clock is at zero
        (use_sim_time before the first /clock message)."""
        arrival = self._arrival_s(info)
        return arrival if arrival > 0.0 else float('nan')

    def _arrival_s(self, info: dict | None) -> float:
        """When a message arrived, s: the middleware's reception stamp (system clock = the node clock) if known, else
        the node clock's now (always under simulated time)."""
        clock = cast(ROSClock, self.get_clock())  # a node's clock is a ROSClock (rclpy annotates a Clock)
        received = (info or {}).get('received_timestamp') or 0
        if received > 0 and not clock.ros_time_is_active:
            return received * 1e-9
        return clock.now().nanoseconds * 1e-9

    def _held_until_watermark(self, handle, command: bool = False):
        """``handle`` itself on wall-clock time; on simulated time a callback that holds the message until the
        watermark (:meth:`_drain_all` handles it then, commands first: the same order in every run)."""
        if not self.sim_time:
            return handle

        def hold(msg) -> None:
            self.held.append((command, handle, msg))
        return hold

    def _then_drain(self, handle):
        """A subscription callback: ``handle`` the message, then what is already queued (see ``_take_queued``),
        then publish the estimate once if any of them changed it.

        Message-only on purpose: rclpy's EventsExecutor (Jazzy) fails on callbacks that take the message info.
        """
        if self.sim_time:
            return self._held_until_watermark(handle)

        def callback(msg) -> None:
            # Commands and rejections already queued go first: a sample must be judged under the command in force
            # at its stamp (a command published just before it may be queued but not yet taken).
            for subscription, on_command in self.drained[:2]:
                for _ in range(MAX_BATCH):
                    taken = _take_queued(subscription)
                    if taken is None:
                        break
                    on_command(*taken)
            handle(msg)
            self._catch_up()
        return callback

    def _drain(self) -> bool:
        """Handle the queued messages: commands first (a pair's branch follows the command in effect at its stamp),
        then force and displacement alternately (neither stream runs ahead of the other). True if it stopped at
        MAX_BATCH rounds (more may be queued)."""
        for _ in range(MAX_BATCH):
            progress = False
            for subscription, handle in self.drained:
                taken = _take_queued(subscription)
                if taken is not None:
                    handle(*taken)
                    progress = True
            if not progress:
                return False
        return True

    def _drain_all(self) -> None:
        """Simulated time: handle everything held and queued (however much): the commands and rejections first (a
        pair is judged under the command in force at its stamp), then the samples in the order they came; then
        publish the estimate once if it changed."""
        held, self.held = self.held, []
        for command, handle, msg in held:
            if command:
                handle(msg)
        for subscription, handle in self.drained[:2]:
            while (taken := _take_queued(subscription)) is not None:
                handle(*taken)
        for command, handle, msg in held:
            if not command:
                handle(msg)
        while self._drain():
            pass
        if self.changed:
            self._publish_values()

    def _catch_up(self) -> None:
        """Handle what is queued (:meth:`_drain`; on simulated time only the watermark does), then publish the
        estimate once if it changed."""
        if not self.sim_time:
            self._drain()
        if self.changed:
            self._publish_values()

    def _on_zero_epoch(self, stream: str, msg: Float64) -> None:
        # The readings queued were published before the sensor's zero changed: they belong to the old segment.
        self._catch_up()
        assert self.core is not None
        if self.core.zero_epoch(stream, msg.data):
            self.get_logger().warn(f'new fit segment: {self.core.segment_reason} (zero epoch {msg.data:g})')
            self._publish_values()

    def _on_tangent(self, msg: Float64MultiArray) -> None:
        k = np.asarray(msg.data, dtype=float)
        if k.size != 36:  # not the model's 6x6 (a foreign publisher): said, not fatal
            self.get_logger().warn(f'{topics.PREDICTED_STIFFNESS}: {k.size} values, expected 36 (6x6); ignored',
                                   throttle_duration_sec=5.0)
            return
        self.tangent = k.reshape(6, 6)
        self._set_prediction()

    def _set_prediction(self) -> None:
        """The prediction of the fitted axis: the model's tangent along ``force_axis`` (N/m, or N·m/rad)."""
        if self.core is not None and self.tangent is not None:
            self.core.set_prediction(axis_stiffness(self.tangent, self.core.settings.force_axis))

    # --- outputs ---
    def _publish_values(self) -> None:
        assert self.core is not None
        self.changed = False
        self.values_msg.data = self.core.values()
        self.pub_values.publish(self.values_msg)
        self.core.published(self._now_s())
        k = self.core.headline_stiffness()
        if k != self.last_stiffness and k == k:  # changed and not NaN
            self.pub_stiffness.publish(Float64(data=k))
        self.last_stiffness = k
        self._publish_pairs(False)

    def _publish_pairs(self, now: bool) -> None:
        """/stiffness/fitted_pairs: the pairs fitted since the last one, once PAIRS_PERIOD_S has passed (or ``now``)."""
        assert self.core is not None
        t = self._now_s()
        if not now and t - self.pairs_published_s < PAIRS_PERIOD_S:
            return
        self.pairs_published_s = t
        data = self.core.take_fitted_pairs()
        if data:
            self.pub_pairs.publish(_table(data, 'pair', PAIR_FIELDS))

    def _check_publishers(self) -> None:
        """A new publisher on a sensor topic while one was already matched (a sensor restarted before its old
        publisher was found gone) starts a new fit segment."""
        assert self.core is not None and self.sub_displacement is not None  # both set by the first _apply
        for stream, sub in ((FORCE, self.sub_force), (DISPLACEMENT, self.sub_displacement)):
            count = sub.get_publisher_count()
            before = self.publisher_counts.get(stream)
            if before and count > before and self.core.health[stream].count:
                self.core.new_segment(f'a new {stream} publisher ({before} -> {count} matched)')
                self.get_logger().warn(f'new fit segment: a new {stream} publisher appeared')
            self.publisher_counts[stream] = count

    def _publish_estimate(self) -> None:
        # Judge the inputs on everything already delivered: take what is queued first.
        self._catch_up()
        self._check_publishers()
        assert self.core is not None
        stiffness = self.core.headline_stiffness()
        if stiffness == stiffness:  # not NaN; also at this slow rate, for a late subscriber during a hold
            self.pub_stiffness.publish(Float64(data=stiffness))
        self.core.refresh()
        name = self.get_fully_qualified_name()
        msg = DiagnosticArray()
        msg.header.stamp = Time(nanoseconds=self._now_ns()).to_msg()
        now = self._now_s()
        for r in self.core.report(now):
            msg.status.append(DiagnosticStatus(level=bytes([wire_level(r.level)]), name=f'{name}: {r.branch}',
                                               message=r.message, hardware_id=self.get_name(),
                                               values=[KeyValue(key=k, value=v) for k, v in r.values]))
        level, message, pairs = self.core.input_report('estimate', now)
        msg.status.append(DiagnosticStatus(level=bytes([wire_level(level)]), name=f'{name}: input', message=message,
                                           hardware_id=self.get_name(),
                                           values=[KeyValue(key=k, value=v) for k, v in pairs]))
        self.pub_estimate.publish(msg)
        self._publish_pairs(True)
        self.pub_lines.publish(_table(self.core.fit_lines(), 'branch', FIT_LINE_FIELDS))

    def _srv_reset(self, request, response):
        fitted = self.core.counters.pairs_fitted
        self.core.reset()
        self._publish_values()
        response.success = True
        response.message = (f'fits cleared, pairing, branches, commands and stream health restarted ({fitted} pairs '
                            f'fitted so far; segment {self.core.counters.segments})')
        self.get_logger().info(f'~/reset by {self.callers.caller(self.callers.service_name("~/reset"))}: '
                               f'{response.message}')
        return response


def _table(data: list[float], rows: str, columns: tuple[str, ...]) -> Float64MultiArray:
    """A row-major Float64MultiArray of ``data`` with ``len(columns)`` columns, its layout labelled."""
    n = len(columns)
    msg = Float64MultiArray(data=data)
    msg.layout.dim = [MultiArrayDimension(label=rows, size=len(data) // n, stride=len(data)),
                      MultiArrayDimension(label='field', size=n, stride=n)]
    return msg


#: The node a rig host loads (crane_stiffness.launcher.rig_host), built with its node arguments (``cli_args``).
COMPONENT = StiffnessEstimatorNode


def main(args=None) -> int:
    return run(StiffnessEstimatorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
