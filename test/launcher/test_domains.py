"""A ROS domain claimed host-wide before a rig uses it (crane_stiffness.launcher.domains): a lock file per domain that
another process sees, names its holder and loses when its process is killed; a domain whose graph holds nodes of
others is passed over; a campaign started in a domain where a foreign node publishes commands moves on to the next
free domain and measures its own crane, never mixing the two."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from crane_stiffness.launcher.domains import (INHERITED_ENV, DomainInUseError, claim_domain, foreign_nodes,
                                              try_claim, with_claim)
from helpers import REPO

CLI = Path(sys.prefix) / 'bin' / 'crane-stiffness'
#: The graph look of the tests that show a foreign node found [s]: it ends when the node is seen, which a loaded
#: machine delays (the look at the free domain after it lasts all of it).
PATIENCE_LOOK_S = 20.0
HOLD = ('import sys, time\nfrom crane_stiffness.launcher.domains import try_claim\n'
        'claim = try_claim(int(sys.argv[1]), "holder of the test")\n'
        'print("claimed" if claim else "refused", flush=True)\ntime.sleep(600)\n')


def _own_claims(tmp_path: Path, monkeypatch) -> Path:
    """The claims made from now on in a directory of their own: what a test asserts does not depend on other tests'
    claims (its own domains taken before, in the suite's directory)."""
    path = tmp_path / 'claims'
    monkeypatch.setenv('CRANE_STIFFNESS_DOMAIN_CLAIMS_DIR', str(path))
    return path


@pytest.fixture
def claims_dir(tmp_path, monkeypatch) -> Path:
    return _own_claims(tmp_path, monkeypatch)


def _holder(domain: int) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, '-c', HOLD, str(domain)], stdout=subprocess.PIPE, text=True, cwd=REPO)
    assert proc.stdout is not None and proc.stdout.readline().strip() == 'claimed'
    return proc


def test_a_claim_is_seen_by_other_processes_names_its_holder_and_ends_when_its_process_is_killed(claims_dir):
    holder = _holder(7)
    try:
        assert try_claim(7, 'second') is None
        with pytest.raises(DomainInUseError, match=rf'ROS domain 7 is in use \(claimed by pid {holder.pid} '
                                                   r'\(holder of the test'):
            claim_domain(7, 'second', search=False, look_s=0)
        moved = claim_domain(7, 'second', look_s=0)  # searching: the next free domain
        assert moved.domain == 8 and moved.own and [d for d, _ in moved.skipped] == [7]
        assert json.loads((claims_dir / 'domain-8.lock').read_text())['pid'] == os.getpid()
        moved.release()
    finally:
        holder.kill()  # SIGKILL: no clean-up of its own, the kernel drops its lock
        holder.wait()
    again = try_claim(7, 'after')
    assert again is not None and again.domain == 7
    again.release()


def test_a_claim_passes_to_the_processes_a_rig_starts_and_bad_domains_are_refused(claims_dir):
    with claim_domain(12, 'parent', look_s=0) as parent:
        env = with_claim({'PATH': os.environ['PATH']}, parent.domain)
        assert env['ROS_DOMAIN_ID'] == '12' and env[INHERITED_ENV] == '12'
        child = claim_domain(12, 'child', env=env, look_s=0)  # the claimer's own child: takes it as it is
        assert child.domain == 12 and not child.own
        assert claim_domain(12, 'stranger', look_s=0).domain == 13  # anyone else: passed over
    with pytest.raises(DomainInUseError, match='ROS domain 233: DDS domain ids go from 0 to 232'):
        claim_domain(233, look_s=0)


@pytest.mark.ros
def test_a_domain_with_nodes_of_others_is_passed_over(ros_domains, tmp_path, monkeypatch):
    import rclpy
    first, spare = ros_domains(2)  # (this test's own domains: no other test's nodes are in them)
    _own_claims(tmp_path, monkeypatch)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=first)
    foreign = rclpy.create_node('someone_elses_node', context=ctx)
    try:
        assert '/someone_elses_node' in foreign_nodes(first)
        # (a rig started by a user: no claim handed down)
        claim = claim_domain(first, 'rig of the test', env={}, look_s=PATIENCE_LOOK_S)
        assert claim.domain == spare, claim
        assert 'someone_elses_node' in claim.skipped[0][1]
        claim.release()
    finally:
        foreign.destroy_node()
        rclpy.shutdown(context=ctx)


@pytest.mark.ros
def test_a_campaign_in_a_domain_where_a_foreign_node_commands_moves_on_and_never_mixes(tmp_path, ros_domains,
                                                                                      monkeypatch):
    """The misconfiguration that mixed two rigs' data: a campaign started in a domain where another ROS program
    publishes fy commands and listens to the load cell. The campaign's rig takes the next free domain: the foreign
    node hears none of its samples and the session measures its own crane, OK."""
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.executors import SingleThreadedExecutor
    first, spare = ros_domains(2)
    _own_claims(tmp_path, monkeypatch)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=first)
    node = rclpy.create_node('another_rig_program', context=ctx)
    heard: list[object] = []
    node.create_subscription(WrenchStamped, '/load_cell/wrench', heard.append, 10)
    commands = node.create_publisher(WrenchStamped, '/crane/wrench_command', 10)

    def command() -> None:
        msg = WrenchStamped()
        msg.wrench.force.y = 3.0
        commands.publish(msg)
    node.create_timer(0.02, command)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    spinning = threading.Thread(target=executor.spin, daemon=True)
    spinning.start()
    spec = tmp_path / 'one.yaml'
    spec.write_text('campaign:\n  ros__parameters:\n    name: one\n    series: [fy]\n'
                    '    programs: [campaign_side_force]\n    weights: [50.0]\n    lengths: [0.5]\n')
    env = {k: v for k, v in os.environ.items() if k != INHERITED_ENV}  # started as a user starts it: no claim
    env['ROS_DOMAIN_ID'] = str(first)
    env['CRANE_STIFFNESS_DOMAIN_LOOK_S'] = str(PATIENCE_LOOK_S)
    try:
        run = subprocess.run([str(CLI), 'campaign', 'run', str(spec), '--out', str(tmp_path / 'c'), '--jobs', '1'],
                             capture_output=True, text=True, timeout=600, env=env)
    finally:
        executor.shutdown()
        spinning.join()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads((tmp_path / 'c' / 'sessions' / 'fy_W50_l0.5_r1' / 'result.json').read_text())
    assert result['ros_domain_id'] == spare, result['ros_domain_id']
    assert result['status']['loading']['level'] == 'OK', result['status']
    assert result['status']['input']['level'] == 'OK', result['status']
    assert heard == []  # not one of the rig's samples reached the foreign program's domain
