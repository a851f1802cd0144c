"""``crane-stiffness campaign run | analyze`` and ``crane-stiffness calibrate``: thin command-line layers over
crane_stiffness.campaign (added to the parser of crane_stiffness.cli.main by :func:`add_commands`).

Exit codes: 0 ok; 2 bad input (a campaign file with an unknown key or a value against its rule, a directory that is
not a campaign or holds another one, data that cannot determine a calibrated parameter; one stderr line naming the
file, key or parameter); 1 a session failed on the rig (the node's log tail on stderr); 5 ``campaign run``: a
session is NOT OK or its bag was cut short (each named on stderr with its causes; this run's and those done before);
130 interrupted (Ctrl-C or the operator stopped it: run the same command again to resume).
"""
from __future__ import annotations

import argparse
import sys
from typing import Any, Callable

from crane_stiffness.cli.exit_codes import (EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, EXIT_SESSION_NOT_OK, EXIT_USAGE,
                                            run_to_exit_code)


def _guarded(run: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    def wrapper(args: argparse.Namespace) -> int:
        from crane_stiffness.campaign.runner import CampaignInterrupted
        from crane_stiffness.errors import CraneStiffnessError
        from crane_stiffness.launcher.rosrun import RosRunError
        return run_to_exit_code(lambda: run(args), [
            (CampaignInterrupted, EXIT_INTERRUPTED, '{exc}'),
            (KeyboardInterrupt, EXIT_INTERRUPTED, 'interrupted'),
            (RosRunError, EXIT_FAILED, 'a session failed on the rig: {exc}'),
            ((CraneStiffnessError, OSError, ValueError), EXIT_USAGE, '{exc}'),
        ])
    wrapper.__name__ = run.__name__
    return wrapper


def _rig_arguments(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        name, sep, value = item.partition(':=')
        if not sep or not name:
            raise ValueError(f'--rig-arg {item!r}: expected NAME:=VALUE (a rig.launch.py argument)')
        out[name] = value
    return out


def cmd_run(args: argparse.Namespace) -> int:
    import functools
    from crane_stiffness.campaign.runner import run_campaign, service_confirm, terminal_confirm
    from crane_stiffness.campaign.spec import load_campaign
    from crane_stiffness.campaign.verdict import Review, not_ok_summary
    campaign = load_campaign(args.campaign)
    confirm = (service_confirm(operator=args.operator) if args.confirm == 'service' else
               functools.partial(terminal_confirm, operator=args.operator))
    # Asked after a NOT OK session only on hardware with someone at this terminal (a simulated session repeated
    # gives the same numbers); else it goes on and the session stays marked NOT OK.
    review = Review(args.out, on_not_ok=args.on_not_ok,
                    interactive=args.hardware and args.confirm == 'terminal' and sys.stdin.isatty())
    run = run_campaign(campaign, args.out, hardware=args.hardware, confirm=confirm,
                       arguments=_rig_arguments(args.rig_arg), progress=not args.quiet, jobs=args.jobs,
                       scheduler=args.scheduler, rig=args.rig, review=review,
                       load_application=args.load_application, settle_s=args.settle_s, operator=args.operator)
    print(f'campaign {campaign.name}: {len(run.ran)} session(s) run, {len(run.skipped)} done before, '
          f'{run.planned} planned -> {run.out}'
          + (f' ({len(run.repeated)} repeated after a NOT OK verdict)' if run.repeated else ''))
    verdicts = {name: _verdict_before(args.out, name) for name in run.skipped}
    verdicts.update(review.verdicts)
    bad = not_ok_summary(verdicts)
    if bad:
        print(f'crane-stiffness: {len(bad)} of {len(verdicts)} session(s) NOT OK (each analysed after its run; '
              f'`campaign analyze {args.out}` for the whole campaign):', file=sys.stderr)
        for line in bad:
            print(f'  {line}', file=sys.stderr)
        return EXIT_SESSION_NOT_OK
    return EXIT_OK


def _verdict_before(out: str, session: str) -> Any:
    """The verdict of a session done before this run: the one kept, else (a run stopped while judging it) judged
    now and kept."""
    import json
    from pathlib import Path
    from crane_stiffness.campaign.runner import read_plan
    from crane_stiffness.campaign.session import RESULT_FILE
    from crane_stiffness.campaign.verdict import read_verdict, session_verdict, write_verdict
    verdict = read_verdict(out, session)
    if verdict is None:
        plan = next(p for p in read_plan(out)['sessions'] if p['id'] == session)
        result = json.loads((Path(out) / 'sessions' / session / RESULT_FILE).read_text())
        verdict = session_verdict(out, plan, result)
        verdict.decision = 'judged when the campaign was resumed'
        write_verdict(out, verdict)
    return verdict


def cmd_analyze(args: argparse.Namespace) -> int:
    from crane_stiffness.campaign.analyze import analyze_campaign
    done = []

    def note(bag: str) -> None:
        done.append(bag)
        if not args.quiet:
            print(f'  analysed {len(done)}: {bag}', file=sys.stderr, flush=True)
    result = analyze_campaign(args.dir, workers=args.workers, scheduler=args.scheduler, formats=(args.format,),
                              progress=note)
    count = len(result.rows) + len(result.full)
    print(f'campaign {result.campaign}: {count} session(s) ({len(result.analysed)} analysed now, '
          f'{count - len(result.analysed)} unchanged)')
    if result.rows:
        print(f'{"session":<20} {"k":>12} {"95 % interval":>27} {"model":>12} {"error":>9}  status')
    for r in result.rows:
        print(f'{r.session:<20} {r.k:>12.6g} [{r.ci95_low:>12.6g}, {r.ci95_high:>12.6g}] {r.model_tangent:>12.6g} '
              f'{100 * r.relative_error:>+8.3f}%  {r.status}')
    if result.full:
        from crane_stiffness.contract.axes import AXES
        print('the whole 6x6 K against the tangent (measured / tangent - 1; * interval misses the tangent):')
        print(f'{"session":<20} ' + ' '.join(f'{a:>8}' for a in AXES) + f' {"K2":>8} {"sign":>5} {"cover":>6}  status')
    for f in result.full:
        diag = ' '.join(f'{100 * d["relative_error"]:>+7.2f}' + (' ' if d['covers'] else '*')
                        if d['relative_error'] is not None else f'{"-":>8}' for d in f.diagonal)
        sign = 'ok' if f.k2 * f.k2_tangent > 0 else 'WRONG'
        print(f'{f.session:<20} {diag} {100 * f.k2_relative_error:>+7.2f}% {sign:>5} {f.covered:>3}/36  {f.status}')
    for name in result.missing:
        print(f'  missing: {name}')
    for name, why in result.failed.items():
        print(f'  analysis failed: {name}: {why}', file=sys.stderr)
    print('wrote:')
    for path in result.files:
        print(f'  {path}')
    return EXIT_OK


def cmd_calibrate(args: argparse.Namespace) -> int:
    from crane_stiffness.campaign.calibrate import calibrate_campaign
    cal, files = calibrate_campaign(args.dir, weight=args.weight, height=args.height, only_ok=args.only_ok,
                                    formats=(args.format,))
    print(f'calibrated on {len(cal.sessions)} session(s): chi2 = {cal.chi2:.4g} on {cal.dof} degrees of freedom')
    for p in cal.parameters:
        print(f'  {p.name:<24} {p.value:.7g} ± {p.stderr:.2g} (95 %: {p.ci95_low:.7g} .. {p.ci95_high:.7g}) '
              f'[{p.unit}]  {p.description}')
    names = [p.name for p in cal.parameters]
    if len(names) > 1:
        print('  correlations: ' + '; '.join(f'{names[i]}/{names[j]} {cal.correlation[i][j]:+.3f}'
                                             for i in range(len(names)) for j in range(i + 1, len(names))))
    print('wrote:')
    for path in files:
        print(f'  {path}')
    return EXIT_OK


def add_commands(subparsers: Any) -> None:
    """Add ``campaign`` (run, analyze) and ``calibrate`` to the ``crane-stiffness`` subparsers."""
    p = subparsers.add_parser('campaign', help="a test campaign (the paper's matrix of sessions): run, analyze")
    sub = p.add_subparsers(dest='campaign_command', required=True)
    r = sub.add_parser('run', help='run every session of a campaign file on the rig (resumes an interrupted one)')
    r.add_argument('campaign', metavar='CAMPAIGN.yaml', help='campaign file (see config/campaign_paper.yaml)')
    r.add_argument('--out', metavar='DIR', required=True, help='campaign directory (bags, logs, results)')
    r.add_argument('--hardware', action='store_true',
                   help="real hardware: stop before each session, say what to set up and wait for the operator's "
                        'confirmation (recorded with the session)')
    r.add_argument('--confirm', choices=('terminal', 'service'), default='terminal',
                   help='with --hardware: a prompt at this terminal, or a call of /campaign/continue '
                        '(std_srvs/srv/Trigger) from any machine of the lab (default terminal)')
    r.add_argument('--operator', default='', metavar='NAME',
                   help='who confirms the set-ups, recorded with each confirmation (default: the login name)')
    r.add_argument('--load-application', choices=('model', 'operator', 'actuator'), default=None,
                   help='how the load reaches the crane: model = the simulated crane applies each command (the '
                        'default without --hardware); operator = a person applies each new level the program names '
                        '(the default with --hardware; the program holds until the level is confirmed); actuator '
                        '= a loading actuator\'s driver subscribed to /crane/wrench_command')
    r.add_argument('--settle-s', type=float, default=2.0, metavar='S',
                   help='--load-application operator: a level counts as applied once the measured load has stayed '
                        'within load_program\'s operator_tolerance of it for S seconds; 0 = only a call of '
                        '/load_program/confirm confirms it (default 2)')
    r.add_argument('--on-not-ok', choices=('ask', 'continue', 'stop'), default='ask',
                   help='after a session whose verdict is NOT OK (each session is analysed at once and its verdict '
                        'shown before the next set-up): ask the operator (repeat / continue / stop; with --hardware '
                        'at a terminal, else continue), continue, or stop the campaign; either way the run exits 5 '
                        'naming the NOT OK sessions (default ask)')
    r.add_argument('--rig-arg', action='append', default=[], metavar='NAME:=VALUE',
                   help='a rig.launch.py argument for every session (e.g. transport:=drivers); repeatable')
    r.add_argument('--jobs', type=int, default=None, metavar='N',
                   help='sessions run side by side on simulated time, each rig in a ROS domain of its own '
                        '(ROS_DOMAIN_ID, ROS_DOMAIN_ID + 1, ...); default: on simulated time one more than the '
                        'cores (at most 4), else 1')
    r.add_argument('--scheduler', metavar='ADDRESS', default=None,
                   help='a Dask scheduler (tcp://host:8786): run the sessions on its workers (simulated time; each '
                        'worker runs its rigs in ROS domains from its own ROS_DOMAIN_ID, one per thread) and bring '
                        'their bags and results back into --out (needs the extra \'dask\')')
    r.add_argument('--rig', choices=('host', 'processes'), default=None,
                   help="how each session's nodes run: 'host' = the simulated nodes in one process per job that stays "
                        "up between sessions (the same bags and numbers, without starting eight processes per "
                        "session); 'processes' = every node its own process, started anew per session, as ros2 "
                        "launch does (default: host for the simulated rig on simulated time, else processes)")
    r.add_argument('--quiet', action='store_true', help='no progress bar')
    r.set_defaults(func=_guarded(cmd_run))
    a = sub.add_parser('analyze', help='analyse every session of a campaign directory: Figs. 10 and 13 with the '
                       'measured points, force-displacement overlays, the 6x6 K of the series full against W, '
                       'table, report, CSV and JSON')
    a.add_argument('dir', metavar='DIR', help='campaign directory (campaign run --out)')
    a.add_argument('--workers', type=int, default=None, help='local worker processes (default: every core)')
    a.add_argument('--scheduler', metavar='ADDRESS', default=None,
                   help='a Dask scheduler (tcp://host:8786) to run the session analyses on (needs the extra '
                        "'dask'; the workers must see DIR at the same path)")
    a.add_argument('--format', choices=('png', 'svg'), default='png', help='figure format (default png)')
    a.add_argument('--quiet', action='store_true', help='no progress lines')
    a.set_defaults(func=_guarded(cmd_analyze))
    c = subparsers.add_parser('calibrate', help="fit the model's uncertain parameters (wire stiffness E·A; "
                              'optionally W and the height) to an analysed campaign, with 95 %% intervals')
    c.add_argument('dir', metavar='DIR', help='campaign directory, analysed (campaign analyze DIR)')
    c.add_argument('--weight', choices=('none', 'scale', 'per-weight', 'per-session'), default='none',
                   help='also fit W: one factor for the campaign, one per weight hung, one per session '
                        '(default none)')
    c.add_argument('--height', action='store_true', help='also fit an offset of the height of each wire length')
    c.add_argument('--only-ok', action='store_true', help='leave out the sessions whose status is not OK')
    c.add_argument('--format', choices=('png', 'svg'), default='png', help='figure format (default png)')
    c.set_defaults(func=_guarded(cmd_calibrate))
