"""Simulated time: the lockstep clock's rules (pure), and the rig on simulated time giving the same bag, every topic
message for message with the same log times, at real-time factor 1 on a quiet machine and as fast as it goes beside
two busy processes, with nothing lost and nothing cut; the sensor streams logged at their stamps (their pacing kept
for a player, the same log times in every run) and every file in log-time order."""
from __future__ import annotations

import glob
import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from crane_stiffness.launcher import rosrun
from crane_stiffness.launcher.rig import run_rig
from crane_stiffness.sim.errors import ParameterError
from crane_stiffness.sim.lockstep import LEFT_NS, LockstepClock

MS = 1_000_000
SEEDS = {'load_cell': {'seed': 11}, 'lvdt': {'seed': 12}}
STREAMS = ('/crane/wrench_command', '/crane/applied_wrench', '/load_cell/wrench', '/lvdt/displacement')


def _clock(rtf: float = 0.0) -> LockstepClock:
    return LockstepClock(['prog', 'model', 'sensor', 'sink'], start_ns=1000 * 10 * MS, step_ns=10 * MS,
                         real_time_factor=rtf, max_lead_ns=50 * MS)


def test_time_waits_for_every_participant_then_for_the_slowest():
    c = _clock()
    start = c.now_ns
    assert not c.advance(0) and c.missing() == ['prog', 'model', 'sensor', 'sink']
    for stage, name in enumerate(['prog', 'model', 'sensor', 'sink']):
        c.report(name, stage, start)
    assert c.advance(0) and c.now_ns == start + 50 * MS  # as fast as allowed: the lead over the slowest
    assert not c.advance(0)                               # nobody moved: time holds
    assert c.watermarks() == [c.now_ns, start, start, start, start]
    c.report('prog', 0, start + 50 * MS)
    assert c.watermarks() == [c.now_ns, start + 50 * MS, start, start, start]  # the model may act up to the program
    for name, stage in (('model', 1), ('sensor', 2)):
        c.report(name, stage, start + 50 * MS)
    assert not c.advance(0)                               # the sink still holds it
    c.report('sink', 3, LEFT_NS)                          # ... until it leaves
    assert c.advance(0) and c.now_ns == start + 100 * MS
    assert not c.report('stranger', 0, start)             # not a participant: ignored


def test_the_wall_clock_paces_time_and_a_stall_does_not_make_it_rush():
    c = _clock(rtf=1.0)
    for stage, name in enumerate(['prog', 'model', 'sensor', 'sink']):
        c.report(name, stage, LEFT_NS - 1)
    start = c.now_ns
    assert not c.advance(0)                 # the pacing's origin
    assert c.advance(30 * MS) and c.now_ns == start + 30 * MS
    assert c.advance(35 * MS) is False      # not a whole step more
    for name in ('prog', 'model', 'sensor', 'sink'):
        c.table[name].progress_ns = c.now_ns  # everyone just there: a lead of 50 ms at most
    c.advance(10_000 * MS)                  # the wall clock allows 10 s, the participants 50 ms
    assert c.now_ns <= start + 80 * MS and c.held == 1
    held_at = c.now_ns
    for name in ('prog', 'model', 'sensor', 'sink'):
        c.table[name].progress_ns = LEFT_NS - 1
    c.advance(10_020 * MS)                  # paced on from the stall: 20 ms more at most, no 10 s burst
    assert held_at < c.now_ns <= held_at + 30 * MS


@pytest.mark.parametrize('bad', [dict(step_ns=0), dict(start_ns=15 * MS), dict(real_time_factor=-1.0),
                                 dict(max_lead_ns=MS), dict(participants=[])])
def test_bad_settings_are_refused_naming_the_field(bad):
    args = dict(participants=['a'], start_ns=1000 * MS, step_ns=10 * MS, real_time_factor=1.0, max_lead_ns=50 * MS)
    with pytest.raises(ParameterError, match=next(iter(bad))):
        LockstepClock(**{**args, **bad})


def _streams(bag: Path) -> dict[str, list[tuple[int, int, bytes]]]:
    """Each topic's (publish time, log time, serialized message) as the mcap package reads the bag in file order;
    asserts that every file's log times (all topics) never go back."""
    out: dict[str, list[tuple[int, int, bytes]]] = {}
    for path in sorted(glob.glob(str(bag / '*.mcap'))):
        with open(path, 'rb') as f:
            logs = []
            for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
                logs.append(message.log_time)
                out.setdefault(channel.topic, []).append(
                    (message.publish_time, message.log_time, bytes(message.data)))
        assert logs == sorted(logs), path
    return out


def _session_end(bag: Path) -> dict:
    """The session record's end (crane_stiffness/session_end), its JSON values decoded."""
    for path in sorted(glob.glob(str(bag / '*.mcap'))):
        with open(path, 'rb') as f:
            for record in make_reader(f).iter_metadata():
                if record.name == 'crane_stiffness/session_end':
                    return {k: _json(v) for k, v in record.metadata.items()}
    raise AssertionError(f'{bag}: no session end record')


def _json(text: str):
    try:
        return json.loads(text)
    except ValueError:
        return text


