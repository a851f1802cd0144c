"""session_recorder: real rclpy and DDS on loopback, bags read back by independent readers (rosbags, mcap_ros2).

In process: every rig topic recorded with its QoS (a latched value published before the recorder started included),
the session metadata, stop at the program's end, the ~/start and ~/stop services. As processes started like
``ros2 run`` from the colcon install tree: SIGINT and SIGTERM close the bag (metadata.yaml written); after SIGKILL
all but the unfinished chunk is readable and ``crane-stiffness recover`` repairs the bag.
"""
from __future__ import annotations

import json
import os
import signal
import time
import warnings
from pathlib import Path

import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped, WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger

from helpers import PATIENCE_S, REPO, collect_for, spin_until
from crane_stiffness.contract import topics
from crane_stiffness.launcher import rosrun
from crane_stiffness.bag import BagDamageWarning, BagReader
from crane_stiffness.cli.main import main as cli_main
from crane_stiffness.rosnode.qos import KEPT_QOS, LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS
from crane_stiffness.nodes.session_recorder import SESSION_END_METADATA, SessionRecorder
from crane_stiffness.bag.session_metadata import read_session

pytestmark = pytest.mark.ros  # every test here starts ROS (conftest)

NS = 1_000_000_000


def stamp(msg, ns: int):
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, NS)
    return msg


def wrench(ns: int, fy: float) -> WrenchStamped:
    m = stamp(WrenchStamped(), ns)
    m.header.frame_id = 'load_cell'
    m.wrench.force.y = fy
    return m


def read_rosbags(bag: Path) -> dict[str, list]:
    from rosbags.highlevel import AnyReader
    out: dict[str, list] = {}
    with AnyReader([bag]) as reader:
        for connection, timestamp, raw in reader.messages():
            out.setdefault(connection.topic, []).append((timestamp, reader.deserialize(raw, connection.msgtype)))
    return out


def read_mcap_ros2(bag: Path) -> dict[str, list]:
    from mcap_ros2.reader import read_ros2_messages
    out: dict[str, list] = {}
    for path in sorted(bag.glob('*.mcap')):
        for m in read_ros2_messages(str(path)):
            out.setdefault(m.channel.topic, []).append(m)
    return out


class Publisher:
    """The rig's topics, published by a test node with the rig's QoS."""

    def __init__(self, ctx):
        self.node = Node('rig_publisher', context=ctx)
        n = self.node
        self.pubs = {
            topics.LOAD_CELL_WRENCH: n.create_publisher(WrenchStamped, topics.LOAD_CELL_WRENCH, SENSOR_QOS),
            topics.LVDT_DISPLACEMENT: n.create_publisher(PointStamped, topics.LVDT_DISPLACEMENT, SENSOR_QOS),
            topics.WRENCH_COMMAND: n.create_publisher(WrenchStamped, topics.WRENCH_COMMAND, RELIABLE_QOS),
            topics.WIRE_STATES: n.create_publisher(JointState, topics.WIRE_STATES, RELIABLE_QOS),
            topics.PREDICTED_STIFFNESS: n.create_publisher(Float64MultiArray, topics.PREDICTED_STIFFNESS,
                                                           LATCHED_QOS),
            topics.PROGRAM_STATE: n.create_publisher(String, topics.PROGRAM_STATE, LATCHED_QOS),
            topics.STIFFNESS_ESTIMATE: n.create_publisher(DiagnosticArray, topics.STIFFNESS_ESTIMATE, KEPT_QOS),
        }

    def matched(self, count: int = 1) -> bool:
        return all(p.get_subscription_count() >= count for p in self.pubs.values())


