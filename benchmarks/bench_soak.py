"""Soak benchmark: the whole simulated rig (recorder included) at 1 kHz for a long run, every node's memory sampled.

Every node starts the way `ros2 run` starts it, from a colcon install tree, all at once as `ros2 launch` starts them
(crane_stiffness.launcher.rig.start_rig); the side-force program repeats for the whole run. Every ``--every`` seconds
the resident set size (RSS, /proc/<pid>/status VmRSS, the node's process and any children) of every node is
sampled. Reported per node: RSS at the start of the steady state (``--warmup`` s after the program started: start-up,
JIT compilation and DDS discovery are over), at the end, the growth between them [MB] and the least-squares slope
over the steady state [MB/min]. Target: growth ≤ 5 MB per node over a 10-minute run, and the session recorder, which
a lab runs all day, flat within 0.5 MB (``--max-recorder-growth-mb``).

Run: .venv/bin/python benchmarks/bench_soak.py [--seconds 600] [--rate 1000] [--every 10] [--json out.json]
Exit status 1 when a node grew more than ``--max-growth-mb`` or a node died.
"""
from __future__ import annotations

import argparse
import json
import math
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

MB = 1024 * 1024
PROGRAM = 'side_force'


def _children() -> dict[int, list[int]]:
    """Parent pid → child pids, from /proc."""
    tree: dict[int, list[int]] = {}
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            with open(f'/proc/{entry}/stat') as f:
                stat = f.read()
        except OSError:
            continue
        ppid = int(stat[stat.rindex(')') + 2:].split()[1])
        tree.setdefault(ppid, []).append(int(entry))
    return tree


def rss_bytes(pid: int, tree: dict[int, list[int]] | None = None) -> int | None:
    """RSS of ``pid`` and its descendants [bytes] (a node run through `ros2 run` is a child); None if it is gone."""
    tree = _children() if tree is None else tree
    total, found, stack = 0, False, [pid]
    while stack:
        p = stack.pop()
        try:
            with open(f'/proc/{p}/status') as f:
                for line in f:
                    if line.startswith('VmRSS:'):
                        total += int(line.split()[1]) * 1024
                        found = True
                        break
        except OSError:
            continue
        stack.extend(tree.get(p, []))
    return total if found else None


def program_length_s(share: Path) -> float:
    from crane_stiffness.launcher.rig import config_files
    from crane_stiffness.sim.program import load_program_file
    program = load_program_file(config_files(share, PROGRAM)['program'])
    return program.duration_s / program.repeats  # one pass of the segments [s]


