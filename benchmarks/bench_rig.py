"""Rig benchmark: the simulated rig as separate processes at 1 kHz (and 5 kHz), for 60 s each; with
``--transports sim drivers`` also the rig through the drivers (rig.launch.py transport:=drivers: the load cell as a
7 kHz RDT device read by netft, which publishes 1 ms means; the LVDT as a Modbus TCP device polled by modbus_lvdt
at the same rate), so the two transports' estimate lags are measured back to back.

Every node starts the way `ros2 run` starts it, from a colcon install tree. For each rate it reports, per sensor
topic, the messages the sensor node published (its exit counter) against those the estimator received (its counter)
and the samples an independent observer in this process received against the stamp grid (exact loss). Lag, from the
stamp of the newest pair an estimate includes:
- at the estimator, when it publishes (its own record of every estimate, reported on /stiffness/estimate): the
  figure the target is about;
- at the observer (one more DDS hop), in steady state from ``--warmup`` s after the program start;
- per sample: every displacement sample's stamp to the arrival of the first estimate that includes it (adds the
  wait inside the sensor's buffer).
The baseline, measured in the same run, is the raw transport lag of the sensor messages (stamp to arrival here).
Targets at 1 kHz: nothing lost, p99 ≤ 5 ms.

Through the drivers, ``rate`` is netft's publish rate and modbus_lvdt's poll rate (the RDT device runs at 7 kHz);
"sent" is what netft and modbus_lvdt published; the LVDT's stamps are mid-request, not on a grid, so only the
wrench's grid loss is counted; the LVDT's achieved poll rate is reported.

Run: .venv/bin/python benchmarks/bench_rig.py [--seconds 60] [--rates 1000 5000] [--publish-rate HZ]
     [--transports sim drivers] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import sys
import time
from array import array
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)

import numpy as np  # noqa: E402


def final_counters(log: str) -> dict:
    """The FINAL_COUNTERS line a node prints at exit (crane_stiffness.rosnode.run.final_counters)."""
    for line in reversed(log.splitlines()):
        if line.startswith('FINAL_COUNTERS '):
            return json.loads(line.split(' ', 2)[2])
    return {}


def view_client(port: int, stop, counts: list) -> None:
    """A client of the live view (a thread): subscribes to what the page shows (every /live_view/ channel) and
    reads until ``stop`` is set; counts[0] = messages received. The page's own drawing is not the view's cost."""
    from websockets.sync.client import connect
    ws = connect(f'ws://127.0.0.1:{port}', subprotocols=['foxglove.sdk.v1'], max_size=None, legacy=True)
    subscribed = False
    while not stop.is_set():
        try:
            frame = ws.recv(timeout=0.2)
        except TimeoutError:
            continue
        if isinstance(frame, str) and not subscribed and json.loads(frame).get('op') == 'advertise':
            channels = [c for c in json.loads(frame)['channels'] if c['topic'].startswith('/live_view/')]
            ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [{'id': i + 1, 'channelId': c['id']}
                                                                       for i, c in enumerate(channels)]}))
            subscribed = True
        elif isinstance(frame, bytes):
            counts[0] += 1
    ws.close()


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far, s (/proc/<pid>/stat)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def run_rate(rate: float, seconds: float, env: dict, share: Path, log_dir: Path, publish_rate: float = 0.0,
             warmup_s: float = 2.0, transport: str = 'sim', view_clients: int | None = None) -> dict:
    """One run; ``view_clients``: start live_view too, with that many clients connected (None: no view)."""
    import threading
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PointStamped, WrenchStamped
    from std_msgs.msg import Float64MultiArray

    from crane_stiffness.contract import topics
    from crane_stiffness.serde import decode_stamped
    from crane_stiffness.rosnode.qos import RELIABLE_QOS, SENSOR_QOS
    from crane_stiffness.rosnode.run import make_executor
    from crane_stiffness.launcher.rig_description import rig_nodes
    from crane_stiffness.launcher import rosrun
    from crane_stiffness.testing.lab_network import emulated_ports
    from crane_stiffness.launcher.rig import estimate_fields, start_node

    fields = estimate_fields()
    i_stamp = fields.index('sample_stamp')
    rclpy.init()
    node = rclpy.create_node('bench_observer')
    executor = make_executor('events', node.context)  # the observer must not be the bottleneck it measures
    executor.add_node(node)
    sensors = (topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT)
    # Flat arrays, not lists of tuples: a quarter of a million tuples would make the observer's garbage collector
    # stall it for tens of milliseconds (and lose samples) - an artefact of the measurement, not of the rig.
    seen = {t: array('q') for t in sensors}  # stamp, arrival here, stamp, arrival, ... ns
    est_seen = array('d')  # newest pair stamp, arrival here, ... of every estimate, s
    est_input: dict[str, str] = {}

    def on_sensor(topic, count):
        out = seen[topic]

        def cb(data: bytes):  # serialized: the observer decodes only the stamp, a few µs
            sec, nanosec, _ = decode_stamped(data, count)
            out.extend((sec * 1_000_000_000 + nanosec, time.time_ns()))
        return cb

    def on_values(msg: Float64MultiArray):
        stamp = np.nanmax([msg.data[i_stamp], msg.data[len(fields) + i_stamp]])
        if np.isfinite(stamp) and stamp > 0:
            est_seen.extend((stamp, time.time()))

    def on_estimate(msg: DiagnosticArray):
        for st in msg.status:
            if st.name.endswith(': input'):
                est_input.update({kv.key: kv.value for kv in st.values})

    node.create_subscription(WrenchStamped, topics.LOAD_CELL_WRENCH, on_sensor(topics.LOAD_CELL_WRENCH, 6),
                             SENSOR_QOS, raw=True)
    node.create_subscription(PointStamped, topics.LVDT_DISPLACEMENT, on_sensor(topics.LVDT_DISPLACEMENT, 3),
                             SENSOR_QOS, raw=True)
    node.create_subscription(Float64MultiArray, topics.STIFFNESS_VALUES, on_values, RELIABLE_QOS)
    node.create_subscription(DiagnosticArray, topics.STIFFNESS_ESTIMATE, on_estimate, RELIABLE_QOS)
    # The rig of rig.launch.py without the recorder, the sensors at the benchmark's rates.
    nodes = rig_nodes(share, {'program': 'side_force', 'record': False, 'transport': transport,
                              'live_view': view_clients is not None})
    if transport == 'sim':
        sensor_nodes = {t: n for t, n in zip(sensors, ('load_cell', 'lvdt'))}
        rates = {'sample_rate_hz': rate, **({'publish_rate_hz': publish_rate} if publish_rate else {})}
        overrides = {'load_cell': rates, 'lvdt': rates}
    else:
        sensor_nodes = {t: n for t, n in zip(sensors, ('netft', 'modbus_lvdt'))}
        overrides = emulated_ports()
        overrides['netft'] |= {'publish_rate_hz': rate, **({'flush_rate_hz': publish_rate} if publish_rate else {})}
        overrides['modbus_lvdt'] |= {'poll_rate_hz': rate}
    if view_clients is not None:
        from crane_stiffness.launcher.ports import free_port
        overrides['live_view'] = {'port': free_port(), 'http_port': free_port()}
    stop_clients = threading.Event()
    client_counts: list[list[int]] = []
    view_cpu: list[float] = []
    repeats = int(np.ceil(seconds / 21.0))
    suffix = '' if view_clients is None else f'_view{view_clients}'
    with rosrun.Processes(env, log_dir / f'{transport}_{int(rate)}hz{suffix}') as procs:
        for n in nodes:
            if not n.runs_program:
                start_node(procs, n, overrides.get(n.name))
        deadline = time.monotonic() + 150
        while not (node.count_subscribers(topics.LOAD_CELL_WRENCH) >= 2
                   and node.count_subscribers(topics.LVDT_DISPLACEMENT) >= 2
                   and node.count_publishers(topics.STIFFNESS_VALUES) >= 1):
            procs.check_alive()
            if time.monotonic() > deadline:
                raise RuntimeError('rig did not connect')
            executor.spin_once(timeout_sec=0.05)
        clients = []
        if view_clients is not None:
            while 'live view: page' not in procs.log('live_view'):
                procs.check_alive()
                if time.monotonic() > deadline:
                    raise RuntimeError('the live view did not start')
                executor.spin_once(timeout_sec=0.05)
            for _ in range(view_clients):
                client_counts.append([0])
                clients.append(threading.Thread(target=view_client, daemon=True, args=(
                    overrides['live_view']['port'], stop_clients, client_counts[-1])))
                clients[-1].start()
        for n in nodes:
            if n.runs_program:
                start_node(procs, n, {'repeats': repeats, 'start_delay_s': 0.5})
        program_start = time.time()
        window = (program_start + warmup_s, program_start + seconds)  # steady state, wall clock s
        t_end = time.monotonic() + seconds
        t_cpu = time.monotonic() + warmup_s
        while time.monotonic() < t_end:
            executor.spin_once(timeout_sec=0.01)
            if view_clients is not None and not view_cpu and time.monotonic() >= t_cpu:
                view_cpu += [time.monotonic(), cpu_seconds(procs.procs['live_view'].pid)]
        if view_cpu:
            view_cpu = [(cpu_seconds(procs.procs['live_view'].pid) - view_cpu[1]) / (time.monotonic() - view_cpu[0])]
        stop_clients.set()
        for c in clients:
            c.join(5)
        procs.check_alive()
        # Stop the program and the sensors; everything they sent must still arrive.
        procs.stop(names=('load_program', *sensor_nodes.values()))
        t_drain = time.monotonic() + 3.0
        while time.monotonic() < t_drain:
            executor.spin_once(timeout_sec=0.01)
        sent = {t: final_counters(procs.log(n)).get('published') for t, n in sensor_nodes.items()}
        driver_counters = ({n: final_counters(procs.log(n)) for n in sensor_nodes.values()}
                           if transport == 'drivers' else {})
    executor.remove_node(node)
    node.destroy_node()
    rclpy.shutdown()
    arrays = {t: np.frombuffer(v, dtype=np.int64).reshape(-1, 2) for t, v in seen.items()}
    est = np.frombuffer(est_seen, dtype=float).reshape(-1, 2)
    if os.environ.get('BENCH_DUMP'):  # raw arrays for a closer look
        np.savez(os.environ['BENCH_DUMP'], est=est, **{t.strip('/').replace('/', '_'): a for t, a in arrays.items()})

    def grid_loss(ns: np.ndarray, on_grid: bool = True) -> dict:
        """Samples sit on a grid of 1/rate: every missing grid point between the first and last received stamp
        is a message lost on the way to this observer (exact, unlike counts that include start-up)."""
        ns = np.unique(ns)
        if len(ns) < 2 or not on_grid:
            return {'expected': None, 'received': len(ns), 'lost': None, 'gaps': []}
        period = 1e9 / rate
        expected = int(round((ns[-1] - ns[0]) / period)) + 1
        steps = np.round(np.diff(ns) / period).astype(int)
        where = np.nonzero(steps > 1)[0]
        gaps = [(round(float(ns[i] * 1e-9 - program_start), 3), int(steps[i] - 1)) for i in where[:20]]
        return {'expected': expected, 'received': len(ns), 'lost': expected - len(ns), 'gaps': gaps}

    def stats(lag_s: np.ndarray) -> dict:
        if lag_s.size == 0:
            return {'p50': float('nan'), 'p99': float('nan'), 'max': float('nan'), 'n': 0}
        p50, p99 = np.percentile(lag_s * 1e3, [50, 99])
        return {'p50': round(float(p50), 3), 'p99': round(float(p99), 3), 'max': round(float(lag_s.max() * 1e3), 3),
                'n': int(lag_s.size)}

    in_window = lambda arrival_s: (arrival_s >= window[0]) & (arrival_s <= window[1])  # noqa: E731
    est_in = est[in_window(est[:, 1])]
    raw = np.concatenate([a for a in arrays.values()]) if arrays else np.zeros((0, 2), np.int64)
    raw_lag = (raw[:, 1] - raw[:, 0]) * 1e-9
    raw_lag = raw_lag[in_window(raw[:, 1] * 1e-9)]

    # Every displacement sample in the window to the first estimate whose newest pair is at least as new.
    per_sample = np.zeros(0)
    if len(est):
        newest = np.maximum.accumulate(est[:, 0])
        t = np.unique(arrays[topics.LVDT_DISPLACEMENT][:, 0]) * 1e-9
        t = t[(t >= window[0]) & (t <= window[1] - 1.0)]
        i = np.searchsorted(newest, t - 1e-6)
        ok = i < len(newest)
        per_sample = est[i[ok], 1] - t[ok]
    received = {topics.LOAD_CELL_WRENCH: int(est_input.get('force_received', -1)),
                topics.LVDT_DISPLACEMENT: int(est_input.get('displacement_received', -1))}
    lvdt_ns = np.unique(arrays[topics.LVDT_DISPLACEMENT][:, 0])
    achieved = (len(lvdt_ns) - 1) / ((lvdt_ns[-1] - lvdt_ns[0]) * 1e-9) if len(lvdt_ns) > 1 else float('nan')
    return {
        'transport': transport, 'driver_counters': driver_counters,
        'lvdt_achieved_rate_hz': round(float(achieved), 1),
        'rate_hz': rate, 'seconds': seconds, 'publish_rate_hz': publish_rate or None, 'steady_state_from_s': warmup_s,
        'topics': {t: {'sent': sent[t], 'estimator_received': received[t], 'observer_received': len(arrays[t]),
                       'sent_minus_estimator_received': None if sent[t] is None else sent[t] - received[t],
                       'observer_grid': grid_loss(arrays[t][:, 0], transport == 'sim' or t == topics.LOAD_CELL_WRENCH)}
                   for t in sensors},
        'estimator_own_lag_ms': {k: float(est_input.get(f'lag_{k}_ms', 'nan')) for k in ('p50', 'p99', 'max')}
        | {'n': int(est_input.get('lag_n', 0))},
        'estimate_lag_ms': stats(est_in[:, 1] - est_in[:, 0]),
        'sample_to_estimate_ms': stats(per_sample),
        'baseline_sensor_transport_lag_ms': stats(raw_lag),
        'live_view': None if view_clients is None else {
            'clients': view_clients, 'messages_per_client': [c[0] for c in client_counts],
            'cpu_fraction_of_a_core': round(view_cpu[0], 4) if view_cpu else None},
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=60.0)
    ap.add_argument('--rates', type=float, nargs='+', default=[1000.0, 5000.0])
    ap.add_argument('--publish-rate', type=float, default=0.0,
                    help='sensor publish (burst) rate [Hz]; 0 = config/sensors.yaml')
    ap.add_argument('--warmup', type=float, default=2.0,
                    help='observer statistics start this long after the program start [s]')
    ap.add_argument('--transports', nargs='+', default=['sim'], choices=['sim', 'drivers'],
                    help="sim: the simulated sensors' direct topics; drivers: through the device emulators and the "
                         'drivers (rig.launch.py transport:=drivers)')
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)
    from crane_stiffness.launcher import rosrun
    ws = REPO / 'out' / 'bench_rig'
    env, share = rosrun.build_workspace(REPO, ws)
    results = [run_rate(r, args.seconds, env, share, ws / 'logs', args.publish_rate, args.warmup, transport)
               for transport in args.transports for r in args.rates]
    for res in results:
        via = (f"through the drivers (RDT 7 kHz -> netft {res['rate_hz']:.0f} Hz means; modbus_lvdt polls achieved "
               f"{res['lvdt_achieved_rate_hz']} Hz)" if res['transport'] == 'drivers' else 'simulated sensors, direct')
        print(f"--- {res['rate_hz']:.0f} Hz load cell and LVDT, {res['seconds']:.0f} s, {via}")
        for topic, c in res['topics'].items():
            g = c['observer_grid']
            print(f"  {topic:22s} sent {c['sent']}, estimator received {c['estimator_received']} (difference "
                  f"{c['sent_minus_estimator_received']}, includes samples sent before it was matched); observer: "
                  f"{g['received']} of {g['expected']} grid samples, lost {g['lost']}"
                  + (f" (at s after the program start, count: {g['gaps']})" if g['gaps'] else ''))
        e, b = res['estimate_lag_ms'], res['baseline_sensor_transport_lag_ms']
        s, o = res['sample_to_estimate_ms'], res['estimator_own_lag_ms']
        print(f"  estimator's lag at publication (its clock - newest pair stamp; whole run, its /stiffness/estimate):"
              f" p50 {o['p50']:.1f} ms, p99 {o['p99']:.1f} ms, max {o['max']:.1f} ms (n = {o['n']})")
        print(f"  at this observer, steady state (from {res['steady_state_from_s']:.0f} s after the program start):")
        print(f"    estimate arrival - its newest pair stamp: p50 {e['p50']} ms, p99 {e['p99']} ms, max {e['max']} ms "
              f"(n = {e['n']})")
        print(f"    every displacement sample to the first estimate including it (adds the wait in the sensor's "
              f"buffer): p50 {s['p50']} ms, p99 {s['p99']} ms (n = {s['n']})")
        print(f"    baseline, raw sensor messages stamp to arrival: p50 {b['p50']} ms, p99 {b['p99']} ms "
              f"(n = {b['n']})")
    by = {(r['transport'], r['rate_hz']): r for r in results}
    for rate in args.rates:
        if ('sim', rate) in by and ('drivers', rate) in by:
            a, b = by[('sim', rate)], by[('drivers', rate)]
            print(f"=== {rate:.0f} Hz, estimate arrival - newest pair stamp, steady state: direct p50 "
                  f"{a['estimate_lag_ms']['p50']} / p99 {a['estimate_lag_ms']['p99']} ms; through the drivers p50 "
                  f"{b['estimate_lag_ms']['p50']} / p99 {b['estimate_lag_ms']['p99']} ms (raw sensor messages: direct "
                  f"p50 {a['baseline_sensor_transport_lag_ms']['p50']} ms, drivers p50 "
                  f"{b['baseline_sensor_transport_lag_ms']['p50']} ms)")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
