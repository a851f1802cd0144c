"""`crane-stiffness campaign run` on the simulated rig (the real nodes, from the installed package, each session its
own bag): interrupted by Ctrl-C and resumed it loses no session; each session records the nominal crane and the
true one the crane_model ran; the measured stiffness is the true crane's; with --hardware it waits for the operator
(a terminal prompt, or a /campaign/continue service call from another node) and records the confirmation."""
from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import PATIENCE_S
from helpers.verdicts import check_exit_and_verdict, read_verdict
from crane_stiffness.bag import BagReader
from crane_stiffness.campaign.analyze import analyze_campaign
from crane_stiffness.launcher import rosrun
from crane_stiffness.bag.session_metadata import read_node_parameters, read_session

pytestmark = pytest.mark.ros  # every test here starts the rig's nodes

CLI = Path(sys.prefix) / 'bin' / 'crane-stiffness'


def campaign_file(tmp_path: Path, weights: str, factor: float = 1.0) -> Path:
    path = tmp_path / 'small.yaml'
    path.write_text('campaign:\n  ros__parameters:\n    name: small\n    series: [fy]\n'
                    f'    programs: [campaign_side_force]\n    weights: {weights}\n    lengths: [0.5]\n'
                    f'    true.wire_stiffness_factor: {factor}\n')
    return path


