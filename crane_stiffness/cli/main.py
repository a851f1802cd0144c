"""``crane-stiffness``: the offline command line, a thin layer over crane_stiffness.model and .analysis.

Subcommands: solve, stiffness, sweep, workspace (design maps: crane_stiffness.design.cli) and, with the bag
module, analyze, compare, recover; campaign run / analyze and calibrate (crane_stiffness.campaign.cli); full6 design
(the multi-axis load program of the 6×6 test: crane_stiffness.full6.cli). Geometry
comes from
``--config FILE`` (a ROS parameter YAML, the same file the nodes read) and/or flags, flags winning; SI units.
Exit codes: 0 ok, 2 bad input (named on stderr), 3 no equilibrium for the load, 4 solver gave up, 5 ``analyze``'s
verdict NOT OK (crane_stiffness.cli.exit_codes).
"""
from __future__ import annotations

import argparse
import csv
import json
import re
import sys
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from crane_stiffness.params.errors import ConfigError
from crane_stiffness.cli.geometry_args import UsageError, add_geometry, geometry_from_args
from crane_stiffness.model import (AXES, WIRE_NAMES, ConvergenceError, CraneGeometry, GeometryError,
                                   NoEquilibriumError, axis_stiffness, paper_coefficients,
                                   paper_stiffness, solve_equilibrium, tangent_stiffness)

from crane_stiffness.cli.exit_codes import EXIT_NO_EQUILIBRIUM, EXIT_SOLVER, EXIT_USAGE, run_to_exit_code


# --- argument groups -------------------------------------------------------------------------------------------