def test_records_every_rig_topic_with_metadata_readable_by_independent_readers(rclpy_context, tmp_path):
    ctx = rclpy_context
    sensors = tmp_path / 'sensors.yaml'
    sensors.write_text(yaml.safe_dump({
        'load_cell': {'ros__parameters': {'sample_rate_hz': 1000.0, 'noise_std': [0.01] * 6}},
        'lvdt': {'ros__parameters': {'axis': [0.0, 1.0, 0.0], 'contact_point': [0.0, 0.0, 0.0]}},
        'stiffness_estimator': {'ros__parameters': {'window': 300, 'force_axis': 'fy', 'slop_s': 0.0004}}}))
    files = [str(REPO / 'config' / 'crane_lab.yaml'), str(sensors), str(REPO / 'config' / 'program_side_force.yaml')]
    ex = SingleThreadedExecutor(context=ctx)
    pub = Publisher(ctx)
    ex.add_node(pub.node)
    latched = Float64MultiArray(data=[float(i) for i in range(36)])
    pub.pubs[topics.PREDICTED_STIFFNESS].publish(latched)  # before the recorder exists: transient local
    recorder = SessionRecorder(params_files=files, context=ctx, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path / 'bags')), Parameter('session', value='inproc'),
        Parameter('geometry.weight', value=42.0), Parameter('notes', value='operator: test rig'),
        Parameter('stop_delay_s', value=0.3), Parameter('flush_interval_s', value=0.2)])
    ex.add_node(recorder)
    assert spin_until(ex, pub.matched, PATIENCE_S)
    sent: dict[str, list] = {t: [] for t in pub.pubs}
    sent[topics.PREDICTED_STIFFNESS].append(latched)

    def publish(topic, msg):
        pub.pubs[topic].publish(msg)
        sent[topic].append(msg)

    publish(topics.PROGRAM_STATE, String(data=json.dumps({'program': 'side_force', 'state': 'running'})))
    t0 = 1_700_000_000 * NS
    for i in range(200):
        publish(topics.LOAD_CELL_WRENCH, wrench(t0 + i * 1_000_000, 0.01 * i))
        p = stamp(PointStamped(), t0 + i * 1_000_000)
        p.point.x = 1e-6 * i
        publish(topics.LVDT_DISPLACEMENT, p)
        if i % 4 == 0:
            publish(topics.WRENCH_COMMAND, wrench(t0 + i * 1_000_000, 0.01 * i))
        if i % 20 == 0:
            j = stamp(JointState(), t0 + i * 1_000_000)
            j.name = [f'wire_{k}' for k in range(1, 7)]
            j.position = [0.5 + k * 1e-3 for k in range(6)]
            j.effort = [8.0 + i * 1e-2] * 6
            publish(topics.WIRE_STATES, j)
            d = DiagnosticArray()
            d.header.stamp.sec = 1_700_000_000 + i
            d.status = [DiagnosticStatus(level=b'\x00', name='estimator: loading', message=f'k = {i}')]
            publish(topics.STIFFNESS_ESTIMATE, d)
        ex.spin_once(timeout_sec=0.001)
    expected = {t: len(v) for t, v in sent.items()}
    assert spin_until(ex, lambda: all(recorder.channels[t].count >= n for t, n in expected.items()), PATIENCE_S), \
        {t: recorder.channels[t].count for t in expected}
    publish(topics.PROGRAM_STATE, String(data=json.dumps({'program': 'side_force', 'state': 'done'})))
    expected[topics.PROGRAM_STATE] += 1
    assert spin_until(ex, lambda: not recorder.recording, PATIENCE_S)  # stopped 0.3 s after 'done'
    bag = tmp_path / 'bags' / 'inproc'
    # Per topic, naming who publishes it: a message more than was sent can only come from another node in this
    # test's domain (seen once at high load, 475 for 473, before the counts were compared per topic).
    recorded = {t: c.count for t, c in recorder.channels.items() if c.count}
    assert recorded == expected, {t: (recorded.get(t), expected.get(t), [
        f'{i.node_namespace.rstrip("/")}/{i.node_name}' for i in pub.node.get_publishers_info_by_topic(t)])
        for t in set(recorded) | set(expected) if recorded.get(t) != expected.get(t)}
    assert recorder.last_bag == bag and recorder.last_count == sum(expected.values())
    ex.shutdown()

    # crane_stiffness.bag: counts, QoS and the session description
    with BagReader(bag) as reader:
        info = reader.topics
        assert {t: i.count for t, i in info.items()} == expected
        qos = {t: yaml.safe_load(i.offered_qos_profiles)[0] for t, i in info.items()}
        assert qos[topics.LOAD_CELL_WRENCH]['reliability'] == 'best_effort'
        assert qos[topics.WRENCH_COMMAND]['reliability'] == 'reliable'
        assert qos[topics.PREDICTED_STIFFNESS]['durability'] == 'transient_local'
        assert info[topics.LOAD_CELL_WRENCH].type_description_hash.startswith('RIHS01_')
        session = read_session(reader)
        end = reader.metadata_records()[SESSION_END_METADATA]
        forces = reader.decode(topics.LOAD_CELL_WRENCH)
    assert forces['fy'].tolist() == [m.wrench.force.y for m in sent[topics.LOAD_CELL_WRENCH]]
    assert forces['frame_id'].astype(str).tolist() == ['load_cell'] * 200
    assert session['rig']['geometry']['geometry.weight'] == 42.0
    assert session['rig']['geometry']['geometry.a'] == pytest.approx(0.1143)
    assert session['rig']['l0'] == pytest.approx(0.517126, rel=1e-5)
    assert session['program']['name'] == 'side_force' and len(session['program']['segments.kind']) == 21
    assert session['program']['source'] == 'parameter file section load_program'
    assert session['sensors']['stiffness_estimator']['window'] == 300
    assert session['sensors']['lvdt']['axis'] == [0.0, 1.0, 0.0]
    assert 'load_program' not in session['sensors'] and '/**' not in session['sensors']
    assert session['notes'] == 'operator: test rig' and session['software_version'] == '0.1.0'
    assert int(session['start_time_ns']) > 1_600_000_000 * NS and session['session'] == 'inproc'
    assert [Path(f['path']).name for f in session['config_files']] == ['crane_lab.yaml', 'sensors.yaml',
                                                                       'program_side_force.yaml']
    assert end['stop_reason'] == 'program done' and json.loads(end['message_count']) == sum(expected.values())

    # rosbags: metadata.yaml + MCAP + its own CDR decoder, every message
    got = read_rosbags(bag)
    assert {t: len(v) for t, v in got.items()} == expected
    assert [m.wrench.force.y for _, m in got[topics.LOAD_CELL_WRENCH]] == \
        [m.wrench.force.y for m in sent[topics.LOAD_CELL_WRENCH]]
    assert [m.point.x for _, m in got[topics.LVDT_DISPLACEMENT]] == \
        [m.point.x for m in sent[topics.LVDT_DISPLACEMENT]]
    assert [list(m.effort) for _, m in got[topics.WIRE_STATES]] == [list(m.effort) for m in sent[topics.WIRE_STATES]]
    assert [s.message for _, m in got[topics.STIFFNESS_ESTIMATE] for s in m.status] == \
        [s.message for m in sent[topics.STIFFNESS_ESTIMATE] for s in m.status]
    assert list(got[topics.PREDICTED_STIFFNESS][0][1].data) == list(latched.data)
    assert [m.data for _, m in got[topics.PROGRAM_STATE]] == [m.data for m in sent[topics.PROGRAM_STATE]]

    # mcap_ros2: publish time = header stamp for stamped types, the receive (log) time otherwise
    got = read_mcap_ros2(bag)
    assert {t: len(v) for t, v in got.items()} == expected
    for m, original in zip(got[topics.LOAD_CELL_WRENCH], sent[topics.LOAD_CELL_WRENCH]):
        s = original.header.stamp
        assert m.publish_time_ns == s.sec * NS + s.nanosec and m.log_time_ns > m.publish_time_ns
        assert m.ros_msg.wrench.force.y == original.wrench.force.y
    assert all(m.publish_time_ns == m.log_time_ns for m in got[topics.PROGRAM_STATE])


