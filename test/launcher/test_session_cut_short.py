"""A session stopped from outside says so: the recorder stopped by a ~/stop service call in the middle of the program
(as any ROS client, or a page through the live view, can call it) closes a valid bag whose session record says why it
stopped and when; the rig's summary names the early stop, and the demo's verdict refuses the session for it. The
same rig left alone gives a whole bag and no problem."""
from __future__ import annotations

import importlib.util

import pytest

from crane_stiffness.bag import BagReader
from crane_stiffness.bag.session_metadata import cut_short, read_session_end
from crane_stiffness.launcher import rosrun
from crane_stiffness.launcher.rig import run_rig
from helpers import REPO, call_trigger

pytestmark = pytest.mark.ros
SIM = {'use_sim_time': 'true', 'real_time_factor': '1.0'}


def _verdict():
    """scripts/demo.py's verdict on a run's summary."""
    spec = importlib.util.spec_from_file_location('crane_stiffness_demo', REPO / 'scripts' / 'demo.py')
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.verdict


def test_a_recording_stopped_from_outside_is_named_and_the_run_refused(install_tree, tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    install, env = install_tree
    share = rosrun.installed_config(install)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    stranger = rclpy.create_node('someone_on_the_network', context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(stranger)
    answers = []

    def midway(fraction: float) -> None:  # the program's progress, as the rig reports it
        if fraction >= 0.3 and not answers:
            answers.append(call_trigger(executor, stranger, '/session_recorder/stop'))
    try:
        summary, _, _, _ = run_rig(share, env, tmp_path, 'campaign_side_force', session='cut', arguments=SIM,
                                   progress=midway)
    finally:
        executor.shutdown()
        stranger.destroy_node()
        rclpy.shutdown(context=ctx)
    assert answers and answers[0].success, answers
    problem = summary['recording']['problem']
    assert summary['recording']['stop_reason'] == 'service'
    assert 'stopped from outside (a ~/stop service call)' in problem and 'not the whole run' in problem
    assert problem in _verdict()(summary, 0.02)  # the demo exits non-zero, naming it
    with BagReader(tmp_path / 'bags' / 'cut') as reader:  # a valid bag, closed cleanly, saying why it stopped
        end = read_session_end(reader)
        wrenches = sum(1 for _ in reader.messages(['/load_cell/wrench']))
    assert end['stop_reason'] == 'service' and cut_short(end) == problem
    assert 0 < wrenches < 5000  # about a third of the program's 5.8 s at 1 kHz


def test_a_whole_session_has_no_problem(install_tree, tmp_path):
    install, env = install_tree
    summary, _, _, _ = run_rig(rosrun.installed_config(install), env, tmp_path, 'campaign_side_force',
                               session='whole', arguments={'use_sim_time': 'true', 'real_time_factor': 'max'})
    assert summary['recording'] == {'stop_reason': 'program done', 'complete': 'true', 'problem': ''}
    assert _verdict()(summary, 0.02) == ''
