"""Benchmark: replay timing of ``session_player`` against plain loops publishing the same messages.

Two kinds of session bag are played, 15 s of each (load cell and LVDT at 1 kHz):

- a bag recorded on the wall clock (``scripts/demo.py --wall-time``: log time = the recorder's receipt time);
- a bag recorded on simulated time (``scripts/demo.py``, the default: the counted streams logged at their header
  stamps, crane_stiffness.sim.log_times).

Without ``--wall-bag``/``--sim-bag`` both are recorded first with the demo (about 2 min each on a busy machine).
Each bag is played three times in the same run:

- the baseline: a plain loop in a process of its own that has every message in memory beforehand, sleeps until its
  log time and publishes it (the machine's own jitter: scheduler, DDS, Python's sleep);
- the former pacing: the same loop reading the bag as it goes, in the publishing thread (what ``session_player``
  did: each chunk's read made the messages after it late);
- ``session_player`` (this tree's code, started as ``ros2 run`` starts it).

A subscriber in this process takes each message's DDS source timestamp (the instant its publisher wrote it) and
compares it with the message's log time in the bag; after the median is removed, the p50/p99/max of the absolute
deviation and the messages missing are reported (those lost once the listener had matched the publisher fail it;
those before, DDS discovery's doing, are only reported). Target: the player's p99 <= 1 ms on a quiet machine for
both bags, or, on a machine whose own jitter (the baseline's p99) is above 1 ms, no more than 1.2x the baseline's.
Exits 1 on a miss.

    python benchmarks/bench_replay.py [--wall-bag BAG] [--sim-bag BAG] [--offset 5] [--seconds 15] [--json OUT]
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

#: The baseline publishers: sleep until each message's time and publish it, either with every message in memory
#: beforehand (``memory``) or reading the bag as it goes in the publishing thread (``inline``, the former pacing of
#: session_player). argv: mode, bag, offset s, seconds, start delay s, topics.
BASELINE = r'''
import sys, time
import rclpy
from crane_stiffness.bag import BagReader
from crane_stiffness.rosnode.session_qos import message_class, playback_qos
mode, bag, offset_s, seconds, delay_s = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), \
    float(sys.argv[5])
topics = sys.argv[6:]
rclpy.init()
node = rclpy.create_node('replay_baseline')
reader = BagReader(bag)
infos = reader.topics
pubs = {t: node.create_publisher(message_class(infos[t].msg_type), t,
                                 playback_qos(t, infos[t].offered_qos_profiles)) for t in topics}
base = reader.start_ns + int(offset_s * 1e9)
source = reader.messages(topics, start_ns=base, end_ns=base + int(seconds * 1e9))
if mode == 'memory':
    source = list(source)
time.sleep(delay_s)
wall0 = None
for m in source:
    if wall0 is None:
        wall0 = time.monotonic_ns()
    wait = wall0 + m.log_time_ns - base - time.monotonic_ns()
    if wait > 0:
        time.sleep(wait / 1e9)
    pubs[m.topic].publish(m.data)
time.sleep(0.5)
reader.close()
node.destroy_node()
rclpy.shutdown()
'''
#: The runs of each bag, in order: name, and the baseline mode (None: session_player).
RUNS = (('plain loop, in memory', 'memory'), ('former pacing (reads inline)', 'inline'), ('session_player', None))


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
        # Serialized messages, the stamp read from the bytes: a light callback, so that the listener keeps up on a
        # loaded machine (a deep queue for when it is not scheduled for a while).
        qos = QoSProfile(depth=30000, reliability=ReliabilityPolicy.BEST_EFFORT)
        for topic, cls in zip(TOPICS, (WrenchStamped, PointStamped)):
            self.node.create_subscription(cls, topic, self._callback(topic), qos, raw=True)
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
        from crane_stiffness.serde import header_stamp_ns

        def on_message(data, info) -> None:
            self.seen[(topic, header_stamp_ns(data) or 0)] = info['source_timestamp']
        return on_message

    def settle(self, quiet_s: float = 1.0, timeout_s: float = 60.0) -> None:
        """Wait until nothing new has come for ``quiet_s`` (a loaded machine delivers the last messages late)."""
        end = time.monotonic() + timeout_s
        count = -1
        while len(self.seen) != count and time.monotonic() < end:
            count = len(self.seen)
            time.sleep(quiet_s)

    def take(self, since_ns: int) -> dict[tuple[str, int], int]:
        """What was heard since the last take, written at or after ``since_ns`` (system time): a message of the
        run before that a loaded machine delivered late has the same key and is left out."""
        out, self.seen = self.seen, {}
        return {k: t for k, t in out.items() if t >= since_ns}

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
        return {'messages': len(expected), 'received': 0, 'missing_between': 'all', 'lost_after_match': len(expected),
                'worst_1pct_at_s': [], 'p50_ms': float('nan'), 'p99_ms': float('nan'), 'max_ms': float('nan')}
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


def record_bag(directory: Path, wall_time: bool) -> Path:
    """The demo's session recorded on the wall clock or on simulated time (``scripts/demo.py``) into ``directory``."""
    kind = 'wall' if wall_time else 'sim'
    bags = directory / f'{kind}_bags'
    cmd = [sys.executable, str(REPO / 'scripts' / 'demo.py'), '--no-live-view', '--bags', str(bags),
           '--out', str(directory / f'{kind}_out'), *(['--wall-time'] if wall_time else [])]
    print(f'recording the demo on {"the wall clock" if wall_time else "simulated time"} ...', flush=True)
    # exit status 1 = the estimate was not signed (e.g. samples lost on a busy machine): the bag is still a bag
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    found = sorted(bags.glob('*/metadata.yaml'))
    if not found:
        raise SystemExit(f'the demo recorded no bag (exit {done.returncode}):\n'
                         f'{done.stdout[-2000:]}{done.stderr[-2000:]}')
    return found[-1].parent


