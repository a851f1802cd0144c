"""``crane-stiffness workspace {pose,margins,map}``: the design questions on the command line.

- ``pose``: the inverse problem at (x, y, z, rotation), the equilibrium, the split stiffness, the tensions.
- ``margins``: slack margins over the sphere of force and of couple directions at a pose: CSV, JSON, polar and
  sphere plots.
- ``map``: two variables on a grid (CSV, resumable; heatmaps with contours and the usable-workspace outline).

Geometry flags as in the other subcommands (``--lab-model``, ``--config``, ``--height``, ``--weight`` ...); without
them the lab model at h = 0.5 m, W = 50 N. Bad
input exits 2 with one line naming the value and the rule (crane_stiffness.cli.main.main).
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from crane_stiffness.design.errors import DesignInputError
from crane_stiffness.cli.geometry_args import add_geometry, geometry_from_args
from crane_stiffness.model import CraneGeometry
from crane_stiffness.model.geometry import WIRE_NAMES

#: Height [m] and weight [N] when neither flags nor --config give them: the lab's test case.
DEFAULT_HEIGHT = 0.5
DEFAULT_WEIGHT = 50.0


def _geometry(args: argparse.Namespace) -> CraneGeometry:
    if not (args.config or args.a is not None):
        args.lab_model = True  # the rest of the geometry defaults to the paper's lab model ...
    if not args.config:  # ... at the lab's test case, h = 0.5 m and W = 50 N
        if args.height is None and args.l0 is None:
            args.height = DEFAULT_HEIGHT
        if args.weight is None:
            args.weight = DEFAULT_WEIGHT
    if args.a is not None and args.a <= 0:
        raise DesignInputError('a', args.a, 'must be > 0 (the platform triangle cannot be inverted)')
    if args.b is not None and args.b <= 0:
        raise DesignInputError('b', args.b, 'must be > 0 (the overhead triangle cannot be inverted)')
    if args.weight is not None and args.weight <= 0:
        raise DesignInputError('weight', args.weight, 'must be > 0 (the wires hold a pose only under tension)')
    g = geometry_from_args(args)
    if g.weight <= 0:
        raise DesignInputError('weight', g.weight, 'must be > 0 (the wires hold a pose only under tension)')
    return g


def _add_pose_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group('pose (fixed frame, z down; z = 0 is the unloaded rest height)')
    g.add_argument('--position', type=float, nargs=3, metavar=('X', 'Y', 'Z'), default=None,
                   help='platform centre [m] (default: centred, at the sag under W)')
    g.add_argument('--rotation', type=float, nargs=3, metavar=('PHI', 'THETA', 'PSI'), default=[0.0, 0.0, 0.0],
                   help='Q = Rz(phi) Rx(theta) Ry(psi) [rad] (default level)')


def _print_report(report: Any) -> None:
    d = report.to_dict()
    print(f'pose: centre {(np.round(d["position_m"], 9) + 0.0).tolist()} m, angles (phi, theta, psi) '
          f'{(np.round(d["rotation_zxy_rad"], 9) + 0.0).tolist()} rad')
    print(f'{"wire":>8} {"offset [m]":>14} {"tension [N]":>12}')
    for name in WIRE_NAMES:
        print(f'{name:>8} {d["length_offsets_m"][name]:14.6e} {d["tensions_N"][name]:12.6f}')
    print(f'smallest tension {d["tension_min_N"]:.6g} N ({d["tension_min_wire"]})')
    print(f'smallest force stiffness  {d["force_stiffness_min_N_per_m"]:.6g} N/m along '
          f'{(np.round(d["force_stiffness_direction"], 6) + 0.0).tolist()} (platform free to tilt)')
    print(f'smallest moment stiffness {d["moment_stiffness_min_Nm_per_rad"]:.6g} N·m/rad about '
          f'{(np.round(d["moment_stiffness_axis"], 6) + 0.0).tolist()} (platform free to shift)')


def cmd_pose(args: argparse.Namespace) -> int:
    from crane_stiffness.design.pose import at_pose
    report = at_pose(_geometry(args), args.position, args.rotation)
    if args.json:
        json.dump(report.to_dict(), sys.stdout, indent=1)
        print()
    else:
        _print_report(report)
    return 0


def _write_margins(path: Path, m: Any) -> Path:
    with path.open('w', newline='') as fh:
        wr = csv.writer(fh)
        unit = 'N' if m.kind == 'force' else 'Nm'
        wr.writerow(['dir_x', 'dir_y', 'dir_z', f'margin_{unit}', 'wire', 'status'])
        for d, s, w, st in zip(m.directions, m.margin, m.wire, m.status):
            wr.writerow([*d.tolist(), float(s), int(w) + 1, int(st)])
    return path


def cmd_margins(args: argparse.Namespace) -> int:
    from crane_stiffness.design.figures import plot_margin_polar, plot_margin_sphere
    from crane_stiffness.design.margins import circle_directions, slack_margins, sphere_directions
    from crane_stiffness.design.pose import at_pose
    g = _geometry(args)
    report = at_pose(g, args.position, args.rotation)
    held, eq = report.solution.geometry, report.equilibrium
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    runs = {
        'force': slack_margins(held, eq, sphere_directions(args.directions), 'force', cap=args.cap),
        'moment': slack_margins(held, eq, sphere_directions(args.moment_directions), 'moment', cap=args.cap),
        'force_horizontal': slack_margins(held, eq, circle_directions(args.polar_points), 'force', cap=args.cap),
        'moment_horizontal': slack_margins(held, eq, circle_directions(args.polar_points), 'moment', cap=args.cap),
    }
    written = [_write_margins(out / f'margins_{name}.csv', m) for name, m in runs.items()]
    where = (f'a = {g.a:.4g} m, b = {g.b:.4g} m, h = {g.height:.4g} m, W = {g.weight:.4g} N, centre '
             f'{np.round(eq.displacement, 6).tolist()} m')
    written.append(plot_margin_polar(runs['force_horizontal'], runs['moment_horizontal'],
                                     out / 'margins_polar.png', f'slack margin per direction: {where}'))
    for kind in ('force', 'moment'):
        written.append(plot_margin_sphere(runs[kind], out / f'margins_sphere_{kind}.png',
                                          f'slack margin over the sphere of {kind} directions\n{where}'))
    summary: dict[str, Any] = {'pose': report.to_dict()}
    for name, m in runs.items():
        value, i = m.smallest
        summary[name] = {'smallest': value, 'direction': m.directions[i].tolist(), 'wire': WIRE_NAMES[m.wire[i]]
                         if m.wire[i] >= 0 else None, 'directions': len(m.margin)}
    for axis, vec in (('+x', [1.0, 0, 0]), ('+y', [0, 1.0, 0]), ('up', [0, 0, -1.0])):
        one = slack_margins(held, eq, np.array([vec]), 'force', cap=args.cap)
        summary[f'force_{axis}'] = float(one.margin[0])
    (out / 'margins.json').write_text(json.dumps(summary, indent=1) + '\n')
    written.append(out / 'margins.json')
    _print_report(report)
    for name in runs:
        s = summary[name]
        unit = 'N' if name.startswith('force') else 'N·m'
        print(f'smallest slack margin, {name.replace("_", " ")} ({s["directions"]} directions): '
              f'{s["smallest"]:.6g} {unit} along {np.round(s["direction"], 4).tolist()} ({s["wire"]} first)')
    print(f'slack margin along +x {summary["force_+x"]:.6g} N, +y {summary["force_+y"]:.6g} N, '
          f'up {summary["force_up"]:.6g} N')
    for p in written:
        print(p)
    return 0


def cmd_map(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from crane_stiffness.design.figures import plot_maps
    from crane_stiffness.design.maps import GridAxis, MapSpec, read_map, run_map
    if len(args.grid) != 2:
        raise DesignInputError('--grid', len(args.grid), 'give exactly two: --grid NAME LO HI N twice')
    axes = []
    for name, lo, hi, n in args.grid:
        try:
            axes.append(GridAxis(name, float(lo), float(hi), int(n)))
        except ValueError as exc:
            if isinstance(exc, DesignInputError):
                raise
            raise DesignInputError('--grid', [name, lo, hi, n], 'must be NAME LO HI N (numbers, N an integer)')
    base = _geometry(args)
    spec = MapSpec(axes[0], axes[1], base, position=tuple(args.position), z=args.z, rotation=tuple(args.rotation),
                   directions=args.directions, cap=args.cap)
    out = Path(args.out)
    bar = tqdm(total=spec.axis1.n, desc='map', unit='row', disable=args.quiet)

    def progress(done: int, total: int) -> None:
        bar.update(done - bar.n)
    try:
        csv_path = run_map(spec, out, fresh=args.fresh, progress=progress)
    finally:
        bar.close()
    meta, grids = read_map(csv_path)
    figures = plot_maps(meta, grids, out, args.usable_load)
    ok = grids['status'] == 0
    print(f'{int(ok.sum())} of {ok.size} points reachable; smallest force stiffness '
          f'{np.nanmin(grids["force_stiffness_min_N_per_m"]):.6g} N/m, smallest slack margin '
          f'{np.nanmin(grids["margin_min_N"]):.6g} N, smallest tension {np.nanmin(grids["tension_min_N"]):.6g} N')
    if args.usable_load is not None:
        usable = ok & (grids['margin_min_N'] > args.usable_load)
        print(f'usable (margin > {args.usable_load:g} N in every direction): {int(usable.sum())} points')
    for p in [csv_path, csv_path.parent / 'map.json', *figures]:
        print(p)
    return 0


def add_command(sub: Any) -> None:
    """Register ``workspace`` and its three subcommands on the main parser's subparsers."""
    from crane_stiffness.design.margins import CAP
    ws = sub.add_parser('workspace', help='design questions: a pose, slack margins per direction, maps')
    wsub = ws.add_subparsers(dest='workspace_command', required=True, parser_class=type(ws))
    p = wsub.add_parser('pose', help='inverse problem, equilibrium, split stiffness and tensions at a pose')
    add_geometry(p)
    _add_pose_args(p)
    p.add_argument('--json', action='store_true', help='machine-readable output')
    p.set_defaults(func=cmd_pose)
    p = wsub.add_parser('margins', help='slack margin per force and couple direction at a pose')
    add_geometry(p)
    _add_pose_args(p)
    p.add_argument('--directions', type=int, default=256, help='force directions on the sphere')
    p.add_argument('--moment-directions', type=int, default=256, help='couple directions on the sphere')
    p.add_argument('--polar-points', type=int, default=360, help='directions around the polar plots')
    p.add_argument('--cap', type=float, default=CAP, help='largest load tried: cap*W [N], cap*W*max(a, b) [N·m]')
    p.add_argument('--out', default='out/workspace', help='output directory (default out/workspace)')
    p.set_defaults(func=cmd_margins)
    p = wsub.add_parser('map', help='two variables on a grid: stiffness, slack margin, tension (resumable)')
    add_geometry(p)
    p.add_argument('--grid', nargs=4, action='append', default=[], metavar=('NAME', 'LO', 'HI', 'N'),
                   help='a grid variable (x, y, h, W, a, b, com_x, com_y) from LO to HI in N points; twice')
    p.add_argument('--position', type=float, nargs=2, metavar=('X', 'Y'), default=[0.0, 0.0],
                   help='platform centre where x, y are not mapped [m]')
    p.add_argument('--z', type=float, default=None, help='platform centre z [m] (default: the sag under W)')
    p.add_argument('--rotation', type=float, nargs=3, metavar=('PHI', 'THETA', 'PSI'), default=[0.0, 0.0, 0.0],
                   help='platform rotation [rad] (default level)')
    p.add_argument('--directions', type=int, default=64, help='force directions per point for the slack margin')
    p.add_argument('--cap', type=float, default=CAP, help='largest force tried: cap*W [N]')
    p.add_argument('--usable-load', type=float, default=None,
                   help='outline where the slack margin exceeds this force [N] in every direction')
    p.add_argument('--out', default='out/workspace_map', help='output directory (default out/workspace_map)')
    p.add_argument('--fresh', action='store_true', help='start again instead of resuming a map in --out')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.set_defaults(func=cmd_map)
