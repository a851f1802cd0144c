"""Live 6×6 U benchmark: what the stiffness6_estimator adds per publication to state U of every entry of K and of K2.

The step means of config/program_full6.yaml on the lab model (h = 0.5 m, W = 50 N; the model's responses read
through sensors with errors drawn from their declarations, coloured noise: crane_stiffness.testing.synthetic_full6)
and the simulated load cell's and pose sensor's default declarations (every component counted): the law of
propagation of crane_stiffness.full6.live_uncertainty (:class:`LiveMatrixUncertainty`, its cache defeated: new step
means every call, as while a step is being held), timed in CPU time (the process's: a busy machine's waits do not
count) over ``--repeat`` calls after one warm-up. Baseline in the same run: the 6×6 fit the node publishes anyway
(``fit_compliance`` of the same pairs' statistics). The load average is printed before and after. Target: U ≤ 10 ms
of CPU a publication, ≤ 2 % of a core at the node's default 2 Hz.

Run: .venv/bin/python benchmarks/bench_live_u6.py [--repeat 100] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from crane_stiffness.full6.identify import fit_compliance  # noqa: E402
from crane_stiffness.full6.live_uncertainty import LiveMatrixUncertainty  # noqa: E402
from crane_stiffness.full6.statistics import pair_statistics  # noqa: E402
from crane_stiffness.model.geometry import lab_model  # noqa: E402
from crane_stiffness.sim.program import load_program_file  # noqa: E402
from crane_stiffness.testing.synthetic_full6 import (declared_calibrations, draw_errors,  # noqa: E402
                                                     gum_step_means, model_responses, synthetic_pairs)

TARGET_MS = 10.0
RATE_HZ = 2.0  # the node's default publish_rate_hz


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=100)
    parser.add_argument('--json', type=Path)
    args = parser.parse_args(argv)
    truth = model_responses(lab_model(0.5, 50.0), load_program_file(HERE.parent / 'config' / 'program_full6.yaml'),
                            0.5)
    w, d = gum_step_means(truth, draw_errors(1), 1)
    session = synthetic_pairs(truth, seed=1)
    stats = pair_statistics(session.wrench, session.deflection, session.step)
    # the step means of a real session (its pairs' statistics, with these sensors' errors in their means)
    stats = type(stats)(stats.n, stats.mean, stats.within, stats.steps, stats.step_counts, np.hstack([w, d]))
    load_cell, pose = declared_calibrations()
    live = LiveMatrixUncertainty()
    live.set_calibration('load_cell', load_cell)
    live.set_calibration('pose_sensor', pose)
    live.of(stats)  # warm-up
    rng = np.random.default_rng(0)
    load_before = os.getloadavg()
    u_s, fit_s = [], []
    for _ in range(args.repeat):
        moved = type(stats)(stats.n, stats.mean, stats.within, stats.steps, stats.step_counts,
                            stats.step_means * (1.0 + 1e-9 * rng.standard_normal(stats.step_means.shape)))
        t = time.process_time()
        u = live.of(moved)
        u_s.append(time.process_time() - t)
        t = time.process_time()
        fit_compliance(moved)
        fit_s.append(time.process_time() - t)
    load_after = os.getloadavg()
    u_ms, fit_ms = 1e3 * float(np.mean(u_s)), 1e3 * float(np.mean(fit_s))  # (process_time ticks coarsely: the mean)
    met = u_ms <= TARGET_MS
    print(f'load average {load_before[0]:.1f} -> {load_after[0]:.1f}; {len(stats.steps)} steps, '
          f'{len(live.inputs().inputs)} calibration inputs ({u.statement})')  # type: ignore[union-attr]
    print(f'  U of K and K2 (law of propagation): {u_ms:.2f} ms of CPU a publication (mean), '
          f'{100 * u_ms * 1e-3 * RATE_HZ:.2f} % of a core at {RATE_HZ:g} Hz (target <= {TARGET_MS:g} ms: '
          f'{"met" if met else "MISSED"})')
    print(f'  baseline, the 6x6 fit itself: {fit_ms:.2f} ms of CPU a publication')
    out = {'u_ms': u_ms, 'fit_ms': fit_ms, 'steps': len(stats.steps), 'load_before': load_before[0],
           'load_after': load_after[0], 'met': met}
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return out


if __name__ == '__main__':
    sys.exit(0 if main()['met'] else 1)
