"""CPU budget: what `make demo` costs the machine. The demo's rig (every node its own process, the side-force program
on simulated time at real-time factor 1, the recorder and the live view) is run twice in one run: first with nobody
watching (the baseline), then with the page open in headless Chromium. ``--program full6``: the six-axis run (its
page leads with the 6×6), the same way.

Reports, over the program (from its start to its end), the CPU time (user + system, /proc) of the rig's processes and
of Chromium's process tree, each as a fraction of one core, and the rig's cost with the page against the baseline.
Targets: the rig ≤ 1 core, the page in Chromium ≤ 15 % of a core. Exits 1 when a target is missed.

Run: .venv/bin/python benchmarks/bench_cpu.py [--program full6] [--json out.json]   (needs `chromium` on PATH)
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

from bench_rig import REPO  # noqa: E402  (sets the DDS environment first)

RIG_LIMIT = 1.0
PAGE_LIMIT = 0.15
TICK = os.sysconf('SC_CLK_TCK')


def tree_cpu_s(roots: list[int]) -> float:
    """User + system CPU time [s] of the processes ``roots`` and all their descendants alive now."""
    parent: dict[int, int] = {}
    ticks: dict[int, int] = {}
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f'/proc/{entry}/stat').read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(')') + 2:].split()  # after "pid (comm) "
        parent[int(entry)] = int(fields[1])
        ticks[int(entry)] = int(fields[11]) + int(fields[12])  # utime, stime
    wanted, total = set(roots), 0
    for pid in ticks:
        p = pid
        while p > 1 and p not in wanted:
            p = parent.get(p, 0)
        if p in wanted:
            total += ticks[pid]
    return total / TICK


def run(env: dict, share: Path, ws: Path, page: bool, program_name: str = 'side_force') -> dict:
    """One demo run; CPU fractions of one core over the program."""
    import rclpy

    from crane_stiffness.launcher import rosrun
    from crane_stiffness.launcher.ports import free_port
    from crane_stiffness.launcher.rig import Observer, start_rig, wait_for_program_start
    rclpy.init()
    observer = Observer()
    browser = None
    profile = tempfile.mkdtemp(prefix='bench_cpu_chromium_')
    try:
        with rosrun.Processes(env, ws / 'logs') as procs:
            view = {'port': free_port(), 'http_port': free_port()}
            session = f'bench_cpu_{"page" if page else "baseline"}_{time.strftime("%Y%m%dT%H%M%S")}'
            program = start_rig(procs, share, program_name, session,
                                ws / 'bags', live_view=True, overrides={'live_view': view},
                                arguments={'use_sim_time': 'true', 'real_time_factor': '1.0'})
            deadline = time.monotonic() + 60
            while 'live view: page http://' not in procs.log('live_view'):
                procs.check_alive()
                assert time.monotonic() < deadline, procs.log('live_view')[-2000:]
                time.sleep(0.1)
            if page:
                chromium = shutil.which('chromium')
                assert chromium, 'chromium is not on PATH (apt-get install chromium)'
                browser = subprocess.Popen([chromium, '--headless=new', '--no-sandbox', '--disable-gpu',
                                            f'--user-data-dir={profile}', '--remote-debugging-port=0',
                                            f'http://127.0.0.1:{view["http_port"]}/'],
                                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            wait_for_program_start(observer, procs, 90)
            rig_pids = [p.pid for p in procs.procs.values()]
            t0, rig0 = time.monotonic(), tree_cpu_s(rig_pids)
            nodes0 = {name: tree_cpu_s([p.pid]) for name, p in procs.procs.items()}
            page0 = tree_cpu_s([browser.pid]) if browser else 0.0
            end = time.monotonic() + program.duration_s + 60
            while not observer.done and procs.procs['load_program'].poll() is None and time.monotonic() < end:
                observer.spin_once(0.1)
            wall = time.monotonic() - t0
            rig = (tree_cpu_s(rig_pids) - rig0) / wall
            per_node = {name: round((tree_cpu_s([p.pid]) - nodes0[name]) / wall, 3) for name, p in procs.procs.items()}
            page_cpu = (tree_cpu_s([browser.pid]) - page0) / wall if browser else 0.0
            procs.stop()
    finally:
        if browser is not None:
            browser.terminate()
            browser.wait(10)
        shutil.rmtree(profile, ignore_errors=True)
        observer.destroy_node()
        rclpy.shutdown()
    return {'page': page, 'wall_s': round(wall, 2), 'rig_cores': round(rig, 3), 'chromium_cores': round(page_cpu, 3),
            'nodes': len(rig_pids), 'per_node_cores': per_node}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--json', help='write the figures here')
    ap.add_argument('--program', default='side_force', help="the program played (config/program_<name>.yaml)")
    args = ap.parse_args(argv)
    from crane_stiffness.launcher import rosrun
    ws = REPO / 'out' / 'bench_cpu'
    env, share = rosrun.build_workspace(REPO, ws)
    base = run(env, share, ws, page=False, program_name=args.program)
    watched = run(env, share, ws, page=True, program_name=args.program)
    print(f'program {args.program}')
    for r in (base, watched):
        print(f"--- {'page open' if r['page'] else 'baseline '}: the rig's {r['nodes']} processes "
              f"{100 * r['rig_cores']:.0f} % of a core, Chromium {100 * r['chromium_cores']:.1f} % "
              f"(over the program's {r['wall_s']:.1f} s)")
        print('    ' + ', '.join(f'{name} {100 * c:.0f} %' for name, c in
                              sorted(r['per_node_cores'].items(), key=lambda kv: -kv[1])))
    ratio = watched['rig_cores'] / base['rig_cores'] if base['rig_cores'] else float('nan')
    rig = max(base['rig_cores'], watched['rig_cores'])
    met = rig <= RIG_LIMIT and watched['chromium_cores'] <= PAGE_LIMIT
    print(f"rig {100 * rig:.0f} % of a core (target <= {100 * RIG_LIMIT:.0f} %), with the page {ratio:.2f}x the "
          f"baseline; the page in Chromium {100 * watched['chromium_cores']:.1f} % (target <= "
          f"{100 * PAGE_LIMIT:.0f} %): {'met' if met else 'MISSED'}")
    if args.json:
        Path(args.json).write_text(json.dumps({'baseline': base, 'page': watched, 'rig_ratio': ratio,
                                               'met': met}, indent=1))
    return 0 if met else 1


if __name__ == '__main__':
    sys.exit(main())
