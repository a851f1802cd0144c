"""Benchmark: ``crane-stiffness campaign run`` of the paper's campaign on the simulated rig, on rig hosts that stay up
between sessions against a fresh rig of separate processes per session.

Runs config/campaign_paper.yaml (18 sessions, 115 s of simulated programs) twice, as a user runs it (the installed
``crane-stiffness``, a fresh process, default ``--jobs``): first with ``--rig processes`` (the baseline: every
session starts the rig's eight node processes anew, as ``ros2 launch`` does), then with ``--rig host`` (the
default: one process per job keeps the simulated nodes' interpreter and DDS participant up and loads each
session's nodes into it). Reports each run's wall time and real-time factor (simulated seconds per wall second,
each session counted from simulated time's start to its run's end: its program, the program's start delay and the
second after it, as /clock has it in the bag), the ratio of the two, and checks that every session's numbers (the
estimate with its interval and status; the six-axis fit where there is one) are **bit-identical** between the runs,
and how many of the recorded streams are identical message for message. ``--busy N`` keeps N busy processes
beside both runs.

Targets (issue 35): the host run at least ``TARGET_RTF`` (3) times real time on the idle two-core machine, at least
``TARGET_RTF_BUSY`` (2) beside one busy process; every session's numbers identical. Exits 1 when missed.

    python benchmarks/bench_campaign.py [--busy 1] [--json FILE] [--keep] [--campaign FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from crane_stiffness.testing.scratch import keep_or_remove  # noqa: E402
CLI = Path(sys.prefix) / 'bin' / 'crane-stiffness'
TARGET_RTF = 3.0
TARGET_RTF_BUSY = 2.0
#: Streams whose messages depend on the pace of the run, not on the session: the clock's steps.
PACED = ('/clock',)
#: (SIM_INPUTS: the streams the recorder logs at their stamps, the lock-step's inputs; every other one, the
#: estimator's outputs, program state, statuses, it logs at its clock's reading when the message arrives, which may be
#: one clock step apart between two runs: their contents are compared, not their log times.)
from crane_stiffness.rosnode.recorded_channel import SIM_INPUTS  # noqa: E402


def run(campaign: Path, out: Path, rig: str, env: dict[str, str]) -> tuple[float, float]:
    """(wall [s], CPU of the run and its children [s]) of one campaign run."""
    before = os.times()
    start = time.perf_counter()
    proc = subprocess.run([str(CLI), 'campaign', 'run', str(campaign), '--out', str(out), '--rig', rig, '--quiet'],
                          env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = os.times()
    if proc.returncode != 0:
        raise SystemExit(f'campaign run --rig {rig} failed ({proc.returncode}):\n{proc.stderr[-3000:]}')
    return wall, (after.children_user - before.children_user) + (after.children_system - before.children_system)


def numbers(out: Path) -> dict[str, dict]:
    """Each session's numbers as result.json holds them."""
    keep = ('estimate', 'status', 'stiffness6', 'status6', 'node_exit_codes')
    return {p.parent.name: {k: json.loads(p.read_text()).get(k) for k in keep}
            for p in sorted((out / 'sessions').glob('*/result.json'))}


def streams(bag: Path) -> dict[str, list[tuple[int, bytes]]]:
    """A session bag's messages by topic: (log time [ns], serialized message), in log-time order."""
    from mcap.reader import make_reader
    topics: dict[str, list[tuple[int, bytes]]] = {}
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as f:
            for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
                topics.setdefault(channel.topic, []).append((message.log_time, message.data))
    return topics


def simulated_seconds(out: Path) -> float:
    """The simulated time the rig ran, summed over the sessions: from time's start to the run's end, as each bag's
    /clock has it (the program, its start delay and the second after it) [s]."""
    total = 0.0
    for bag in sorted((out / 'bags').iterdir()):
        clock = [t for t, _ in streams(bag).get('/clock', [])]
        total += (max(clock) - min(clock)) * 1e-9
    return total


