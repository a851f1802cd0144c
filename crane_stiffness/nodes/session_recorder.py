"""session_recorder: records a test session of the rig to a rosbag2 bag (MCAP) with the session's description.

Subscribes to ``topics`` (default: every rig topic, crane_stiffness.contract.topics.RIG_TOPICS) as serialized
messages, each with the QoS that matches its publishers, and writes them with crane_stiffness.bag.BagWriter to
``<output_dir>/<session>/`` (metadata.yaml + ``<session>_<n>.mcap``, chunked, zstd, optionally split), each channel
with its publishers' offered QoS. Log time = receive time, publish time = the header stamp (else the log time). On
simulated time each message is held until its step is complete and logged at its stamp or at that step, the same in
every run (crane_stiffness.sim.log_times; the recorder is the lock-step's last stage, see docs/simulated_time.md).

The session record (MCAP metadata ``crane_stiffness/session``, crane_stiffness.bag.session_metadata): the rig's
geometry with the derived l0 and k, the test program, the sensor sections and text of the parameter files it was
started with, software version, start time and ``notes``; the parameters the rig's nodes actually run with
(``record_node_parameters``, the drivers' too, read over ROS once they appear, calibration.* among them) in
``crane_stiffness/node_parameters``; on close ``crane_stiffness/session_end`` (stop reason, end time, counts; on
simulated time the rig's own publish counts against the bag's). The offline analysis prefers the nodes' own values.

Recording starts by itself (``autostart``) or with ~/start; ~/stop closes the bag (both std_srvs/Trigger), naming its
caller in the log and the session end (``stopped_by``; crane_stiffness.contract.control_events). With
``stop_on_program_done`` it stops once the program is done: on simulated time at the instant the program fixed, else
``stop_delay_s`` after /load_program/state says 'done' (crane_stiffness.rosnode.program_end). Ctrl-C and SIGTERM close
the bag cleanly, also when repeated; after SIGKILL every chunk written so far (at most ``flush_interval_s`` old) is
readable and ``crane-stiffness recover BAG`` rewrites the files. It runs all day: its freed memory goes back to the
system every ``TRIM_INTERVAL_S`` (crane_stiffness.rosnode.malloc_trim).

A write the system refuses (disk full, I/O error) stops the recording, not the node (ERROR; the file cut after its
last complete chunk, metadata.yaml from what is on disk; ~/start opens a new bag). Every message is counted
(FINAL_COUNTERS): ``received = written + dropped_*``, one counter per reason (docs/recording.md).
"""
from __future__ import annotations

import threading
import time
from functools import partial
from pathlib import Path
from typing import Any, Sequence

from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription
from rclpy.timer import Timer
from std_msgs.msg import String
from std_srvs.srv import Trigger

from crane_stiffness import __version__
from crane_stiffness.contract import topics
from crane_stiffness.contract.control_events import RECORDER_CUT_STATUS
from crane_stiffness.bag import BagWriter, dump_qos_profiles
from crane_stiffness.bag.errors import BagError, BagWriteFailedError
from crane_stiffness.rosnode.diagnostics import Diagnostics
from crane_stiffness.rosnode.malloc_trim import TRIM_INTERVAL_S, release_free_memory, trim_available
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.control_callers import ServiceCallers
from crane_stiffness.rosnode.parameter_reader import NodeParameterReader, plain
from crane_stiffness.rosnode.parameters import Params
from crane_stiffness.rosnode.program_end import ProgramEnd
from crane_stiffness.rosnode.qos import SIM_STREAM_QOS
from crane_stiffness.rosnode.recorded_channel import NO_EVENTS, SIM_INPUTS, SIM_OUTPUTS, RecordedChannel, deep
from crane_stiffness.rosnode.sim_time import SimTimeParticipant, drain, uses_sim_time
from crane_stiffness.rosnode.session_recorder_params import PARAMS, recorder_session_record, session_dir, validate
from crane_stiffness.rosnode.session_qos import (adapted_qos, contract_qos, offered_profiles, publisher_types)
from crane_stiffness.params.files import params_files_from_args
from crane_stiffness.serde import header_stamp_ns
from crane_stiffness.bag.session_metadata import (NODE_PARAMETERS_METADATA, SESSION_END_METADATA, SESSION_METADATA,
                                                  session_end_record)
from crane_stiffness.sim.log_times import SimLogTimes
from crane_stiffness.contract.status import ERROR, OK