def test_start_and_stop_services(rclpy_context, tmp_path):
    ctx = rclpy_context
    ex = SingleThreadedExecutor(context=ctx)
    recorder = SessionRecorder(context=ctx, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path)), Parameter('session', value='svc'),
        Parameter('autostart', value=False), Parameter('topics', value=[topics.WRENCH_COMMAND])])
    client_node = Node('svc_client', context=ctx)
    pub = client_node.create_publisher(WrenchStamped, topics.WRENCH_COMMAND, RELIABLE_QOS)
    start = client_node.create_client(Trigger, '/session_recorder/start')
    stop = client_node.create_client(Trigger, '/session_recorder/stop')
    ex.add_node(recorder)
    ex.add_node(client_node)

    def call(client):
        assert spin_until(ex, client.service_is_ready, PATIENCE_S)
        future = client.call_async(Trigger.Request())
        assert spin_until(ex, future.done, PATIENCE_S)
        return future.result()

    assert not recorder.recording and not any(tmp_path.iterdir())
    res = call(stop)
    assert not res.success and res.message == 'not recording'
    for session, n in (('svc', 5), ('svc_2', 7)):
        res = call(start)
        assert res.success and res.message == f'recording to {tmp_path / session}'
        assert not call(start).success  # already recording
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1, PATIENCE_S)
        for i in range(n):
            pub.publish(wrench(1_700_000_000 * NS + i, float(i)))
        assert spin_until(ex, lambda: recorder.channels[topics.WRENCH_COMMAND].count == n, PATIENCE_S)
        res = call(stop)
        assert res.success and res.message == f'closed {tmp_path / session}: {n} messages'
        assert spin_until(ex, lambda: pub.get_subscription_count() == 0, PATIENCE_S)  # unsubscribed while idle
        with BagReader(tmp_path / session) as reader:
            assert reader.topics[topics.WRENCH_COMMAND].count == n and reader.complete
    ex.shutdown()