def compare_bags(a: Path, b: Path) -> tuple[int, int, dict[str, int]]:
    """(streams identical, streams compared, {topic: sessions where it differs}) over every session's bag. A stream
    is identical when its messages are, in order (the serialized bytes, up to the CDR padding at their end: DDS
    between processes pads a payload to a multiple of 4 bytes, within a process it does not), at the same log
    times for the streams logged at their stamps (:data:`SIM_INPUTS`), the contents alone for the others. The
    paced streams (:data:`PACED`) are left out."""
    same = total = 0
    differing: dict[str, int] = {}
    for bag in sorted((a / 'bags').iterdir()):
        x, y = streams(bag), streams(b / 'bags' / bag.name)
        for topic in sorted(set(x) | set(y)):
            if topic in PACED:
                continue
            total += 1
            timed = topic in SIM_INPUTS
            if [(t if timed else 0, d.rstrip(b'\0')) for t, d in x.get(topic, [])] == \
                    [(t if timed else 0, d.rstrip(b'\0')) for t, d in y.get(topic, [])]:
                same += 1
            else:
                differing[topic] = differing.get(topic, 0) + 1
    return same, total, differing


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--campaign', default=str(REPO / 'config' / 'campaign_paper.yaml'))
    parser.add_argument('--busy', type=int, default=0, help='busy processes beside both runs (default 0)')
    parser.add_argument('--json', default=None, help='write the figures as JSON here')
    parser.add_argument('--keep', action='store_true', help='keep the campaign directories')
    args = parser.parse_args()

    from crane_stiffness.campaign.session import session_program_text
    from crane_stiffness.campaign.spec import load_campaign, plan_sessions
    from crane_stiffness.sim.program import load_program_file

    campaign = load_campaign(args.campaign)
    programs_s = 0.0
    with tempfile.TemporaryDirectory() as programs:
        for plan in plan_sessions(campaign):  # the program each session plays, as the campaign writes it
            path = Path(programs) / f'{plan.id}.yaml'
            path.write_text(session_program_text(plan))
            programs_s += load_program_file(path, 'load_program').duration_s
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    env.setdefault('ROS_DOMAIN_ID', str(random.randint(100, 200)))
    tmp = Path(tempfile.mkdtemp(prefix='bench_campaign_'))
    busy = [subprocess.Popen([sys.executable, '-c', 'while True: pass']) for _ in range(args.busy)]
    try:
        print(f'{campaign.name}: {len(plan_sessions(campaign))} sessions, {programs_s:.1f} s of programs; '
              f'{args.busy} busy process(es) beside; load average {os.getloadavg()[0]:.2f}', flush=True)
        figures = {}
        simulated = 0.0
        for rig in ('processes', 'host'):
            wall, cpu = run(Path(args.campaign), tmp / rig, rig, env)
            simulated = simulated or simulated_seconds(tmp / rig)
            figures[rig] = {'wall_s': round(wall, 2), 'cpu_s': round(cpu, 1), 'rtf': round(simulated / wall, 3)}
            print(f'  --rig {rig:9s}: {wall:6.1f} s wall, {cpu:6.1f} s CPU, {simulated / wall:.2f}x real time '
                  f'({simulated:.1f} s simulated: each session from time\'s start to its run\'s end)', flush=True)
        ratio = figures['processes']['wall_s'] / figures['host']['wall_s']
        a, b = numbers(tmp / 'processes'), numbers(tmp / 'host')
        identical = [s for s in a if json.dumps(a[s], sort_keys=True) == json.dumps(b.get(s), sort_keys=True)]
        same, total, differing = compare_bags(tmp / 'processes', tmp / 'host')
        target = TARGET_RTF_BUSY if args.busy else TARGET_RTF
        ok = figures['host']['rtf'] >= target and len(identical) == len(a) == len(b)
        print(f'host against a fresh rig per session: {ratio:.2f}x as fast; sessions with bit-identical numbers: '
              f'{len(identical)} of {len(a)}; recorded streams identical message for message: {same} of {total} '
              f'(the clock\'s steps left out){"; differing: " + json.dumps(differing) if differing else ""}')
        print(f'host: {figures["host"]["rtf"]:.2f}x real time [target >= {target:g}x with {args.busy} busy]: '
              f'{"met" if ok else "MISSED"}')
        if args.json:
            Path(args.json).write_text(json.dumps({
                'date': time.strftime('%Y-%m-%d'), 'busy': args.busy, 'programs_s': programs_s,
                'simulated_s': simulated, **figures,
                'speedup': ratio, 'sessions': len(a), 'identical_sessions': len(identical),
                'streams_identical': same, 'streams': total, 'differing_streams': differing, 'target_rtf': target,
                'met': ok}, indent=1))
        return 0 if ok else 1
    finally:
        for proc in busy:
            proc.kill()
        keep_or_remove(tmp, args.keep)


if __name__ == '__main__':
    sys.exit(main())
