"""Solver benchmark: per-solve time against scipy.optimize.root, batch throughput and the design map, in one run.

Per solve: the project's solver (solve_equilibrium, one call per case) against scipy.optimize.root(method='hybr')
with a finite-difference Jacobian on the same residual function (the same compiled net wrench) from the same start
(the rest pose under W), on the same load cases; both must land within 1e-10 m (platform points) of a reference
solved to 1e-13 m. Batch: solve_batch on 10,000 load cases. Parallel batch: solve_batch_parallel on 1,000,000 cases
of the rig's load range on every core, beside solve_batch and scipy root on the first of the same cases, and on the
slack-heavy set (side forces up to W/5) beside both. Map: ``crane-stiffness workspace map`` of the lab model over
x–y, 100 × 100 points, 64 force directions each. Absolute times are noisy on a shared 2-core machine (the load
average is printed before and after); the ratios are the figures to read. Targets: ≥ 30× faster than scipy root,
≥ 50,000 solves/s with solve_batch, ≥ 1,000,000 solves/s with solve_batch_parallel, the map in ≤ 30 s.

Run: .venv/bin/python benchmarks/bench_solver.py [--cases 300] [--batch 10000] [--parallel 1000000] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.optimize import root

from crane_stiffness.model import lab_model, net_wrench, rest_pose, solve_batch, solve_equilibrium
from crane_stiffness.model.batch import solve_batch_parallel
from crane_stiffness.model.rotation import rotvec_to_matrix

ACCURACY = 1e-10  # [m]
PARALLEL_TARGET = 1_000_000  # solves/s
MAP_TARGET_S = 30.0


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


def parallel_figures(g, lc, rest, args) -> dict:
    """solve_batch_parallel on the rig's range and on the slack-heavy set, each beside solve_batch and scipy root
    on the first cases of the same set."""
    import numba
    out: dict = {'threads': numba.get_num_threads()}
    for name, scale, n in (('', 1.0, args.parallel), ('hard_', 4.0, max(1, args.parallel // 10))):
        cases = load_cases(n, g.weight, seed=4, scale=scale)
        solve_batch_parallel(g, cases[:1000])  # load the compiled kernels and start the threads before timing
        t0, c0 = time.perf_counter(), time.process_time()
        par = solve_batch_parallel(g, cases, xtol=1e-11)
        t_par, cpu_par = time.perf_counter() - t0, time.process_time() - c0
        m = min(n, args.batch)
        t0 = time.perf_counter()
        solve_batch(g, cases[:m], xtol=1e-11)
        t_serial = time.perf_counter() - t0
        k = min(n, args.cases)
        t0 = time.perf_counter()
        theirs = [scipy_solve(g, ld, rest.displacement, rest.rotation, lc) for ld in cases[:k]]
        t_scipy = time.perf_counter() - t0
        sample = range(0, n, max(1, n // 50))
        err = max(pose_error(g, par.displacement[i], par.rotation[i], r.displacement, r.rotation)
                  for i, r in zip(sample, (solve_equilibrium(g, load=cases[i], xtol=1e-13) for i in sample)))
        key = name or 'parallel_'  # parallel_* for the rig's range, hard_* for the slack-heavy set
        out.update({f'{key}cases': n, f'{key}solves_per_s': n / t_par, f'{key}cpu_s': cpu_par,
                    f'{key}wall_s': t_par, f'{key}serial_solves_per_s': m / t_serial,
                    f'{key}scipy_solves_per_s': k / t_scipy, f'{key}scipy_converged': sum(ok for *_, ok in theirs),
                    f'{key}max_pose_error_m': err})
        if name:
            out['hard_cases_with_slack'] = int(par.slack.any(axis=1).sum())
    out['scipy_cases'] = min(args.parallel, args.cases)
    return out


def map_time(points: int) -> float:
    """Seconds for `workspace map` of the lab model over x-y (points x points, 64 directions), CSV included."""
    from crane_stiffness.design.maps import GridAxis, MapSpec, compute_rows, run_map
    g = lab_model(height=0.5, weight=50.0)
    spec = MapSpec(GridAxis('x', -0.06, 0.06, points), GridAxis('y', -0.06, 0.06, points), g, directions=64)
    compute_rows(spec, range(1))  # load the compiled kernels before timing
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        run_map(spec, Path(tmp))
        return time.perf_counter() - t0


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--cases', type=int, default=300)
    ap.add_argument('--batch', type=int, default=10_000)
    ap.add_argument('--parallel', type=int, default=1_000_000, help='cases for solve_batch_parallel')
    ap.add_argument('--map-points', type=int, default=100, help='points per side of the design map')
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)
    load_before = os.getloadavg()

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

    par = parallel_figures(g, lc, rest, args)
    map_s = map_time(args.map_points)
    load_after = os.getloadavg()

    res = {
        'load_average_before': load_before, 'load_average_after': load_after, **par, 'map_points': args.map_points,
        'map_directions': 64, 'map_s': map_s,
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
    print(f'parallel batch ({par["threads"]} threads; load average {load_before[0]:.2f} before, '
          f'{load_after[0]:.2f} after):')
    print(f'  rig range, {par["parallel_cases"]:,} cases: {par["parallel_solves_per_s"]:,.0f} solves/s '
          f'(target >= {PARALLEL_TARGET:,}/s), max error {par["parallel_max_pose_error_m"]:.1e} m; same cases: '
          f'solve_batch {par["parallel_serial_solves_per_s"]:,.0f}/s, '
          f'scipy root {par["parallel_scipy_solves_per_s"]:,.0f}/s '
          f'({par["parallel_scipy_converged"]}/{par["scipy_cases"]} reported success) -> '
          f'{par["parallel_solves_per_s"] / par["parallel_scipy_solves_per_s"]:,.0f}x scipy')
    print(f'  CPU time of those solves {par["parallel_cpu_s"]:.2f} s in {par["parallel_wall_s"]:.2f} s of wall time: '
          f'{par["parallel_cases"] / par["parallel_cpu_s"]:,.0f} solves per CPU-second (the share of the 2 cores '
          f'this process got: {par["parallel_cpu_s"] / par["parallel_wall_s"] / par["threads"]:.0%})')
    print(f'  slack-heavy, {par["hard_cases"]:,} cases ({par["hard_cases_with_slack"]:,} with slack wires): '
          f'{par["hard_solves_per_s"]:,.0f} solves/s, max error {par["hard_max_pose_error_m"]:.1e} m; '
          f'same cases: solve_batch {par["hard_serial_solves_per_s"]:,.0f}/s, scipy root '
          f'{par["hard_scipy_solves_per_s"]:,.0f}/s ({par["hard_scipy_converged"]}/{par["scipy_cases"]} reported '
          f'success)')
    print(f'design map {args.map_points} x {args.map_points} points, 64 force directions each: {map_s:.1f} s '
          f'(target <= {MAP_TARGET_S:g} s)')
    ok = (t_scipy / t_ours >= 30 and args.batch / t_batch >= 50_000 and err_ours <= ACCURACY
          and err_scipy <= ACCURACY and err_batch <= ACCURACY and par['parallel_solves_per_s'] >= PARALLEL_TARGET
          and par['parallel_max_pose_error_m'] <= ACCURACY and par['hard_max_pose_error_m'] <= ACCURACY
          and map_s <= MAP_TARGET_S)
    print('targets met' if ok else 'TARGETS NOT MET')
    if args.json:
        with open(args.json, 'w') as fh:
            json.dump(res, fh, indent=1)
    res['ok'] = ok
    return res


if __name__ == '__main__':
    sys.exit(0 if main()['ok'] else 1)
