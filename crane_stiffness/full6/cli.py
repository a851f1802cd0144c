"""``crane-stiffness full6 design``: the D-optimal multi-axis load program of a crane on the command line, a thin
layer over crane_stiffness.full6 (admissible.axis_peaks, design.d_optimal_design, program.program_yaml,
precision.compare_designs).

The peaks are each axis' largest load alone under the safety factor (``axis_peaks``) times ``--peak-fraction``
(0.98: just inside), or ``--peaks``. Peaks that one axis alone could not hold under the rule, or a design whose
steps or transitions break it, are refused: exit 2 and one line on stderr naming the step, the direction and the
wire (crane_stiffness.full6.errors.SlackDesignError). Otherwise the program is written to ``--out`` and the predicted
95 % half-widths of K's diagonal and K2 are printed beside the naive program's (each axis in turn, + and −, with the
same peaks, steps and times), with their ratio. Geometry from ``--crane FILE`` (a ROS parameter YAML,
config/crane_lab.yaml) and the geometry flags of the other commands (``--weight``, ``--height`` or ``--l0`` ...).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from crane_stiffness.contract.axes import AXES
from crane_stiffness.cli.exit_codes import EXIT_OK, EXIT_USAGE
from crane_stiffness.full6.admissible import DEFAULT_SAFETY_FACTOR, axis_peaks, check_steps, wire_label
from crane_stiffness.full6.errors import SlackDesignError
from crane_stiffness.full6.linearity import MAX_LACK_OF_FIT, load_cell_full_scale
from crane_stiffness.full6.reference import entry_name
from crane_stiffness.cli.geometry_args import add_geometry, geometry_from_args

#: The peaks used by default: this share of each axis' largest admissible load alone.
DEFAULT_PEAK_FRACTION = 0.98


def _units(i: int) -> str:
    return 'N' if i < 3 else 'N·m'


def _refuse(what: str, exc: SlackDesignError, limits: np.ndarray) -> int:
    alone = ', '.join(f'{a} {v:.4g} {_units(i)}' for i, (a, v) in enumerate(zip(AXES, limits)))
    print(f'crane-stiffness: full6 design refused: {what}: {exc} (each axis alone may hold at most: {alone})',
          file=sys.stderr)
    return EXIT_USAGE


def cmd_design(args: argparse.Namespace) -> int:
    from crane_stiffness.full6.design import LAB_NOISE, NoiseLevels, naive_design
    from crane_stiffness.full6.linearity import linear_design
    from crane_stiffness.full6.precision import compare_designs
    from crane_stiffness.full6.program import program_yaml
    g = geometry_from_args(args)
    sf = args.safety_factor
    limits = axis_peaks(g, sf)
    peaks = np.asarray(args.peaks, dtype=float) if args.peaks else args.peak_fraction * limits
    try:  # the peaks themselves: each axis alone, + then −, as the naive program holds them
        check_steps(g, np.vstack([np.diag(peaks), -np.diag(peaks)]).reshape(2, 6, 6).transpose(1, 0, 2)
                    .reshape(12, 6), sf)
    except SlackDesignError as exc:
        return _refuse('the peak loads (each axis alone, + then −, fx … mz)', exc, limits)
    timing = {'n_steps': args.steps, 'hold_s': args.hold, 'settle_s': args.settle, 'baseline_s': args.baseline,
              'safety_factor': sf}
    full_scale = None if args.full_scale_fraction == 0 else args.full_scale_fraction * np.asarray(
        args.full_scale if args.full_scale else load_cell_full_scale(), dtype=float)
    noise = LAB_NOISE if not args.pose_noise else NoiseLevels.from_sensors(
        LAB_NOISE.wrench_std * np.sqrt(1000.0 / LAB_NOISE.pair_rate_hz), 1000.0, args.pose_noise,
        LAB_NOISE.pair_rate_hz)
    try:
        made = linear_design(g, peaks, full_scale=full_scale, max_lack_of_fit=args.max_lack_of_fit, seed=args.seed,
                             noise=noise, **timing)
    except SlackDesignError as exc:
        return _refuse('the D-optimal program', exc, limits)
    design = made.design
    how = (f'Made by crane-stiffness full6 design: geometry a = {g.a:g} m, b = {g.b:g} m, h = {g.height:g} m, '
           f'W = {g.weight:g} N, k = {g.k:.6g} N/m;\npeaks ' + ', '.join(f'{v:.4g}' for v in design.peaks)
           + f' (scaled by {made.scale:.4g}: predicted lack of fit {made.lack_of_fit:.3f}), seed {args.seed}; '
           f'D-efficiency {design.efficiency:.3f}.')
    Path(args.out).write_text(program_yaml(design, name=args.name, title=args.title, how=how), encoding='utf-8')
    weakest = int(np.argmin(design.slack.factor))
    print(f'D-optimal program: {design.n_steps} steps held {design.hold_s:g} s ({design.settle_s:g} s settling), '
          f'baselines {design.baseline_s:g} s: {design.duration_s:g} s; D-efficiency {design.efficiency:.3f}; '
          f'smallest slack factor {design.slack.factor[weakest]:.4f} (step {weakest + 1}, '
          f'{wire_label(int(design.slack.wire[weakest]))}), safety factor {sf:g}')
    print('peaks: ' + ', '.join(f'{a} {v:.4g} {_units(i)}' for i, (a, v) in enumerate(zip(AXES, design.peaks))))
    if made.scale < 1.0 or full_scale is not None and np.any(peaks > full_scale):
        print('  (the slack rule allowed ' + ', '.join(f'{v:.4g}' for v in peaks) + '; capped at the load cell\'s '
              f'full scale x {args.full_scale_fraction:g} and scaled by {made.scale:.4g} so that the lack of fit '
              f'the model predicts is {made.lack_of_fit:.3f} <= {args.max_lack_of_fit:g})')
    if args.steps % 12:
        print(f'(no naive comparison: its {args.steps} steps are not a multiple of 12, each axis + and −)')
    else:
        _print_comparison(compare_designs(design, naive_design(g, design.peaks, noise=noise, **timing)))
    print(f'wrote {args.out}')
    return EXIT_OK


def _print_comparison(c: Any) -> None:
    a, b = c.designed, c.naive
    print(f'predicted 95 % half-widths, designed against naive (same peaks, {a.n} pairs each):')
    print(f'  {"entry":<12} {"model":>12} {"designed":>10} {"naive":>10} {"naive/designed":>15}')
    for i in range(6):
        k = a.model_stiffness[i, i]
        print(f'  {entry_name(i, i):<12} {k:>12.6g} {100 * a.stiffness[i, i] / k:>9.3f}% '
              f'{100 * b.stiffness[i, i] / k:>9.3f}% {c.stiffness_ratio[i, i]:>15.3f}')
    print(f'  {"K2":<12} {a.model_k2:>12.6g} {100 * a.k2 / a.model_k2:>9.3f}% {100 * b.k2 / a.model_k2:>9.3f}% '
          f'{c.k2_ratio:>15.3f}')
    print(f'  geometric mean over the 36 entries: C {c.compliance_mean_ratio:.3f}, K {c.stiffness_mean_ratio:.3f} '
          'times narrower designed')


def add_commands(subparsers: Any) -> None:
    """Add ``full6 design`` to the ``crane-stiffness`` subparsers."""
    full6 = subparsers.add_parser('full6', help='the whole 6x6 stiffness from one test: designed multi-axis '
                                  'load programs')
    sub = full6.add_subparsers(dest='full6_command', required=True, parser_class=type(full6))
    p = sub.add_parser('design', help='the D-optimal load program within the slack margins, written as a '
                       'load_program parameter file, its precision against the naive program')
    add_geometry(p)
    p.add_argument('--crane', dest='config', metavar='FILE', help='the crane: a ROS parameter YAML with geometry.* '
                   '(e.g. config/crane_lab.yaml); the same as --config')
    p.add_argument('--steps', type=int, default=24, help='held steps, even, >= 12 (default 24)')
    p.add_argument('--hold', type=float, default=4.0, help='time each step is held [s] (default 4)')
    p.add_argument('--settle', type=float, default=0.5, help='first part of each hold left out of the fit [s] '
                   '(default 0.5)')
    p.add_argument('--baseline', type=float, default=2.0, help='zero-load baseline at each end [s] (default 2)')
    p.add_argument('--safety-factor', type=float, default=DEFAULT_SAFETY_FACTOR,
                   help='every held wrench could grow this many times before a wire goes slack (default 2)')
    group = p.add_mutually_exclusive_group()
    group.add_argument('--peak-fraction', type=float, default=DEFAULT_PEAK_FRACTION,
                       help='peaks = this x each axis\' largest admissible load alone (default 0.98)')
    group.add_argument('--peaks', type=float, nargs=6, metavar=('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'),
                       help='peak load per axis [N, N·m] instead')
    p.add_argument('--full-scale', type=float, nargs=6, metavar=('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'),
                   help="the load cell's full scale [N, N·m] (default: load_cell.full_scale of config/sensors.yaml)")
    p.add_argument('--full-scale-fraction', type=float, default=0.9,
                   help='peaks at most this x the full scale (default 0.9; 0: no cap)')
    p.add_argument('--max-lack-of-fit', type=float, default=MAX_LACK_OF_FIT,
                   help='scale the design down until the lack-of-fit statistic the nonlinear model predicts is at '
                        f'most this (1: linear; default {MAX_LACK_OF_FIT:g}; the 6x6 status turns WARN near 1.4)')
    p.add_argument('--pose-noise', type=float, nargs=6, metavar=('UX', 'UY', 'UZ', 'TX', 'TY', 'TZ'),
                   help='white noise of one pose sample [m, m, m, rad, rad, rad] (default the simulated tracker\'s: '
                        '2e-6 m, 2e-5 rad; an LVDT array: about 1.6e-7 1.6e-7 1.2e-7 1.2e-6 1.2e-6 9e-7): a finer '
                        'sensor sees a smaller bend, and the design is scaled for it')
    p.add_argument('--seed', type=int, default=0, help='seed of the exchange\'s random starts (default 0)')
    p.add_argument('--name', default='full6', help='program name (default full6)')
    p.add_argument('--title', default='', help='first lines of the file\'s header comment')
    p.add_argument('--out', required=True, metavar='FILE', help='the program file to write (YAML)')
    p.set_defaults(func=cmd_design)


__all__ = ['DEFAULT_PEAK_FRACTION', 'add_commands', 'cmd_design']
