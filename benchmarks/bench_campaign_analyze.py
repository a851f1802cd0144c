"""Benchmark: ``campaign analyze`` throughput, sessions per minute, with 1 and with 2 local worker processes.

Writes a synthetic campaign (crane_stiffness.testing.synthetic_campaign: the paper's campaign,
config/campaign_paper.yaml, 18 sessions at 1 kHz, each program played ``--repeats`` times: about a minute,
made with the nominal crane) in a temporary
directory, then times ``crane-stiffness campaign analyze`` in a fresh process, as a user runs it (every session
analysed: figures, report, JSON; then the campaign's figures, table and report) with ``--workers`` 1 and then 2, the
analyses removed in between. The baseline is the
1-worker run of the same campaign in the same run. Target: 2 workers at least ``TARGET_SPEEDUP`` (1.4) times the
sessions per minute of 1 (the per-session analyses are independent; two cores). Draws the figure
(``--figure``, docs/figures/campaign_throughput.png) and exits 1 when the target is missed. Usage::

    python benchmarks/bench_campaign_analyze.py [--json FILE] [--figure PNG] [--keep]
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

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from crane_stiffness.testing.scratch import keep_or_remove  # noqa: E402
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)  # the .msg files for the writer's schemas
os.environ.setdefault('MPLBACKEND', 'Agg')

TARGET_SPEEDUP = 1.4


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--campaign', default=str(REPO / 'config' / 'campaign_paper.yaml'))
    parser.add_argument('--repeats', type=int, default=12,
                        help='each session plays its program this many times (default 12: about a minute)')
    parser.add_argument('--json', default=None, help='write the figures as JSON here')
    parser.add_argument('--figure', default=None, help='draw sessions per minute against workers here (PNG)')
    parser.add_argument('--keep', action='store_true', help='keep the generated campaign')
    args = parser.parse_args()

    from crane_stiffness.campaign.spec import load_campaign
    from crane_stiffness.testing.synthetic_campaign import write_synthetic_campaign

    campaign = load_campaign(args.campaign)
    tmp = Path(tempfile.mkdtemp(prefix='bench_campaign_'))
    try:
        start = time.perf_counter()
        plans = write_synthetic_campaign(tmp / 'campaign', campaign, seed=1, repeats=args.repeats)
        print(f'wrote a synthetic campaign of {len(plans)} sessions in {time.perf_counter() - start:.1f} s',
              flush=True)
        rates = {}
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get('PYTHONPATH')])))
        for workers in (1, 2):
            shutil.rmtree(tmp / 'campaign' / 'analysis', ignore_errors=True)
            shutil.rmtree(tmp / 'campaign' / 'campaign', ignore_errors=True)
            start = time.perf_counter()  # as a user runs it: a fresh process, its imports counted
            run = subprocess.run([sys.executable, '-m', 'crane_stiffness.cli', 'campaign', 'analyze',
                                  str(tmp / 'campaign'), '--workers', str(workers), '--quiet'], env=env,
                                 capture_output=True, text=True)
            elapsed = time.perf_counter() - start
            assert run.returncode == 0 and f'({len(plans)} analysed now' in run.stdout, run.stdout + run.stderr
            rates[workers] = 60.0 * len(plans) / elapsed
            print(f'  {workers} worker(s): {len(plans)} sessions in {elapsed:.1f} s = {rates[workers]:.1f} '
                  'sessions per minute', flush=True)
        speedup = rates[2] / rates[1]
        ok = speedup >= TARGET_SPEEDUP
        print(f'2 workers vs 1: {speedup:.2f}x [target >= {TARGET_SPEEDUP}x]: {"met" if ok else "MISSED"}')
        if args.json:
            Path(args.json).write_text(json.dumps({'sessions': len(plans), 'sessions_per_minute': rates,
                                                   'speedup': speedup, 'target': TARGET_SPEEDUP, 'met': ok}))
        if args.figure:
            import matplotlib.pyplot as plt
            fig, ax = plt.subplots(figsize=(4.8, 3.4), dpi=100)
            ax.bar(['1 worker', '2 workers'], [rates[1], rates[2]], color=['tab:gray', 'tab:blue'])
            for i, w in enumerate((1, 2)):
                ax.text(i, rates[w], f'{rates[w]:.1f}', ha='center', va='bottom')
            ax.set_ylabel('sessions analysed per minute')
            ax.set_title(f'campaign analyze, {len(plans)} sessions of ~{5 * args.repeats} s at 1 kHz\n'
                         f'(2 cores, {speedup:.2f}x)',
                         fontsize=9)
            fig.tight_layout()
            fig.savefig(args.figure)
            plt.close(fig)
        return 0 if ok else 1
    finally:
        keep_or_remove(tmp, args.keep)


if __name__ == '__main__':
    sys.exit(main())
