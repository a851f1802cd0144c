"""RDT driver benchmark: ``netft`` against ``rdt_emulator`` at 7 kHz, each in its own process, as `ros2 run` starts
them (the installed console scripts), for ``--duration`` s per configuration:

- every record published (7 kHz WrenchStamped),
- 1 kHz out, each message the mean of 7 records (``publish_rate_hz:=1000``), and
- the same from a buffered stream (``command:=buffered``, 10 records per datagram, as a Net F/T's RDT output
  buffer sends them): a tenth of the datagrams to receive.

Reported per configuration: RDT records the emulator sent, the driver received, lost (from rdt_sequence; goal 0),
out of order, late-dropped; messages the driver published and an observer in this process received (serialized,
stamps only) and the gaps in their stamps; the CPU share of the driver and of the emulator (utime + stime from
/proc over the measured span, as a fraction of one core), and the stamps' lag behind the observer's arrival time
(p50/p99: the sample's age when it reaches a subscriber). The baseline in the same run is the emulator's own CPU share
(sending the records) against the driver's (receiving, stamping and publishing them).

Run: .venv/bin/python benchmarks/bench_netft.py [--duration 60] [--rate 7000] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import socket
import sys
import time
from array import array
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)

from crane_stiffness.launcher import rosrun  # noqa: E402
import numpy as np  # noqa: E402

TICKS = os.sysconf('SC_CLK_TCK')


def cpu_seconds(pid: int) -> float:
    """utime + stime of a process [s]."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def final_counters(log: str, prefix: str = 'FINAL_COUNTERS ') -> dict:
    for line in reversed(log.splitlines()):
        if line.startswith(prefix):
            return json.loads(line.split(' ', 2)[2])
    return {}