def soak(seconds: float, rate: float, every: float, warmup: float, env: dict, share: Path, out: Path) -> dict:
    import rclpy

    from crane_stiffness.launcher import rosrun
    from crane_stiffness.launcher.rig import Observer, start_rig, wait_for_program_start

    repeats = max(1, math.ceil((seconds + 30.0) / program_length_s(share)))
    rates = {'sample_rate_hz': rate}
    overrides = {'load_cell': rates, 'lvdt': rates, 'load_program': {'repeats': repeats},
                 'session_recorder': {'stop_on_program_done': False}}
    rclpy.init()
    observer = Observer()
    samples: dict[str, list[tuple[float, float]]] = {}  # node -> [(s since program start, RSS MB)]
    died: dict[str, int] = {}
    try:
        with rosrun.Processes(env, out / 'logs') as procs:
            start_rig(procs, share, PROGRAM, 'soak', out / 'bags', record=True, ready_timeout_s=120.0,
                      overrides=overrides)
            wait_for_program_start(observer, procs, 180.0)
            t0 = time.monotonic()
            next_sample = t0
            while True:
                now = time.monotonic()
                if now >= next_sample:
                    tree = _children()
                    for name, proc in procs.procs.items():
                        if proc.poll() is not None:
                            died.setdefault(name, proc.returncode)
                            continue
                        rss = rss_bytes(proc.pid, tree)
                        if rss is not None:
                            samples.setdefault(name, []).append((now - t0, rss / MB))
                    line = ', '.join(f'{n} {v[-1][1]:.1f}' for n, v in samples.items())
                    print(f'[{now - t0:6.0f} s] RSS MB: {line}', flush=True)
                    next_sample += every
                    if now - t0 >= seconds:
                        break
                observer.spin_once(timeout_sec=min(0.1, max(0.0, next_sample - time.monotonic())))
            codes = procs.stop()
    finally:
        observer.destroy_node()
        rclpy.try_shutdown()
    nodes = {}
    for name, values in samples.items():
        arr = np.array(values)
        steady = arr[arr[:, 0] >= warmup]
        if len(steady) < 2:
            steady = arr
        slope = float(np.polyfit(steady[:, 0] / 60.0, steady[:, 1], 1)[0]) if len(steady) >= 2 else float('nan')
        nodes[name] = {'rss_start_mb': round(float(steady[0, 1]), 2), 'rss_end_mb': round(float(steady[-1, 1]), 2),
                       'growth_mb': round(float(steady[-1, 1] - steady[0, 1]), 2),
                       'slope_mb_per_min': round(slope, 4), 'rss_max_mb': round(float(arr[:, 1].max()), 2),
                       'samples': len(arr)}
    return {'seconds': seconds, 'rate_hz': rate, 'every_s': every, 'warmup_s': warmup, 'program': PROGRAM,
            'repeats': repeats, 'nodes': nodes, 'died_during_run': died, 'exit_codes': codes}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=600.0, help='length of the soak after the program start [s]')
    ap.add_argument('--rate', type=float, default=1000.0, help='sensor sample rate [Hz]')
    ap.add_argument('--every', type=float, default=10.0, help='RSS sampling period [s]')
    ap.add_argument('--warmup', type=float, default=30.0,
                    help='growth and slope are measured from this long after the program start [s]')
    ap.add_argument('--max-growth-mb', type=float, default=5.0, help='target: growth per node at most this [MB]')
    ap.add_argument('--max-recorder-growth-mb', type=float, default=0.5,
                    help="target: the session recorder's growth at most this [MB] (it records all day)")
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)
    from crane_stiffness.launcher import rosrun
    ws = REPO / 'out' / 'bench_soak'
    env, share = rosrun.build_workspace(REPO, ws)
    res = soak(args.seconds, args.rate, args.every, args.warmup, env, share, ws / time.strftime('%Y%m%dT%H%M%S'))
    print(f"--- soak: whole rig at {res['rate_hz']:.0f} Hz, {res['seconds']:.0f} s after the program start, RSS every "
          f"{res['every_s']:.0f} s; growth from {res['warmup_s']:.0f} s on (target <= {args.max_growth_mb} MB, "
          f"session_recorder <= {args.max_recorder_growth_mb} MB)")
    failed = []
    for name, n in res['nodes'].items():
        limit = args.max_recorder_growth_mb if name == 'session_recorder' else args.max_growth_mb
        ok = n['growth_mb'] <= limit
        failed += [] if ok else [name]
        print(f"  {name:20s} RSS {n['rss_start_mb']:7.1f} -> {n['rss_end_mb']:7.1f} MB: "
              f"growth {n['growth_mb']:+6.2f} MB, "
              f"slope {n['slope_mb_per_min']:+.3f} MB/min, max {n['rss_max_mb']:.1f} MB"
              f"{'' if ok else f'  (over target {limit} MB)'}")
    if res['died_during_run']:
        print(f"  nodes that ended during the run (exit status): {res['died_during_run']}")
    print(f"  exit status at the end: {res['exit_codes']}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(res, indent=1))
    return 1 if failed or res['died_during_run'] or any(c != 0 for c in res['exit_codes'].values()) else 0


if __name__ == '__main__':
    sys.exit(main())
