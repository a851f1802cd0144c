"""``crane-stiffness analyze | compare | recover``: thin command-line layers over crane_stiffness.analysis.analyze,
crane_stiffness.analysis.compare and crane_stiffness.bag.recover_bag (added to the parser of crane_stiffness.cli.main by
:func:`add_commands`). ``analyze`` of a six-axis session (a bag holding /pose_sensor/pose) runs the 6×6 analysis
(crane_stiffness.analysis.full6) and prints its table; the 1-D analysis too when the bag also holds the LVDT.

Exit codes as crane_stiffness.cli.exit_codes: 0 ok, 2 bad input (a missing or unreadable bag, a missing sensor topic,
nothing to fit; the reason on stderr), and for ``analyze`` of a one-axis session 5 when its verdict is NOT OK
(crane_stiffness.analysis.verdict: a fit that is not a stiffness, the fitted axis not the loaded one, a branch far
from the model), after writing everything; the reasons are printed first among the problems. Damage the reader works
around (a truncated or corrupt part of a bag) is reported on stderr as a warning and in the report, and the readable
part is analysed. ``recover`` exits 2 when a file could not be recovered.
"""
from __future__ import annotations

import argparse
import json
import sys
import warnings
from typing import Any, Callable

from crane_stiffness.contract.axes import AXES

from crane_stiffness.cli.exit_codes import EXIT_NOT_OK, EXIT_OK, EXIT_USAGE, run_to_exit_code


