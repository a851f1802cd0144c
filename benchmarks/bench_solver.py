"""Solver benchmark: per-solve time against scipy.optimize.root and batch throughput, measured in one run.

Per solve: the project's solver (solve_equilibrium, one call per case) against scipy.optimize.root(method='hybr')
with a finite-difference Jacobian on the same residual function (the same compiled net wrench) from the same start
(the rest pose under W), on the same load cases; both must land within 1e-10 m (platform points) of a reference
solved to 1e-13 m. Batch: solve_batch on 10,000 load cases. Absolute times are noisy on a shared 2-core machine;
the ratio is the figure to read. Targets: ≥ 30× faster than scipy root, ≥ 50,000 solves/s in batch.

Run: .venv/bin/python benchmarks/bench_solver.py [--cases 300] [--batch 10000] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
from scipy.optimize import root

from crane_stiffness.model import lab_model, net_wrench, rest_pose, solve_batch, solve_equilibrium
from crane_stiffness.model.rotation import rotvec_to_matrix

ACCURACY = 1e-10  # [m]


def load_cases(n: int, weight: float, seed: int, scale: float = 1.0) -> np.ndarray:
    """The rig's test range: side forces up to W/20, vertical ±W/10, moments up to 0.02 N·m (all wires taut).

    scale = 4 gives the hard set: side forces up to W/5, where most cases have slack wires."""
    rng = np.random.default_rng(seed)
    return scale * np.column_stack([rng.uniform(-0.05, 0.05, (n, 2)) * weight, rng.uniform(-0.1, 0.1, n) * weight,
                                    rng.uniform(-0.02, 0.02, (n, 3))])


def pose_error(g, u1, q1, u2, q2) -> float:
    """Largest distance between the two poses over the platform's vertices and centre [m]."""
    pts = np.vstack([np.zeros(3), g.platform_points])
    return float(np.abs((u1 + pts @ q1.T) - (u2 + pts @ q2.T)).max())


def scipy_solve(g, load, u0, q0, lc):
    """scipy root given a fair chance: unknowns are millimetre offsets from the rest pose (rotations times lc),
    equations in N, and the finite-difference step set to 1e-6 mm. MINPACK's default step is relative to |x|,
    which near x = 0 is rounding noise, and then hybr fails on most cases."""
    mm = 1e-3

    def fun(x):
        w = net_wrench(g, u0 + x[:3] * mm, rotvec_to_matrix(x[3:] * mm / lc) @ q0, load)
        return np.concatenate([w[:3], w[3:] / lc])  # same scaling as the project's solver
    sol = root(fun, np.zeros(6), method='hybr', options={'xtol': 1e-12, 'eps': 1e-12})
    return u0 + sol.x[:3] * mm, rotvec_to_matrix(sol.x[3:] * mm / lc) @ q0, sol.success


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--cases', type=int, default=300)
    ap.add_argument('--batch', type=int, default=10_000)
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)

    g = lab_model(height=0.8, weight=60.0)
    rest = rest_pose(g)
    lc = max(g.a, g.b)
    loads = load_cases(args.cases, g.weight, seed=1)
    solve_equilibrium(g, load=loads[0])  # compile and cache before timing
    refs = [solve_equilibrium(g, load=ld, xtol=1e-13) for ld in loads]

    t0 = time.perf_counter()
    ours = [solve_equilibrium(g, load=ld, xtol=1e-11) for ld in loads]
    t_ours = (time.perf_counter() - t0) / len(loads)
    t0 = time.perf_counter()
    theirs = [scipy_solve(g, ld, rest.displacement, rest.rotation, lc) for ld in loads]
    t_scipy = (time.perf_counter() - t0) / len(loads)

    err_ours = max(pose_error(g, e.displacement, e.rotation, r.displacement, r.rotation) for e, r in zip(ours, refs))
    err_scipy = max(pose_error(g, u, q, r.displacement, r.rotation) for (u, q, _), r in zip(theirs, refs))
    scipy_ok = sum(ok for _, _, ok in theirs)

    batch_loads = load_cases(args.batch, g.weight, seed=2)
    solve_batch(g, batch_loads[:10])
    t0 = time.perf_counter()
    batch = solve_batch(g, batch_loads, xtol=1e-11)
    t_batch = time.perf_counter() - t0
    hard = load_cases(args.batch, g.weight, seed=3, scale=4.0)
    t0 = time.perf_counter()
    hard_batch = solve_batch(g, hard, xtol=1e-11)
    t_hard = time.perf_counter() - t0
    hard_slack = int(hard_batch.slack.any(axis=1).sum())
    bref = [solve_equilibrium(g, load=batch_loads[i], xtol=1e-13) for i in range(0, args.batch, args.batch // 50)]
    err_batch = max(pose_error(g, batch.displacement[i], batch.rotation[i], r.displacement, r.rotation)
                    for i, r in zip(range(0, args.batch, args.batch // 50), bref))

    res = {
        'cases': len(loads), 'per_solve_us': t_ours * 1e6, 'scipy_root_hybr_per_solve_us': t_scipy * 1e6,
        'speedup_vs_scipy': t_scipy / t_ours, 'max_pose_error_m': err_ours, 'scipy_max_pose_error_m': err_scipy,
        'scipy_converged': scipy_ok, 'batch_cases': args.batch, 'batch_s': t_batch,
        'batch_solves_per_s': args.batch / t_batch, 'batch_max_pose_error_m': err_batch,
        'hard_batch_solves_per_s': args.batch / t_hard, 'hard_batch_cases_with_slack': hard_slack,
    }
    print(f'per solve ({len(loads)} cases, same start, accuracy {ACCURACY:g} m):')
    print(f'  crane_stiffness solve_equilibrium {t_ours * 1e6:9.1f} µs   max error {err_ours:.1e} m')
    print(f'  scipy.optimize.root hybr, FD jac  {t_scipy * 1e6:9.1f} µs   max error {err_scipy:.1e} m '
          f'({scipy_ok}/{len(loads)} reported success)')
    print(f'  ratio: {t_scipy / t_ours:.1f}x faster (target >= 30x)')
    print(f'batch: {args.batch} cases in {t_batch * 1e3:.1f} ms = {args.batch / t_batch:,.0f} solves/s '
          f'(target >= 50,000/s), max error {err_batch:.1e} m')
    print(f'hard set (side forces up to W/5, {hard_slack} of {args.batch} cases with slack wires, where scipy '
          f'hybr mostly fails): {args.batch / t_hard:,.0f} solves/s')
    ok = (t_scipy / t_ours >= 30 and args.batch / t_batch >= 50_000 and err_ours <= ACCURACY
          and err_scipy <= ACCURACY and err_batch <= ACCURACY)
    print('targets met' if ok else 'TARGETS NOT MET')
    if args.json:
        with open(args.json, 'w') as fh:
            json.dump(res, fh, indent=1)
    res['ok'] = ok
    return res


if __name__ == '__main__':
    sys.exit(0 if main()['ok'] else 1)
