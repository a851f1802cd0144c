"""load_program with the load applied by an operator (load_application operator): it tares at the unloaded state
through the services it is given, holds at each new level until ~/confirm is called or the measured load settles
there, and keeps who confirmed what and the tare's answers in its state (which the recorder keeps); refused on
simulated time. Real rclpy, the node in this process, a probe node standing in for the sensor and the operator."""
from __future__ import annotations

import json

import pytest
import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import String
from std_srvs.srv import Trigger

from helpers import PATIENCE_S, call_trigger, publish_wrench_now, spin_until
from crane_stiffness.contract import topics
from crane_stiffness.nodes.load_program import LoadProgramNode
from crane_stiffness.rosnode.qos import LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS

pytestmark = pytest.mark.ros


def program_params(**extra) -> list[Parameter]:
    # Step fy to 1.5 N, hold; ramp back to 0 and hold: two levels to confirm (the step's, the ramp's end).
    params = {'segments.kind': ['step', 'ramp', 'hold'], 'segments.axis': ['fy', 'fy', 'fy'],
              'segments.target': [1.5, 0.0, 0.0], 'segments.duration': [0.3, 0.3, 0.2], 'rate_hz': 100.0,
              'name': 'two_levels', 'start_delay_s': 0.2, 'wait_for_messages': [''], 'wait_for_subscribers': [''],
              'load_application': 'operator', 'operator': 'alice', **extra}
    return [Parameter(k, value=v) for k, v in params.items()]


def test_operator_levels_confirmed_by_a_call_and_by_the_measured_load_after_the_tare(rclpy_context):
    ex = SingleThreadedExecutor(context=rclpy_context)
    probe = rclpy.create_node('operator_probe', context=rclpy_context)
    states: list[dict] = []
    commands: list[float] = []
    probe.create_subscription(String, topics.PROGRAM_STATE, lambda m: states.append(json.loads(m.data)), LATCHED_QOS)
    probe.create_subscription(WrenchStamped, topics.WRENCH_COMMAND, lambda m: commands.append(m.wrench.force.y),
                              RELIABLE_QOS)
    sensor = probe.create_publisher(WrenchStamped, topics.LOAD_CELL_WRENCH, SENSOR_QOS)
    tared = []

    def tare(request, response):
        tared.append(len(commands))  # commands sent before the tare: none may have been a load
        response.success, response.message = True, 'tared on 100 samples: offset fy = 0.0421 N'
        return response
    probe.create_service(Trigger, '/test_cell/tare', tare)
    prog = LoadProgramNode(context=rclpy_context, parameter_overrides=program_params(
        tare_services=['/test_cell/tare'], operator_settle_s=0.5, operator_tolerance=0.05))
    ex.add_node(prog)
    ex.add_node(probe)
    try:
        # The tare comes first, before any command; then the first level is asked for and the program holds there.
        assert spin_until(ex, lambda: states and states[-1]['state'] == 'waiting', PATIENCE_S), states[-3:]
        assert tared == [0]
        prompt = states[-1]['prompt']
        assert (prompt['level'], prompt['of'], prompt['axis'], prompt['value'], prompt['unit']) == (1, 2, 'fy', 1.5,
                                                                                                    'N')
        assert prompt['text'] == 'level 1/2: set fy = 1.5 N (every other axis unloaded)'
        tare_entry = states[-1]['tare'][0]
        assert tare_entry['service'] == '/test_cell/tare' and tare_entry['success'] and tare_entry['by'] == 'alice'
        assert 'offset fy = 0.0421 N' in tare_entry['message']
        # Held: commands keep coming at the level, the program time does not move (however long the wait).
        n = len(commands)
        assert spin_until(ex, lambda: len(commands) > n + 50, PATIENCE_S)
        assert set(commands[n:]) == {1.5}
        assert states[-1]['state'] == 'waiting' and states[-1]['time_s'] == 0.0
        # A measured load away from the level confirms nothing; the call does.
        publish_wrench_now(probe, sensor, [0, 0.5, 0, 0, 0, 0])
        answer = call_trigger(ex, probe, '/load_program/confirm')
        assert answer.success and 'level 1/2 (fy = 1.5) confirmed (service ~/confirm)' == answer.message
        # The ramp back to 0: at its end the program waits again; the measured load settling at 0 confirms it.
        assert spin_until(ex, lambda: states[-1]['state'] == 'waiting' and states[-1]['prompt']['level'] == 2,
                          PATIENCE_S), states[-3:]
        assert states[-1]['time_s'] == pytest.approx(0.6, abs=1e-9)

        def settle() -> bool:
            publish_wrench_now(probe, sensor, [0, 0.03, 0, 0, 0, 0])  # within 0.05 N of 0
            ex.spin_once(timeout_sec=0.05)
            return states[-1]['state'] in ('running', 'done')
        assert spin_until(ex, settle, PATIENCE_S), states[-3:]
        assert spin_until(ex, lambda: states[-1]['state'] == 'done', PATIENCE_S)
        confirmed = states[-1]['confirmed']
        assert [c['how'] for c in confirmed] == ['service ~/confirm',
                                                 'measured fy settled within 0.05 N for 0.5 s']
        assert [(c['level'], c['value'], c['by']) for c in confirmed] == [(1, 1.5, 'alice'), (2, 0.0, 'alice')]
        assert states[-1]['tare'] == [tare_entry] and states[-1]['load_application'] == 'operator'
        # Nothing left to confirm.
        assert not call_trigger(ex, probe, '/load_program/confirm').success
    finally:
        ex.shutdown()
        prog.destroy_node()
        probe.destroy_node()


def test_a_tare_that_fails_stops_the_program_before_any_load(rclpy_context):
    ex = SingleThreadedExecutor(context=rclpy_context)
    probe = rclpy.create_node('sensor_probe', context=rclpy_context)
    states: list[dict] = []
    probe.create_subscription(String, topics.PROGRAM_STATE, lambda m: states.append(json.loads(m.data)), LATCHED_QOS)

    def refuse(request, response):
        response.success, response.message = False, f'cannot tare: {topics.WAITING_FOR_LOAD}'
        return response
    probe.create_service(Trigger, '/test_cell/tare', refuse)
    prog = LoadProgramNode(context=rclpy_context, parameter_overrides=program_params(
        load_application='actuator', tare_services=['/test_cell/tare'], min_subscribers=0))
    ex.add_node(prog)
    ex.add_node(probe)
    try:
        assert spin_until(ex, lambda: getattr(prog, 'exit_requested', False), PATIENCE_S)
        assert prog.exit_status == 1 and prog.state == 'stopped'
        assert spin_until(ex, lambda: states and states[-1]['state'] == 'stopped', PATIENCE_S)
        assert 'cannot tare' in states[-1]['tare'][-1]['failed']
        assert prog.counters.published == 0  # no command ever went out
    finally:
        ex.shutdown()
        prog.destroy_node()
        probe.destroy_node()


def test_operator_and_tare_refused_on_simulated_time(rclpy_context):
    with pytest.raises(Exception, match='load_application = .?operator.?: needs wall-clock time'):
        LoadProgramNode(context=rclpy_context, parameter_overrides=program_params(use_sim_time=True,
                                                                                  autostart=False))