# ------------------------------------------------------------------------------------------ as processes --
def _recorder_args(share: Path, out: Path, session: str, *extra: str) -> list[str]:
    return ['--ros-args', '--params-file', str(share / 'crane_lab.yaml'), '--params-file',
            str(share / 'program_side_force.yaml'), '-p', f'session:={session}', '-p', f'output_dir:={out}',
            '-p', 'notes:=signal test', *extra]


def _newest_sensor_stamp_on_disk(bag: Path) -> float | None:
    """The newest load-cell stamp [s] in the bag a recorder is writing now (its finished chunks), or None."""
    if not any(bag.glob('*.mcap')):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', BagDamageWarning)  # being written: the last chunk unfinished
        with BagReader(bag) as reader:
            if topics.LOAD_CELL_WRENCH not in reader.topics:
                return None
            stamps = reader.decode(topics.LOAD_CELL_WRENCH)['stamp_s']
    return float(stamps.max()) if stamps.size else None


def test_sigint_sigterm_close_the_bag_and_sigkill_leaves_a_recoverable_one(install_tree, rclpy_context, tmp_path):
    install, env = install_tree
    share = rosrun.installed_config(install)
    out = tmp_path / 'bags'
    ctx = rclpy_context
    node = Node('signal_test_publisher', context=ctx)
    cmd = node.create_publisher(WrenchStamped, topics.WRENCH_COMMAND, RELIABLE_QOS)
    sensor = node.create_publisher(WrenchStamped, topics.LOAD_CELL_WRENCH, SENSOR_QOS)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    state = node.create_publisher(String, topics.PROGRAM_STATE, LATCHED_QOS)
    names = {'int': signal.SIGINT, 'term': signal.SIGTERM, 'kill': signal.SIGKILL}
    # Each recorder's own account on /diagnostics (all four are /session_recorder: told apart by their bag's name).
    reports: dict[str, dict[str, str]] = {}

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if values.get('bag'):
                reports[Path(values['bag']).name] = values

    node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_diagnostics, 10)
    with rosrun.Processes(env, tmp_path / 'logs') as procs:
        for name in names:
            procs.start(name, 'crane_stiffness', 'session_recorder',
                        _recorder_args(share, out, name, '-p', 'stop_on_program_done:=false'))
        # a fourth one records the whole program and exits by itself at its end
        procs.start('done', 'crane_stiffness', 'session_recorder', _recorder_args(
            share, out, 'done', '-p', 'stop_delay_s:=2.0', '-p', 'exit_on_program_done:=true', '-p',
            'executor:=single'))
        ok = spin_until(ex, lambda: cmd.get_subscription_count() >= 4 and sensor.get_subscription_count() >= 4
                        and state.get_subscription_count() >= 4, PATIENCE_S)
        assert ok, {n: procs.log(n)[-1500:] for n in procs.procs}
        state.publish(String(data=json.dumps({'program': 'side_force', 'state': 'running'})))
        t0 = 1_700_000_000 * NS
        for i in range(300):  # 1.5 s of commands, reliable: every recorder gets every one
            cmd.publish(wrench(t0 + i * 5_000_000, float(i)))
            collect_for(ex, 0.005)  # the pace of the commands
        # Signal only once every recorder says it has written all 300 (a starved one may still have them queued:
        # what is queued in DDS when a signal comes is not the recorder's to keep; what it received is).
        recorders = (*names, 'done')
        assert spin_until(ex, lambda: all(reports.get(n, {}).get(topics.WRENCH_COMMAND) == '300' for n in recorders),
                          PATIENCE_S), {n: reports.get(n, {}).get(topics.WRENCH_COMMAND) for n in recorders}
        procs.check_alive()
        state.publish(String(data=json.dumps({'program': 'side_force', 'state': 'done'})))
        for name in ('int', 'term'):
            os.killpg(procs.procs[name].pid, names[name])
        # The third keeps recording a 1 kHz sensor stream, and is killed while it does: once its bag on disk holds
        # a second of it (it finishes a chunk every 0.5 s of log time; a starved recorder later).
        start_s = (t0 + 10 * NS) * 1e-9
        on_disk_before = None
        deadline = time.monotonic() + PATIENCE_S
        i = 0
        while (on_disk_before is None or on_disk_before < start_s + 1.0) and time.monotonic() < deadline:
            sensor.publish(wrench(t0 + 10 * NS + i * 1_000_000, 1.0))
            i += 1
            if i % 10 == 0:
                time.sleep(0.01)
            if i % 250 == 0:
                on_disk_before = _newest_sensor_stamp_on_disk(out / 'kill')
        assert on_disk_before is not None and on_disk_before >= start_s + 1.0, (on_disk_before, procs.log('kill'))
        os.killpg(procs.procs['kill'].pid, signal.SIGKILL)
        for name in procs.procs:
            procs.procs[name].wait(timeout=PATIENCE_S)
        codes = {name: p.returncode for name, p in procs.procs.items()}
        logs = {name: procs.log(name) for name in procs.procs}
    assert codes == {'int': 0, 'term': 0, 'kill': -signal.SIGKILL, 'done': 0}, logs
    assert "program 'side_force' done: closing the bag in 2 s" in logs['done']

    for name in ('int', 'term', 'done'):  # closed cleanly: metadata.yaml, finished files, every command
        bag = out / name
        meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        counts = {t['topic_metadata']['name']: t['message_count'] for t in meta['topics_with_message_count']}
        assert counts[topics.WRENCH_COMMAND] == 300, logs[name]
        with warnings.catch_warnings():
            warnings.simplefilter('error', BagDamageWarning)
            with BagReader(bag) as reader:
                assert reader.complete
                assert reader.decode(topics.WRENCH_COMMAND)['fy'].tolist() == [float(i) for i in range(300)]
                session = read_session(reader)
                assert reader.metadata_records()[SESSION_END_METADATA]['stop_reason'] == \
                    ('program done' if name == 'done' else 'shutdown')
        assert session['program']['name'] == 'side_force' and session['notes'] == 'signal test'
        assert len(read_rosbags(bag)[topics.WRENCH_COMMAND]) == 300
        assert 'closed' in logs[name]

    bag = out / 'kill'  # killed: no metadata.yaml, the last chunk cut; the rest readable
    assert not (bag / 'metadata.yaml').exists()
    with pytest.warns(BagDamageWarning, match='truncated or unfinished'):
        with BagReader(bag) as reader:
            assert reader.decode(topics.WRENCH_COMMAND)['fy'].tolist() == [float(i) for i in range(300)]
            stamps = reader.decode(topics.LOAD_CELL_WRENCH)['stamp_s']
    # What was on disk before the kill is still there.
    assert stamps.size and stamps.max() >= on_disk_before, (stamps.max(), on_disk_before)
    assert cli_main(['recover', str(bag)]) == 0
    assert (bag / 'metadata.yaml').is_file()
    with warnings.catch_warnings():
        warnings.simplefilter('error', BagDamageWarning)
        with BagReader(bag) as reader:
            assert reader.complete
            recovered = {t: i.count for t, i in reader.topics.items()}
            assert read_session(reader)['notes'] == 'signal test'
    assert recovered[topics.WRENCH_COMMAND] == 300 and recovered[topics.LOAD_CELL_WRENCH] >= stamps.size
    assert {t: len(v) for t, v in read_rosbags(bag).items()} == recovered
    assert {t: len(v) for t, v in read_mcap_ros2(bag).items()} == recovered
