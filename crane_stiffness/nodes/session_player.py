"""session_player: republishes a recorded session (a rosbag2 MCAP bag) with its original timing.

Reads ``bag`` with crane_stiffness.bag.BagReader (a damaged bag plays its readable part, with a warning) and
publishes each message's serialized bytes as recorded (no deserialization) at ``log time / rate`` after the start,
on a thread of its own (the bag read ahead on another, the garbage collector kept off the objects of before the
playback: crane_stiffness.rosnode.replay_timing), with the QoS recorded in the bag (reliable / transient local only
where every recorded publisher was; see session_qos.playback_qos). Topics: ``topics_include`` (empty = all) minus
``topics_exclude``, both lists of names or fnmatch patterns; ``remap`` renames topics ('from:=to' strings), and
ordinary ROS remapping (``--ros-args -r /a:=/b``) also applies to the player's publishers. ``start_offset_s`` skips
the start of the bag; ``loop`` plays it again and again. With ``publish_clock`` the bag's log time is published on
/clock (rosgraph_msgs/Clock) at ``clock_rate_hz``, so other nodes can run with use_sim_time.

Stamps are not rewritten: the rig's estimator pairs and fits by header stamp, so a replay reproduces the live
estimates whatever the timing jitter of the replay.

Services (std_srvs/Trigger): ~/start (start, resume after pause, restart when finished), ~/pause, ~/stop. With
``exit_on_end`` the node shuts down once the bag has been played (not with ``loop``).

A ``start_offset_s`` past the end of the bag is an error naming the offset and the bag's duration: at start-up the
node exits with status 2, ~/start answers failure. Counters (FINAL_COUNTERS, /diagnostics) account for every message
read from the bag: ``read = published + skipped_*`` (``read``: taken from the read-ahead buffer to be played; what
the buffer held when the playback stopped is not counted; ``skipped_stopped``: read, then the playback was stopped
before its time; ``skipped_publish_error``: the publish raised). Only message types the ament index lists as
interfaces are played (session_qos.message_class); a bag naming another type gets a warning naming it, and that
topic is not played.
"""
from __future__ import annotations

import fnmatch
import gc
import threading
import time
import warnings
from pathlib import Path
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from crane_stiffness.bag import BagReader, RawMessage
from crane_stiffness.bag.errors import BagDamageWarning, BagError
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.rosnode.diagnostics import Diagnostics
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.parameters import Params, check, positive, valid_topic_name
from crane_stiffness.rosnode import replay_timing
from crane_stiffness.rosnode.replay_timing import ReadAhead, fine_timer_slack, quiet_interpreter
from crane_stiffness.rosnode.session_qos import message_class, playback_qos
from crane_stiffness.serde.stamps import split_ns
from crane_stiffness.contract.status import ERROR, OK, WARN

CLOCK_TOPIC = '/clock'
_NO_EVENTS = PublisherEventCallbacks(use_default_callbacks=False)  # no QoS-event handler in every executor wait
#: Time the node stays up after the last message before ``exit_on_end`` shuts it down, so that the last messages
#: reach their subscribers [s].
END_LINGER_S = 1.0

PARAMS = (
    ParamSpec('bag', '', 'bag directory (with or without metadata.yaml) or .mcap file to play [-]'),
    ParamSpec('rate', 1.0, 'playback speed factor: 2.0 plays twice as fast [-]', above=0.0),
    ParamSpec('loop', False, 'play the bag again when it ends [-]'),
    ParamSpec('start_offset_s', 0.0, 'start this far into the bag, from its first message (log time) [s]',
              low=0.0),
    ParamSpec('publish_clock', False, "publish the bag's log time on /clock (rosgraph_msgs/Clock) for nodes "
              'running with use_sim_time [-]'),
    ParamSpec('clock_rate_hz', 100.0, 'rate of /clock messages [Hz]', above=0.0),
    ParamSpec('autostart', True, 'start playing when the node starts (after start_delay_s); else call ~/start [-]'),
    ParamSpec('start_delay_s', 1.0, 'wait before playing so subscribers can connect [s]', low=0.0,
              high=86400.0),
    ParamSpec('exit_on_end', True, 'shut the node down when the bag has been played (ignored with loop) [-]'),
)
#: String-array parameters, empty by default (declared with their type, see SessionPlayer._declare_lists).
LIST_PARAMS = {
    'topics_include': 'topics to play, names or fnmatch patterns; empty = every topic of the bag [-]',
    'topics_exclude': 'topics not to play, names or fnmatch patterns [-]',
    'remap': "topic renames as 'from:=to' strings, applied before ROS remapping [-]",
}