def run(rate: float, publish_rate: float, seconds: float, log_dir: Path, command: str = 'realtime',
        warmup_s: float = 3.0) -> dict:
    import rclpy
    from geometry_msgs.msg import WrenchStamped

    from crane_stiffness.contract import topics
    from crane_stiffness.serde import decode_stamped
    from crane_stiffness.rosnode.qos import SENSOR_QOS
    from crane_stiffness.rosnode.run import make_executor

    log_dir.mkdir(parents=True, exist_ok=True)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    rclpy.init()
    node = rclpy.create_node('bench_netft_observer')
    executor = make_executor('events', node.context)
    executor.add_node(node)
    seen = array('q')  # stamp, arrival, ...

    def on_wrench(data: bytes) -> None:
        sec, nanosec, _ = decode_stamped(data, 6)
        seen.extend((sec * 1_000_000_000 + nanosec, time.time_ns()))
    node.create_subscription(WrenchStamped, topics.LOAD_CELL_WRENCH, on_wrench, SENSOR_QOS, raw=True)
    emu = rosrun.start_installed('rdt_emulator', ['--ros-args', '-p', f'port:={port}', '-p',
                                                  f'sample_rate_hz:={rate}'], log_dir / 'rdt_emulator.log')
    time.sleep(1.0)
    ft = rosrun.start_installed('netft', ['--ros-args', '-p', 'host:=127.0.0.1', '-p', f'port:={port}', '-p',
                                          'counts_per_force:=1000000.0', '-p', 'counts_per_torque:=1000000.0', '-p',
                                          f'sample_rate_hz:={rate}', '-p', f'publish_rate_hz:={publish_rate}', '-p',
                                          f'command:={command}'], log_dir / 'netft.log')
    try:
        deadline = time.monotonic() + 60
        while node.count_publishers(topics.LOAD_CELL_WRENCH) < 1 or len(seen) < 2000:
            if ft.poll() is not None or emu.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError('driver or emulator did not start:\n' + (log_dir / 'netft.log').read_text()[-2000:]
                                   + (log_dir / 'rdt_emulator.log').read_text()[-2000:])
            executor.spin_once(timeout_sec=0.05)
        t_warm = time.monotonic() + warmup_s
        while time.monotonic() < t_warm:
            executor.spin_once(timeout_sec=0.01)
        cpu0 = {p.pid: cpu_seconds(p.pid) for p in (ft, emu)}
        wall0, first_index = time.monotonic(), len(seen) // 2
        t_end = wall0 + seconds
        while time.monotonic() < t_end:
            executor.spin_once(timeout_sec=0.01)
        wall = time.monotonic() - wall0
        cpu = {p.pid: (cpu_seconds(p.pid) - cpu0[p.pid]) / wall for p in (ft, emu)}
        last_index = len(seen) // 2
    finally:
        rosrun.interrupt(ft, 15.0)
        rosrun.interrupt(emu, 15.0)
        t_drain = time.monotonic() + 1.0
        while time.monotonic() < t_drain:
            executor.spin_once(timeout_sec=0.01)
        executor.remove_node(node)
        node.destroy_node()
        rclpy.shutdown()
    driver = final_counters((log_dir / 'netft.log').read_text())
    device = final_counters((log_dir / 'rdt_emulator.log').read_text())
    a = np.frombuffer(seen, dtype=np.int64).reshape(-1, 2)
    steady = a[first_index:last_index]
    period = 1e9 / (publish_rate or rate)
    gaps = np.diff(steady[:, 0])
    lag_ms = (steady[:, 1] - steady[:, 0]) / 1e6
    return {
        'command': command, 'rate_hz': rate, 'publish_rate_hz': publish_rate or rate, 'seconds': round(wall, 1),
        'records_sent': device.get('published'), 'records_received': driver.get('received'),
        'records_lost': driver.get('records_lost'), 'records_out_of_order': driver.get('records_out_of_order'),
        'records_late_dropped': driver.get('records_late_dropped'), 'clock_resets': driver.get('clock_resets'),
        'published': driver.get('published'), 'observer_received': int(a.shape[0]),
        'observer_stamp_gaps_over_1.5_periods': int((gaps > 1.5 * period).sum()),
        'observer_rate_hz': round(steady.shape[0] / wall, 1),
        'cpu_driver': round(cpu[ft.pid], 3), 'cpu_emulator': round(cpu[emu.pid], 3),
        'lag_ms_p50': round(float(np.percentile(lag_ms, 50)), 2),
        'lag_ms_p99': round(float(np.percentile(lag_ms, 99)), 2),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--duration', type=float, default=60.0, help='measured seconds per configuration')
    ap.add_argument('--rate', type=float, default=7000.0, help="the sensor's sample rate [Hz]")
    ap.add_argument('--json', type=Path, help='write the figures here')
    args = ap.parse_args(argv)
    out = REPO / 'out' / 'bench' / 'netft'
    results = []
    for publish_rate, command in ((0.0, 'realtime'), (1000.0, 'realtime'), (1000.0, 'buffered')):
        r = run(args.rate, publish_rate, args.duration, out / f'{command}_{int(publish_rate or args.rate)}',
                command)
        results.append(r)
        print(json.dumps(r), flush=True)
    for r in results:
        print(f"{r['command']}: {r['rate_hz']:.0f} Hz in, {r['publish_rate_hz']:.0f} Hz out, {r['seconds']} s: "
              f"records sent "
              f"{r['records_sent']}, received {r['records_received']}, lost {r['records_lost']}, out of order "
              f"{r['records_out_of_order']}; published {r['published']}, observer got {r['observer_received']} "
              f"({r['observer_stamp_gaps_over_1.5_periods']} stamp gaps); CPU driver {100 * r['cpu_driver']:.1f} % "
              f"of a core, emulator {100 * r['cpu_emulator']:.1f} %; stamp-to-arrival p50 {r['lag_ms_p50']} ms, "
              f"p99 {r['lag_ms_p99']} ms")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2))
    return 0 if all(r['records_lost'] == 0 for r in results) else 1


if __name__ == '__main__':
    sys.exit(main())
