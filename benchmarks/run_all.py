"""`make bench`: every benchmark, one after the other (they share the machine, so never in parallel).

Each prints its figures and the ratio to the baseline it measures in the same run; the JSON goes to out/bench/.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / 'out' / 'bench'
#: (script, arguments, JSON file name or None: the script writes no JSON).
BENCHMARKS = [
    ('bench_solver.py', [], 'bench_solver.json'),
    ('bench_bag_decode.py', [], None),
    ('bench_bag_storage.py', [], None),
    ('bench_sync.py', [], 'bench_sync.json'),
    ('bench_uncertainty.py', [], 'bench_uncertainty.json'),   # the prediction's Monte Carlo, lab model
    ('bench_live_u6.py', [], 'bench_live_u6.json'),   # the CPU of the live 6x6 U per publication
    ('bench_analyze.py', [], None),
    ('bench_campaign_analyze.py', [], 'bench_campaign_analyze.json'),   # campaign analyze, 1 and 2 workers
    # campaign run of the paper's campaign: rig hosts against a fresh rig of processes per session, idle and busy
    ('bench_campaign.py', [], 'bench_campaign.json'),
    ('bench_campaign.py', ['--busy', '1'], 'bench_campaign_busy.json'),
    ('bench_replay.py', [], 'bench_replay.json'),
    ('bench_rig.py', [], 'bench_rig.json'),
    # The rig through the drivers (rig.launch.py transport:=drivers) against the direct topics, back to back.
    ('bench_rig.py', ['--rates', '1000', '--transports', 'sim', 'drivers'], 'bench_rig_drivers.json'),
    # The rig at 1 kHz without and with the live view and two clients: the cost of watching.
    ('bench_live_view.py', [], 'bench_live_view.json'),
    # The live view's WebSocket front (Origin, Host, token) against the SDK's server straight: its own cost.
    ('bench_view_front.py', [], 'bench_view_front.json'),
    ('bench_netft.py', [], 'bench_netft.json'),
    ('bench_driver_loss.py', [], 'bench_driver_loss.json'),   # LVDT readings lost at the template's DAQ rate
    ('bench_startup.py', [], 'bench_startup.json'),
    ('bench_sim_time.py', [], 'bench_sim_time.json'),   # the simulated rig flat out, idle and beside busy processes
    ('bench_cpu.py', [], 'bench_cpu.json'),             # make demo's rig and its page in Chromium: CPU budget
    ('bench_full6.py', [], 'bench_full6.json'),         # the live 6x6 fit beside a 1 kHz load cell, 250 Hz pose
    ('bench_soak.py', [], 'bench_soak.json'),   # 10 minutes of the whole rig: every node's memory growth
]


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    failed = []
    for script, args, json_name in BENCHMARKS:
        print(f'=== {script} {" ".join(args)}', flush=True)
        argv = [sys.executable, str(HERE / script), *args]
        if json_name is not None:
            argv += ['--json', str(OUT / json_name)]
        if subprocess.run(argv).returncode != 0:
            failed.append(f'{script} {" ".join(args)}'.strip())
    if failed:
        print('targets missed or errors in: ' + ', '.join(failed))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