def wait_for(predicate, timeout_s: float, what: str, proc: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert proc.poll() is None, f'campaign run exited ({proc.returncode}) before {what}:\n{log.read_text()[-3000:]}'
        assert time.monotonic() < deadline, f'no {what} after {timeout_s} s:\n{log.read_text()[-3000:]}'
        time.sleep(0.2)


def test_an_interrupted_campaign_resumes_where_it_stopped_and_records_true_and_nominal(tmp_path):
    spec = campaign_file(tmp_path, '[50.0, 100.0]', factor=0.92)
    out = tmp_path / 'campaign'
    log = tmp_path / 'first.log'
    # (simulated time at the wall clock's pace: the second session is still running 3 s after the first ended)
    first = rosrun.start_installed('crane-stiffness', ['campaign', 'run', str(spec), '--out', str(out),
                                                      '--jobs', '1', '--rig-arg', 'real_time_factor:=1'], log)
    done = out / 'sessions' / 'fy_W50_l0.5_r1' / 'result.json'
    wait_for(done.is_file, 240, 'the first session', first, log)
    time.sleep(3.0)  # the second session's nodes starting: Ctrl-C in the middle of it
    assert rosrun.interrupt(first, timeout_s=PATIENCE_S) == 130, log.read_text()[-3000:]
    assert 'run the same command again to resume' in log.read_text()
    assert done.is_file() and not (out / 'sessions' / 'fy_W100_l0.5_r1' / 'result.json').exists()
    again = subprocess.run([str(CLI), 'campaign', 'run', str(spec), '--out', str(out), '--quiet', '--jobs', '1'],
                           capture_output=True, text=True, timeout=400)
    # Each session judged (the one done before too, when the Ctrl-C came before its verdict): the run exits 0 when
    # every verdict is OK, else 5 (this crane is 8 % softer than the nominal model the verdict compares with).
    verdicts = [json.loads((out / 'sessions' / s / 'verdict.json').read_text())
                for s in ('fy_W50_l0.5_r1', 'fy_W100_l0.5_r1')]
    assert again.returncode == (0 if all(v['status'] == 'OK' for v in verdicts) else 5), again.stderr[-3000:]
    assert '1 session(s) run, 1 done before, 2 planned' in again.stdout
    assert json.loads(done.read_text())['session'] == 'fy_W50_l0.5_r1'  # the first session was not redone
    for session, weight in (('fy_W50_l0.5_r1', 50.0), ('fy_W100_l0.5_r1', 100.0)):
        reader = BagReader(out / 'bags' / session)
        try:
            record, nodes = read_session(reader), read_node_parameters(reader)
        finally:
            reader.close()
        entry = record['campaign']
        assert (entry['session'], entry['weight'], entry['analysis_geometry']) == (session, weight, 'nominal')
        nominal, true = record['rig']['geometry'], entry['true_geometry']
        assert true['geometry.youngs_modulus'] == pytest.approx(0.92 * nominal['geometry.youngs_modulus'])
        assert nodes['crane_model']['geometry.youngs_modulus'] == pytest.approx(true['geometry.youngs_modulus'])
        assert nodes['crane_model']['geometry.weight'] == nominal['geometry.weight'] == weight
    result = analyze_campaign(out, workers=2)
    assert [r.session for r in result.rows] == ['fy_W50_l0.5_r1', 'fy_W100_l0.5_r1']
    for row in result.rows:  # measured: the true crane; modelled: the nominal one, 8 % stiffer
        assert row.relative_error == pytest.approx(-0.08, abs=0.02 * 0.92), (row.session, row.relative_error)


def loading_estimates(out: Path) -> dict[str, float]:
    return {path.parent.name: json.loads(path.read_text())['estimate']['loading']['stiffness']
            for path in sorted((out / 'sessions').glob('*/result.json'))}


def test_sessions_side_by_side_each_in_its_own_domain_give_the_numbers_of_one_at_a_time(tmp_path, ros_domains):
    """Two sessions at once on simulated time, each rig in a DDS domain of its own, Ctrl-C in the middle of both and
    resumed: every number equal to the same campaign run one session at a time (the seeds are the campaign's)."""
    domains = ros_domains(2)
    spec = campaign_file(tmp_path, '[50.0, 100.0]')
    side = tmp_path / 'side_by_side'
    log = tmp_path / 'first.log'
    # (simulated time at the wall clock's pace, so that Ctrl-C finds both running; resumed as fast as it goes: the
    # same numbers at any pace)
    first = rosrun.start_installed('crane-stiffness', ['campaign', 'run', str(spec), '--out', str(side),
                                                      '--jobs', '2', '--rig-arg', 'real_time_factor:=1'], log)
    # (each session's nodes in the rig host of its job: their lines in the session's logs/rig_host.log)
    running = [side / 'sessions' / s / 'logs' / 'rig_host.log' for s in ('fy_W50_l0.5_r1', 'fy_W100_l0.5_r1')]
    wait_for(lambda: all(p.is_file() and 'rig ready' in p.read_text() for p in running), 240,
             'both sessions ready', first, log)
    assert rosrun.interrupt(first, timeout_s=PATIENCE_S) == 130, log.read_text()[-3000:]
    assert 'run the same command again to resume' in log.read_text()
    again = subprocess.run([str(CLI), 'campaign', 'run', str(spec), '--out', str(side), '--quiet', '--jobs', '2'],
                           capture_output=True, text=True, timeout=400)
    assert again.returncode == 0, again.stderr[-3000:]
    resumed = re.search(r'(\d) session\(s\) run, (\d) done before, 2 planned', again.stdout)
    assert resumed and int(resumed[1]) + int(resumed[2]) == 2 and int(resumed[1]) >= 1, again.stdout
    stopped = sorted((side / 'interrupted').glob('*/sessions/logs'))  # each session stopped, set aside whole
    assert len(stopped) == int(resumed[1]), stopped
    for logs in stopped:  # the nodes stopped by Ctrl-C ended cleanly
        assert (logs.parent.parent / 'bags').is_dir()
        for node_log in logs.glob('*.log'):
            assert 'FINAL_COUNTERS' in node_log.read_text(), node_log
    results = {p.parent.name: json.loads(p.read_text()) for p in (side / 'sessions').glob('*/result.json')}
    assert {r['status']['loading']['level'] for r in results.values()} == {'OK'}
    assert {r['ros_domain_id'] for r in results.values()} <= set(domains)
    one = tmp_path / 'one_at_a_time'
    proc = subprocess.run([str(CLI), 'campaign', 'run', str(spec), '--out', str(one), '--quiet', '--jobs', '1'],
                          capture_output=True, text=True, timeout=400)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert {json.loads(p.read_text())['ros_domain_id'] for p in (one / 'sessions').glob('*/result.json')} == {
        domains[0]}
    a, b = loading_estimates(side), loading_estimates(one)
    assert list(a) == list(b) == ['fy_W100_l0.5_r1', 'fy_W50_l0.5_r1']
    for session in a:  # simulated time, the same seeds: the same samples, so the same fit, to rounding
        assert a[session] == pytest.approx(b[session], rel=1e-9), session
    assert a['fy_W50_l0.5_r1'] != pytest.approx(a['fy_W100_l0.5_r1'], rel=1e-3)  # the set-ups do differ


def test_hardware_waits_for_the_operator_at_the_terminal_and_stops_on_q(tmp_path):
    spec = campaign_file(tmp_path, '[40.0]')
    out = tmp_path / 'campaign'
    proc = subprocess.run([str(CLI), 'campaign', 'run', str(spec), '--out', str(out), '--hardware', '--quiet'],
                          input='maybe\nq\n', capture_output=True, text=True, timeout=120)
    assert proc.returncode == 130, proc.stderr
    assert 'hang W = 40 N, set the wires to l0 = 0.5 m' in proc.stderr
    assert 'stopped by the operator before session fy_W40_l0.5_r1' in proc.stderr
    assert not (out / 'bags').exists() or not any((out / 'bags').iterdir())


def test_hardware_confirmed_by_a_service_call_from_another_node(tmp_path, rclpy_context):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger
    spec = campaign_file(tmp_path, '[40.0]')
    out = tmp_path / 'campaign'
    log = tmp_path / 'run.log'
    proc = rosrun.start_installed('crane-stiffness', ['campaign', 'run', str(spec), '--out', str(out), '--hardware',
                                                      '--confirm', 'service', '--quiet'], log)
    node = rclpy.create_node('operator', context=rclpy_context)
    try:
        client = node.create_client(Trigger, '/campaign/continue')
        wait_for(lambda: client.wait_for_service(timeout_sec=0.2), PATIENCE_S, 'the /campaign/continue service', proc,
                 log)
        assert not (out / 'bags' / 'fy_W40_l0.5_r1').exists()  # nothing runs before the operator confirms
        future = client.call_async(Trigger.Request())
        executor = SingleThreadedExecutor(context=rclpy_context)
        executor.add_node(node)
        executor.spin_until_future_complete(future, timeout_sec=PATIENCE_S)
        executor.shutdown()
        answer = future.result()
        assert answer is not None and answer.success and 'hang W = 40 N' in answer.message
    finally:
        node.destroy_node()
    # The session ran on the wall clock: exit 0 when its verdict is OK, 5 when NOT OK for samples lost under load only.
    code = proc.wait(timeout=300)
    check_exit_and_verdict(code, read_verdict(out / 'sessions' / 'fy_W40_l0.5_r1' / 'verdict.json'),
                           log.read_text()[-3000:])
    reader = BagReader(out / 'bags' / 'fy_W40_l0.5_r1')
    try:
        entry = read_session(reader)['campaign']
    finally:
        reader.close()
    assert entry['rig'] == 'hardware' and 'true_geometry' not in entry
    assert entry['confirmed']['how'] == 'service /campaign/continue' and entry['confirmed']['weight'] == 40.0
    # The load applied by the operator (--hardware's default): each level the program waited on was shown at the
    # campaign's terminal as it came, once, in order, the first among them (each wait lasts at least --settle-s).
    shown = [(int(m[1]), int(m[2])) for m in re.finditer(r'fy_W40_l0\.5_r1: level (\d+)/(\d+): set fy = ',
                                                         log.read_text())]
    assert shown and shown[0][0] == 1 and len({total for _, total in shown}) == 1, log.read_text()[-3000:]
    assert [level for level, _ in shown] == sorted({level for level, _ in shown}), shown
