"""`make demo`: the side-force series on the simulated rig, end to end (`--program moment_z` / `force_z`: the paper's
other two series, each with its own measuring arrangement from its program file).

1. colcon-builds the package into build/ and install/ (as a ROS workspace would);
2. starts every node as its own process the way `ros2 run crane_stiffness <node>` starts it, from that install
   tree, all at the same instant as `ros2 launch` does: crane_model, load_cell, lvdt, stiffness_estimator,
   session_recorder and load_program, which starts the program once the rig is ready;
   and live_view (unless --no-live-view), printing the page's and the Foxglove WebSocket's addresses;
   By default the rig runs on simulated time (sim_clock publishes /clock, every node follows it) at real-time
   factor 1: you watch it in real time, and a busy machine (a browser on the page, say) slows simulated time
   instead of losing samples; --wall-time runs it on the wall clock as before, --real-time-factor max as fast as
   the rig keeps up;
3. follows the program with a progress bar, then prints the estimated side stiffness beside the model's
   prediction and writes out/demo/summary.json; the session is recorded to bags/<session>/.

DDS stays on loopback (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) in a domain id of its own.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import shutil
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))  # noqa: E402  (run as a script from the repo)

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
# The observer below discovers the nodes as quickly as they discover each other (crane_stiffness.rosnode.discovery).
from crane_stiffness.rosnode.discovery import use_quick_discovery  # noqa: E402

use_quick_discovery()


def verdict(summary: dict, tolerance: float) -> str:
    """'' when the loading estimate is one to sign (status OK, within ``tolerance`` of the prediction), else why."""
    loading = summary['status'].get('loading')
    if loading is None:
        return 'the estimator published no status'
    if loading['level'] != 'OK':
        return f"the estimator's loading status is {loading['level']}: {loading['message']}"
    bad = {part: st['level'] for part, st in summary['status'].items() if st['level'] in ('ERROR', 'STALE')}
    if bad:
        return f'estimator statuses {bad}'
    recording = summary.get('recording') or {}
    if recording.get('problem'):  # the numbers may be right, but the session's record of them is not the whole run
        return f"the session's bag: {recording['problem']}"
    error = summary['relative_error']
    if not math.isfinite(error) or abs(error) > tolerance:
        return f'the loading estimate differs from the prediction by {100 * error:+.2f} % (> {100 * tolerance:g} %)'
    return ''


def measurement_uncertainty(bag: str | None) -> dict | str:
    """The loading and unloading stiffness with their GUM uncertainty and E_n against the model, from the offline
    analysis of the recorded bag (crane_stiffness.analysis.stiffness_uncertainty); why not, as a string."""
    if not bag:
        return 'no session recorded'
    from crane_stiffness.analysis.analyze import analyze_session
    from crane_stiffness.errors import CraneStiffnessError
    try:
        return analyze_session(bag, write_files=False).uncertainty
    except (CraneStiffnessError, OSError, ValueError) as exc:
        return f'the analysis of {bag} failed: {exc}'


def uncertainty_lines(gum: dict | str, unit: str) -> list[str]:
    """Two lines: the loading estimate's U (k = …) from the bag, and its E_n with the model's prediction."""
    if isinstance(gum, str) or 'loading' not in gum:
        return [f'  measurement uncertainty: none ({gum if isinstance(gum, str) else "no loading fit"})']
    loading = gum['loading']
    u, low, high = loading['uncertainty'], *loading['ci95']
    lines = [f"  GUM (bag, loading {loading['fit']}): k = {u['value']:.1f} {unit}, U = {u['U']:.1f} {unit} "
             f"(k = {u['k']:.2f}, 95 %), statistical 95 % CI [{low:.1f}, {high:.1f}]"
             + ('; statistical only' if loading['statistical_only'] else '')]
    en = loading.get('En')
    if en is None:
        lines.append("  E_n with the model: none (no model prediction with its uncertainty)")
    else:
        lines.append(f"  model {en['reference']:.1f} ± {en['U_reference']:.1f} {unit} (U, 95 %): E_n = "
                     f"{en['en']:+.2f}: {'agree' if en['agrees'] else 'disagree'} (|E_n| <= 1 agrees)")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--program', default='side_force', help='program name in config/ (program_<name>.yaml)')
    ap.add_argument('--out', default=str(REPO / 'out' / 'demo'), help='summary and logs directory')
    ap.add_argument('--bags', default=str(REPO / 'bags'), help='where the session is recorded')
    ap.add_argument('--tolerance', type=float, default=0.02, help='allowed relative error of the estimate')
    ap.add_argument('--no-live-view', dest='live_view', action='store_false',
                    help='do not start live_view (the page and the Foxglove WebSocket server)')
    time_mode = ap.add_mutually_exclusive_group()
    time_mode.add_argument('--sim-time', dest='sim_time', action='store_true', default=True,
                           help='run the rig on simulated time (the default; docs/simulated_time.md)')
    time_mode.add_argument('--wall-time', dest='sim_time', action='store_false',
                           help='run the rig on the wall clock (samples can be lost on a busy machine)')
    ap.add_argument('--seed', default='1',
                    help="the simulated sensors' noise seed (the LVDT takes seed + 1); on simulated time the same seed "
                         "gives the same numbers on any machine at any load; 'random' draws new noise each run")
    ap.add_argument('--real-time-factor', default='1.0',
                    help="simulated seconds per wall second on simulated time; 'max' = as fast as the rig keeps up")
    args = ap.parse_args(argv)
    if args.real_time_factor != 'max':
        try:
            if float(args.real_time_factor) < 0:
                raise ValueError
        except ValueError:
            ap.error(f'--real-time-factor {args.real_time_factor!r}: expected a number >= 0 or max')

    if args.seed == 'random':
        seeds = {}
    else:
        try:
            seed = int(args.seed)
            if seed < 0:
                raise ValueError
        except ValueError:
            ap.error(f"--seed {args.seed!r}: expected an integer >= 0 or random")
        seeds = {'load_cell': {'seed': seed}, 'lvdt': {'seed': seed + 1}, 'pose_sensor': {'seed': seed + 2}}

    import rclpy
    from tqdm import tqdm

    from crane_stiffness.launcher import rosrun
    from crane_stiffness.launcher.domains import INHERITED_ENV, claim_domain, describe_skipped, with_claim
    from crane_stiffness.launcher.ports import free_port
    from crane_stiffness.view.access import new_token
    from crane_stiffness.launcher.rig import Observer, ProgramWatch, start_rig, summarize, wait_for_program_start

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f'[1/3] colcon build into {REPO / "install"} ...', flush=True)
    # A fresh build of the package: setuptools would otherwise keep installing modules since moved or deleted.
    for stale in (REPO / 'build' / 'crane_stiffness', REPO / 'install' / 'crane_stiffness'):
        shutil.rmtree(stale, ignore_errors=True)
    env, share = rosrun.build_workspace(REPO, REPO)  # REPO/build, REPO/install, REPO/log
    # The rig's ROS domain, claimed host-wide (a lock file, and no node of others in its graph): a domain in use is
    # passed over for the next free one, so this rig never mixes its data with another's.
    claim = claim_domain(int(env['ROS_DOMAIN_ID']), 'scripts/demo.py', env=env)
    if claim.skipped:
        print(f'  {describe_skipped(claim)}', flush=True)
    env = with_claim(env, claim.domain)
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', INHERITED_ENV)})  # (the observer below: rclpy.init())
    session = f'demo_{args.program}_{datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")}'
    clock = (f'simulated time at real-time factor {args.real_time_factor}' if args.sim_time else 'wall-clock time')
    print(f'[2/3] starting the rig (ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]}, loopback only), '
          f'program {args.program!r} on {clock}, noise seed {args.seed}, recording bags/{session}', flush=True)
    arguments = {'use_sim_time': 'true', 'real_time_factor': args.real_time_factor} if args.sim_time else {}
    rclpy.init()
    observer = Observer()
    with rosrun.Processes(env, out / 'logs') as procs:
        launched = time.monotonic()
        # the defaults unless taken; the token made here, to print the page's address with it at once (the node
        # would make one too and log it); a ROS parameter reveals nothing DDS does not: its services are DDS's too
        view = {'port': free_port(8765), 'http_port': free_port(8080), 'token': new_token()}
        program = start_rig(procs, share, args.program, session, Path(args.bags), live_view=args.live_view,
                            overrides={'live_view': view, **seeds}, arguments=arguments)
        six_axis = 'stiffness6_estimator' in procs.procs  # a six-axis program (program:=full6): the 6x6 result
        print(f'  started {len(procs.procs)} nodes at once; load_program waits for the rig ...', flush=True)
        if args.live_view:
            print(f"  live view: open http://127.0.0.1:{view['http_port']}/?token={view['token']} in a browser; "
                  f"Foxglove or Lichtblick: ws://127.0.0.1:{view['port']}/?token={view['token']} (layouts in "
                  'install/crane_stiffness/share/crane_stiffness/foxglove/)', flush=True)
        wait_for_program_start(observer, procs, 90)
        print(f'  program started {observer.running_at - launched:.1f} s after launch', flush=True)
        bar = tqdm(total=100, desc=f'program {program.name}', unit='%', mininterval=0.5,
                   bar_format='{l_bar}{bar}| {n:.0f}/{total}% [{elapsed}<{remaining}]')
        watch = ProgramWatch(program.duration_s, margin_s=90)  # waits as long as the program keeps advancing

        def finished() -> bool:  # the final state message, or load_program's clean exit after it
            return observer.done or procs.procs['load_program'].poll() == 0

        while not finished() and not watch.expired(observer.progress):
            observer.spin_once(0.1)
            percent = int(100 * observer.progress)
            if percent != bar.n:
                bar.update(percent - bar.n)
            procs.check_alive(allow_exit=('load_program',))
        bar.update(100 - bar.n if finished() else 0)
        bar.close()
        if not finished():
            print(f'the load program did not finish ({watch.reason()}); logs in', out / 'logs', file=sys.stderr)
            return 1
        observer.settle(procs)  # the last samples reach the estimator (simulated time: through the run's end)
        codes = procs.stop()
        clock_log = procs.log('sim_clock') if 'sim_clock' in procs.procs else ''
    observer.destroy_node()
    rclpy.shutdown()
    print('[3/3] result', flush=True)
    if six_axis:
        return report6(share, args, session, observer, codes, out)
    try:
        summary = summarize(share, args.program, session, Path(args.bags), observer, codes)
    except rosrun.RosRunError as exc:
        print(f'no result: {exc}; logs in {out / "logs"}', file=sys.stderr)
        return 1
    summary['time'] = {'mode': 'simulated' if args.sim_time else 'wall'}
    summary['seed'] = args.seed
    gum = measurement_uncertainty(summary.get('bag'))
    if isinstance(gum, dict):
        summary['uncertainty'] = gum
    if args.sim_time:
        counters = next((json.loads(line.split(' ', 2)[2]) for line in reversed(clock_log.splitlines())
                         if line.startswith('FINAL_COUNTERS sim_clock ')), {})
        summary['time'].update(real_time_factor_asked=args.real_time_factor, **counters)
    (out / 'summary.json').write_text(json.dumps(summary, indent=1))
    est, pred = summary['estimate'], summary['prediction']
    prog, k_unit = summary['program'], summary['unit']
    print(f"  geometry: lab model, h = {summary['geometry']['height']} m, W = {summary['geometry']['weight']} N, "
          f"l0 = {summary['geometry']['l0']:.4f} m")
    print(f"  program: {prog['name']} ({prog['axis']} up to {prog['peak']:g} {prog['unit']}), "
          f"{prog['duration_s']:.0f} s")
    for branch in ('loading', 'unloading'):
        e = est[branch]
        n = f"{e['n']:.0f}" if math.isfinite(e['n']) else 'none'
        print(f"  estimated {branch:9s} stiffness {e['stiffness']:12.1f} {k_unit}  95 % CI [{e['ci95_low']:.1f}, "
              f"{e['ci95_high']:.1f}]  R² {e['r2']:.5f}  n = {n}")
    print(f"  model prediction {pred['stiffness']:12.1f} {k_unit} (exact tangent at rest along {prog['axis']}; "
          f"eq. 18: {pred['eq18']:.1f})")
    # The estimator's own verdict on those numbers (its last /stiffness/estimate statuses).
    for part in ('loading', 'unloading', 'input'):
        st = summary['status'].get(part, {'level': 'NONE', 'message': 'no status received'})
        print(f"  estimator status {part:9s} {st['level']:7s} {st['message']}")
    low, high = est['loading']['ci95_low'], est['loading']['ci95_high']
    covers = 'covers' if low <= pred['stiffness'] <= high else 'does NOT cover'
    print(f"  the loading 95 % interval {covers} the prediction")
    if args.sim_time and 'simulated_s' in summary['time']:
        t = summary['time']
        print(f"  simulated time: {t['simulated_s']:.1f} s in {t['wall_s']:.1f} s of wall time (real-time factor "
              f"{t['real_time_factor']:.2f}; held back by the rig {t['held']} times)")
    print(f"  relative error (loading) {100 * summary['relative_error']:+.2f} %   -> {out / 'summary.json'}")
    if summary.get('bag'):
        print(f"  session recorded: {summary['bag']}")
    for line in uncertainty_lines(gum, k_unit):
        print(line)
    why = verdict(summary, args.tolerance)
    if why:
        print(f'the estimate cannot be signed: {why}', file=sys.stderr)
        return 1
    return 0


def report6(share: Path, args: argparse.Namespace, session: str, observer, codes: dict, out: Path) -> int:
    """The six-axis result: the 6x6 K against the exact tangent, K2, the status; 0 when it can be signed."""
    import numpy as np

    from crane_stiffness.contract.axes import AXES
    from crane_stiffness.full6.reference import DISPLACEMENTS
    from crane_stiffness.launcher.rig import config_files
    from crane_stiffness.launcher.summary6 import summarize6, verdict6
    summary = summarize6(config_files(share, args.program)['crane'], observer.stiffness6, observer.status6)
    # The one-axis estimator runs beside the 6x6 fit (its pairs are recorded); its statuses say it does not apply.
    one_axis = {part: {'level': level, 'message': message} for part, (level, message) in observer.statuses.items()}
    summary.update(program=args.program, seed=args.seed, node_exit_codes=codes,
                   bag=str(Path(args.bags) / session), one_axis_estimator=one_axis)
    (out / 'summary.json').write_text(json.dumps(summary, indent=1))
    status = summary['status'] or {'level': 'NONE', 'message': 'no status received'}
    if summary['stiffness'] is not None:
        units = ('N/m', 'N/m', 'N/m', 'N·m/rad', 'N·m/rad', 'N·m/rad')
        print('  the 6x6 stiffness K, diagonal (measured, 95 % CI, exact tangent at rest):')
        for (axis, d), unit, low, high in zip(summary['diagonal'].items(), units, np.diag(summary['ci95_low']),
                                              np.diag(summary['ci95_high'])):
            print(f"    K[{axis}, {DISPLACEMENTS[AXES.index(axis)]}] {d['measured']:12.6g} [{low:.6g}, {high:.6g}] "
                  f"{unit:8s} tangent "
                  f"{d['tangent']:.6g} ({100 * d['relative_error']:+.2f} %{'' if d['covers'] else ', NOT covered'})")
        k2 = summary['k2']
        print(f"  coupling K2 (side force with tilt) {k2['measured']:.6g} N/rad, tangent {k2['tangent']:.6g} "
              f"({100 * k2['relative_error']:+.2f} %, sign {'right' if k2['same_sign'] else 'WRONG'}); "
              f"{summary['covered']} of 36 intervals cover the tangent's entry")
    message = status['message']
    print(f"  6x6 status {message if message.startswith(status['level']) else status['level'] + ': ' + message}")
    loading = one_axis.get('loading', {'level': 'NONE', 'message': 'no status received'})
    print(f"  one-axis estimator {loading['level']}: {loading['message']}")
    print(f"  summary -> {out / 'summary.json'}; session recorded: {summary['bag']}")
    why = verdict6(summary)
    if why:
        print(f'the 6x6 result cannot be signed: {why}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
