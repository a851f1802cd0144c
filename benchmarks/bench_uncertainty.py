"""Uncertainty benchmark: the model's prediction with its uncertainty for the lab model, in one run.

The prediction of the lab model's side stiffness (fy at rest, h = 0.5 m, W = 50 N) with the default input
uncertainties (config/uncertainty_lab.yaml): the budget (the law of propagation with central-difference
sensitivities, 2N + 1 cranes) and the adaptive Monte Carlo of JCGM 101 (batches of 10⁴ cranes, 2 significant
digits), each timed over ``--repeat`` runs after one warm-up run (which loads the compiled kernels). Baseline in the
same run: the same number of cranes through the one-crane path (``tangent_stiffness(g, rest_pose(g))`` on a
CraneGeometry per draw), timed on ``--baseline`` draws and scaled. The load average is printed before and after:
absolute times are noisy on a shared 2-core machine. Target: the prediction's Monte Carlo ≤ 1 s.

Run: .venv/bin/python benchmarks/bench_uncertainty.py [--repeat 3] [--baseline 300] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from crane_stiffness.model import lab_model, rest_pose, tangent_stiffness
from crane_stiffness.uncertainty.crane_inputs import crane_inputs
from crane_stiffness.uncertainty.montecarlo import draw_inputs, monte_carlo
from crane_stiffness.uncertainty.prediction import predict_stiffness, stiffness_function

TARGET_S = 1.0


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--baseline', type=int, default=300, help='draws through the one-crane path')
    parser.add_argument('--json', type=Path)
    args = parser.parse_args(argv)
    g = lab_model(0.5, 50.0)
    inputs = crane_inputs(g)
    f = stiffness_function(g, 'fy', [q.name for q in inputs])
    predict_stiffness(g, 'fy', seed=0)  # warm-up: the compiled kernels load once per process
    load_before = os.getloadavg()
    budget_s, mc_s, trials = [], [], []
    result = None
    for i in range(args.repeat):
        t0 = time.perf_counter()
        result = predict_stiffness(g, 'fy', monte_carlo_run=False)
        budget_s.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        mc = monte_carlo(f, inputs, seed=i, significant_digits=2)
        mc_s.append(time.perf_counter() - t0)
        trials.append(mc.trials)
    assert result is not None
    # baseline: the one-crane path on the same kind of draws
    x = draw_inputs(inputs, args.baseline, np.random.default_rng(0))
    names = [q.name for q in inputs]
    t0 = time.perf_counter()
    for j in range(args.baseline):
        v = dict(zip(names, x[:, j]))
        gj = g.replace(a=v['a'], b=v['b'], height=v['height'], weight=v['weight'], wire_diameter=v['wire_diameter'],
                       youngs_modulus=v['youngs_modulus'],
                       length_offsets=tuple(v[f'length_offset_{k}'] for k in range(1, 7)),
                       com_offset=(v['com_offset_x'], v['com_offset_y'], v['com_offset_z']))
        tangent_stiffness(gj, rest_pose(gj))
    per_crane_baseline = (time.perf_counter() - t0) / args.baseline
    load_after = os.getloadavg()
    best = min(mc_s)
    per_crane = best / trials[mc_s.index(best)]
    print(f'load average before {load_before[0]:.2f}, after {load_after[0]:.2f}')
    print(f'  prediction fy = {result.value:.1f} N/m, u_c = {result.u_c:.1f} N/m, dominant {result.dominant.name}')
    print(f'  budget (law of propagation, {2 * len(inputs) + 1} cranes): {min(budget_s) * 1e3:.1f} ms (best of '
          f'{args.repeat})')
    print(f'  Monte Carlo (adaptive, 2 digits): {", ".join(f"{s:.3f} s ({n:,} trials)" for s, n in zip(mc_s, trials))}'
          f' (target <= {TARGET_S:g} s)')
    print(f'  per crane: {per_crane * 1e6:.1f} us; one-crane path {per_crane_baseline * 1e6:.0f} us '
          f'({per_crane_baseline / per_crane:.0f}x)')
    ok = max(mc_s) <= TARGET_S
    print('targets met' if ok else 'TARGETS NOT MET')
    res = {'load_before': load_before[0], 'load_after': load_after[0], 'value': result.value, 'u_c': result.u_c,
           'budget_s': budget_s, 'monte_carlo_s': mc_s, 'trials': trials, 'per_crane_us': per_crane * 1e6,
           'baseline_per_crane_us': per_crane_baseline * 1e6, 'target_s': TARGET_S, 'ok': ok}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        with open(args.json, 'w') as fh:
            json.dump(res, fh, indent=1)
    return res


if __name__ == '__main__':
    sys.exit(0 if main()['ok'] else 1)
