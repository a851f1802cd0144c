"""The README's `ros2` lines with the genuine ros2 command line (ros2cli, launch, launch_ros), as a ROS user runs them.

A ROS user has `ros2` on PATH from a sourced setup file, then sources the workspace's setup on top: these tests find
`ros2` on PATH (conftest.GENUINE_CLI) and run it over the session's colcon workspace. Without it they do not run and
the test run says so in one line (conftest). Nothing here imitates launch or launch_ros.

Ctrl-C in a terminal sends SIGINT to the whole foreground process group, `ros2 launch` and every node it started;
launch then forwards SIGINT once more to each node. Every node must end with exit status 0, no traceback, and the
session bag closed.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest
from rclpy.executors import SingleThreadedExecutor

from crane_stiffness.params.files import ParamFile
from crane_stiffness.launcher.rig_description import rig_nodes
from crane_stiffness.launcher.rig import Observer, decode_values
from crane_stiffness.launcher.rosrun import command, installed_config
from crane_stiffness.nodes.stiffness_estimator import VALUE_FIELDS
from helpers import PATIENCE_S, collect_for, spin_until
from helpers.processes import UNCLEAN, assert_bag_complete

pytestmark = [pytest.mark.genuine_cli, pytest.mark.ros]

#: launch's own lines about each process it ran: '[INFO] [crane_model-1]: process has finished cleanly [pid 12]'.
FINISHED = re.compile(r'\[(?P<name>[a-z_]+)-\d+\]: process has finished cleanly')
DIED = re.compile(r'\[(?P<name>[a-z_]+)-\d+\]: process has died \[pid \d+, exit code (?P<code>-?\d+)')
STARTED = re.compile(r'\[(?P<name>[a-z_]+)-\d+\]: process started with pid')


class Launch:
    """`ros2 launch crane_stiffness rig.launch.py ARGS` in a process group of its own, as in a terminal."""

    def __init__(self, env: dict[str, str], cwd: Path, *arguments: str) -> None:
        self.log_path = cwd / 'launch.log'
        with open(self.log_path, 'w') as log:
            self.proc = subprocess.Popen(['ros2', 'launch', 'crane_stiffness', 'rig.launch.py', *arguments],
                                         env=env, cwd=cwd, stdout=log, stderr=subprocess.STDOUT,
                                         stdin=subprocess.DEVNULL, process_group=0)

    @property
    def output(self) -> str:
        return self.log_path.read_text(errors='replace')

    def ctrl_c(self, timeout_s: float = PATIENCE_S) -> int:
        """SIGINT to the whole group (launch forwards it once more itself); launch's exit status."""
        os.killpg(self.proc.pid, signal.SIGINT)
        try:
            return self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
            raise AssertionError(f'ros2 launch still running {timeout_s:.0f} s after Ctrl-C:\n{self.output[-4000:]}')

    def kill(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()


def assert_every_node_ended_cleanly(output: str, expected: set[str]) -> None:
    """launch started ``expected`` and says each finished cleanly (exit 0); nothing unclean was printed."""
    started = set(STARTED.findall(output))
    assert started == expected, (sorted(started), output[-4000:])
    died = DIED.findall(output)
    assert not died, (died, output[-6000:])
    assert set(FINISHED.findall(output)) == expected, output[-6000:]
    for sign in UNCLEAN:
        assert sign not in output, f'{sign!r} in the launch output:\n{output[-6000:]}'


def watch(ctx) -> tuple[Observer, SingleThreadedExecutor]:
    observer = Observer(context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(observer)
    return observer, ex


def test_show_args_prints_readable_defaults(install_tree):
    _, env = install_tree
    out = subprocess.run(['ros2', 'launch', 'crane_stiffness', 'rig.launch.py', '--show-args'], env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    for name in ('program', 'crane', 'sensors', 'record', 'transport', 'drivers', 'machine'):
        assert f"'{name}':" in out.stdout, out.stdout
    assert "(default: 'crane_lab.yaml')" in out.stdout and "(default: 'side_force')" in out.stdout, out.stdout
    assert 'Substitution' not in out.stdout and 'PathJoin' not in out.stdout, out.stdout


@pytest.mark.parametrize('transport, sim_time', [('sim', 'false'), ('drivers', 'false'), ('sim', 'true')])
def test_launch_side_force_gives_the_prediction_and_one_ctrl_c_ends_every_node(install_tree, rclpy_context,
                                                                                 tmp_path, transport, sim_time):
    """The README's `ros2 launch crane_stiffness rig.launch.py program:=side_force` (and transport:=drivers, and
    use_sim_time:=true): the program runs, the loading estimate is within 2 % of the prediction, one Ctrl-C ends every
    process with exit status 0, and the bag is complete."""
    install, env = install_tree
    nodes = {n.name for n in rig_nodes(installed_config(install), {'transport': transport, 'use_sim_time': sim_time})}
    launch = Launch(env, tmp_path, 'program:=side_force', f'transport:={transport}', f'use_sim_time:={sim_time}',
                    'session:=genuine')
    observer, ex = watch(rclpy_context)
    try:
        deadline = time.monotonic() + 150
        while not observer.done:
            assert launch.proc.poll() is None, launch.output[-6000:]
            assert time.monotonic() < deadline, f'program not done, progress {observer.progress}:\n' + \
                launch.output[-6000:]
            collect_for(ex, 0.2)
        # The estimator publishes after every batch of pairs: its values once it has fitted two seconds past the end
        # of the program (stamps on this host's clock; on simulated time, once every node has published through the
        # run's end), however late a loaded machine delivers them.
        newest = VALUE_FIELDS.index('sample_stamp')
        through = time.time() + 2.0
        spin_until(ex, lambda: observer.values is not None and observer.predicted is not None and (
            observer.sim_ended if sim_time == 'true' else observer.values.data[newest] >= through), PATIENCE_S)
        assert observer.values is not None and observer.predicted is not None
        loading = decode_values(observer.values)['loading']
        error = (loading['stiffness'] - observer.predicted) / observer.predicted
        print(f'{transport}: loading {loading["stiffness"]:.1f} N/m (95 % {loading["ci95_low"]:.1f} .. '
              f'{loading["ci95_high"]:.1f}, {loading["n"]:.0f} pairs), prediction {observer.predicted:.1f} N/m, '
              f'{100 * error:+.2f} %, statuses {observer.statuses}')
        assert abs(error) < 0.02, (loading, observer.predicted, observer.statuses)
    finally:
        ex.shutdown()
        observer.destroy_node()
        code = launch.ctrl_c() if launch.proc.poll() is None else launch.proc.returncode
        launch.kill()
    assert code == 0, launch.output[-6000:]
    assert_every_node_ended_cleanly(launch.output, nodes)
    assert assert_bag_complete(tmp_path / 'bags' / 'genuine') > 10_000


@pytest.mark.parametrize('after_s', [0.3, 2.0])
def test_ctrl_c_during_start_up_ends_every_node_cleanly(install_tree, tmp_path, after_s):
    """Ctrl-C while the rig starts: 0.3 s after launch started every process (interpreters starting, modules
    importing), 2 s after (nodes up, the program waiting for the rig). (A signal within the first millisecond of a
    process, before its sh prologue ignores it, would still end it: no person presses Ctrl-C that fast.)"""
    install, env = install_tree
    nodes = {n.name for n in rig_nodes(installed_config(install), {})}
    launch = Launch(env, tmp_path, 'program:=side_force', 'session:=early')
    try:
        deadline = time.monotonic() + PATIENCE_S
        while set(STARTED.findall(launch.output)) != nodes:
            assert launch.proc.poll() is None and time.monotonic() < deadline, launch.output[-4000:]
            time.sleep(0.02)
        time.sleep(after_s)
        code = launch.ctrl_c()
    finally:
        launch.kill()
    assert code == 0, launch.output[-6000:]
    assert_every_node_ended_cleanly(launch.output, nodes)


def test_launch_ros_writes_parameter_dicts_our_reader_reads(install_tree, monkeypatch, tmp_path):
    """The real round trip: launch_ros's own code turns each parameter dict of the launch file into its temporary
    params file; every node's reader (crane_stiffness.params.files) reads back the values given."""
    from launch import LaunchContext
    from launch_ros.actions import Node

    install, env = install_tree
    monkeypatch.setenv('AMENT_PREFIX_PATH', env['AMENT_PREFIX_PATH'])
    context = LaunchContext()
    for given in ({}, {'program': 'moment_z'}, {'program': 'force_z', 'session': 'a: b'}, {'transport': 'drivers'}):
        for start in rig_nodes(installed_config(install), given):
            if not start.parameters:
                continue
            node = Node(package='crane_stiffness', executable=start.executable, name=start.name,
                        parameters=[start.parameters])
            # What Node.execute does before it starts the process: substitutions, then each parameter dict
            # written to its temporary params file (the path it passes with --params-file).
            node._perform_substitutions(context)
            written = [p for p, is_file in node._Node__expanded_parameter_arguments if is_file]
            assert len(written) == 1, written
            path = Path(written[0])
            try:
                read = ParamFile.read(path)
                assert read.params(read.sections) == {k: list(v) if isinstance(v, (list, tuple)) else v
                                                      for k, v in start.parameters.items()}, path.read_text()
            finally:
                path.unlink()


def test_ros2_run_a_node_and_ctrl_c(install_tree, tmp_path):
    """`ros2 run crane_stiffness crane_model --ros-args --params-file .../crane_lab.yaml` (docs/running.md), then
    Ctrl-C in its terminal: the node says what it runs, then ends with its counters, and `ros2 run` exits 0."""
    install, env = install_tree
    argv = command('crane_stiffness', 'crane_model',
                   ['--ros-args', '--params-file', str(installed_config(install) / 'crane_lab.yaml')],
                   env, use_ros2_cli=True)
    assert argv[:2] == ['ros2', 'run']
    log = tmp_path / 'run.log'
    with open(log, 'w') as out:
        proc = subprocess.Popen(argv, env=env, cwd=tmp_path, stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, process_group=0)
    try:
        deadline = time.monotonic() + PATIENCE_S
        while 'geometry: a = ' not in log.read_text():
            assert proc.poll() is None and time.monotonic() < deadline, log.read_text()[-3000:]
            time.sleep(0.1)
        os.killpg(proc.pid, signal.SIGINT)
        code = proc.wait(PATIENCE_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    text = log.read_text()
    assert code == 0, text[-3000:]
    assert 'FINAL_COUNTERS crane_model' in text, text[-3000:]
    for sign in UNCLEAN:
        assert sign not in text, text[-3000:]


def test_launch_with_live_view_serves_the_page_and_ends_cleanly(install_tree, tmp_path):
    """`ros2 launch crane_stiffness rig.launch.py live_view:=true view_port:=P view_http_port:=H`: the view starts
    with the ports given (integers through launch_ros), serves the page and names the WebSocket port in it, and
    one Ctrl-C ends every node cleanly."""
    import json
    import urllib.request

    from crane_stiffness.launcher.ports import free_port
    install, env = install_tree
    port, http_port = free_port(), free_port()
    nodes = {n.name for n in rig_nodes(installed_config(install), {'live_view': 'true', 'record': 'false'})}
    assert 'live_view' in nodes
    launch = Launch(env, tmp_path, 'live_view:=true', 'record:=false', f'view_port:={port}',
                    f'view_http_port:={http_port}')
    try:
        deadline = time.monotonic() + PATIENCE_S
        while f'Foxglove ws://127.0.0.1:{port}' not in launch.output:
            assert launch.proc.poll() is None and time.monotonic() < deadline, launch.output[-6000:]
            time.sleep(0.2)
        with urllib.request.urlopen(f'http://127.0.0.1:{http_port}/', timeout=PATIENCE_S) as page:
            assert b'<canvas id="xy"' in page.read()
        with urllib.request.urlopen(f'http://127.0.0.1:{http_port}/config.json', timeout=PATIENCE_S) as config:
            assert json.loads(config.read())['ws_port'] == port
        while set(STARTED.findall(launch.output)) != nodes:
            assert time.monotonic() < deadline, launch.output[-6000:]
            time.sleep(0.2)
        code = launch.ctrl_c()
    finally:
        launch.kill()
    assert code == 0, launch.output[-6000:]
    assert_every_node_ended_cleanly(launch.output, nodes)


def test_a_recording_stopped_from_outside_ends_the_launch_non_zero_naming_it(install_tree, tmp_path):
    """`ros2 service call /session_recorder/stop` during a launched session (anyone on the domain can): the bag is
    closed cleanly and says who stopped it; at Ctrl-C the recorder exits with status 3 and `ros2 launch` with 1,
    naming the cut recording, while every other node still ends cleanly."""
    install, env = install_tree
    nodes = {n.name for n in rig_nodes(installed_config(install), {'use_sim_time': 'true'})}
    launch = Launch(env, tmp_path, 'program:=side_force', 'use_sim_time:=true', 'session:=cut')
    try:
        deadline = time.monotonic() + PATIENCE_S
        while "started 'side_force' at simulated time" not in launch.output:  # the program runs: a cut, not a start
            assert launch.proc.poll() is None and time.monotonic() < deadline, launch.output[-6000:]
            time.sleep(0.2)
        stop = subprocess.run(['ros2', 'service', 'call', '/session_recorder/stop', 'std_srvs/srv/Trigger'],
                              env=env, capture_output=True, text=True, timeout=PATIENCE_S)
        assert stop.returncode == 0 and 'success=True' in stop.stdout, stop.stdout + stop.stderr
    finally:
        code = launch.ctrl_c() if launch.proc.poll() is None else launch.proc.returncode
        launch.kill()
    output = launch.output
    assert code == 1, output[-6000:]
    assert 'session_recorder exited with status 3: its recording was stopped from outside' in output, output[-6000:]
    died = dict(DIED.findall(output))
    assert died == {'session_recorder': '3'}, (died, output[-6000:])
    assert set(FINISHED.findall(output)) == nodes - {'session_recorder'}, output[-6000:]
    from crane_stiffness.bag import BagReader
    from crane_stiffness.bag.session_metadata import cut_short, read_session_end
    with BagReader(tmp_path / 'bags' / 'cut') as reader:
        end = read_session_end(reader)
    assert 'stopped from outside' in cut_short(end) and 'a ROS service client' in end['stopped_by'], end
