"""Simulated-time benchmark: how much faster than real time the simulated rig runs flat out, and with busy processes.

The whole rig is started as `ros2 launch crane_stiffness rig.launch.py use_sim_time:=true real_time_factor:=max`
starts it (crane_stiffness.launcher.rig.run_rig, from a colcon install tree) with the paper campaign's short
side-force program, once on the machine as it is and once beside ``--busy`` processes (``while True: pass``). The
baseline is the run's own simulated duration: the real-time factor reached (simulated seconds per wall second of
sim_clock, from its FINAL_COUNTERS) is the ratio reported. Target: >= 2 on an otherwise idle two-core machine. The
1-minute load average before each run is printed beside it: on a shared machine the factor follows the load.

Run: .venv/bin/python benchmarks/bench_sim_time.py [--busy 2] [--program campaign_side_force] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)

#: The real-time factor flat out on an idle machine should reach at least this.
TARGET_FACTOR = 2.0


def run_once(share: Path, env: dict, out: Path, program: str) -> dict:
    """One run flat out: sim_clock's counters (simulated_s, wall_s, real_time_factor, held) and the statuses."""
    from crane_stiffness.launcher.rig import run_rig
    summary, _, _, logs = run_rig(share, env, out, program, session='bench', record=True,
                                  arguments={'use_sim_time': 'true', 'real_time_factor': 'max'})
    line = next(line for line in reversed(logs['sim_clock'].splitlines())
                if line.startswith('FINAL_COUNTERS sim_clock '))
    counters = json.loads(line.split(' ', 2)[2])
    counters['statuses'] = {part: st['level'] for part, st in summary['status'].items()}
    return counters


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--busy', type=int, default=2, help='busy processes beside the second run')
    ap.add_argument('--program', default='campaign_side_force', help='program name in config/')
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args()
    from crane_stiffness.launcher import rosrun
    work = Path(tempfile.mkdtemp(prefix='bench_sim_time_'))
    env, share = rosrun.build_workspace(REPO, work / 'ws')
    results = {}
    for label, busy in (('as is', 0), (f'beside {args.busy} busy', args.busy)):
        procs = [subprocess.Popen([sys.executable, '-c', 'while True: pass']) for _ in range(busy)]
        try:
            load = os.getloadavg()[0]
            r = run_once(share, env, work / label.replace(' ', '_'), args.program)
        finally:
            for p in procs:
                p.kill()
                p.wait()
        r['load_before'] = round(load, 2)
        results[label] = r
        print(f'{label:>16}: {r["simulated_s"]:.2f} s simulated in {r["wall_s"]:.2f} s of wall time: real-time '
              f'factor {r["real_time_factor"]:.2f} (held back {r["held"]} times; load before {load:.2f}); '
              f'statuses {r["statuses"]}', flush=True)
    idle = results['as is']['real_time_factor']
    print(f'real-time factor flat out {idle:.2f} (target >= {TARGET_FACTOR:g} on an idle machine)')
    if args.json:
        Path(args.json).write_text(json.dumps({'target_factor': TARGET_FACTOR, 'runs': results}, indent=1))
    return 0 if idle >= TARGET_FACTOR else 1


if __name__ == '__main__':
    sys.exit(main())
