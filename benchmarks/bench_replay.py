"""Benchmark: replay timing of ``session_player`` against a plain timer loop publishing the same messages.

A session bag of the rig (load cell and LVDT at 1 kHz, 500 Hz bursts, as the demo records them; generated with
crane_stiffness.testing.synthetic, or ``--bag`` for a recorded one) is played twice in the same run, 15 s of it from
20 s in, load cell and LVDT only:

- the baseline: a plain loop in a process of its own that has every message in memory beforehand, sleeps until its
  log time and publishes it (the machine's own jitter: scheduler, DDS, Python's sleep);
- ``session_player`` (the installed node, as ``ros2 run`` starts it).

A subscriber in this process takes each message's DDS source timestamp (the instant its publisher wrote it) and
compares it with the message's log time in the bag; after the median is removed, the p50/p99/max of the absolute
deviation and the messages missing are reported (those lost once the listener had matched the publisher fail it;
those before, DDS discovery's doing, are only reported). Target: the player's p99 ≤ 1 ms (``ros2 bag play`` class),
or, on a
machine whose own jitter (the baseline's p99) is above 1 ms, no more than 1.2× the baseline's. Exits 1 on a miss.

    python benchmarks/bench_replay.py [--bag BAG] [--offset 20] [--seconds 15] [--json OUT]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(60 + os.getpid() % 30))

TOPICS = ('/load_cell/wrench', '/lvdt/displacement')
TARGET_P99_MS = 1.0
BASELINE_FACTOR = 1.2

#: The baseline publisher: every message in memory, then sleep until its time and publish. argv: bag, offset s,
#: seconds, start delay s.
BASELINE = r'''
import sys, time
import rclpy
from crane_stiffness.bag import BagReader
from crane_stiffness.rosnode.session_qos import message_class, playback_qos
bag, offset_s, seconds, delay_s = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
topics = sys.argv[5:]
rclpy.init()
node = rclpy.create_node('replay_baseline')
with BagReader(bag) as reader:
    infos = reader.topics
    pubs = {t: node.create_publisher(message_class(infos[t].msg_type), t,
                                     playback_qos(t, infos[t].offered_qos_profiles)) for t in topics}
    base = reader.start_ns + int(offset_s * 1e9)
    msgs = [(m.log_time_ns - base, pubs[m.topic], m.data)
            for m in reader.messages(topics, start_ns=base, end_ns=base + int(seconds * 1e9))]
time.sleep(delay_s)
wall0 = time.monotonic_ns()
for rel, pub, data in msgs:
    wait = wall0 + rel - time.monotonic_ns()
    if wait > 0:
        time.sleep(wait / 1e9)
    pub.publish(data)
time.sleep(0.5)
node.destroy_node()
rclpy.shutdown()
'''


class Listener:
    """Source timestamps of the messages on TOPICS, keyed by (topic, header stamp)."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from geometry_msgs.msg import PointStamped, WrenchStamped
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node('replay_listener', context=self.ctx)
        self.seen: dict[tuple[str, int], int] = {}
        qos = QoSProfile(depth=5000, reliability=ReliabilityPolicy.BEST_EFFORT)
        for topic, cls in zip(TOPICS, (WrenchStamped, PointStamped)):
            self.node.create_subscription(cls, topic, self._callback(topic), qos)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException
        try:
            self.executor.spin()
        except ExternalShutdownException:
            pass

    def _callback(self, topic: str):
        def on_message(msg, info) -> None:
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            self.seen[(topic, stamp)] = info['source_timestamp']
        return on_message

    def take(self) -> dict[tuple[str, int], int]:
        out, self.seen = self.seen, {}
        return out

    def close(self) -> None:
        self.ctx.try_shutdown()      # wakes the executor: spin() returns
        self.thread.join(10.0)
        self.executor.shutdown()
        self.node.destroy_node()


def expected_messages(bag: Path, offset_s: float, seconds: float) -> dict[tuple[str, int], int]:
    """(topic, header stamp) → log time [ns] of the messages played."""
    from crane_stiffness.bag import BagReader
    from crane_stiffness.rosnode.session_qos import message_class
    from rclpy.serialization import deserialize_message
    out = {}
    with BagReader(bag) as reader:
        classes = {t: message_class(reader.topics[t].msg_type) for t in TOPICS}
        base = reader.start_ns + int(offset_s * 1e9)
        for m in reader.messages(TOPICS, start_ns=base, end_ns=base + int(seconds * 1e9)):
            msg = deserialize_message(m.data, classes[m.topic])
            out[(m.topic, msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)] = m.log_time_ns
    return out


