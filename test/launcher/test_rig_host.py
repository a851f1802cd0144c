"""The rig host (crane_stiffness.launcher.rig_host): the simulated rig's nodes loaded into one process that stays up
between sessions give every session what a fresh rig of separate processes gives, on simulated time: the same
numbers bit for bit and the same recorded streams message for message; a session before it leaves nothing behind;
a session stopped half-way closes its bag and the host runs the next one; what a host cannot run is refused by
name."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from mcap.reader import make_reader

from crane_stiffness.launcher import rosrun
from crane_stiffness.launcher.rig import run_rig
from crane_stiffness.launcher.rig_host import RigHost, component_class
from crane_stiffness.launcher.rosrun import RigInterrupted, RosRunError

SIM = {'use_sim_time': 'true', 'real_time_factor': 'max'}
SEEDS = {'load_cell': {'seed': 21}, 'lvdt': {'seed': 22}}


def streams(bag: Path) -> dict[str, list[tuple[int, bytes]]]:
    """A bag's messages by topic as the mcap package reads them: (log time, serialized data up to the CDR padding
    at its end: DDS between processes pads a payload to a multiple of 4 bytes, within one process it does not)."""
    out: dict[str, list[tuple[int, bytes]]] = {}
    for path in sorted(bag.glob('*.mcap')):
        with open(path, 'rb') as f:
            for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
                out.setdefault(channel.topic, []).append(
                    (message.log_time, bytes(message.data).rstrip(b'\0')))
    return out


def numbers(summary: dict) -> str:
    return json.dumps({k: summary[k] for k in ('estimate', 'status', 'node_exit_codes')}, sort_keys=True)


@pytest.mark.ros
def test_a_host_gives_each_session_what_a_fresh_rig_of_processes_gives(install_tree, tmp_path):
    install, env = install_tree
    share = rosrun.installed_config(install)
    fresh, _, _, _ = run_rig(share, env, tmp_path / 'fresh', 'campaign_side_force', session='a', overrides=SEEDS,
                             arguments=SIM)
    with RigHost(int(os.environ['ROS_DOMAIN_ID'])) as host:
        first = host.run(share, tmp_path / 'host' / 'a', 'campaign_side_force', session='a', overrides=SEEDS,
                         arguments=SIM, bags=tmp_path / 'host' / 'bags')[0]
        between = host.run(share, tmp_path / 'host' / 'b', 'campaign_moment_z', session='b',
                           overrides={'load_cell': {'seed': 5}, 'lvdt': {'seed': 6}}, arguments=SIM,
                           bags=tmp_path / 'host' / 'bags')[0]
        again = host.run(share, tmp_path / 'host' / 'c', 'campaign_side_force', session='c', overrides=SEEDS,
                         arguments=SIM, bags=tmp_path / 'host' / 'bags')[0]
    assert host.sessions == 3
    assert fresh['status']['loading']['level'] == 'OK' and set(fresh['node_exit_codes'].values()) == {0}
    assert between['program']['axis'] == 'mz' and between['status']['loading']['level'] == 'OK'
    # The numbers, bit for bit: estimate (every field), status messages, exit codes.
    assert numbers(first) == numbers(fresh)
    assert numbers(again) == numbers(fresh)
    a = streams(tmp_path / 'fresh' / 'bags' / 'a')
    for session in ('a', 'c'):
        b = streams(tmp_path / 'host' / 'bags' / session)
        assert set(a) == set(b)
        for topic in sorted(a):  # every topic, its log times too: the same at any pace, processes or not
            assert len(a[topic]) > 0 and a[topic] == b[topic], (session, topic, len(a[topic]), len(b[topic]))
    # Each session's own log: its nodes' lines and final counters, not another session's.
    for session in ('a', 'b', 'c'):
        log = (tmp_path / 'host' / session / 'logs' / 'rig_host.log').read_text()
        assert f'session {"abc".index(session) + 1} of this host: {session}' in log
        for node in fresh['node_exit_codes']:
            assert f'FINAL_COUNTERS {node} ' in log, (session, node)
        assert log.count('FINAL_COUNTERS session_recorder ') == 1


@pytest.mark.ros
def test_a_session_stopped_half_way_closes_its_bag_and_the_host_runs_the_next(install_tree, tmp_path):
    install, _ = install_tree
    share = rosrun.installed_config(install)
    seen: list[float] = []
    paced = {**SIM, 'real_time_factor': '1.0'}  # the 5.3 s program at the wall clock's pace: stopped in its middle
    with RigHost(int(os.environ['ROS_DOMAIN_ID'])) as host:
        with pytest.raises(RigInterrupted):
            host.run(share, tmp_path / 'stopped', 'campaign_side_force', session='stopped', overrides=SEEDS,
                     arguments=paced, bags=tmp_path / 'bags', progress=seen.append,
                     should_stop=lambda: bool(seen) and seen[-1] >= 0.3)
        after = host.run(share, tmp_path / 'next', 'campaign_side_force', session='next', overrides=SEEDS,
                         arguments=SIM, bags=tmp_path / 'bags')[0]
        with pytest.raises(RosRunError, match='simulated sensors only .*transport:=drivers'):
            host.run(share, tmp_path / 'drivers', 'campaign_side_force', arguments={'transport': 'drivers'})
    assert 0.3 <= seen[-1] < 1.0
    log = (tmp_path / 'stopped' / 'logs' / 'rig_host.log').read_text()
    assert 'FINAL_COUNTERS session_recorder ' in log and 'closed ' in log
    stopped = streams(tmp_path / 'bags' / 'stopped')  # the bag was closed: a summary, every message readable
    commands = stopped['/crane/wrench_command']
    assert 0 < len(commands) < len(streams(tmp_path / 'bags' / 'next')['/crane/wrench_command'])
    assert after['status']['loading']['level'] == 'OK' and set(after['node_exit_codes'].values()) == {0}


def test_what_a_host_cannot_run_is_refused_by_name(tmp_path):
    with pytest.raises(RosRunError, match="node 'netft' cannot run in a rig host"):
        component_class('netft')
    assert component_class('crane_model').__name__ == 'CraneModel'


@pytest.mark.ros
def test_a_host_process_that_dies_mid_session_says_so_and_the_next_session_gets_a_new_one(install_tree, tmp_path):
    """A campaign job's host in a process of its own (crane_stiffness.launcher.host_process): SIGKILL in the middle
    of a session fails that session naming the host, and the same job's next session runs on a new host process."""
    import signal

    from crane_stiffness.launcher.host_process import HostProcess

    install, env = install_tree
    share = rosrun.installed_config(install)
    kwargs = dict(share=share, program='campaign_side_force', overrides=SEEDS, bags=tmp_path / 'bags')
    killed: list[int] = []

    def kill_once(fraction: float) -> None:
        if fraction >= 0.2 and not killed:
            killed.extend(host._pool._processes)  # the one process of the host's pool
            os.kill(killed[0], signal.SIGKILL)
    with HostProcess(int(os.environ['ROS_DOMAIN_ID']), env) as host:
        with pytest.raises(RosRunError, match='died during the session'):
            host.run(progress=kill_once, out=tmp_path / 'killed', session='killed',
                     arguments={**SIM, 'real_time_factor': '1.0'}, **kwargs)
        after = host.run(out=tmp_path / 'next', session='next', arguments=SIM, **kwargs)
    assert len(killed) == 1
    summary = after['summary']
    assert summary['status']['loading']['level'] == 'OK' and set(summary['node_exit_codes'].values()) == {0}
    assert after['values'] is not None and after['startup_s'] > 0