def play_bag(bag: Path, offset: float, seconds: float, listener: Listener) -> dict[str, dict]:
    """The three runs of one bag (RUNS): their timing against the log times."""
    expected = expected_messages(bag, offset, seconds)
    print(f'{bag}: {len(expected):,} load-cell and LVDT messages, {seconds:g} s from {offset:g} s in', flush=True)
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join([str(REPO), os.environ.get('PYTHONPATH', '')])}
    results = {}
    for name, mode in RUNS:
        if mode is not None:
            cmd = [sys.executable, '-c', BASELINE, mode, str(bag), str(offset), str(seconds), '3.0', *TOPICS]
        else:
            cmd = [str(Path(sys.prefix) / 'bin' / 'session_player'), '--ros-args', '-p', f'bag:={bag}',
                   '-p', f'start_offset_s:={offset}', '-p', f'topics_include:={json.dumps(list(TOPICS))}',
                   '-p', 'start_delay_s:=3.0']
        started = time.time_ns()  # DDS source time stamps are system time
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=seconds + 120, env=env)
        if run.returncode:
            raise SystemExit(f'{name} failed:\n{run.stdout}{run.stderr}')
        listener.settle()
        results[name] = timing(expected, listener.take(started))
    return results


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--wall-bag', type=Path, help='a bag recorded on the wall clock (default: record the demo)')
    parser.add_argument('--sim-bag', type=Path, help='a bag recorded on simulated time (default: record the demo)')
    parser.add_argument('--offset', type=float, default=5.0, help='start this far into each bag [s] (default 5)')
    parser.add_argument('--seconds', type=float, default=15.0, help='seconds played (default 15)')
    parser.add_argument('--json', type=Path, help='write the figures here')
    args = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix='bench_replay_'))
    bags = {'wall clock': args.wall_bag or record_bag(tmp, wall_time=True),
            'simulated time': args.sim_bag or record_bag(tmp, wall_time=False)}
    load = os.getloadavg()
    listener = Listener()
    results: dict[str, dict[str, dict]] = {}
    try:
        for kind, bag in bags.items():
            results[kind] = play_bag(bag, args.offset, args.seconds, listener)
    finally:
        listener.close()
    load = (load[0], os.getloadavg()[0])
    ok = True
    for kind, runs in results.items():
        print(f'bag recorded on {kind} ({bags[kind]}):')
        for name, r in runs.items():
            print(f'  {name:29s}: {r["received"]:,}/{r["messages"]:,} received; |publish time - log time| after the '
                  f'median: p50 {r["p50_ms"]:.3f} ms, p99 {r["p99_ms"]:.3f} ms, max {r["max_ms"]:.3f} ms'
                  + (f'; missing {r["missing_between"]}' if r.get('missing_between') else ''))
            print(f'    the worst 1 % in the 0.1 s spans starting at (s): {r["worst_1pct_at_s"][:20]}')
        player, base = runs['session_player'], runs['plain loop, in memory']
        limit = max(TARGET_P99_MS, BASELINE_FACTOR * base['p99_ms'])
        met = player['p99_ms'] <= limit and player['lost_after_match'] == 0
        ok &= met
        runs['summary'] = {'limit_ms': limit, 'ok': met,
                           'p99_over_plain_loop': player['p99_ms'] / base['p99_ms']}
        print(f'  session_player p99 / plain loop p99 = {player["p99_ms"] / base["p99_ms"]:.2f}; target p99 <= '
              f'{limit:.3f} ms (1 ms, or {BASELINE_FACTOR}x the plain loop on a machine that jitters more): '
              + ('met' if met else f'MISSED ({player["lost_after_match"]} message(s) lost after the listener '
                                   'matched the player)'))
    print(f'load average (1 min) before and after: {load[0]:.1f}, {load[1]:.1f}')
    if args.json:
        args.json.write_text(json.dumps({'results': results, 'load_average': load, 'ok': ok}, indent=1))
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