def timing(expected: dict[tuple[str, int], int], seen: dict[tuple[str, int], int]) -> dict[str, float]:
    keys = [k for k in expected if k in seen]
    error = np.array([seen[k] - expected[k] for k in keys], dtype=np.float64)
    if error.size == 0:
        return {'messages': len(expected), 'received': 0, 'p50_ms': float('nan'), 'p99_ms': float('nan'),
                'max_ms': float('nan')}
    deviation = np.abs(error - np.median(error)) / 1e6
    log = np.array(sorted(expected.values()), dtype=np.int64)
    lost = np.array(sorted(expected[k] for k in expected if k not in seen), dtype=np.int64)
    where = (f'{(lost[0] - log[0]) / 1e9:.3f} .. {(lost[-1] - log[0]) / 1e9:.3f} s into the part played'
             if lost.size else '')
    t = np.array([expected[k] for k in keys], dtype=np.int64)
    worst = np.argsort(deviation)[-max(1, deviation.size // 100):]   # the 1 % beyond p99: when they came
    spans = np.unique(np.floor((t[worst] - log[0]) / 1e8).astype(int)) / 10.0
    # Lost once the listener had matched the publisher (before, DDS discovery, not the replay, decides).
    first = t.min()
    lost_after_match = int(sum(1 for k in expected if k not in seen and expected[k] > first))
    return {'messages': len(expected), 'received': len(keys), 'missing_between': where,
            'lost_after_match': lost_after_match,
            'worst_1pct_at_s': spans.tolist(), 'p50_ms': float(np.percentile(deviation, 50)),
            'p99_ms': float(np.percentile(deviation, 99)), 'max_ms': float(deviation.max())}


def make_bag(directory: Path) -> Path:
    from crane_stiffness.model import lab_model
    from crane_stiffness.sim.program import LoadProgram, load_program_file
    from crane_stiffness.testing.synthetic import write_synthetic_session
    base = load_program_file(REPO / 'config' / 'program_side_force.yaml')
    program = LoadProgram(base.segments, repeats=2, name=base.name, rate_hz=base.rate_hz)
    bag = directory / 'replay_session'
    write_synthetic_session(bag, program, geometry=lab_model(0.5, 50.0), sample_rate_hz=1000.0,
                            publish_rate_hz=500.0)
    return bag


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--bag', type=Path, help='bag to play (default: a generated 42 s rig session)')
    parser.add_argument('--offset', type=float, default=20.0, help='start this far into the bag [s] (default 20)')
    parser.add_argument('--seconds', type=float, default=15.0, help='seconds played (default 15)')
    parser.add_argument('--json', type=Path, help='write the figures here')
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix='bench_replay_'))
    bag = args.bag or make_bag(tmp)
    expected = expected_messages(bag, args.offset, args.seconds)
    listener = Listener()
    results = {}
    try:
        print(f'{bag}: {len(expected):,} load-cell and LVDT messages, {args.seconds:g} s from {args.offset:g} s in')
        base = subprocess.run([sys.executable, '-c', BASELINE, str(bag), str(args.offset), str(args.seconds), '3.0',
                               *TOPICS], capture_output=True, text=True, timeout=args.seconds + 120)
        if base.returncode:
            print(base.stdout + base.stderr)
            return 1
        time.sleep(0.5)
        results['plain timer loop'] = timing(expected, listener.take())
        player = Path(sys.prefix) / 'bin' / 'session_player'
        run = subprocess.run([str(player), '--ros-args', '-p', f'bag:={bag}', '-p', f'start_offset_s:={args.offset}',
                              '-p', f'topics_include:={json.dumps(list(TOPICS))}', '-p', 'start_delay_s:=3.0'],
                             capture_output=True, text=True, timeout=args.seconds + 120)
        if run.returncode:
            print(run.stdout + run.stderr)
            return 1
        time.sleep(0.5)
        results['session_player'] = timing(expected, listener.take())
    finally:
        listener.close()
    for name, r in results.items():
        print(f'  {name:17s}: {r["received"]:,}/{r["messages"]:,} received; |publish time - log time| after the '
              f'median: p50 {r["p50_ms"]:.3f} ms, p99 {r["p99_ms"]:.3f} ms, max {r["max_ms"]:.3f} ms'
              + (f'; missing {r["missing_between"]}' if r.get('missing_between') else ''))
        print(f'    the worst 1 % in the 0.1 s spans starting at (s): {r["worst_1pct_at_s"][:20]}')
    player_p99, base_p99 = results['session_player']['p99_ms'], results['plain timer loop']['p99_ms']
    limit = max(TARGET_P99_MS, BASELINE_FACTOR * base_p99)
    print(f'session_player p99 / plain loop p99 = {player_p99 / base_p99:.2f}; target p99 <= {limit:.3f} ms '
          f'(1 ms, or {BASELINE_FACTOR}x the plain loop on a machine that jitters more)')
    lost = results['session_player']['lost_after_match']
    ok = player_p99 <= limit and lost == 0
    print('targets met' if ok else f'TARGET MISSED: p99 {player_p99:.3f} ms, {lost} message(s) lost after the '
          f'listener matched the player')
    if args.json:
        args.json.write_text(json.dumps({'results': results, 'limit_ms': limit, 'ok': ok}, indent=1))
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
