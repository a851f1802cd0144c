"""LVDT readings lost on the hardware template against the DAQ's poll rate: the rig on
config/drivers_ati_labjack.yaml over the device emulators (crane_stiffness.testing.driver_loss: rdt_emulator and
modbus_emulator as processes of their own, the drivers pointed at them), the side-force program (21 s), beside one
busy process, for each ``--rates`` value of modbus_lvdt's ``poll_rate_hz`` (``--runs`` times each).

Reported per run, counts only: polls made, grid instants the driver's timer skipped (taken late at the next tick,
``caught_up_polls``, or never, ``missed_polls``), failed polls (and their share of the grid instants), the bag's
readings within the program and the grid instants there with none (the share lost); the F/T driver's RDT records
received and lost beside it. Baseline: the template's former 500 Hz; target: nothing
lost at the template's rate.

Run: .venv/bin/python benchmarks/bench_driver_loss.py [--rates 500 100] [--runs 2] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--rates', type=float, nargs='+', default=[500.0, 100.0], help='poll rates to try [Hz]')
    ap.add_argument('--runs', type=int, default=2, help='runs per rate')
    ap.add_argument('--idle', action='store_true', help='without the busy process')
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)
    from crane_stiffness.launcher import rosrun
    from crane_stiffness.testing.driver_loss import run_template_rig
    ws = REPO / 'out' / 'bench_driver_loss'
    env, share = rosrun.build_workspace(REPO, ws)
    results = []
    for rate in args.rates:
        for run in range(args.runs):
            figures = run_template_rig(share, env, ws / f'run_{rate:g}_{run}', poll_rate_hz=rate, busy=not args.idle)
            load = os.getloadavg()[0]
            results.append({**figures.as_dict(), 'load_average_1min': load})
            print(f'{rate:6.0f} Hz run {run + 1}: {figures.polls} polls, {figures.caught_up} skipped and taken late, '
                  f'{figures.missed_polls} never taken, {figures.failures} failed ({100 * figures.skipped_share:.2f} % '
                  f'skipped); bag within the program '
                  f'{figures.bag_readings} readings, {figures.bag_missing} missing ({100 * figures.lost_share:.2f} % '
                  f'lost); RDT {figures.ft_received} records, '
                  f'{figures.ft_lost} lost; load average {load:.1f}', flush=True)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(results, indent=1))
    # The target: nothing lost at the template's own rate (the last of --rates by default).
    from crane_stiffness.params.files import load_params
    template = load_params(share / 'drivers_ati_labjack.yaml', 'modbus_lvdt')['poll_rate_hz']
    missed = [r for r in results if r['poll_rate_hz'] == template and (r['missed_polls'] or r['bag_missing'])]
    print(f"target, nothing lost at the template's {template:g} Hz: {'missed' if missed else 'met'}")
    return 1 if missed else 0


if __name__ == '__main__':
    sys.exit(main())
