"""A session stopped from outside says so: the recorder stopped by a ~/stop service call in the middle of the program
(as any ROS client, or a page through the live view, can call it) closes a valid bag whose session record says why it
stopped, when and who asked (``stopped_by``: a ROS service client, or the live view's WebSocket client with its
address and Origin); the rig's summary names the early stop, and the demo's verdict refuses the session for it. The
same rig left alone gives a whole bag and no problem."""
from __future__ import annotations

import importlib.util

import pytest

import re

from crane_stiffness.bag import BagReader
from crane_stiffness.contract.control_events import ROS_CALLER
from crane_stiffness.launcher.ports import free_port
from crane_stiffness.bag.session_metadata import cut_short, read_session_end
from crane_stiffness.launcher import rosrun
from crane_stiffness.launcher.rig import run_rig
from helpers import REPO, call_trigger
from helpers.foxglove_client import FoxgloveClient

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
    end = _check_cut(summary, tmp_path / 'bags' / 'cut', re.escape(ROS_CALLER))
    assert end['stopped_by'] == ROS_CALLER  # a plain Trigger call names no caller: said so


def _check_cut(summary: dict, bag, by: str) -> dict:
    """The summary and the bag of a session stopped from outside by ``by`` (a regular expression); its end record."""
    problem = summary['recording']['problem']
    assert summary['recording']['stop_reason'] == 'service'
    assert re.search(r'stopped from outside \(a ~/stop service call by ' + by + r'\)', problem), problem
    assert 'not the whole run' in problem
    assert problem in _verdict()(summary, 0.02)  # the demo exits non-zero, naming it
    with BagReader(bag) as reader:  # a valid bag, closed cleanly, saying why it stopped and who stopped it
        end = read_session_end(reader)
        wrenches = sum(1 for _ in reader.messages(['/load_cell/wrench']))
    assert end['stop_reason'] == 'service' and cut_short(end) == problem
    assert re.fullmatch(by, end['stopped_by']), end
    assert 0 < wrenches < 5000  # about a third of the program's 5.8 s at 1 kHz
    return end


def _run_with_view(share, env: dict, out, view: dict, progress) -> tuple[dict, dict[str, str]]:
    """The side-force campaign rig on simulated time with the live view (``view``: its parameters), the program
    played to its end as run_rig plays it (which starts no view): (summary, each node's log)."""
    import rclpy
    from crane_stiffness.launcher.domains import claim_domain, with_claim
    from crane_stiffness.launcher.rig import (Observer, start_rig, summarize, wait_for_program_end,
                                              wait_for_program_start)
    claim = claim_domain(int(env.get('ROS_DOMAIN_ID', 0) or 0), 'rig cut through the view', env=env)
    env = with_claim(env, claim.domain)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=claim.domain)
    observer = Observer('rig_observer', context=ctx)
    try:
        with rosrun.Processes(env, out / 'logs') as procs:
            program = start_rig(procs, share, 'campaign_side_force', 'cut', out / 'bags', arguments=SIM,
                                overrides={'live_view': view}, live_view=True)
            wait_for_program_start(observer, procs, 150.0)
            wait_for_program_end(procs, observer, program.duration_s, progress)
            observer.settle()
            codes = procs.stop()
            observer.drain()
            logs = {name: procs.log(name) for name in procs.procs}
        return summarize(share, 'campaign_side_force', 'cut', out / 'bags', observer, codes), logs
    finally:
        observer.destroy_node()
        rclpy.shutdown(context=ctx)
        claim.release()


def test_a_recording_stopped_through_the_live_view_names_its_client(install_tree, tmp_path):
    """A page (of the view's own origin, with the token) stops the recording through the live view's WebSocket:
    the session end names that client, its address and its Origin, and the recorder's log says so."""
    install, env = install_tree
    share = rosrun.installed_config(install)
    port, http_port, token = free_port(), free_port(), 'a-token-for-this-test-only'
    origin = f'http://127.0.0.1:{http_port}'
    answers = []

    def midway(fraction: float) -> None:
        if fraction >= 0.3 and not answers:
            client = FoxgloveClient(port, token=token, origin=origin)
            try:
                answers.append(client.call('/session_recorder/stop', 'json', b'{}', 1))
            finally:
                client.close()
    summary, logs = _run_with_view(share, env, tmp_path, {'port': port, 'http_port': http_port, 'token': token},
                                   midway)
    assert answers and b'"success": true' in answers[0][1], answers
    by = (r"the live view's WebSocket client 127\.0\.0\.1:\d+ \(Origin " + re.escape(origin)
          + r'\) \(through /live_view\)')
    end = _check_cut(summary, tmp_path / 'bags' / 'cut', by)
    assert f"(service by {end['stopped_by']})" in logs['session_recorder'], logs['session_recorder'][-2000:]
    client = end['stopped_by'].split('client ', 1)[1].split(' (through')[0]
    assert f'called through the WebSocket by {client}: success=True' in logs['live_view'], logs['live_view'][-2000:]