def parse_remap(entries: list[str]) -> dict[str, str]:
    """{'from': 'to'} of 'from:=to' strings; raises ValueError naming a bad entry."""
    out: dict[str, str] = {}
    for entry in entries:
        source, sep, target = entry.partition(':=')
        check(bool(sep) and bool(source.strip()) and bool(target.strip()), 'remap', entry,
              "each entry must read 'from:=to'")
        for name in (source.strip(), target.strip()):  # a bad name would stop ~/start later
            check(valid_topic_name(name), 'remap', entry, f'{name!r} is not a valid topic name')
        out[source.strip()] = target.strip()
    return out


def select_topics(available: list[str], include: list[str], exclude: list[str]) -> list[str]:
    """Topics of ``available`` matching an include pattern (all when none) and no exclude pattern."""
    chosen = [t for t in available if not include or any(fnmatch.fnmatchcase(t, p) for p in include)]
    return [t for t in chosen if not any(fnmatch.fnmatchcase(t, p) for p in exclude)]


def _validate(values: dict[str, Any]) -> dict[str, Any]:
    check(isinstance(values['bag'], str) and values['bag'] != '', 'bag', values['bag'],
          'must name a bag directory or .mcap file')
    check(Path(values['bag']).expanduser().exists(), 'bag', values['bag'], 'does not exist')
    positive(values, 'rate', 'clock_rate_hz')
    return values


class _Playback(threading.Thread):
    """Publishes the messages of one BagReader at their log times (scaled by rate) until the end or stop."""

    def __init__(self, player: SessionPlayer, reader: BagReader, publishers: dict[str, Any], clock_pub: Any,
                 rate: float, offset_ns: int, loop: bool, clock_period_s: float) -> None:
        super().__init__(name='session_player', daemon=True)
        self.player = player
        self.reader = reader
        self.publishers = publishers
        self.clock_pub = clock_pub
        self.rate = rate
        self.offset_ns = offset_ns
        self.loop = loop
        self.clock_period_ns = int(clock_period_s * 1e9)
        self.stop_event = threading.Event()
        self.resume_event = threading.Event()
        self.resume_event.set()
        self.error: BaseException | None = None
        self.finished = False
        self.pending = False  # a message read but not yet published (counted as skipped if the playback stops)
        self.base_ns = 0  # the bag time the playback starts at [ns]
        self.last_clock: int | None = None  # when /clock was last published (monotonic ns)

    def run(self) -> None:
        try:
            fine_timer_slack()
            with quiet_interpreter():
                self._play()
            self.finished = not self.stop_event.is_set()
        except BaseException as exc:  # reported by the node; the thread must not die silently
            self.error = exc
        finally:
            if self.pending:
                self.player.stats['skipped_stopped'] += 1
                self.pending = False

    def _publish_clock(self, bag_ns: float) -> None:
        """Publish /clock at bag time ``bag_ns`` [ns] (a float when scaled by the rate; truncated to an int)."""
        if self.clock_pub is not None:
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = split_ns(int(bag_ns))
            self.clock_pub.publish(msg)

    def _play(self) -> None:
        start = self.reader.start_ns
        if start is None:
            return
        base_ns = self.base_ns = start + self.offset_ns
        topics = list(self.publishers)
        while not self.stop_event.is_set():
            ahead = ReadAhead(self.reader.messages(topics, start_ns=base_ns), replay_timing.READ_AHEAD_HIGH,
                              replay_timing.READ_AHEAD_LOW, name='session_player_read')
            try:
                if not self._play_once(ahead, base_ns):
                    return
            finally:
                ahead.close()  # before the reader can be closed
            self.player.stats['loops'] += 1
            if not self.loop:
                self._publish_clock(self.player.stats.get('bag_time_ns') or base_ns)
                return

    def _play_once(self, ahead: ReadAhead[RawMessage], base_ns: int) -> bool:
        """Publish the messages of ``ahead`` at their times; False when stopped."""
        stats = self.player.stats
        while not ahead.wait_filled(0.05):  # the clock starts once the buffer is full: the reads at the start do not
            if self.stop_event.is_set():    # make the first messages late
                return False
        gc.freeze()  # the messages read ahead: out of the full collections' reach (each would scan them all)
        wall0 = time.monotonic_ns()
        self.last_clock = None
        while True:
            try:
                got, msg = ahead.take(0.05)
            except StopIteration:
                return True
            if self.stop_event.is_set():
                if got:
                    stats['read'] += 1
                    stats['skipped_stopped'] += 1
                return False
            if msg is None:  # the read-ahead is behind (a busy machine): this message will be late
                continue
            stats['read'] += 1
            self.pending = True
            due = wall0 + int((msg.log_time_ns - base_ns) / self.rate)
            # A message due within EARLY_NS goes out at once (no clock to publish, not paused): in a burst of log
            # times (a wall-clock bag's receipt times come dozens within tens of µs) every µs per message adds up.
            if (due - time.monotonic_ns() > replay_timing.EARLY_NS or self.clock_pub is not None
                    or not self.resume_event.is_set()):
                shift = self._wait_until(due, msg.log_time_ns - base_ns, wall0)
                if shift is None:
                    return False
                wall0 += shift
                due += shift
            self.pending = False
            try:
                self.publishers[msg.topic].publish(msg.data)
            except BaseException:
                stats['skipped_publish_error'] += 1
                raise
            now = time.monotonic_ns()
            late = now - due
            stats['published'] += 1
            if late > stats['max_late_ms'] * 1e6:
                stats['max_late_ms'] = late / 1e6
            if -late > stats['max_early_ms'] * 1e6:
                stats['max_early_ms'] = -late / 1e6
            stats['played_s'] = (now - wall0) / 1e9  # this pass's start (pauses left out) to this publish
            stats['bag_time_ns'] = msg.log_time_ns

    def _wait_until(self, due: int, bag_rel_ns: int, wall0: int) -> int | None:
        """Sleep until monotonic time ``due`` [ns] (publishing /clock meanwhile, holding while paused); returns how
        far a pause moved the schedule [ns], or None when stopped."""
        shift = 0
        while True:
            if self.stop_event.is_set():
                return None
            if not self.resume_event.is_set():
                paused_at = time.monotonic_ns()
                while not self.resume_event.wait(0.05):
                    if self.stop_event.is_set():
                        return None
                moved = time.monotonic_ns() - paused_at
                shift += moved
                wall0 += moved
                due += moved
            now = time.monotonic_ns()
            if self.clock_pub is not None and (self.last_clock is None
                                               or now - self.last_clock >= self.clock_period_ns):
                self._publish_clock(self.base_ns + min(bag_rel_ns, (now - wall0) * self.rate))
                self.last_clock = now
            wait = due - now
            if wait <= 0:
                return shift
            if wait <= replay_timing.EARLY_NS:  # a sleep this short costs more than it waits: publish now
                return shift
            time.sleep(min(wait, self.clock_period_ns if self.clock_pub is not None else wait, 50_000_000) / 1e9)


