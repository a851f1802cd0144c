"""Shutdown as the genuine tools cause it: every node ends on SIGINT or SIGTERM, once or repeated, with
exit status 0, no traceback, no FATAL line, its FINAL_COUNTERS line, and its files closed.

The rig is started the way ``ros2 launch`` starts it: every node at the same instant (no start order, no waiting for
readiness) from the colcon install tree, as ``ros2 run`` executes it, all in one process group with a stand-in for
the launch process. Ctrl-C in that terminal is SIGINT to the whole group; launch then forwards SIGINT once more to
every node (the second signal 50 ms later here).
"""
from __future__ import annotations

import json
import re
import signal
import time
from pathlib import Path

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64, String

from helpers import PATIENCE_S, collect_for, spin_until
from helpers.processes import UNCLEAN, assert_bag_complete
from crane_stiffness.bag import BagWriter, dump_qos_profiles, qos_profile
from crane_stiffness.launcher.rig_description import PACKAGE, rig_nodes
from crane_stiffness.launcher import rosrun
from crane_stiffness.launcher.rig import Observer, decode_values, start_node

pytestmark = pytest.mark.ros  # every test here starts ROS (conftest)

SESSION = 'shutdown'
#: How long the rig runs (program playing, recording on) before the signal [s], at least: on until the estimator has
#: fitted pairs.
RUN_S = 3.0


def assert_clean_exit(name: str, code: int | None, log: str) -> dict:
    """Exit status 0, nothing unclean in the output, and the FINAL_COUNTERS line (returned, decoded)."""
    assert code == 0, f'{name} exited with status {code}:\n{log[-3000:]}'
    for sign in UNCLEAN:
        assert sign not in log, f'{name} printed {sign!r}:\n{log[-3000:]}'
    match = re.search(rf'^FINAL_COUNTERS {re.escape(name)} (\{{.*\}})$', log, re.M)
    assert match, f'{name} printed no FINAL_COUNTERS line:\n{log[-3000:]}'
    return json.loads(match.group(1))


def start_rig_at_once(procs: rosrun.Processes, share: Path, bags: Path) -> None:
    """Every rig node at the same instant, as ``ros2 launch crane_stiffness rig.launch.py record:=true`` does."""
    for node in rig_nodes(share, {'program': 'side_force', 'record': True, 'session': SESSION}):
        start_node(procs, node, {'output_dir': bags} if node.name == 'session_recorder' else None)