def _run(install: Path, env: dict, out: Path, rtf: str) -> tuple[dict, dict]:
    summary, _, _, logs = run_rig(rosrun.installed_config(install), env, out, 'campaign_side_force', session='s',
                                  overrides=SEEDS, arguments={'use_sim_time': 'true', 'real_time_factor': rtf})
    return summary, logs


@pytest.mark.ros
def test_the_same_streams_at_any_speed_and_load(install_tree, tmp_path):
    install, env = install_tree
    quiet, quiet_logs = _run(install, env, tmp_path / 'quiet', '1.0')
    busy = [subprocess.Popen([sys.executable, '-c', 'while True: pass']) for _ in range(2)]
    try:
        fast, fast_logs = _run(install, env, tmp_path / 'busy', 'max')
    finally:
        for p in busy:
            p.kill()
            p.wait()
    for summary, logs in ((quiet, quiet_logs), (fast, fast_logs)):
        assert set(summary['node_exit_codes'].values()) == {0}, summary['node_exit_codes']
        assert 'still missing' not in ''.join(logs.values())  # no watermark waited long for its inputs
        assert summary['status']['loading']['level'] == 'OK', summary['status']
        assert summary['status']['input']['level'] == 'OK', summary['status']
    # The run ends at the same simulated time (the program's end and a second): the same final estimates.
    for branch in ('loading', 'unloading'):
        for field in ('stiffness', 'ci95_low', 'ci95_high', 'n'):
            assert fast['estimate'][branch][field] == pytest.approx(quiet['estimate'][branch][field], rel=1e-9)
    a, b = _streams(tmp_path / 'quiet' / 'bags' / 's'), _streams(tmp_path / 'busy' / 'bags' / 's')
    # The session ends at the simulated instant the program fixed, in both runs, with every message the rig's nodes
    # published through it in the bag (their own counters against the bag's): the whole bag is the same, every
    # topic, every message, its log and publish times, and the counts in the session record.
    ends = [_session_end(tmp_path / run / 'bags' / 's') for run in ('quiet', 'busy')]
    for end in ends:
        assert end['stop_reason'] == 'program done' and end['complete'] is True and end['missing'] == {}, end
        assert end['published'] == {t: end['topics'][t] for t in end['published']}, end
        assert set(STREAMS) <= set(end['published']), end['published']
    assert ends[0] == ends[1]
    assert sorted(a) == sorted(b) and set(STREAMS) | {'/clock', '/stiffness/estimate'} <= set(a)
    for topic in a:
        assert len(a[topic]) > 0 and a[topic] == b[topic], (topic, len(a[topic]), len(b[topic]))
    # Every sample of the program (5.3 s at 1 kHz, after 0.5 s at rest) is there, on its 1 ms grid.
    stamps = [t for t, _, _ in a['/load_cell/wrench']]
    assert len(stamps) >= 5800 and all(t2 - t1 == MS for t1, t2 in zip(stamps, stamps[1:]))
    # The sensor streams logged at their stamps in both runs (so the same log times): distinct log times keeping
    # the stream's 1 ms period, not one per 50 ms clock step.
    for topic in ('/load_cell/wrench', '/lvdt/displacement'):
        assert all(log == stamp for stamp, log, _ in a[topic] + b[topic]), topic


@pytest.mark.ros
def test_a_join_sent_before_the_clock_listens_still_reaches_it(rclpy_context):
    """DDS matches the two directions between two nodes separately: a participant may hear the clock's watermark and
    answer it before the clock's reader of /sim/progress is matched to it. Its answer, sent once, must still reach
    the clock (else time waits for that node forever): the progress topic keeps it for a reader that comes later."""
    import json

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from crane_stiffness.contract import topics
    from crane_stiffness.rosnode.sim_time import SIM_QOS, SimTimeParticipant

    node = rclpy.create_node('late_heard', context=rclpy_context,
                             parameter_overrides=[Parameter('use_sim_time', value=True)])
    part = SimTimeParticipant(node, 0, lambda t: None)
    part.report(1_000 * 10**9, end_ns=1_006 * 10**9)  # the join, and where the run ends, said once
    part.report(1_000 * 10**9 + 5_000_000)
    clock_ctx = rclpy.Context()  # the clock: another DDS participant, its reader created after the reports
    rclpy.init(context=clock_ctx)
    try:
        clock = rclpy.create_node('clock_listening_late', context=clock_ctx)
        heard: list[dict] = []
        clock.create_subscription(String, topics.SIM_PROGRESS, lambda m: heard.append(json.loads(m.data)), SIM_QOS)
        executor = SingleThreadedExecutor(context=clock_ctx)
        executor.add_node(clock)
        for _ in range(400):  # until both reports are in (a failure waits 40 s at most)
            if len(heard) >= 2:
                break
            executor.spin_once(timeout_sec=0.1)
        executor.shutdown()
        clock.destroy_node()
    finally:
        rclpy.shutdown(context=clock_ctx)
        node.destroy_node()
    assert [(h['name'], h['t'], h.get('end')) for h in heard] == [
        ('late_heard', 1_000 * 10**9, 1_006 * 10**9), ('late_heard', 1_000 * 10**9 + 5_000_000, 1_006 * 10**9)]