def _add_load(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group('external load (fixed frame, z down)')
    g.add_argument('--force', type=float, nargs=3, default=[0.0, 0.0, 0.0], metavar=('FX', 'FY', 'FZ'),
                   help='force [N] at the load point')
    g.add_argument('--moment', type=float, nargs=3, default=[0.0, 0.0, 0.0], metavar=('MX', 'MY', 'MZ'),
                   help='moment [N·m]')


# --- output ----------------------------------------------------------------------------------------------------

def _fmt_matrix(m: np.ndarray) -> str:
    names = ['u_x', 'u_y', 'u_z', 'θ_x', 'θ_y', 'θ_z']
    lines = ['        ' + ''.join(f'{n:>13}' for n in names)]
    for n, row in zip(names, m):
        lines.append(f'  {n:>5} ' + ''.join(f'{v:13.5g}' for v in row))
    return '\n'.join(lines)


def _print_geometry(g: CraneGeometry) -> None:
    print(f'geometry: a = {g.a:.6g} m, b = {g.b:.6g} m, h = {g.height:.6g} m, l0 = {g.l0:.6g} m, '
          f'W = {g.weight:.6g} N, k = {g.k:.6g} N/m')


def cmd_solve(args: argparse.Namespace) -> int:
    g = geometry_from_args(args)
    eq = solve_equilibrium(g, args.force, args.moment)
    if args.json:
        json.dump(eq.to_dict(), sys.stdout, indent=1)
        print()
        return 0
    _print_geometry(g)
    print(f'load: F = {args.force} N, M = {args.moment} N·m (fixed frame, z down)')
    u = eq.displacement
    phi, theta, psi = eq.euler_zxy
    print(f'displacement u = [{u[0]:.6e}, {u[1]:.6e}, {u[2]:.6e}] m (from the unloaded rest pose)')
    print(f'rotation φ = {phi:.6e}, θ = {theta:.6e}, ψ = {psi:.6e} rad (Q = Rz(φ)Rx(θ)Ry(ψ))')
    print(f'{"wire":>8} {"length [m]":>14} {"tension [N]":>14}  state')
    for name, length, t, s in zip(WIRE_NAMES, eq.wire_lengths, eq.wire_tensions, eq.slack):
        print(f'{name:>8} {length:14.8f} {t:14.6f}  {"SLACK" if s else "taut"}')
    print(f'iterations {eq.iterations}, continuation steps {eq.continuation_steps}, '
          f'residual {np.abs(eq.residual).max():.2e}')
    return 0


def cmd_stiffness(args: argparse.Namespace) -> int:
    g = geometry_from_args(args)
    eq = solve_equilibrium(g, args.force, args.moment)
    kt = tangent_stiffness(g, eq)
    kp = paper_stiffness(g)
    coeff = paper_coefficients(g)
    along = {ax: axis_stiffness(kt, ax) for ax in AXES}
    if args.json:
        json.dump({'tangent': kt.tolist(), 'paper': kp.tolist(),
                   'paper_coefficients': {'K1': coeff.k1, 'K2': coeff.k2, 'K3': coeff.k3, 'K4': coeff.k4,
                                          'K5': coeff.k5, 'Kj': coeff.side, 'h_w': coeff.h_w, 'l_w': coeff.l_w},
                   'tangent_along_axis': along, 'slack': [bool(s) for s in eq.slack]}, sys.stdout, indent=1)
        print()
        return 0
    _print_geometry(g)
    print(f'\nexact tangent stiffness at the equilibrium under F = {args.force} N, M = {args.moment} N·m '
          f'({int(eq.slack.sum())} slack wire(s)):')
    print(_fmt_matrix(kt))
    print(f'\npaper eq. (18) at the rest pose under W (h_w = {coeff.h_w:.6g} m, l_w = {coeff.l_w:.6g} m):')
    print(_fmt_matrix(kp))
    print(f'\nK1 = {coeff.k1:.6g} N/m, K2 = {coeff.k2:.6g} N/rad, K3 = {coeff.k3:.6g} N/m, '
          f'K4 = {coeff.k4:.6g} N·m/rad, K5 = {coeff.k5:.6g} N·m/rad; side stiffness K_j (eq. 19) = '
          f'{coeff.side:.6g} N/m')
    print('tangent stiffness along each load axis, other DOFs free: ' +
          ', '.join(f'{ax} {v:.6g}' for ax, v in along.items()))
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from crane_stiffness.analysis.figures import plot_force_displacement, plot_stiffness_vs_weight
    from crane_stiffness.analysis.sweep import force_displacement, slack_threshold, stiffness_vs_weight

    # Height and weight are swept; the rest of the geometry defaults to the paper's lab model.
    if not (args.config or args.a is not None):
        args.lab_model = True
    if args.height is None and args.l0 is None and not args.config:
        args.height = args.heights[0]
    if args.weight is None and not args.config:
        args.weight = args.weights[1]
    base = geometry_from_args(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []

    def bar(desc: str):
        return lambda it: tqdm(list(it), desc=desc, unit='case', leave=False, disable=args.quiet)

    for axis, fig in (('fy', 'fig10'), ('mz', 'fig13')):
        rows = stiffness_vs_weight(base, axis, args.heights, np.linspace(args.weights[0], args.weights[1],
                                                                         args.weight_points), bar(fig))
        csv_path = out / f'{fig}_stiffness_{axis}_vs_weight.csv'
        with csv_path.open('w', newline='') as fh:
            wr = csv.writer(fh)
            wr.writerow(['height_m', 'l0_m', 'weight_N', 'tangent', 'paper_eq18', 'elastic_W0'])
            for r in rows:
                wr.writerow([r.height, r.l0, r.weight, r.tangent, r.paper, r.elastic])
        written += [csv_path, plot_stiffness_vs_weight(rows, axis, out / f'{fig}_stiffness_{axis}_vs_weight.png')]
    # Force–displacement cases like Figs. 5–9: two weights at two wire lengths, then low W with long wires.
    w_hi, w_lo = args.weights[1], max(args.weights[1] / 2.0, args.weights[0])
    h_short, h_long = args.heights[0], args.heights[-1]
    cases = [('fig5', h_short, w_hi), ('fig6', h_short, w_lo), ('fig7', h_long, w_hi), ('fig8', h_long, w_lo),
             ('fig9', h_long, args.low_weight)]
    for fig, h, w in tqdm(cases, desc='force-displacement', unit='curve', disable=args.quiet):
        g = base.replace(height=h, weight=w)
        # Figs. 5-8 stay in the linear range (60 % of the side force that slackens the first wire); Fig. 9 goes
        # to 4x that force, where wires reach zero tension and the curve bends away.
        threshold = slack_threshold(g, 'fy')
        max_force = args.max_force if args.max_force else (4.0 if fig == 'fig9' else 0.6) * threshold
        curves = force_displacement(g, 'fy', max_force, args.points)
        csv_path = out / f'{fig}_force_displacement.csv'
        cols = curves.columns()
        with csv_path.open('w', newline='') as fh:
            wr = csv.writer(fh)
            wr.writerow(['force_N', 'u_nonlinear_m', 'u_linear_m', 'u_elastic_W0_m', 'u_pendulum_W6_m',
                         'slack_wires'])
            wr.writerows(zip(*cols.values()))
        title = (f'{fig}: side force fy, W = {w:.4g} N, l0 = {g.l0:.3f} m\nfirst wire slack at '
                 f'{threshold:.3g} N ({int((curves.slack_wires > 0).sum())}/{len(curves.load)} points slack)')
        written += [csv_path, plot_force_displacement(curves, out / f'{fig}_force_displacement.png', title)]
    for p in written:
        print(p)
    return 0


# argparse takes "-1.5e-05" for an option (its negative-number pattern has no exponent): accept scientific notation.
_NEGATIVE_NUMBER = re.compile(r'^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$')


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog='crane-stiffness', description=__doc__.split('\n\n')[0])
    sub = parser.add_subparsers(dest='command', required=True, parser_class=_Parser)
    p = sub.add_parser('solve', help='nonlinear equilibrium under weight and an external load')
    add_geometry(p)
    _add_load(p)
    p.add_argument('--json', action='store_true', help='machine-readable output')
    p.set_defaults(func=cmd_solve)
    p = sub.add_parser('stiffness', help='exact tangent stiffness and the paper eq. (18)')
    add_geometry(p)
    _add_load(p)
    p.add_argument('--json', action='store_true', help='machine-readable output')
    p.set_defaults(func=cmd_stiffness)
    p = sub.add_parser('sweep', help="the paper's parametric studies (Figs. 5-10, 13) as CSV and PNG")
    add_geometry(p)
    p.add_argument('--out', default='out/sweep', help='output directory (default out/sweep)')
    p.add_argument('--heights', type=float, nargs='+', default=[0.5, 1.0, 1.5], help='unloaded heights [m]')
    p.add_argument('--weights', type=float, nargs=2, default=[5.0, 100.0], metavar=('MIN', 'MAX'),
                   help='weight range [N]')
    p.add_argument('--weight-points', type=int, default=20)
    p.add_argument('--low-weight', type=float, default=5.0, help='weight of the slack case, Fig. 9 [N]')
    p.add_argument('--max-force', type=float, default=None,
                   help='largest side force [N] (default: 0.6x the slack threshold, 4x for Fig. 9)')
    p.add_argument('--points', type=int, default=41, help='points per force-displacement curve')
    p.add_argument('--quiet', action='store_true', help='no progress bars')
    p.set_defaults(func=cmd_sweep)
    _add_workspace_command(sub)
    _add_bag_commands(sub)
    _add_full6_commands(sub)
    return parser


def _add_full6_commands(sub: Any) -> None:
    """full6 design (crane_stiffness.full6.cli)."""
    from crane_stiffness.full6 import cli as full6_cli
    full6_cli.add_commands(sub)


def _add_workspace_command(sub: Any) -> None:
    """workspace pose / margins / map (crane_stiffness.design.cli)."""
    from crane_stiffness.design import cli as design_cli
    design_cli.add_command(sub)


def _add_bag_commands(sub: Any) -> None:
    """Bag subcommands: analyze, compare, recover (crane_stiffness.analysis.session_cli)."""
    from crane_stiffness.analysis import session_cli
    from crane_stiffness.campaign import cli as campaign_cli
    session_cli.add_commands(sub)
    campaign_cli.add_commands(sub)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_to_exit_code(lambda: int(args.func(args) or 0), [
        (NoEquilibriumError, EXIT_NO_EQUILIBRIUM, '{exc}'),
        (ConvergenceError, EXIT_SOLVER, 'solver gave up: {exc}'),
        ((GeometryError, ConfigError, UsageError, ValueError), EXIT_USAGE, '{exc}'),
    ])


if __name__ == '__main__':
    sys.exit(main())
