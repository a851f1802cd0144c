"""The colcon install tree, checked the way `ros2 run` and `ros2 launch` use it."""
from __future__ import annotations

import importlib
import json
import subprocess
import sys
import time

import pytest
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from helpers import PATIENCE_S, REPO, spin_until
from crane_stiffness.contract import topics
from crane_stiffness.launcher.rig_description import rig_nodes
from crane_stiffness.launcher import rosrun
from crane_stiffness.launcher.rig import start_node
from crane_stiffness.rosnode.qos import RELIABLE_QOS

pytestmark = pytest.mark.ros  # every test here starts ROS (conftest)

# The node executables setup.py installs: nodes_bin/, the one list of the package's nodes.
NODES = sorted(p.name for p in (REPO / 'nodes_bin').iterdir())

EXECUTABLES = sorted(NODES) + ['crane-stiffness']


def test_install_tree_has_index_marker_executables_config_and_launch(install_tree):
    install, env = install_tree
    prefix = install / 'crane_stiffness'
    assert (prefix / 'share/ament_index/resource_index/packages/crane_stiffness').is_file()
    assert (prefix / 'share/crane_stiffness/package.xml').is_file()
    for exe in EXECUTABLES:
        # Exactly what `ros2 run crane_stiffness <exe>` executes.
        assert rosrun.executable_path('crane_stiffness', exe, env['AMENT_PREFIX_PATH']) == \
            prefix / 'lib' / 'crane_stiffness' / exe
    for name in ('crane_lab.yaml', 'program_side_force.yaml', 'program_moment_z.yaml', 'program_force_z.yaml',
                 'program_side_force_slack.yaml', 'sensors.yaml'):
        assert (prefix / 'share/crane_stiffness/config' / name).is_file(), name
    assert (prefix / 'share/crane_stiffness/launch/rig.launch.py').is_file()
    assert (prefix / 'share/crane_stiffness/rosdep/crane_stiffness.yaml').is_file()  # the rosdep keys it ships
    for name in ('stiffness_test.json', 'sensors.json', 'stiffness6.json'):  # the Foxglove layouts, read back
        layout = json.loads((prefix / 'share/crane_stiffness/foxglove' / name).read_text())
        assert layout['configById'] and layout['layout']
    site = next(prefix.glob('lib/python3*/site-packages/crane_stiffness/view/web'))
    assert {p.name for p in site.iterdir()} >= {'index.html', 'app.js', 'style.css'}  # the live view's page
    with pytest.raises(rosrun.RosRunError, match='No executable'):
        rosrun.executable_path('crane_stiffness', 'no_such_node', env['AMENT_PREFIX_PATH'])
    with pytest.raises(rosrun.RosRunError, match='not found'):
        rosrun.executable_path('no_such_package', 'x', env['AMENT_PREFIX_PATH'])


def test_cli_runs_from_the_install_tree_with_installed_config(install_tree):
    _, env = install_tree
    argv = rosrun.command('crane_stiffness', 'crane-stiffness',
                          ['stiffness', '--config', 'crane_lab', '--json'], env, use_ros2_cli=False)
    out = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout)
    assert res['paper_coefficients']['Kj'] == pytest.approx(53793.509, rel=1e-6)  # lab model, h 0.5, W 50
    assert len(res['tangent']) == 6
    # And the module form of the stand-in for `ros2 run`.
    out = subprocess.run([sys.executable, '-m', 'crane_stiffness.launcher.rosrun', 'crane_stiffness', 'crane-stiffness',
                          'solve', '--config', 'crane_lab', '--force', '0', '1', '0', '--json'],
                         env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)['displacement'][1] > 0


