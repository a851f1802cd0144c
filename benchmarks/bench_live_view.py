"""Live view benchmark: the cost of watching. The rig at 1 kHz (bench_rig's run) without the view, then with
live_view and two clients subscribed to every channel the page shows, in one run, alternating ``--pairs`` times.

Reports, per case, the estimator's lag at publication (its own record: p50, p99) and the losses (samples missing
on the 1 ms grid at an independent observer; the sensors' sent minus the estimator's received is shown too), and
the view's own CPU (user + system time of its process over the steady state, as a fraction of one core), with the
rates its clients received. Targets: with the view, the estimator's lag p99 and the loss counts within 10 % of the
run without it (a loss count of 0 stays 0; lag and losses compared as medians over the pairs of runs, every run
printed), and the view's CPU ≤ 15 % of one core in the worst run. Exits 1 when a target is missed.

Run: .venv/bin/python benchmarks/bench_live_view.py [--seconds 60] [--pairs 1] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

from bench_rig import REPO, run_rate  # noqa: E402  (sets the DDS environment first)

RATE = 1000.0
LAG_RATIO = 1.10
CPU_LIMIT = 0.15


def losses(res: dict) -> int:
    """Samples lost on the way, both topics: missing on the 1 ms grid at the independent observer (exact; the
    sensors' sent minus the estimator's received also counts samples sent before the estimator matched them, so it
    is reported, not compared)."""
    return sum(c['observer_grid']['lost'] or 0 for c in res['topics'].values())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=60.0)
    ap.add_argument('--pairs', type=int, default=1, help='runs without and with the view, alternating')
    ap.add_argument('--clients', type=int, default=2)
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)
    from crane_stiffness.launcher import rosrun
    ws = REPO / 'out' / 'bench_live_view'
    env, share = rosrun.build_workspace(REPO, ws)
    runs: dict[str, list[dict]] = {'without': [], 'with': []}
    for _ in range(args.pairs):
        runs['without'].append(run_rate(RATE, args.seconds, env, share, ws / 'logs'))
        runs['with'].append(run_rate(RATE, args.seconds, env, share, ws / 'logs', view_clients=args.clients))
    summary = {}
    for case, results in runs.items():
        p99 = statistics.median(r['estimator_own_lag_ms']['p99'] for r in results)
        p50 = statistics.median(r['estimator_own_lag_ms']['p50'] for r in results)
        lost = statistics.median(losses(r) for r in results)
        summary[case] = {'lag_p50_ms': p50, 'lag_p99_ms': p99, 'lost': lost}
        print(f'--- {case} the view: estimator lag p50 {p50:.2f} ms, p99 {p99:.2f} ms (median of {len(results)}); '
              f'samples lost {lost:g} (median; ' + '; '.join(
                  f"{t}: sent-received {c['sent_minus_estimator_received']}, observer grid lost "
                  f"{c['observer_grid']['lost']}" for r in results for t, c in r['topics'].items()) + ')')
    views = [r['live_view'] for r in runs['with']]
    cpu = max(v['cpu_fraction_of_a_core'] for v in views)
    rates = [round(n / args.seconds, 1) for v in views for n in v['messages_per_client']]
    print(f"--- the view's own CPU: {100 * cpu:.1f} % of one core (worst run); its {args.clients} clients received "
          f'{rates} messages/s')
    ratio = summary['with']['lag_p99_ms'] / summary['without']['lag_p99_ms']
    lost_ok = summary['with']['lost'] <= summary['without']['lost'] * LAG_RATIO  # 0 stays 0
    print(f"=== lag p99 with / without: {ratio:.2f} (target <= {LAG_RATIO}); samples lost "
          f"{summary['with']['lost']:g} vs {summary['without']['lost']:g} (target within 10 %); "
          f'view CPU {100 * cpu:.1f} % (target <= {100 * CPU_LIMIT:.0f} %)')
    met = ratio <= LAG_RATIO and lost_ok and cpu <= CPU_LIMIT
    print('targets met' if met else 'targets missed')
    if args.json:
        Path(args.json).write_text(json.dumps({'runs': runs, 'summary': summary, 'lag_p99_ratio': ratio,
                                               'view_cpu': cpu, 'client_rates': rates, 'met': met}, indent=1))
    return 0 if met else 1


if __name__ == '__main__':
    sys.exit(main())
