"""Rig benchmark: the simulated rig as separate processes at 1 kHz (and 5 kHz), for 60 s each.

Every node starts the way `ros2 run` starts it, from a colcon install tree. For each rate it reports, per sensor
topic, the messages the sensor node published (its /diagnostics counter) against those the estimator received (its
counter) and those an independent observer in this process received; and the estimator's lag from the stamp of the
newest sample it used to the arrival of the estimate here (p50, p99). The baseline, measured in the same run, is the
transport lag of the raw sensor messages (stamp to arrival here): the estimator's own share is the difference.
Targets at 1 kHz: nothing lost, p99 ≤ 5 ms.

Run: .venv/bin/python benchmarks/bench_rig.py [--seconds 60] [--rates 1000 5000] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)

import numpy as np  # noqa: E402


def final_counters(log: str) -> dict:
    """The FINAL_COUNTERS line a node prints at exit (crane_stiffness.nodes.common.final_counters)."""
    for line in reversed(log.splitlines()):
        if line.startswith('FINAL_COUNTERS '):
            return json.loads(line.split(' ', 2)[2])
    return {}


def run_rate(rate: float, seconds: float, env: dict, share: Path, log_dir: Path, publish_rate: float = 0.0) -> dict:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PointStamped, WrenchStamped
    from std_msgs.msg import Float64MultiArray

    from crane_stiffness import rosrun, topics
    from crane_stiffness.nodes.common import RELIABLE_QOS, SENSOR_QOS, stamp_to_s
    from crane_stiffness.rig import estimate_fields

    fields = estimate_fields()
    i_stamp = fields.index('sample_stamp')
    rclpy.init()
    node = rclpy.create_node('bench_observer')
    from crane_stiffness.nodes.common import make_executor
    executor = make_executor('events', node.context)  # the observer must not be the bottleneck it measures
    executor.add_node(node)
    counts = {topics.LOAD_CELL_WRENCH: 0, topics.LVDT_DISPLACEMENT: 0}
    stamps: dict[str, list[int]] = {topics.LOAD_CELL_WRENCH: [], topics.LVDT_DISPLACEMENT: []}
    sensor_lag: list[float] = []
    est_lag: list[float] = []
    est_input: dict[str, str] = {}

    def on_sensor(topic):
        def cb(msg):
            counts[topic] += 1
            stamps[topic].append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            sensor_lag.append(time.time() - stamp_to_s(msg.header.stamp))
        return cb

    def on_values(msg: Float64MultiArray):
        stamp = np.nanmax([msg.data[i_stamp], msg.data[len(fields) + i_stamp]])
        if np.isfinite(stamp) and stamp > 0:
            est_lag.append(time.time() - stamp)

    def on_estimate(msg: DiagnosticArray):
        for st in msg.status:
            if st.name.endswith(': input'):
                est_input.update({kv.key: kv.value for kv in st.values})

    node.create_subscription(WrenchStamped, topics.LOAD_CELL_WRENCH, on_sensor(topics.LOAD_CELL_WRENCH), SENSOR_QOS)
    node.create_subscription(PointStamped, topics.LVDT_DISPLACEMENT, on_sensor(topics.LVDT_DISPLACEMENT), SENSOR_QOS)
    node.create_subscription(Float64MultiArray, topics.STIFFNESS_VALUES, on_values, RELIABLE_QOS)
    node.create_subscription(DiagnosticArray, topics.STIFFNESS_ESTIMATE, on_estimate, RELIABLE_QOS)
    cfg = lambda n: ['--params-file', str(share / n)]  # noqa: E731
    rate_args = ['-p', f'sample_rate_hz:={rate}'] + (['-p', f'publish_rate_hz:={publish_rate}'] if publish_rate else [])
    repeats = int(np.ceil(seconds / 21.0))
    with rosrun.Processes(env, log_dir / f'{int(rate)}hz') as procs:
        procs.start('crane_model', 'crane_stiffness', 'crane_model', ['--ros-args', *cfg('crane_lab.yaml')])
        procs.start('load_cell', 'crane_stiffness', 'load_cell', ['--ros-args', *cfg('sensors.yaml'), *rate_args])
        procs.start('lvdt', 'crane_stiffness', 'lvdt', ['--ros-args', *cfg('sensors.yaml'), *rate_args])
        procs.start('stiffness_estimator', 'crane_stiffness', 'stiffness_estimator',
                    ['--ros-args', *cfg('crane_lab.yaml'), *cfg('sensors.yaml')])
        deadline = time.monotonic() + 90
        while not (node.count_subscribers(topics.LOAD_CELL_WRENCH) >= 2
                   and node.count_subscribers(topics.LVDT_DISPLACEMENT) >= 2
                   and node.count_publishers(topics.STIFFNESS_VALUES) >= 1):
            procs.check_alive()
            if time.monotonic() > deadline:
                raise RuntimeError('rig did not connect')
            executor.spin_once(timeout_sec=0.05)
        procs.start('load_program', 'crane_stiffness', 'load_program',
                    ['--ros-args', *cfg('program_side_force.yaml'), '-p', f'repeats:={repeats}',
                     '-p', 'start_delay_s:=0.5'])
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            executor.spin_once(timeout_sec=0.01)
        procs.check_alive()
        # Stop the program and the sensors; everything they sent must still arrive.
        procs.stop(names=('load_program', 'load_cell', 'lvdt'))
        t_drain = time.monotonic() + 3.0
        while time.monotonic() < t_drain:
            executor.spin_once(timeout_sec=0.01)
        sent = {topics.LOAD_CELL_WRENCH: final_counters(procs.log('load_cell')).get('published'),
                topics.LVDT_DISPLACEMENT: final_counters(procs.log('lvdt')).get('published')}
    executor.remove_node(node)
    node.destroy_node()
    rclpy.shutdown()

    def grid_loss(ns: list[int]) -> dict:
        """Samples sit on a grid of 1/rate: every missing grid point between the first and last received stamp
        is a message lost on the way to this observer (exact, unlike counts that include start-up)."""
        if len(ns) < 2:
            return {'expected': None, 'received': len(ns), 'lost': None}
        period = 1e9 / rate
        expected = int(round((max(ns) - min(ns)) / period)) + 1
        return {'expected': expected, 'received': len(set(ns)), 'lost': expected - len(set(ns))}

    def pct(xs, q):
        return round(float(np.percentile(np.asarray(xs) * 1e3, q)), 3) if xs else float('nan')

    received = {topics.LOAD_CELL_WRENCH: int(est_input.get('force_received', -1)),
                topics.LVDT_DISPLACEMENT: int(est_input.get('displacement_received', -1))}
    return {
        'rate_hz': rate, 'seconds': seconds,
        'topics': {t: {'sent': sent[t], 'estimator_received': received[t], 'observer_received': counts[t],
                       'sent_minus_estimator_received': None if sent[t] is None else sent[t] - received[t],
                       'observer_grid': grid_loss(stamps[t])} for t in sent},
        'estimate_lag_ms': {'p50': pct(est_lag, 50), 'p99': pct(est_lag, 99), 'n': len(est_lag)},
        'baseline_sensor_transport_lag_ms': {'p50': pct(sensor_lag, 50), 'p99': pct(sensor_lag, 99),
                                             'n': len(sensor_lag)},
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=60.0)
    ap.add_argument('--rates', type=float, nargs='+', default=[1000.0, 5000.0])
    ap.add_argument('--publish-rate', type=float, default=0.0,
                    help='sensor publish (burst) rate [Hz]; 0 = config/sensors.yaml')
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)
    from crane_stiffness import rosrun
    ws = REPO / 'out' / 'bench_rig'
    rosrun.colcon_build(REPO, ws / 'build', ws / 'install', ws / 'log')
    env = rosrun.install_environment(ws / 'install')
    share = ws / 'install' / 'crane_stiffness' / 'share' / 'crane_stiffness' / 'config'
    results = [run_rate(r, args.seconds, env, share, ws / 'logs', args.publish_rate) for r in args.rates]
    for res in results:
        print(f"--- {res['rate_hz']:.0f} Hz load cell and LVDT, {res['seconds']:.0f} s")
        for topic, c in res['topics'].items():
            g = c['observer_grid']
            print(f"  {topic:22s} sent {c['sent']}, estimator received {c['estimator_received']} (difference "
                  f"{c['sent_minus_estimator_received']}, includes samples sent before it was matched); observer: "
                  f"{g['received']} of {g['expected']} grid samples, lost {g['lost']}")
        e, b = res['estimate_lag_ms'], res['baseline_sensor_transport_lag_ms']
        print(f"  estimate lag from sample stamp: p50 {e['p50']} ms, p99 {e['p99']} ms (n = {e['n']}); "
              f"baseline raw sensor lag p50 {b['p50']} ms, p99 {b['p99']} ms")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