def test_node_started_like_ros2_run_answers_over_dds(install_tree, rclpy_context, tmp_path):
    _, env = install_tree
    with rosrun.Processes(env, tmp_path) as procs:
        procs.start('crane_model', 'crane_stiffness', 'crane_model',
                    ['--ros-args', '--params-file', str(install_tree[0] / 'crane_stiffness/share/crane_stiffness'
                                                        '/config/crane_lab.yaml')])
        node = Node('probe_install', context=rclpy_context)
        poses: list[PoseStamped] = []
        node.create_subscription(PoseStamped, topics.PLATFORM_POSE, poses.append, RELIABLE_QOS)
        pub = node.create_publisher(WrenchStamped, topics.WRENCH_COMMAND, RELIABLE_QOS)
        ex = SingleThreadedExecutor(context=rclpy_context)
        ex.add_node(node)
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1, PATIENCE_S), procs.log('crane_model')
        msg = WrenchStamped()
        msg.wrench.force.y = 2.0
        pub.publish(msg)
        assert spin_until(ex, lambda: poses and poses[-1].pose.position.y > 0, PATIENCE_S), procs.log('crane_model')
        assert poses[-1].pose.position.y == pytest.approx(2.0 / 53793.5, rel=2e-3)
        procs.check_alive()
        codes = procs.stop()
    assert codes['crane_model'] == 0, procs.log('crane_model')  # Ctrl-C is a clean exit
    ex.shutdown()


def _message_class(type_name: str):
    """'geometry_msgs/msg/PoseStamped' → the class, as rosidl_runtime_py.utilities.get_message does."""
    package, kind, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


def _echo_qos(node: Node, topic: str) -> QoSProfile:
    """The QoS `ros2 topic echo` picks: reliable / transient local only if every publisher offers it."""
    infos = node.get_publishers_info_by_topic(topic)
    reliable = all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
    latched = all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    return QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def test_every_rig_node_runs_from_the_install_tree_and_its_topics_echo(install_tree, rclpy_context, tmp_path):
    """What `ros2 run crane_stiffness <node>` then `ros2 topic echo --once <topic>` do, for every node of the rig:
    the executable found through the ament index, each topic the node advertises found in the ROS graph, its type
    imported from the advertised type name, a subscription with the QoS echo would choose, one message received."""
    install, env = install_tree
    config = install / 'crane_stiffness/share/crane_stiffness/config'
    params = {n.name: n for n in rig_nodes(config, {'record': False})}  # the launch file's rig, no recorder
    node = Node('probe_echo', context=rclpy_context)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    received: dict[str, object] = {}
    expected = {topics.WRENCH_COMMAND, topics.PLATFORM_POSE, topics.WIRE_STATES, topics.PREDICTED_STIFFNESS,
                topics.PREDICTED_AXIS_STIFFNESS, topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT,
                topics.STIFFNESS_ESTIMATE, topics.STIFFNESS_VALUES, topics.STIFFNESS, topics.PROGRAM_STATE,
                topics.PROGRAM_PROGRESS, topics.DIAGNOSTICS}

    def advertised_now() -> dict[str, str]:
        found: dict[str, str] = {}
        for name in params:
            for topic, types in node.get_publisher_names_and_types_by_node(name, '/'):
                if topic not in ('/rosout', '/parameter_events'):
                    found[topic] = types[0]
        return found

    with rosrun.Processes(env, tmp_path) as procs:
        for name, rig_node in params.items():
            start_node(procs, rig_node, {'start_delay_s': 0.5, 'min_subscribers': 3} if rig_node.runs_program else None)
        assert spin_until(ex, lambda: set(params) <= set(node.get_node_names()), PATIENCE_S), procs.log('load_program')
        # A node's name is discovered apart from its publishers (which can take longer on a busy machine).
        spin_until(ex, lambda: expected <= set(advertised_now()), PATIENCE_S)
        advertised = advertised_now()
        for topic, type_name in advertised.items():
            node.create_subscription(_message_class(type_name), topic,
                                     lambda msg, t=topic: received.setdefault(t, msg), _echo_qos(node, topic))
        deadline = time.monotonic() + PATIENCE_S
        while set(received) < set(advertised) - {topics.REJECTED_COMMAND} and time.monotonic() < deadline:
            procs.check_alive()
            ex.spin_once(timeout_sec=0.05)
        codes = procs.stop()
    ex.shutdown()
    assert expected <= set(advertised), sorted(advertised)
    # /crane/rejected_command carries only commands the model rejects: none in this program.
    assert set(received) == set(advertised) - {topics.REJECTED_COMMAND}, sorted(set(advertised) - set(received))
    assert received[topics.LOAD_CELL_WRENCH].header.frame_id == 'load_cell'
    assert received[topics.PLATFORM_POSE].header.frame_id == topics.FRAME_BASE
    assert all(code == 0 for code in codes.values()), codes