class SessionPlayer(Node):
    """Idle → playing ⇄ paused → finished (or stopped). See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('session_player', **kwargs)
        self.playback: _Playback | None = None
        self.publishers_by_topic: dict[str, Any] = {}
        self.clock_pub: Publisher | None = None
        self.state = 'idle'
        self.problems: list[str] = []
        # (max_late_ms, max_early_ms: the most a publish came after / before its due time; played_s: the wall
        # seconds from the pass's start, pauses left out, to its newest publish)
        self.stats: dict[str, Any] = {'read': 0, 'published': 0, 'skipped_stopped': 0, 'skipped_publish_error': 0,
                                      'max_late_ms': 0.0, 'max_early_ms': 0.0, 'played_s': 0.0, 'loops': 0,
                                      'bag_time_ns': None}
        self.topic_map: dict[str, str] = {}
        self.finished_at: float | None = None
        self.reader: BagReader | None = None
        self.playing_topics: dict[str, Any] = {}
        self._prepared_key: tuple | None = None
        self.exit_requested = False  # read by run.run: ends the node with exit_status (exit_on_end)
        self.exit_status = 0
        self._declare_lists()
        self.params = Params(self, PARAMS, _validate, lambda built, values: None)
        self.prepare()  # publishers exist from the start, so subscribers can connect before playing
        self._check_offset()  # an offset past the end stops the node at start with the reason (exit status 2)
        self.create_service(Trigger, '~/start', self._srv_start)
        self.create_service(Trigger, '~/pause', self._srv_pause)
        self.create_service(Trigger, '~/stop', self._srv_stop)
        self.diagnostics = Diagnostics(self, self._report)
        self.watch_timer = self.create_timer(0.1, self._watch)
        self._autostart = None
        if self.params['autostart']:
            self._autostart = self.create_timer(max(self.params['start_delay_s'], 1e-3), self._auto)

    # --- list parameters ---
    def _declare_lists(self) -> None:
        for name, description in LIST_PARAMS.items():
            self.declare_parameter(name, Parameter.Type.STRING_ARRAY, ParameterDescriptor(description=description))
        parse_remap(self.list_param('remap'))  # a bad remap stops the node at start with the reason
        self.add_on_set_parameters_callback(self._on_set_lists)

    def list_param(self, name: str) -> list[str]:
        try:
            value = self.get_parameter(name).value
        except ParameterUninitializedException:
            return []
        return [str(v) for v in (value or [])]

    def _on_set_lists(self, params) -> SetParametersResult:
        for p in params:
            if p.name == 'remap':
                try:
                    parse_remap([str(v) for v in (p.value or [])])
                except ValueError as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    # --- playing ---
    def _key(self) -> tuple:
        return (self.params['bag'], tuple(self.list_param('topics_include')),
                tuple(self.list_param('topics_exclude')), tuple(self.list_param('remap')),
                self.params['publish_clock'])

    def prepare(self) -> None:
        """Open the bag and create the publishers (again only if bag, topics, remap or clock changed).

        Raises BagError/OSError for an unreadable bag and ValueError when no topic is left to play.
        """
        key = self._key()
        if key == self._prepared_key and self.reader is not None:
            return
        p = self.params
        path = Path(p['bag']).expanduser()
        if self.reader is not None:
            self.reader.close()
            self.reader = None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always', BagDamageWarning)
            reader = BagReader(path)
        for w in caught:
            self._problem(str(w.message))
        try:
            infos = reader.topics
            chosen = select_topics(sorted(infos), self.list_param('topics_include'),
                                   self.list_param('topics_exclude'))
            publishers = self._make_publishers({t: infos[t] for t in chosen}, parse_remap(self.list_param('remap')))
            if not publishers:
                refused = ''.join(f'; {p}' for p in self.problems if ' not played: ' in p)
                raise ValueError(f'no topic of {path} to play{refused} (topics in the bag: '
                                 f'{", ".join(sorted(infos))}; include {self.list_param("topics_include")}, exclude '
                                 f'{self.list_param("topics_exclude")})')
            if p['publish_clock'] and self.clock_pub is None:
                self.clock_pub = self.create_publisher(Clock, CLOCK_TOPIC, QoSProfile(
                    depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
        except BaseException:
            reader.close()
            raise
        self.reader = reader
        self.playing_topics = publishers
        self.topic_map = {t: pub.topic_name for t, pub in publishers.items()}
        self._prepared_key = key
        self.get_logger().info(f'{path}: {len(publishers)} topic(s) to play, '
                               f'{reader.duration_ns * 1e-9:.3f} s, {reader.message_count} messages')

    def start(self) -> str:
        """Start playing from the beginning (or resume after pause); returns what happened."""
        if self.playback is not None and self.playback.is_alive():
            if not self.playback.resume_event.is_set():
                self.playback.resume_event.set()
                self.state = 'playing'
                return 'resumed'
            return 'already playing'
        self.prepare()
        assert self.reader is not None  # prepare() opened the bag
        p = self.params
        self._check_offset()
        self.stats.update(read=0, published=0, skipped_stopped=0, skipped_publish_error=0, max_late_ms=0.0,
                          max_early_ms=0.0, played_s=0.0, loops=0, bag_time_ns=None)
        self.playback = _Playback(self, self.reader, self.playing_topics,
                                  self.clock_pub if p['publish_clock'] else None, float(p['rate']),
                                  int(round(p['start_offset_s'] * 1e9)), bool(p['loop']), 1.0 / p['clock_rate_hz'])
        self.finished_at = None
        self.state = 'playing'
        self.playback.start()
        message = (f'playing {len(self.playing_topics)} topic(s) of {p["bag"]} at rate {p["rate"]:g}'
                   f'{" from " + format(p["start_offset_s"], "g") + " s" if p["start_offset_s"] else ""}'
                   f'{", looping" if p["loop"] else ""}')
        self.get_logger().info(message)
        return message

    def _check_offset(self) -> None:
        """Raise ValueError when ``start_offset_s`` lies past the bag's last message: nothing would be played."""
        reader = self.reader
        offset = float(self.params['start_offset_s'])
        if reader is None or reader.start_ns is None:
            return
        duration_ns = reader.duration_ns
        if int(round(offset * 1e9)) > duration_ns:
            raise ValueError(f'start_offset_s = {offset:g} s is past the end of the bag {self.params["bag"]} '
                             f'({duration_ns * 1e-9:.3f} s long): nothing to play; use an offset in 0 .. '
                             f'{duration_ns * 1e-9:.3f} s')

    def _make_publishers(self, infos: dict[str, Any], remap: dict[str, str]) -> dict[str, Any]:
        wanted: dict[str, tuple[str, Any, QoSProfile]] = {}
        for topic, info in infos.items():
            try:
                cls = message_class(info.msg_type)
            except ValueError as exc:
                self._problem(f'{topic} not played: {exc}')
                continue
            wanted[topic] = (remap.get(topic, topic), cls, playback_qos(topic, info.offered_qos_profiles))
        publishers: dict[str, Any] = {}
        for topic, (target, cls, qos) in wanted.items():
            key = (target, cls)
            existing = self.publishers_by_topic.get(topic)
            if existing is not None and existing[0] == key:
                publishers[topic] = existing[1]
                continue
            if existing is not None:
                self.destroy_publisher(existing[1])
            pub = self.create_publisher(cls, target, qos, event_callbacks=_NO_EVENTS)
            self.publishers_by_topic[topic] = (key, pub)
            publishers[topic] = pub
        return publishers

    def _problem(self, text: str) -> None:
        self.problems.append(text)
        self.get_logger().warning(text)

    def pause(self) -> bool:
        if self.playback is None or not self.playback.is_alive() or not self.playback.resume_event.is_set():
            return False
        self.playback.resume_event.clear()
        self.state = 'paused'
        return True

    def stop(self) -> bool:
        """Stop playing (idempotent); returns True if a playback was running."""
        playback, self.playback = self.playback, None
        if playback is None:
            return False
        playback.stop_event.set()
        playback.resume_event.set()
        playback.join(timeout=5.0)
        self.state = 'stopped'
        return True

    def close(self) -> None:
        """Called by ``run`` on shutdown."""
        self.stop()
        if self.reader is not None:
            self.reader.close()
            self.reader = None

    def destroy_node(self) -> None:
        self.close()
        super().destroy_node()

    @property
    def finished(self) -> bool:
        return self.state == 'finished'

    def _auto(self) -> None:
        assert self._autostart is not None  # the timer calling this
        self.destroy_timer(self._autostart)
        self._autostart = None
        if self.state == 'idle':
            try:
                self.start()
            except (BagError, OSError, ValueError) as exc:
                self.state = 'error'
                self._problem(f'cannot play: {exc}')
                if self.params['exit_on_end']:
                    self._request_exit(2)

    def _watch(self) -> None:
        playback = self.playback
        if playback is None or playback.is_alive():
            if self.finished_at is not None and self.params['exit_on_end'] and \
                    time.monotonic() - self.finished_at >= END_LINGER_S:
                self._request_exit(0)
            return
        self.playback = None
        if playback.error is not None:
            self.state = 'error'
            self._problem(f'playback failed: {type(playback.error).__name__}: {playback.error}')
            return
        if playback.finished:
            self.state = 'finished'
            self.get_logger().info(f'finished: {self.stats["published"]} messages published')
            self.finished_at = time.monotonic()

    def _request_exit(self, status: int) -> None:
        # A flag, not SystemExit: an exception out of a callback is reported by the executor as FATAL (and the C++
        # EventsExecutor cannot pass it through cleanly); run.run ends the spin and exits with this status.
        self.exit_status = status
        self.exit_requested = True

    # --- services ---
    def _srv_start(self, request, response):
        try:
            response.message = self.start()
            response.success = True
        except (BagError, OSError, ValueError) as exc:
            response.success, response.message = False, f'cannot play: {exc}'
        return response

    def _srv_pause(self, request, response):
        response.success = self.pause()
        response.message = 'paused' if response.success else f'not playing (state {self.state})'
        return response

    def _srv_stop(self, request, response):
        response.success = self.stop()
        response.message = 'stopped' if response.success else f'not playing (state {self.state})'
        return response

    @property
    def counters(self) -> dict:
        """What ``run`` prints at exit (FINAL_COUNTERS)."""
        s = self.stats
        return {'state': self.state, 'read': s['read'], 'published': s['published'],
                'skipped_stopped': s['skipped_stopped'], 'skipped_publish_error': s['skipped_publish_error'],
                'loops': s['loops'], 'problems': len(self.problems)}

    def _report(self):
        s = self.stats
        pairs = [('bag', str(self.params['bag'])), ('read', str(s['read'])), ('published', str(s['published'])),
                 ('skipped_stopped', str(s['skipped_stopped'])),
                 ('skipped_publish_error', str(s['skipped_publish_error'])),
                 ('max_late_ms', f'{s["max_late_ms"]:.3f}'), ('loops', str(s['loops'])),
                 ('problems', str(len(self.problems)))]
        level = ERROR if self.state == 'error' else (WARN if self.problems else OK)
        return level, self.state, pairs


def main(args=None) -> int:
    return run(SessionPlayer, args)


if __name__ == '__main__':
    raise SystemExit(main())
