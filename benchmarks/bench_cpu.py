"""CPU budget: what `make demo` costs the machine. The demo's rig (every node its own process, the side-force program
on simulated time at real-time factor 1, the recorder and the live view) is run twice in one run: first with nobody
watching (the baseline), then with the page open in headless Chromium. ``--program full6``: the six-axis run (its
page leads with the 6×6), the same way.

Reports, over the program (from its start to its end), the CPU time (user + system, /proc) of the rig's processes and
of Chromium's process tree, each as a fraction of one core, and the rig's cost with the page against the baseline.
Targets: the rig ≤ 1 core, the page in Chromium ≤ 15 % of a core. Exits 1 when a target is missed.

``--estimator``: the cost of the live uncertainty instead (no page): the rig run with the estimator statistical only
(no calibration read, no model prediction's U: what it was before it stated U and E_n), then as it ships, alternating
``--rounds`` times; the estimator's CPU over the program and from its start to the program's end (start-up and
the one-time prediction Monte Carlo included), the best of each (a shared machine only ever adds time), as a
ratio. Target: within 5 %.

Run: .venv/bin/python benchmarks/bench_cpu.py [--program full6] [--estimator [--rounds 3]] [--json out.json]
     (the page's run needs `chromium` on PATH)
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
from typing import Any, Mapping

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

from bench_rig import REPO  # noqa: E402  (sets the DDS environment first)

RIG_LIMIT = 1.0
#: The live uncertainty's cost: the estimator's CPU with it against without, at most this ratio.
ESTIMATOR_LIMIT = 1.05
#: The estimator statistical only: no sensor node's calibration read (no such node), no model prediction's U.
STATISTICAL_ONLY = {'load_cell_nodes': ['/bench_no_load_cell'], 'lvdt_nodes': ['/bench_no_lvdt'],
                    'model_node': '/bench_no_model'}
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


def run(env: dict, share: Path, ws: Path, page: bool, program_name: str = 'side_force',
        estimator: Mapping[str, Any] | None = None) -> dict:
    """One demo run; CPU fractions of one core over the program; ``estimator``: its parameters overridden."""
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
            overrides: dict[str, Mapping[str, Any]] = {'live_view': view}
            if estimator:
                overrides['stiffness_estimator'] = estimator
            program = start_rig(procs, share, program_name, session,
                                ws / 'bags', live_view=True, overrides=overrides,
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
            estimator_pid = procs.procs['stiffness_estimator'].pid
            estimator_program_s = tree_cpu_s([estimator_pid]) - nodes0['stiffness_estimator']
            estimator_life_s = _life_cpu_s(estimator_pid)
            procs.stop()
    finally:
        if browser is not None:
            browser.terminate()
            browser.wait(10)
        shutil.rmtree(profile, ignore_errors=True)
        observer.destroy_node()
        rclpy.shutdown()
    return {'page': page, 'wall_s': round(wall, 2), 'rig_cores': round(rig, 3), 'chromium_cores': round(page_cpu, 3),
            'nodes': len(rig_pids), 'per_node_cores': per_node,
            'estimator_program_cpu_s': round(estimator_program_s, 3),
            'estimator_life_cpu_s': round(estimator_life_s, 3)}


def _life_cpu_s(pid: int) -> float:
    """A process's CPU time [s] since it started, its own and its ended children's (the estimator's whole life so
    far, start-up included)."""
    stat = Path(f'/proc/{pid}/stat').read_text()
    fields = stat[stat.rindex(')') + 2:].split()
    return sum(int(f) for f in fields[11:15]) / TICK  # utime, stime, cutime, cstime


def estimator_cost(env: dict, share: Path, ws: Path, program_name: str, rounds: int) -> dict:
    """The estimator's CPU statistical only and as shipped, alternating ``rounds`` times; the best of each."""
    runs: dict[str, list[dict]] = {'statistical only': [], 'with U and E_n': []}
    for i in range(rounds):
        for name, params in (('statistical only', STATISTICAL_ONLY), ('with U and E_n', None)):
            r = run(env, share, ws, page=False, program_name=program_name, estimator=params)
            runs[name].append(r)
            print(f"  round {i + 1} {name}: estimator {r['estimator_program_cpu_s']:.2f} CPU-s over the program "
                  f"({r['wall_s']:.1f} s), {r['estimator_life_cpu_s']:.2f} CPU-s over its life", flush=True)
    best = {name: {key: min(r[key] for r in rs) for key in ('estimator_program_cpu_s', 'estimator_life_cpu_s')}
            for name, rs in runs.items()}
    ratios = {key: best['with U and E_n'][key] / best['statistical only'][key]
              for key in ('estimator_program_cpu_s', 'estimator_life_cpu_s')}
    return {'runs': runs, 'best': best, 'ratios': ratios,
            'met': all(r <= ESTIMATOR_LIMIT for r in ratios.values())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--json', help='write the figures here')
    ap.add_argument('--program', default='side_force', help="the program played (config/program_<name>.yaml)")
    ap.add_argument('--estimator', action='store_true',
                    help="the live uncertainty's cost: the estimator statistical only against as shipped")
    ap.add_argument('--rounds', type=int, default=3, help='--estimator: alternating rounds (the best counts)')
    args = ap.parse_args(argv)
    from crane_stiffness.launcher import rosrun
    ws = REPO / 'out' / 'bench_cpu'
    env, share = rosrun.build_workspace(REPO, ws)
    if args.estimator:
        load = os.getloadavg()[0]
        cost = estimator_cost(env, share, ws, args.program, args.rounds)
        program_ratio = cost['ratios']['estimator_program_cpu_s']
        life_ratio = cost['ratios']['estimator_life_cpu_s']
        print(f"program {args.program}, load average {load:.2f} before, {os.getloadavg()[0]:.2f} after")
        for name, b in cost['best'].items():
            print(f"  {name:16s}: estimator {b['estimator_program_cpu_s']:.2f} CPU-s over the program, "
                  f"{b['estimator_life_cpu_s']:.2f} over its life (best of {args.rounds})")
        print(f"the live U and E_n cost the estimator {100 * (program_ratio - 1):+.1f} % over the program, "
              f"{100 * (life_ratio - 1):+.1f} % over its life (target <= {100 * (ESTIMATOR_LIMIT - 1):+.0f} %): "
              f"{'met' if cost['met'] else 'MISSED'}")
        if args.json:
            Path(args.json).write_text(json.dumps(cost, indent=1))
        return 0 if cost['met'] else 1
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