def _guarded(run: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """Run a command: bag, analysis and file errors become exit 2 with the message; warnings go to stderr."""
    def wrapper(args: argparse.Namespace) -> int:
        from crane_stiffness.errors import CraneStiffnessError
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            code = run_to_exit_code(lambda: run(args),
                                    [((CraneStiffnessError, OSError, ValueError, KeyError), EXIT_USAGE, '{exc}')])
        seen = set()
        for w in caught:
            text = str(w.message)
            if text not in seen and not issubclass(w.category, (DeprecationWarning, PendingDeprecationWarning)):
                seen.add(text)
                print(f'crane-stiffness: warning: {text}', file=sys.stderr)
        return code
    wrapper.__name__ = run.__name__
    return wrapper


def _fit_line(name: str, fit: Any, unit: str) -> str:
    if fit is None:
        return f'  {name:<10} no fit (too few pairs or no spread in displacement beyond its noise)'
    noise = f', displacement noise {fit.x_noise:.3g} counted' if fit.x_noise > 0.0 else ''
    return (f'  {name:<10} k = {fit.stiffness:.6g} {unit} (95 % CI {fit.ci95_low:.6g} … {fit.ci95_high:.6g}), '
            f'R² {fit.r2:.6f}, n = {fit.n}, nonlinearity {fit.nonlinearity:+.3g}{noise}')


def _print_summary(a: Any) -> None:
    print(f'session {a.session} ({a.bag}): axis {a.axis}, {len(a.steps)} hold step(s), {a.pairing.get("pairs", 0)} '
          f'pairs of {a.pairing.get("force_messages", 0)} load-cell and {a.pairing.get("displacement_messages", 0)} '
          'LVDT samples')
    if a.mapping:
        from crane_stiffness.analysis.report import mapping_text
        print(f'read: {mapping_text(a.mapping)}')
    print('stiffness, all pairs of each branch over the program:')
    for branch in ('loading', 'unloading'):
        print(_fit_line(branch, a.branch_fits.get(branch), a.unit))
    print('stiffness, hold means (quasi-static):')
    for branch in ('loading', 'unloading'):
        print(_fit_line(branch, a.hold_fits.get(branch), a.unit))
    if a.model is not None:
        m = a.model
        line = (f'model ({m.axis}): exact tangent at rest {m.tangent_at_rest:.6g} {m.unit}, eq. (18) {m.eq18:.6g}, '
                f'W = 0 elastic {m.elastic_w0:.6g}')
        fit = a.branch_fits.get('loading')
        if fit is not None and m.lvdt_scale:
            ref = m.tangent_at_rest * m.lvdt_scale
            line += f'; loading fit {100 * (fit.stiffness - ref) / ref:+.3f} % from the tangent'
        print(line)
    if a.uncertainty:
        from crane_stiffness.analysis.stiffness_uncertainty import uncertainty_lines
        for line in uncertainty_lines(a.uncertainty, a.unit):
            print(f'uncertainty: {line}')
    if a.live is not None:
        parts = [f'{b} live {a.live.live[b]["stiffness"]:.10g} vs offline {a.live.offline[b]["stiffness"]:.10g} '
                 f'(largest relative difference {a.live.max_rel_diff[b]:.2g})' for b in ('loading', 'unloading')]
        print('last live estimate reproduced: ' + '; '.join(parts))
    reasons = list(a.verdict.get('reasons', []))
    for problem in reasons + [p for p in a.problems if p not in reasons]:
        print(f'  ! {problem}')
    print(f"verdict: {a.verdict.get('level', 'OK')}" + (f" ({len(reasons)} reason(s): the first problem(s) above)"
                                                        if reasons else ''))


def _mapping(args: argparse.Namespace) -> Any:
    """The :class:`~crane_stiffness.analysis.mapping.SensorMapping` the flags ask for (MappingError /
    ParameterError / ConfigError naming a bad value)."""
    from crane_stiffness.analysis.mapping import SensorMapping
    from crane_stiffness.cli.geometry_args import config_geometry_params
    from crane_stiffness.estimation.settings import ESTIMATOR_PARAMS
    from crane_stiffness.params.files import config_path, load_params
    estimator = source = None
    if args.params_file:
        path = config_path(args.params_file)
        names = {spec.name for spec in ESTIMATOR_PARAMS} | {'displacement_type'}
        estimator = {k: v for k, v in load_params(path, 'stiffness_estimator').items() if k in names}
        source = f'--params-file {path}'
    geometry = geometry_source = None
    if args.config:
        geometry = config_geometry_params(args.config)
        geometry_source = f'--config {config_path(args.config)}'
    return SensorMapping(wrench_topic=args.wrench_topic, displacement_topic=args.displacement_topic,
                         displacement_type=args.displacement_type, displacement_gain=args.displacement_gain,
                         displacement_offset=args.displacement_offset, estimator_params=estimator,
                         estimator_params_source=source or '', geometry_params=geometry,
                         geometry_source=geometry_source or '')


def _analyze_full6(args: argparse.Namespace) -> int:
    """A six-axis session (the bag holds /pose_sensor/pose): the 6×6 analysis; the 1-D one too when the bag also
    holds the LVDT, into the same folder (its files are named apart)."""
    from crane_stiffness.analysis.full6 import analyze_full6
    from crane_stiffness.analysis.full6_report import summary_lines
    from crane_stiffness.bag import BagReader
    mapping = _mapping(args)
    with BagReader(args.bag) as reader:
        info = reader.topics.get(mapping.displacement_topic)
        one_axis = info is not None and info.count > 0
    result = analyze_full6(args.bag, args.out, formats=(args.format,), reports=(args.report,))
    one = None
    if one_axis:
        from crane_stiffness.analysis.analyze import analyze_session
        one = analyze_session(args.bag, args.out, formats=(args.format,), reports=(args.report,),
                              write_json=args.json, axis=args.axis, settle_fraction=args.settle,
                              progress=not args.quiet and not args.json, mapping=mapping)
    if args.json:
        json.dump({'full6': result.to_dict(), 'one_axis': None if one is None else one.to_dict()}, sys.stdout,
                  indent=1, allow_nan=False)
        print()
        return EXIT_OK
    print('\n'.join(summary_lines(result)))
    if one is not None:
        print('\nthe 1-D analysis of the LVDT:')
        _print_summary(one)
    else:
        print(f'(no {mapping.displacement_topic} in the bag: no 1-D analysis)')
    print('wrote:')
    for path in result.files + (one.files if one is not None else []):
        print(f'  {path}')
    return EXIT_OK


def cmd_analyze(args: argparse.Namespace) -> int:
    from crane_stiffness.analysis.analyze import analyze_session
    from crane_stiffness.analysis.full6_load import is_full6_bag
    if is_full6_bag(args.bag):
        return _analyze_full6(args)
    analysis = analyze_session(args.bag, args.out, formats=(args.format,), reports=(args.report,),
                               write_json=args.json, axis=args.axis, settle_fraction=args.settle,
                               progress=not args.quiet and not args.json, mapping=_mapping(args),
                               uncertainty_file=args.uncertainty, monte_carlo=args.monte_carlo == 'on')
    code = EXIT_OK if analysis.verdict.get('level', 'OK') == 'OK' else EXIT_NOT_OK
    if args.json:
        json.dump(analysis.to_dict(), sys.stdout, indent=1, allow_nan=False)
        print()
        return code
    _print_summary(analysis)
    print('wrote:')
    for path in analysis.files:
        print(f'  {path}')
    return code


def cmd_compare(args: argparse.Namespace) -> int:
    from crane_stiffness.analysis.compare import compare_sessions
    comparison = compare_sessions(args.bags, args.out, formats=(args.format,), reports=(args.report,),
                                  write_json=args.json, axis=args.axis, progress=not args.quiet and not args.json,
                                  mapping=_mapping(args))
    if args.json:
        json.dump(comparison.to_dict(), sys.stdout, indent=1, allow_nan=False)
        print()
        return EXIT_OK
    print(f'{"session":<28} {"axis":<4} {"loading k":>12} {"unloading k":>12} {"model k":>12} {"error":>9}  '
          f'{"loading k ± U (hold means)":>26} {"E_n model":>9}')
    for r in comparison.rows:
        err = r['relative_error_loading']
        measured = f'{r["loading_measured_k"]:.6g} ± {r["loading_U"]:.4g}'
        print(f'{r["session"]:<28} {r["axis"]:<4} {r["loading_k"]:>12.6g} {r["unloading_k"]:>12.6g} '
              f'{r["model_tangent_k"]:>12.6g} {100 * err:>+8.3f}%  {measured:>26} {r["loading_En_model"]:>+9.2f}')
    for p in comparison.agreement:
        print(f'{p["b"]} against {p["a"]}, {p["branch"]}: {p["k_b"]:.6g} ± {p["U_b"]:.4g} vs {p["k_a"]:.6g} ± '
              f'{p["U_a"]:.4g} {p["unit"]} (U, 95 %): E_n = {p["En"]:+.2f}, {"agree" if p["agrees"] else "DISAGREE"}')
    print('wrote:')
    for path in comparison.files:
        print(f'  {path}')
    return EXIT_OK


def cmd_recover(args: argparse.Namespace) -> int:
    from crane_stiffness.bag import recover_bag
    report = recover_bag(args.bag, backup=not args.no_backup)
    print(report)
    if not report.ok:
        bad = ', '.join(f.path.name for f in report.files if f.status not in ('intact', 'recovered'))
        print(f'crane-stiffness: could not recover {bad}', file=sys.stderr)
        return EXIT_USAGE
    return EXIT_OK


def _add_output_options(p: argparse.ArgumentParser, default_out: str) -> None:
    p.add_argument('--out', metavar='DIR', default=None, help=f'output directory (default {default_out})')
    p.add_argument('--format', choices=('png', 'svg'), default='png', help='figure format (default png)')
    p.add_argument('--report', choices=('md', 'html'), default='md', help='report format (default md)')
    p.add_argument('--json', action='store_true', help='also write the results as JSON and print them on stdout')
    p.add_argument('--axis', choices=AXES, default=None,
                   help="load axis (default: the estimator's recorded force_axis, else the program's axis)")
    p.add_argument('--quiet', action='store_true', help='no progress bar')


def _add_mapping_options(p: argparse.ArgumentParser) -> None:
    """The topics and units of a lab's own recording, as the stiffness_estimator node takes them (its remaps and its
    displacement_type / _gain / _offset parameters; analysis.mapping), and the geometry of a bag without one."""
    from crane_stiffness.contract import topics
    from crane_stiffness.estimation.settings import DISPLACEMENT_TYPE_PARAM, DISPLACEMENT_TYPES, ESTIMATOR_PARAMS
    spec = {s.name: s for s in ESTIMATOR_PARAMS}
    g = p.add_argument_group("topics and units (the stiffness_estimator node's remaps and parameters, same names "
                             'and meanings; docs/recording.md)')
    g.add_argument('--wrench-topic', metavar='TOPIC', default=topics.LOAD_CELL_WRENCH,
                   help='the F/T sensor\'s geometry_msgs/WrenchStamped topic in the bag, wrench in N and N·m '
                   '(live: -r %(default)s:=TOPIC; default %(default)s)')
    g.add_argument('--displacement-topic', metavar='TOPIC', default=topics.LVDT_DISPLACEMENT,
                   help='the displacement topic in the bag: PointStamped (point.x in m) or std_msgs/Float64 (in V) '
                   '(live: -r %(default)s:=TOPIC; default %(default)s)')
    g.add_argument('--displacement-type', choices=DISPLACEMENT_TYPES, default=None,
                   help=f'{DISPLACEMENT_TYPE_PARAM.description}; a Float64 is taken at its log time in the bag, as the '
                   "node takes it at its receipt (default: --params-file's, else the recorded message type's)")
    for name, metavar in (('displacement_gain', 'M_PER_V'), ('displacement_offset', 'M')):
        rule = spec[name].rule_text()
        g.add_argument('--' + name.replace('_', '-'), type=float, metavar=metavar, default=None,
                       help=f'{spec[name].description}{f" ({rule})" if rule else ""}; reading [m] = '
                       'displacement_gain × volts + displacement_offset (default: --params-file\'s, else the '
                       f'recorded parameter, else {spec[name].default:g})')
    g.add_argument('--params-file', metavar='FILE', default=None,
                   help='ROS parameter YAML (as ros2 run ... --params-file): its stiffness_estimator parameters '
                   '(displacement_type, displacement_gain, pairing, ...) over the recorded ones, under these flags '
                   '(a path, or a name in the installed config/)')
    g.add_argument('--config', metavar='CRANE.yaml', default=None,
                   help='ROS parameter YAML with geometry.* parameters [m, N, Pa] for the model, over the bag\'s '
                   'recorded geometry (a bag without session metadata has none); a path, or a name in the installed '
                   'config/, e.g. crane_lab')


def add_commands(subparsers: Any) -> None:
    """Add ``analyze``, ``compare`` and ``recover`` to the ``crane-stiffness`` subparsers."""
    p = subparsers.add_parser('analyze', help='stiffness, test steps, model curves, figures and report of a '
                              'recorded session (bag); of a six-axis session (with /pose_sensor/pose) the 6x6 '
                              'stiffness and compliance with intervals, against the exact tangent and eq. (18)')
    p.add_argument('bag', metavar='BAG', help='bag directory (or .mcap file) written by session_recorder, or by '
                   'ros2 bag record with the flags below')
    _add_output_options(p, 'out/analysis/<bag name>')
    p.add_argument('--settle', type=float, default=0.3, metavar='FRACTION',
                   help='part of each hold skipped before averaging (default 0.3)')
    p.add_argument('--uncertainty', metavar='FILE', default=None,
                   help="the crane inputs' uncertainties for the model's prediction and E_n (default "
                        'config/uncertainty_lab.yaml; docs/uncertainty.md)')
    p.add_argument('--monte-carlo', choices=('on', 'off'), default='on',
                   help="JCGM 101's Monte Carlo beside each GUM result (seeded: the same bag, the same numbers); "
                        'off: the GUM alone, about 0.4 s less (default on)')
    _add_mapping_options(p)
    p.set_defaults(func=_guarded(cmd_analyze))
    p = subparsers.add_parser('compare', help='sessions side by side: table and overlay figure')
    p.add_argument('bags', metavar='BAG', nargs='+', help='bag directories (or .mcap files)')
    _add_output_options(p, 'out/compare')
    _add_mapping_options(p)
    p.set_defaults(func=_guarded(cmd_compare))
    p = subparsers.add_parser('recover', help='repair a bag left unfinished by a crash (SIGKILL, power loss) and '
                              'rewrite its metadata.yaml')
    p.add_argument('bag', metavar='BAG', help='bag directory or .mcap file')
    p.add_argument('--no-backup', action='store_true', help='delete damaged originals instead of keeping .bak')
    p.set_defaults(func=_guarded(cmd_recover))