class SessionRecorder(Node):
    """Idle ⇄ recording; one BagWriter per recording. See the module docstring."""

    def __init__(self, params_files: Sequence[str] = (), **kwargs: Any) -> None:
        super().__init__('session_recorder', **kwargs)
        # Simulated time: /clock is recorded too, the sensor streams are taken reliably, and the clock waits for
        # this node (stage 4, above the estimators: their outputs too), so nothing published is lost at any load.
        self.sim_time = uses_sim_time(self)
        self.before_time: list[tuple[RecordedChannel, bytes]] = []  # received on simulated time before it started
        # Simulated time: the messages held until their simulated time is complete, with their log times (per
        # recording; None on the wall clock)
        self.log_times: SimLogTimes[tuple[RecordedChannel, bytes, int | None]] | None = None
        self.writer: BagWriter | None = None
        self.bag_path: Path | None = None
        self.channels: dict[str, RecordedChannel] = {}
        self.pending: list[str] = []          # topics outside the contract not yet seen in the graph
        self.last_bag: Path | None = None
        self.last_count = 0
        self.recordings = 0
        self.errors = 0
        self.status = 'idle'
        self.write_errors = 0                   # recordings stopped by a write error
        self.write_failure: str | None = None   # the write error that stopped the last recording (cleared by start)
        self.received = 0                       # every message callback (all recordings)
        self.written = 0                        # on disk, recordings closed so far
        self.dropped = {'not_recording': 0, 'write_error': 0, 'lost_with_chunk': 0, 'rejected': 0, 'after_end': 0,
                        'clock_repeat': 0}
        self.state_subscription: Subscription | None = None
        self.program = ProgramEnd()  # the program's state, and the session's end (this recording)
        self.stop_timer: Timer | None = None
        self.exit_requested = False
        self.exit_status = 0  # run.run's exit status: RECORDER_CUT_STATUS once a ~/stop cut the recording
        self.node_parameters: dict[str, dict[str, Any]] = {}
        self.parameter_reader: NodeParameterReader | None = None
        self._flushed_at = 0
        self._lock = threading.Lock()
        # (the files it records: given, else those of its own node arguments, as a rig host builds it)
        self.params_files = list(params_files) or params_files_from_args(kwargs.get('cli_args') or [])
        self.built: dict[str, Any] = {}
        self.params = Params(self, PARAMS, validate, self._apply)
        self.create_service(Trigger, '~/start', self._srv_start)
        self.create_service(Trigger, '~/stop', self._srv_stop)
        self.callers = ServiceCallers(self)  # who calls ~/stop (the live view names its client)
        self.diagnostics = Diagnostics(self, self._report)
        recorded = {self.resolve_topic_name(t) for t in self.params['topics']}
        outputs = [t for t in SIM_OUTPUTS if t in recorded]
        self.sim = SimTimeParticipant(self, 4, self._sim_report, drain=self._drain_channels,
                                      inputs=[t for t in SIM_INPUTS if t in recorded] + outputs, soft=outputs)
        self.discovery_timer = self.create_timer(0.2, self._discover)
        self.flush_timer: Timer | None = None
        # A recorder runs all day: the pages its allocator freed go back to the system now and then (malloc_trim).
        self.trim_timer = self.create_timer(TRIM_INTERVAL_S, release_free_memory)
        if not trim_available():
            self.get_logger().info('this C library has no malloc_trim: freed memory stays with the process')
        if self.params['autostart']:
            self.start()  # a bad output directory stops the node at start with the reason

    # --- parameters ---
    def _apply(self, built: dict[str, Any], values: dict[str, Any]) -> None:
        self.built = built

    # --- recording ---
    @property
    def recording(self) -> bool:
        return self.writer is not None

    def _session_dir(self) -> Path:
        # Named by the wall clock also on simulated time (which starts at the same instant in every run).
        now_ns = time.time_ns() if self.sim_time else self.get_clock().now().nanoseconds
        return session_dir(self.params['output_dir'], self.params['session'], self.recordings, now_ns)

    def start(self) -> Path:
        """Open a new bag and subscribe; returns its directory. Raises BagError/OSError if it cannot be created."""
        if self.writer is not None:
            assert self.bag_path is not None  # set with the writer
            return self.bag_path
        p = self.params
        path = self._session_dir()
        start_ns = self.get_clock().now().nanoseconds
        self.writer = BagWriter(
            path, compression=p['compression'], chunk_size=int(p['chunk_size']),
            split_max_bytes=int(p['split_max_bytes']) or None,
            split_max_duration_s=float(p['split_max_duration_s']) or None,
            flush_interval_s=float(p['flush_interval_s']) or None, fsync=bool(p['fsync']),
            custom_data={'session': path.name, 'software_version': __version__})
        self.bag_path = path
        # (simulated time: /clock logged at the time it says, once, like the paced streams at their stamps)
        self.log_times = SimLogTimes(self.sim.inputs, distinct=[topics.CLOCK]) if self.sim.active else None
        self.joined_ns: int | None = None  # simulated time: the first watermark of this recording
        self.recordings += 1
        self.write_failure = None
        self.program = ProgramEnd()
        self._flushed_at = 0
        try:
            self.writer.add_metadata(SESSION_METADATA, self._session_record(path.name, start_ns))
            self.node_parameters = {}
            self.parameter_reader = NodeParameterReader(self, self.params['record_node_parameters'],
                                                        self._on_node_parameters)
            self._subscribe_all()
        except BaseException as exc:
            self.stop('failed to start')
            if isinstance(exc, BagWriteFailedError):
                self.write_failure = str(exc)
            raise
        if p['flush_interval_s'] > 0:
            self.flush_timer = self.create_timer(float(p['flush_interval_s']), self._flush)
        self.status = f'recording to {path}'
        self.get_logger().info(f'recording {len(self.channels)} topic(s) to {path}')
        return path

    def stop(self, reason: str = 'service', through_ns: int | None = None, by: str = '') -> tuple[Path | None, int]:
        """Close the bag (metadata.yaml written), unsubscribe; returns (bag directory, messages written). ``by``: who
        called ~/stop (the session end's ``stopped_by``). ``through_ns``: simulated time, the session's end [ns]: what
        is held up to it is written, anything logged later is left out (counted as ``after_end``), so the bag ends at
        the same instant in every run."""
        if self.writer is not None:  # (outside the lock: a write error in them stops the recording itself)
            self._write_before_time(self.get_clock().now().nanoseconds)  # time never started: logged at 0, not lost
            self._release(through_ns)  # simulated time: what is held, in log-time order
            if through_ns is not None and self.log_times is not None:
                self.dropped['after_end'] += len(self.log_times.release_all())
        with self._lock:
            writer, self.writer = self.writer, None
            if writer is None:
                return self.last_bag, self.last_count
            for timer_name in ('stop_timer', 'flush_timer'):
                timer = getattr(self, timer_name)
                if timer is not None:
                    self.destroy_timer(timer)
                    setattr(self, timer_name, None)
            self._unsubscribe_all()
            self.sim.leave()  # simulated time: no more inputs taken, so none waited for
            if self.parameter_reader is not None:
                self.parameter_reader.close()
                self.parameter_reader = None
            count = writer.message_count
            try:
                writer.add_metadata(SESSION_END_METADATA, session_end_record(
                    reason, self.get_clock().now().nanoseconds if through_ns is None else through_ns, count,
                    {c.topic: c.count for c in self.channels.values()}, self.program.state,
                    self.sim.published, self.sim.watermark_ns, at_end=through_ns is not None, stopped_by=by or None))
            except BagWriteFailedError as exc:
                self._note_write_failure(exc)
            except BagError:
                pass  # stopped by an earlier write error: reported then
            try:
                writer.close()
            except BagWriteFailedError as exc:
                self._note_write_failure(exc)
            count = writer.message_count  # after a write error: what is on disk
            self.written += count
            self.dropped['lost_with_chunk'] += writer.lost_messages
            self.last_bag, self.last_count = self.bag_path, count
            self.bag_path = None
            if self.write_failure is not None:
                self.status = (f'recording stopped by a write error: {self.write_failure}; {writer.salvage}; '
                               'call ~/start once there is room')
                self.get_logger().error(f'{self.last_bag}: {writer.salvage}')
            else:
                self.status = f'idle; last bag {self.last_bag} ({count} messages, {reason})'
                self.get_logger().info(f'closed {self.last_bag}: {count} messages ({reason}{" by " * bool(by)}{by})')
            return self.last_bag, count

    def _note_write_failure(self, exc: BagWriteFailedError) -> None:
        """Count and log a write error once (the first one stops the writer)."""
        if self.write_failure is None:
            self.write_errors += 1
            self.write_failure = str(exc)
            self.get_logger().error(f'recording stopped: {exc}')

    def _write_failed(self, exc: BagWriteFailedError) -> None:
        """A write the disk refused: stop this recording (closing the bag as far as the disk allows), keep the node
        running; ~/start begins a new bag."""
        self._note_write_failure(exc)
        self.stop('write error')

    def close(self) -> None:
        """Called by ``run`` on every exit (Ctrl-C, SIGTERM, end of spin): close the bag, writing metadata.yaml.

        A repeated Ctrl-C cannot cut the closing short: ``run``'s signal handlers only set a flag.
        """
        self.stop('shutdown')

    # --- session description ---
    def _session_record(self, session: str, start_ns: int) -> dict[str, str]:
        record, warnings = recorder_session_record(
            session, start_ns, {k: plain(v) for k, v in self.params.values.items()}, self.built, self.params_files,
            self.get_fully_qualified_name(), self.sim_time)
        for warning in warnings:
            self.get_logger().warning(warning)
        return record

    # --- subscriptions ---
    def _subscribe_all(self) -> None:
        self.channels = {}
        self.pending = []
        for name in [*self.params['topics'], *([topics.CLOCK] if self.sim_time else [])]:
            topic = self.resolve_topic_name(name)
            if topic in self.channels or topic in self.pending:
                continue
            graph = publisher_types(self, topic)
            msg_type = next(iter(graph)) if len(graph) == 1 else topics.RIG_TOPICS.get(topic)
            if msg_type is None:
                self.pending.append(topic)  # subscribed once a publisher shows its type
                continue
            self._subscribe(topic, msg_type)
        if self.params['stop_on_program_done'] and topics.PROGRAM_STATE not in self.channels:
            qos = contract_qos(topics.PROGRAM_STATE)
            assert qos is not None  # a rig topic: in the contract
            self.state_subscription = self.create_subscription(
                String, topics.PROGRAM_STATE, lambda msg: self._on_program_state(str(getattr(msg, 'data'))), qos)

    def _sim_report(self, t_ns: int) -> None:
        """Simulated time: everything up to ``t_ns`` is recorded (drained before this call). Not recording (never
        started, or stopped), the recorder takes no part: time does not wait for it. At the session's end (see
        :meth:`_session_end_ns`) the bag is closed with everything through that instant, and nothing after it."""
        if self.writer is None:
            self.sim.leave()
            return
        if self.log_times is not None and self.joined_ns is None:  # joining, before time starts: what DDS has
            self.joined_ns = t_ns  # delivered differs from run to run, so nothing is released; it is held, at
            for channel, data in self.before_time:  # its stamp or at the first step
                self._take(channel, data, t_ns)
            self.before_time = []
            self.sim.report(t_ns)
            return
        end = self._session_end_ns()
        self._release(t_ns if end is None else min(t_ns, end))
        end = self._session_end_ns()  # (the program's 'done' may have been among what was just written)
        if end is not None and t_ns >= end:
            self._stop_after_program(through_ns=end)
            return
        self.sim.report(t_ns)

    def _session_end_ns(self) -> int | None:
        """Simulated time: where the session ends [ns] (crane_stiffness.rosnode.program_end), else None."""
        if not self.params['stop_on_program_done'] or self.log_times is None:
            return None
        return self.program.end_ns(self.sim.watermark_ns >= 0, self.sim.end_ns)

    def _release(self, t_ns: int | None) -> None:
        """Simulated time: write the messages held with log times up to ``t_ns`` (None: all), in log-time order."""
        log_times = self.log_times
        if log_times is None:
            return
        for log_ns, (channel, data, stamp) in log_times.release_all() if t_ns is None else log_times.release(t_ns):
            self._write(channel, data, log_ns, stamp)

    def _drain_channels(self) -> None:
        for channel in list(self.channels.values()):
            if channel.subscription is not None:
                drain(channel.subscription, partial(self._on_message, channel))

    def _subscribe(self, topic: str, msg_type: str) -> None:
        qos = contract_qos(topic)
        if self.sim_time and topic in SIM_INPUTS:
            qos = SIM_STREAM_QOS
        elif self.sim_time and qos is not None and topic in SIM_OUTPUTS:
            qos = deep(qos)
        if qos is None:
            qos = adapted_qos([i.qos_profile for i in self.get_publishers_info_by_topic(topic)])
        try:
            channel = RecordedChannel(topic, msg_type, qos)
        except ValueError as exc:
            self.get_logger().error(f'cannot record {topic}: {exc}')
            self.errors += 1
            return
        channel.subscription = self.create_subscription(
            channel.msg_class, topic, partial(self._on_message, channel), qos, raw=True,
            event_callbacks=NO_EVENTS)
        self.channels[topic] = channel

    def _unsubscribe_all(self) -> None:
        for channel in self.channels.values():
            if channel.subscription is not None:
                self.destroy_subscription(channel.subscription)
                channel.subscription = None
        if self.state_subscription is not None:
            self.destroy_subscription(self.state_subscription)
            self.state_subscription = None

    def _on_node_parameters(self, node: str, values: dict[str, Any]) -> None:
        """A rig node's parameters, read: stored with the session (the record rewritten with every node read)."""
        self.node_parameters[node] = values
        if self.writer is not None:
            try:
                self.writer.add_metadata(NODE_PARAMETERS_METADATA, self.node_parameters)
            except BagWriteFailedError as exc:
                self._write_failed(exc)

    def _discover(self) -> None:
        """Subscribe topics outside the contract once they appear; follow a publisher whose type differs from the
        contract's (e.g. a real LVDT driver publishing std_msgs/Float64) while nothing was received yet; read the
        rig nodes' parameters."""
        if self.writer is None:
            return
        if self.parameter_reader is not None:
            self.parameter_reader.poll()
        for topic in list(self.pending):
            graph = publisher_types(self, topic)
            if len(graph) == 1:
                self.pending.remove(topic)
                self._subscribe(topic, next(iter(graph)))
        for topic, channel in list(self.channels.items()):
            if channel.count or channel.added:
                continue
            graph = publisher_types(self, topic)
            if len(graph) == 1 and channel.msg_type not in graph:
                self.get_logger().warning(f'{topic} is published as {next(iter(graph))}, not {channel.msg_type}: '
                                          'recording that type')
                assert channel.subscription is not None  # subscribed while recording
                self.destroy_subscription(channel.subscription)
                del self.channels[topic]
                self._subscribe(topic, next(iter(graph)))

    # --- messages ---
    def _on_message(self, channel: RecordedChannel, data: bytes) -> None:
        self.received += 1
        self.sim.received(channel.topic)
        if self.writer is None:
            self.dropped['not_recording'] += 1  # delivered after the bag was closed
            return
        if self.log_times is not None and self.log_times.repeat(channel.topic, header_stamp_ns(data)):
            self.dropped['clock_repeat'] += 1  # (the clock saying its time again, for nodes that join late)
            return
        now_ns = self.get_clock().now().nanoseconds
        # Before time starts, or before this recorder joined the lock-step: held, logged as decided at the join.
        if self.sim_time and (now_ns == 0 or (self.sim.watermark_ns < 0 and self.log_times is not None
                                              and self.count_publishers(topics.SIM_WATERMARKS) > 0)):
            self.before_time.append((channel, data))
            return
        self._write_before_time(now_ns)
        self._take(channel, data, now_ns)

    def _write_before_time(self, now_ns: int) -> None:
        """The messages received before simulated time started, logged at ``now_ns``, in the order received."""
        held, self.before_time = self.before_time, []
        for channel, data in held:
            self._take(channel, data, now_ns)

    def _take(self, channel: RecordedChannel, data: bytes, now_ns: int) -> None:
        """A message received at clock time ``now_ns``: written (wall clock), or held with its log time until its
        simulated time is complete (simulated time). Simulated time from a /clock without the lock-step's watermarks
        (a player's or a simulator's clock: no watermark ever heard) is logged at receipt, as on the wall clock."""
        stamp = header_stamp_ns(data) if channel.stamped else None
        if self.log_times is None or self.sim.watermark_ns < 0:
            self._write(channel, data, now_ns, stamp)
        else:
            self.log_times.hold(channel.topic, stamp, (channel, data, stamp))

    def _write(self, channel: RecordedChannel, data: bytes, log_ns: int, stamp: int | None) -> None:
        writer = self.writer
        if writer is None:  # closed meanwhile (stop() from another thread)
            self.dropped['not_recording'] += 1
            return
        try:
            if not channel.added:
                offered = offered_profiles(self, channel.topic, fallback=channel.qos)
                writer.add_topic(channel.topic, channel.msg_type, dump_qos_profiles(offered))
                channel.added = True
            writer.write(channel.topic, data, log_ns, stamp if stamp is not None else log_ns)
        except BagWriteFailedError as exc:
            self._write_failed(exc)  # closes the bag as far as the disk allows: what is on disk is known after it
            if writer.failed_write_on_disk or writer.failed_write_counted:
                channel.count += 1  # in the bag (its chunk went out whole) or accepted before the error: not refused
            else:
                self.dropped['write_error'] += 1
            return
        except BagError as exc:
            self.dropped['rejected'] += 1
            self.errors += 1
            self.get_logger().error(f'writing {channel.topic} failed: {exc}', throttle_duration_sec=2.0)
            return
        channel.count += 1
        if channel.topic == topics.PROGRAM_STATE:
            try:
                self._on_program_state(deserialize_message(data, String).data)
            except Exception as exc:  # a malformed state must not stop the recording
                self.get_logger().warning(f'unreadable program state: {exc}', throttle_duration_sec=5.0)

    def _on_program_state(self, text: str) -> None:
        if not (self.program.read(text) and self.params['stop_on_program_done'] and self.writer is not None
                and self.stop_timer is None):
            return
        name = self.program.state.get('program')
        end = self._session_end_ns()
        if end is not None:  # simulated time: closed at that instant by _sim_report, whatever the load
            self.get_logger().info(f'program {name!r} done: closing the bag at simulated time {end * 1e-9:.3f} s, '
                                   'the end of the run')
            return
        delay = float(self.params['stop_delay_s'])
        self.get_logger().info(f'program {name!r} done: closing the bag in {delay:g} s')
        self.stop_timer = self.create_timer(max(delay, 1e-3), self._stop_after_program)

    def _stop_after_program(self, through_ns: int | None = None) -> None:
        self.stop('program done', through_ns)
        if self.params['exit_on_program_done']:
            self.exit_requested = True  # the spin loop of main() ends (in-process executors are not disturbed)

    def _flush(self) -> None:
        writer = self.writer
        if writer is not None and writer.message_count != self._flushed_at:
            try:
                writer.flush()
            except BagWriteFailedError as exc:
                self._write_failed(exc)
                return
            self._flushed_at = writer.message_count

    # --- services ---
    def _srv_start(self, request, response):
        if self.writer is not None:
            response.success, response.message = False, f'already recording to {self.bag_path}'
            return response
        try:
            path = self.start()
            self.exit_status = 0  # a new recording: the one cut before is not this one's
        except (BagError, OSError, ValueError) as exc:
            response.success, response.message = False, f'cannot start recording: {exc}'
            self.get_logger().error(response.message)
            return response
        response.success, response.message = True, f'recording to {path}'
        return response

    def _srv_stop(self, request, response):
        if self.writer is None:
            response.success = False
            response.message = 'not recording' + (f' (last bag {self.last_bag})' if self.last_bag else '')
            return response
        who = self.callers.caller(self.callers.service_name('~/stop'))  # logged by stop()
        program = self.program.state.get('state')  # (read before stop(): a recording's program, none by hand)
        path, count = self.stop('service', by=who)
        if program is not None and program != 'done':  # a program's session cut: the launch ends non-zero, naming it
            self.exit_status = RECORDER_CUT_STATUS
        response.success, response.message = True, f'closed {path}: {count} messages'
        return response

    @property
    def counters(self) -> dict:
        """What ``run`` prints at exit (FINAL_COUNTERS, after ``close``): the recordings and the last bag."""
        writer = self.writer
        written = self.written + (writer.message_count if writer is not None else 0)
        return {'recordings': self.recordings, 'errors': self.errors, 'write_errors': self.write_errors,
                'received': self.received,
                'written': written, **{f'dropped_{k}': v for k, v in self.dropped.items()},
                'messages': writer.message_count if writer is not None else self.last_count,
                'bag': str(self.bag_path or self.last_bag or ''),
                **({'write_failure': self.write_failure} if self.write_failure else {})}

    def _report(self):
        writer = self.writer
        pairs = [(k, str(v)) for k, v in self.counters.items() if k != 'messages' or writer is not None]
        if writer is not None:
            pairs += [(c.topic, str(c.count)) for c in self.channels.values()]
            if self.pending:
                pairs.append(('waiting_for', ', '.join(self.pending)))
        # A write error is an ERROR until a new recording starts (the last bag stays incomplete, say so); other
        # errors (a topic that cannot be recorded) stay ERROR.
        level = ERROR if self.errors or self.write_failure else OK
        return level, self.status, pairs


#: The node a rig host loads (crane_stiffness.launcher.rig_host), built with its node arguments (``cli_args``).
COMPONENT = SessionRecorder


def main(args=None) -> int:
    files = params_files_from_args(args)

    def session_recorder() -> SessionRecorder:
        return SessionRecorder(params_files=files)

    return run(session_recorder, args, executor=lambda node: node.params['executor'])


if __name__ == '__main__':
    raise SystemExit(main())