def wait_until_running(ctx, procs: rosrun.Processes, timeout_s: float = PATIENCE_S) -> Observer:
    """Until every node is up (in the ROS graph) and the program plays, then RUN_S more (the sensors stream, the
    estimator fits, the recorder records) and on until the estimator has published a fit of the loading."""
    observer = Observer(context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(observer)
    deadline = time.monotonic() + timeout_s
    while not (observer.progress > 0 and set(procs.procs) <= set(observer.get_node_names())):
        assert time.monotonic() < deadline, {n: procs.log(n)[-1500:] for n in procs.procs}
        procs.check_alive()
        collect_for(ex, 0.1)
    collect_for(ex, RUN_S)
    assert spin_until(ex, lambda: observer.values is not None and decode_values(observer.values)['loading']['n'] > 0,
                      PATIENCE_S), {n: procs.log(n)[-1500:] for n in procs.procs}
    procs.check_alive()
    ex.shutdown()
    observer.destroy_node()
    return observer


def wait_all(procs: rosrun.Processes, names=None) -> dict[str, int | None]:
    deadline = time.monotonic() + PATIENCE_S  # how long a node may take to end after the signal
    chosen = {n: p for n, p in procs.procs.items() if names is None or n in names}
    while any(p.poll() is None for p in chosen.values()) and time.monotonic() < deadline:
        time.sleep(0.05)
    return {n: p.poll() for n, p in chosen.items()}


def config_dir(install: Path) -> Path:
    return rosrun.installed_config(install)


def signal_group_repeatedly(procs: rosrun.Processes, sig: int, times: int, gap_s: float = 0.05) -> None:
    """``sig`` to the whole group ``times`` times, ``gap_s`` apart (Ctrl-C pressed again, launch forwarding it)."""
    for i in range(times):
        if i:
            time.sleep(gap_s)
        try:
            procs.signal_group(sig)
        except ProcessLookupError:
            return  # every process already gone


@pytest.mark.parametrize('how', ['sigint', 'sigint_twice', 'sigint_thrice', 'sigterm'])
def test_rig_ends_cleanly_on_signals_to_the_process_group(install_tree, rclpy_context, tmp_path, how):
    """Ctrl-C once, twice (launch forwards it once more to each node) or three times, or SIGTERM."""
    install, env = install_tree
    bags = tmp_path / 'bags'
    bags.mkdir()
    with rosrun.Processes(env, tmp_path / 'logs', process_group=True) as procs:
        start_rig_at_once(procs, config_dir(install), bags)
        assert len(procs.procs) == 6
        wait_until_running(rclpy_context, procs)
        if how == 'sigterm':
            procs.signal_group(signal.SIGTERM)
        else:  # Ctrl-C: launch and every node
            signal_group_repeatedly(procs, signal.SIGINT, {'sigint': 1, 'sigint_twice': 2, 'sigint_thrice': 3}[how])
        codes = wait_all(procs)
        logs = {n: procs.log(n) for n in procs.procs}
    for name in procs.procs:
        assert_clean_exit(name, codes[name], logs[name])
    total = assert_bag_complete(bags / SESSION)
    recorder = assert_clean_exit('session_recorder', codes['session_recorder'], logs['session_recorder'])
    assert recorder['messages'] == total and recorder['recordings'] == 1 and recorder['errors'] == 0
    assert 'messages (shutdown)' in logs['session_recorder']  # closed by the signal, not by the program's end


def test_estimator_alone_ends_cleanly_on_sigint_while_it_receives_data(install_tree, rclpy_context, tmp_path):
    """SIGINT to the estimator only, while the sensors stream at 1 kHz and it fits the program's load steps."""
    install, env = install_tree
    bags = tmp_path / 'bags'
    bags.mkdir()
    with rosrun.Processes(env, tmp_path / 'logs', process_group=True) as procs:
        start_rig_at_once(procs, config_dir(install), bags)
        wait_until_running(rclpy_context, procs)
        procs.procs['stiffness_estimator'].send_signal(signal.SIGINT)
        codes = wait_all(procs, ['stiffness_estimator'])
        others_alive = all(p.poll() is None for n, p in procs.procs.items() if n != 'stiffness_estimator')
        log = procs.log('stiffness_estimator')
    counters = assert_clean_exit('stiffness_estimator', codes['stiffness_estimator'], log)
    assert counters['force_received'] > 0 and counters['pairs_fitted'] > 0, counters
    assert others_alive


@pytest.fixture
def short_bag(tmp_path) -> Path:
    """/a Float64 × 101 over 1 s (best effort), /b String × 11 (reliable)."""
    path = tmp_path / 'short'
    t0 = 1_700_000_000 * 1_000_000_000
    with BagWriter(path) as w:
        w.add_topic('/a', 'std_msgs/msg/Float64', dump_qos_profiles([qos_profile(reliability='best_effort')]))
        w.add_topic('/b', 'std_msgs/msg/String', dump_qos_profiles([qos_profile(depth=10)]))
        for i in range(101):
            log = t0 + i * 10_000_000
            w.write('/a', serialize_message(Float64(data=float(i))), log)
            if i % 10 == 0:
                w.write('/b', serialize_message(String(data=f'b{i}')), log + 1)
    return path


def test_player_ends_cleanly_after_playback_and_on_repeated_sigint(install_tree, tmp_path, short_bag):
    """exit_on_end: the player ends by itself after playing the bag, status 0, no FATAL (it raised SystemExit in a
    timer callback before). A looping player given SIGINT twice ends the same way."""
    _, env = install_tree
    args = ['--ros-args', '-p', f'bag:={short_bag}', '-p', 'start_delay_s:=0.2', '-p', 'rate:=2.0']
    with rosrun.Processes(env, tmp_path / 'logs') as procs:
        procs.start('to_the_end', PACKAGE, 'session_player', args)
        procs.start('looping', PACKAGE, 'session_player', args + ['-p', 'loop:=true'])
        codes = wait_all(procs, ['to_the_end'])
        procs.check_alive(allow_exit=['to_the_end'])
        # The looping player is playing (a loaded machine may start it after the other has finished) before it is
        # signalled: the signal must stop a playback, not a player still waiting to start.
        deadline = time.monotonic() + PATIENCE_S
        while ', looping' not in procs.log('looping') and time.monotonic() < deadline:
            time.sleep(0.05)
        procs.procs['looping'].send_signal(signal.SIGINT)
        time.sleep(0.05)
        procs.procs['looping'].send_signal(signal.SIGINT)
        codes = wait_all(procs)
        logs = {n: procs.log(n) for n in procs.procs}
    end = assert_clean_exit('session_player', codes['to_the_end'], logs['to_the_end'])
    assert end == {'state': 'finished', 'read': 112, 'published': 112, 'skipped_stopped': 0,
                   'skipped_publish_error': 0, 'loops': 1, 'problems': 0}, logs['to_the_end']
    assert 'finished: 112 messages published' in logs['to_the_end']
    looping = assert_clean_exit('session_player', codes['looping'], logs['looping'])
    assert looping['state'] == 'stopped', looping  # stopped while playing (however much it had published)
    assert looping['read'] == looping['published'] + looping['skipped_stopped'] + looping['skipped_publish_error']


def signal_caught(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` (the SigCgt mask of /proc/<pid>/status)."""
    try:
        status = Path(f'/proc/{pid}/status').read_text()
    except FileNotFoundError:
        return False
    mask = int(re.search(r'^SigCgt:\s*([0-9a-f]+)$', status, re.M).group(1), 16)
    return bool(mask >> (sig - 1) & 1)


def test_a_signal_while_the_node_still_imports_ends_it_cleanly(install_tree, tmp_path):
    """Ctrl-C right after ``ros2 launch``: the signal (twice, as launch forwards it) reaches nodes that are still
    importing rclpy, numpy and numba (about 0.9 s for crane_model on an idle machine). Each node is signalled as soon
    as it handles SIGTERM, i.e. once crane_stiffness.rosnode.entry runs, before its node module is imported. (Python's
    default SIGTERM is not caught; the interpreter's own start-up before that is out of our hands.) Before entry.py
    held the signals, each ended with a KeyboardInterrupt traceback."""
    _, env = install_tree
    names = ('crane_model', 'stiffness_estimator', 'session_recorder')
    importing: dict[str, bool] = {}
    with rosrun.Processes(env, tmp_path / 'logs') as procs:
        for name in names:  # one at a time: a node's import (0.3–1 s) is the window to hit
            proc = procs.start(name, PACKAGE, name, ['--ros-args', '-p', f'output_dir:={tmp_path}']
                               if name == 'session_recorder' else [])
            deadline = time.monotonic() + PATIENCE_S
            while not signal_caught(proc.pid, signal.SIGTERM):
                assert proc.poll() is None and time.monotonic() < deadline, procs.log(name)
                time.sleep(0.001)
            # rclpy's extension not mapped yet: the node module is still importing when the signal comes.
            importing[name] = '_rclpy_pybind11' not in Path(f'/proc/{proc.pid}/maps').read_text()
            proc.send_signal(signal.SIGINT)
            time.sleep(0.05)
            proc.send_signal(signal.SIGINT)
        codes = wait_all(procs)
        logs = {n: procs.log(n) for n in procs.procs}
    assert all(importing.values()), importing
    for name in names:
        assert_clean_exit(name, codes[name], logs[name])


@pytest.mark.parametrize('how', ['sigint_thrice', 'sigterm'])
def test_signals_while_the_node_initialises_end_it_cleanly(install_tree, tmp_path, how):
    """Ctrl-C pressed three times (or SIGTERM) once rclpy is loaded: the node is initialising rclpy, building its
    node or starting to spin when the signals come, some of them while it already shuts down. It ends with status 0
    and its FINAL_COUNTERS line all the same."""
    _, env = install_tree
    names = ('crane_model', 'lvdt', 'session_recorder')
    with rosrun.Processes(env, tmp_path / 'logs') as procs:
        for name in names:  # one at a time: each node's initialisation is the window to hit
            proc = procs.start(name, PACKAGE, name, ['--ros-args', '-p', f'output_dir:={tmp_path}']
                               if name == 'session_recorder' else [])
            deadline = time.monotonic() + PATIENCE_S
            while '_rclpy_pybind11' not in Path(f'/proc/{proc.pid}/maps').read_text():
                assert proc.poll() is None and time.monotonic() < deadline, procs.log(name)
                time.sleep(0.001)
            if how == 'sigterm':
                proc.send_signal(signal.SIGTERM)
            else:
                for i in range(3):
                    if i:
                        time.sleep(0.05)
                    if proc.poll() is None:
                        proc.send_signal(signal.SIGINT)
        codes = wait_all(procs)
        logs = {n: procs.log(n) for n in procs.procs}
    for name in names:
        assert_clean_exit(name, codes[name], logs[name])
