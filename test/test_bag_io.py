"""Bag I/O: write rig messages serialized by rclpy, read them back with our reader and two independent readers.

Independent readers: ``rosbags`` (AnyReader: metadata.yaml + MCAP, own CDR decoder) and ``mcap_ros2`` (parses the
ros2msg schema text we wrote). Crash safety is checked on a copy cut in the middle of a chunk and on a real writer
process killed with SIGKILL.
"""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(1, 100)))

from crane_stiffness.bag import (  # noqa: E402
    BagCorruptError, BagDamageWarning, BagExistsError, BagFormatError, BagReader, BagWriter, BagWriterError,
    McapFile, TopicNotFoundError, UnsupportedTypeError, dump_qos_profiles, qos_profile, recover_bag,
)
from crane_stiffness.bag.msgdef import SEPARATOR, message_definition, type_description_hash  # noqa: E402
from crane_stiffness.session_record import SESSION_METADATA, read_session, session_metadata  # noqa: E402

rclpy_serialization = pytest.importorskip('rclpy.serialization')
from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64, String  # noqa: E402

serialize = rclpy_serialization.serialize_message

T0 = 1_700_000_000_000_000_000
TOPICS = {
    '/load_cell/wrench': 'geometry_msgs/msg/WrenchStamped',
    '/lvdt/displacement': 'geometry_msgs/msg/PointStamped',
    '/crane/platform_pose': 'geometry_msgs/msg/PoseStamped',
    '/program/setpoint': 'std_msgs/msg/Float64',
    '/crane/winches': 'sensor_msgs/msg/JointState',
}
JOINTS = ['winch_1', 'winch_2', 'winch_3', 'winch_4', 'winch_5', 'winch_6']
RIG = {'wires': 6, 'anchor_radius_m': 1.25, 'platform_radius_m': 0.3}


# ------------------------------------------------------------------------------------------------- helpers --
def _stamp(t_ns: int) -> Time:
    return Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def make_messages(n_fast: int = 1200, n_slow: int = 200, seed: int = 7) -> list[tuple[str, int, object, bytes]]:
    """(topic, log_time_ns, rclpy message, its CDR bytes) in log-time order; random floats.

    Serialized once: rclpy leaves CDR padding bytes uninitialized, so serializing again may differ in them.
    """
    rng = np.random.default_rng(seed)
    out: list[tuple[str, int, object]] = []
    for i in range(n_fast):
        t = T0 + i * 1_000_000
        w = WrenchStamped()
        w.header.stamp = _stamp(t)
        w.header.frame_id = 'load_cell' if i % 7 else 'load_cell_spare'  # two frame_id lengths
        f = rng.normal(size=6) * [50, 50, 900, 3, 3, 0.5]
        w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = map(float, f[:3])
        w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = map(float, f[3:])
        out.append(('/load_cell/wrench', t + 120_000, w))
        p = PointStamped()
        p.header.stamp = _stamp(t + 1)
        p.header.frame_id = 'lvdt'
        p.point.x, p.point.y, p.point.z = map(float, rng.normal(size=3) * 1e-4)
        out.append(('/lvdt/displacement', t + 130_000, p))
        if i % (n_fast // n_slow) == 0:
            q = PoseStamped()
            q.header.stamp = _stamp(t + 2)
            q.header.frame_id = 'world'
            q.pose.position.x, q.pose.position.y, q.pose.position.z = map(float, rng.normal(size=3))
            quat = rng.normal(size=4)
            quat /= np.linalg.norm(quat)
            (q.pose.orientation.x, q.pose.orientation.y, q.pose.orientation.z,
             q.pose.orientation.w) = map(float, quat)
            out.append(('/crane/platform_pose', t + 140_000, q))
            out.append(('/program/setpoint', t + 150_000, Float64(data=float(rng.normal() * 1000))))
            j = JointState()
            j.header.stamp = _stamp(t + 3)
            j.header.frame_id = 'crane'
            j.name = JOINTS
            j.position = [float(x) for x in rng.normal(size=6)]
            j.velocity = [float(x) for x in rng.normal(size=6)]
            j.effort = [float(x) for x in rng.normal(size=6) * 100]
            out.append(('/crane/winches', t + 160_000, j))
    return [(topic, log, msg, serialize(msg)) for topic, log, msg in out]


def values_of(msg_type: str, m) -> tuple:
    """Comparable plain values of a message from rclpy, rosbags or mcap_ros2 (same attribute names)."""
    if msg_type == 'std_msgs/msg/Float64':
        return (float(m.data),)
    head = (int(m.header.stamp.sec), int(m.header.stamp.nanosec), str(m.header.frame_id))
    if msg_type.endswith('WrenchStamped'):
        f, t = m.wrench.force, m.wrench.torque
        return head + tuple(float(v) for v in (f.x, f.y, f.z, t.x, t.y, t.z))
    if msg_type.endswith('PointStamped'):
        return head + (float(m.point.x), float(m.point.y), float(m.point.z))
    if msg_type.endswith('PoseStamped'):
        p, o = m.pose.position, m.pose.orientation
        return head + tuple(float(v) for v in (p.x, p.y, p.z, o.x, o.y, o.z, o.w))
    return head + (tuple(str(x) for x in m.name), tuple(float(x) for x in m.position),
                   tuple(float(x) for x in m.velocity), tuple(float(x) for x in m.effort))


def values_of_row(msg_type: str, row: np.void) -> tuple:
    """The same values from one row of a bulk-decoded array."""
    if msg_type == 'std_msgs/msg/Float64':
        return (float(row['data']),)
    head = (int(row['stamp_sec']), int(row['stamp_nanosec']), row['frame_id'].decode())
    names = {'geometry_msgs/msg/WrenchStamped': ('fx', 'fy', 'fz', 'mx', 'my', 'mz'),
             'geometry_msgs/msg/PointStamped': ('x', 'y', 'z'),
             'geometry_msgs/msg/PoseStamped': ('x', 'y', 'z', 'qx', 'qy', 'qz', 'qw')}.get(msg_type)
    if names:
        return head + tuple(float(row[n]) for n in names)
    return head + (tuple(x.decode() for x in row['name']), tuple(map(float, row['position'])),
                   tuple(map(float, row['velocity'])), tuple(map(float, row['effort'])))


def expected_by_topic(messages) -> dict[str, list[tuple[int, tuple]]]:
    out: dict[str, list[tuple[int, tuple]]] = {t: [] for t in TOPICS}
    for topic, log, msg, _ in messages:
        out[topic].append((log, values_of(TOPICS[topic], msg)))
    return out


def write_bag(path: Path, messages, **options) -> Path:
    with BagWriter(path, metadata={SESSION_METADATA: session_metadata(
            rig=RIG, program={'kind': 'ramp', 'max_load_N': 900}, start_time_ns=T0, notes='test session')},
            **options) as writer:
        for topic, msg_type in TOPICS.items():
            writer.add_topic(topic, msg_type, dump_qos_profiles([qos_profile(depth=100)]))
        for topic, log, _, data in messages:
            writer.write(topic, data, log, log - 50_000)
    return path


def read_with_rosbags(bag: Path) -> dict[str, list[tuple[int, tuple]]]:
    from rosbags.highlevel import AnyReader
    out: dict[str, list[tuple[int, tuple]]] = {}
    with AnyReader([bag]) as reader:
        for connection, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            out.setdefault(connection.topic, []).append((timestamp, values_of(connection.msgtype, msg)))
    return out


def read_with_mcap_ros2(files: list[Path]) -> dict[str, list[tuple[int, tuple]]]:
    from mcap_ros2.reader import read_ros2_messages
    out: dict[str, list[tuple[int, tuple]]] = {}
    for path in files:
        for m in read_ros2_messages(str(path)):
            out.setdefault(m.channel.topic, []).append(
                (m.log_time_ns, values_of(m.schema.name, m.ros_msg)))
    return {t: sorted(v, key=lambda x: x[0]) for t, v in out.items()}


def decoded(reader: BagReader) -> dict[str, list[tuple[int, tuple]]]:
    arrays = reader.decode_topics([t for t in TOPICS if t in reader.topics])
    return {t: [(int(r['log_time_ns']), values_of_row(TOPICS[t], r)) for r in a] for t, a in arrays.items()}


# ------------------------------------------------------------------------------------------------ fixtures --
@pytest.fixture(scope='module')
def messages():
    return make_messages()


@pytest.fixture(scope='module')
def bag(tmp_path_factory, messages) -> Path:
    return write_bag(tmp_path_factory.mktemp('bags') / 'session', messages, chunk_size=16 * 1024)


# ------------------------------------------------------------------------------------------- round trips --
def test_bulk_decode_equals_inputs_exactly(bag, messages):
    expected = expected_by_topic(messages)
    with BagReader(bag) as reader:
        assert reader.complete and not reader.problems
        got = decoded(reader)
        wrench = reader.decode('/load_cell/wrench')
    for topic in TOPICS:
        assert got[topic] == expected[topic], topic
    assert len(wrench) == 1200
    assert wrench.dtype.names == ('log_time_ns', 'stamp_sec', 'stamp_nanosec', 'stamp_s', 'frame_id',
                                  'fx', 'fy', 'fz', 'mx', 'my', 'mz')
    assert set(wrench['frame_id'].tolist()) == {b'load_cell', b'load_cell_spare'}
    np.testing.assert_allclose(wrench['stamp_s'], (T0 + np.arange(1200) * 1_000_000) / 1e9, rtol=0, atol=1e-6)


def test_raw_messages_topics_and_session_metadata(bag, messages):
    with BagReader(bag) as reader:
        raw = list(reader.messages())
        topics = reader.topics
        records = reader.metadata_records()
        session = read_session(reader)
        part = list(reader.messages(['/program/setpoint'], start_ns=T0 + 500_000_000, end_ns=T0 + 900_000_000))
    assert [(m.topic, m.log_time_ns, m.data) for m in raw] == [(t, log, d) for t, log, _, d in messages]
    assert {t: (i.msg_type, i.count) for t, i in topics.items()} == {
        '/load_cell/wrench': ('geometry_msgs/msg/WrenchStamped', 1200),
        '/lvdt/displacement': ('geometry_msgs/msg/PointStamped', 1200),
        '/crane/platform_pose': ('geometry_msgs/msg/PoseStamped', 200),
        '/program/setpoint': ('std_msgs/msg/Float64', 200),
        '/crane/winches': ('sensor_msgs/msg/JointState', 200)}
    assert topics['/load_cell/wrench'].type_description_hash == type_description_hash(
        'geometry_msgs/msg/WrenchStamped')
    assert yaml.safe_load(topics['/load_cell/wrench'].offered_qos_profiles)[0]['depth'] == 100
    assert set(records) == {SESSION_METADATA}
    assert session['rig'] == RIG and session['program'] == {'kind': 'ramp', 'max_load_N': 900}
    assert session['notes'] == 'test session' and session['start_time_ns'] == str(T0)
    assert [m.log_time_ns for m in part] == [T0 + k * 6_000_000 + 150_000 for k in range(84, 150)]


def test_metadata_yaml_is_rosbag2_v9(bag):
    text = (bag / 'metadata.yaml').read_text()
    info = yaml.safe_load(text)['rosbag2_bagfile_information']
    assert list(info) == ['version', 'storage_identifier', 'duration', 'starting_time', 'message_count',
                          'topics_with_message_count', 'compression_format', 'compression_mode',
                          'relative_file_paths', 'files', 'custom_data', 'ros_distro']
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap' and info['ros_distro'] == 'jazzy'
    assert info['message_count'] == 3000
    assert info['starting_time']['nanoseconds_since_epoch'] == T0 + 120_000
    assert info['duration']['nanoseconds'] == 1199 * 1_000_000 + 10_000
    counts = {t['topic_metadata']['name']: t['message_count'] for t in info['topics_with_message_count']}
    assert counts == {'/load_cell/wrench': 1200, '/lvdt/displacement': 1200, '/crane/platform_pose': 200,
                      '/program/setpoint': 200, '/crane/winches': 200}
    meta = info['topics_with_message_count'][0]['topic_metadata']
    assert list(meta) == ['name', 'type', 'serialization_format', 'offered_qos_profiles', 'type_description_hash']
    assert meta['serialization_format'] == 'cdr'
    assert meta['offered_qos_profiles'][0]['reliability'] == 'reliable'
    assert meta['offered_qos_profiles'][0]['deadline'] == {'sec': 9223372036, 'nsec': 854775807}
    assert meta['type_description_hash'].startswith('RIHS01_') and len(meta['type_description_hash']) == 71
    assert info['relative_file_paths'] == ['session_0.mcap']
    assert info['files'] == [{'path': 'session_0.mcap', 'starting_time': info['starting_time'],
                              'duration': info['duration'], 'message_count': 3000}]
    assert info['compression_format'] == '' and info['custom_data'] is None
    assert '\n    - topic_metadata:\n        name: /load_cell/wrench\n' in text  # yaml-cpp layout


def test_mcap_profile_schema_and_channels(bag):
    with McapFile(bag / 'session_0.mcap') as f:
        assert f.complete
        schemas = {s.name: s for s in f.schemas.values()}
        channels = {c.topic: c for c in f.channels.values()}
        assert len(f.chunks) > 5 and {c.compression for c in f.chunks} == {'zstd'}
    assert set(schemas) == set(TOPICS.values())
    assert {s.encoding for s in schemas.values()} == {'ros2msg'}
    assert {c.message_encoding for c in channels.values()} == {'cdr'}
    assert set(channels['/lvdt/displacement'].metadata) == {'offered_qos_profiles', 'topic_type_hash'}
    text = schemas['geometry_msgs/msg/WrenchStamped'].data.decode()
    share = Path(os.environ['AMENT_PREFIX_PATH'].split(os.pathsep)[0]) / 'share'
    parts = text.split('\n' + SEPARATOR + '\n')
    assert parts[0] == (share / 'geometry_msgs/msg/WrenchStamped.msg').read_text()
    assert [p.split('\n', 1)[0] for p in parts[1:]] == [
        'MSG: geometry_msgs/Wrench', 'MSG: geometry_msgs/Vector3', 'MSG: std_msgs/Header',
        'MSG: builtin_interfaces/Time']
    assert parts[2].split('\n', 1)[1] == (share / 'geometry_msgs/msg/Vector3.msg').read_text()


def test_rosbags_reads_every_message(bag, messages):
    assert read_with_rosbags(bag) == expected_by_topic(messages)


def test_mcap_ros2_reads_every_message(bag, messages):
    assert read_with_mcap_ros2([bag / 'session_0.mcap']) == expected_by_topic(messages)


# -------------------------------------------------------------------------------- options and splitting --
@pytest.mark.parametrize('compression', ['none', 'lz4', 'zstd'])
def test_compression(tmp_path, compression):
    msgs = make_messages(n_fast=300, n_slow=30, seed=3)
    path = write_bag(tmp_path / 'c', msgs, compression=compression, chunk_size=8 * 1024)
    with McapFile(path / 'c_0.mcap') as f:
        assert {c.compression for c in f.chunks} == {'' if compression == 'none' else compression}
    with BagReader(path) as reader:
        assert decoded(reader) == expected_by_topic(msgs)
    assert read_with_mcap_ros2([path / 'c_0.mcap']) == expected_by_topic(msgs)


def test_split_by_size_and_duration(tmp_path, messages):
    by_size = write_bag(tmp_path / 'big', messages, split_max_bytes=40_000, chunk_size=8 * 1024)
    by_time = write_bag(tmp_path / 'timed', messages, split_max_duration_s=0.25)
    expected = expected_by_topic(messages)
    for path in (by_size, by_time):
        info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        names = [f'{path.name}_{i}.mcap' for i in range(len(info['files']))]
        assert info['relative_file_paths'] == names == sorted(p.name for p in path.glob('*.mcap'))
        assert sum(f['message_count'] for f in info['files']) == info['message_count'] == 3000
        with BagReader(path) as reader:
            assert decoded(reader) == expected
            assert len(list(reader.messages())) == 3000
        assert read_with_rosbags(path) == expected
    assert len(list(by_size.glob('*.mcap'))) >= 3
    timed = yaml.safe_load((by_time / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert len(timed['files']) == 5  # 1.2 s of data, a new file every 0.25 s
    assert all(f['duration']['nanoseconds'] < 250_000_000 for f in timed['files'])
    with BagReader(by_time) as reader:  # the session record is repeated in every file
        assert read_session(reader)['rig'] == RIG
        for path in reader.files:
            with McapFile(path) as f:
                assert SESSION_METADATA in dict(f.metadata)


def test_flush_interval_puts_slow_topics_on_disk(tmp_path):
    writer = BagWriter(tmp_path / 'slow', chunk_size=1 << 20, flush_interval_s=0.5)
    writer.add_topic('/program/setpoint', 'std_msgs/msg/Float64')
    for i in range(40):
        writer.write('/program/setpoint', serialize(Float64(data=float(i))), T0 + i * 100_000_000)
    with pytest.warns(BagDamageWarning, match='truncated or unfinished'):
        with BagReader(tmp_path / 'slow' / 'slow_0.mcap') as reader:
            on_disk = reader.decode('/program/setpoint')['data']
    writer.close()
    assert len(on_disk) >= 30 and np.array_equal(on_disk, np.arange(len(on_disk), dtype=float))


def test_chunk_indexes_wait_on_disk_so_memory_stays_flat(tmp_path):
    """A chunk every 0.5 s all day: the writer keeps each chunk's index on disk until the summary (the library kept
    ~2 KB of objects per chunk in memory, 15 MB per hour); the file's summary holds every chunk index, as the
    library writes it, and an independent reader finds every message through them."""
    import tracemalloc
    from mcap.reader import make_reader
    from crane_stiffness.bag.index_spool import ChunkIndexSpool
    data = serialize(Float64(data=1.0))

    def write_chunks(writer: BagWriter, first: int, n: int) -> None:
        for i in range(first, first + n):
            writer.write('/program/setpoint', data, T0 + i * 1000)
            writer._file.mcap.flush()  # one chunk per message, as flush_interval_s does on a slow topic

    writer = BagWriter(tmp_path / 'day', chunk_size=1 << 20)
    writer.add_topic('/program/setpoint', 'std_msgs/msg/Float64')
    assert isinstance(writer._file.index_spool, ChunkIndexSpool)
    write_chunks(writer, 0, 500)  # warm-up
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    write_chunks(writer, 500, 4000)
    grown = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    assert len(writer._file.index_spool) == 4500
    assert grown < 100_000, f'{grown} bytes kept for 4,000 chunks'   # the library's list: ~8 MB
    writer.close()
    with open(tmp_path / 'day' / 'day_0.mcap', 'rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert len(summary.chunk_indexes) == 4500 and summary.statistics.chunk_count == 4500
        offsets = [c.chunk_start_offset for c in summary.chunk_indexes]
        assert offsets == sorted(offsets) and all(c.message_index_offsets for c in summary.chunk_indexes)
        assert sum(1 for _ in reader.iter_messages()) == 4500


# ------------------------------------------------------------------------------------------ crash safety --
def test_truncated_copy_reads_complete_chunks_and_recovers(tmp_path, bag, messages):
    source = bag / 'session_0.mcap'
    with McapFile(source) as f:
        chunks = f.chunks
        per_chunk = [sum(len(m) for m in f.chunk_messages(c, f.chunk_data(c)).values()) for c in chunks]
    cut_chunk = chunks[len(chunks) // 2]
    cut_at = cut_chunk.records_offset + cut_chunk.compressed_size // 2  # inside that chunk
    damaged = tmp_path / 'crashed'
    damaged.mkdir()
    (damaged / 'crashed_0.mcap').write_bytes(source.read_bytes()[:cut_at])  # no summary, no metadata.yaml
    readable = sum(per_chunk[:len(chunks) // 2])
    assert 0 < readable < 3000
    expected = expected_by_topic(messages[:readable])

    with pytest.warns(BagDamageWarning, match='truncated or unfinished'):
        with BagReader(damaged) as reader:
            assert not reader.complete and reader.message_count == readable
            assert decoded(reader) == expected
            assert read_session(reader)['rig'] == RIG

    report = recover_bag(damaged)
    # whole blocks of the cut chunk that are on disk are saved too (none when the chunk is one zstd block)
    saved = report.message_count
    assert report.ok and saved == readable + report.files[0].partial_messages
    expected = expected_by_topic(messages[:saved])
    assert [f.status for f in report.files] == ['recovered']
    assert report.files[0].backup.name == 'crashed_0.mcap.bak' and report.files[0].bytes_ignored > 0
    assert 'recovered' in str(report) and report.metadata_path == damaged / 'metadata.yaml'
    info = yaml.safe_load(report.metadata_path.read_text())['rosbag2_bagfile_information']
    assert info['message_count'] == saved and info['relative_file_paths'] == ['crashed_0.mcap']
    with warnings.catch_warnings():
        warnings.simplefilter('error', BagDamageWarning)
        with BagReader(damaged) as reader:
            assert reader.complete and decoded(reader) == expected
            assert read_session(reader)['rig'] == RIG
    assert read_with_rosbags(damaged) == expected
    assert read_with_mcap_ros2([damaged / 'crashed_0.mcap']) == expected
    again = recover_bag(damaged)  # idempotent: the file is now intact
    assert [f.status for f in again.files] == ['intact'] and again.message_count == saved


KILL_SCRIPT = textwrap.dedent('''
    import struct, sys, time
    from crane_stiffness.bag import BagWriter
    T0 = 1_700_000_000_000_000_000

    def wrench(i):  # WrenchStamped, frame_id "load_cell", fx = i, fz = -2 i (same layout rclpy produces)
        return (b"\\x00\\x01\\x00\\x00" + struct.pack("<iII", i // 1000, (i % 1000) * 1000000, 10)
                + b"load_cell\\x00\\x00\\x00" + struct.pack("<6d", i, 0.5, -2.0 * i, 0.0, 0.0, 1.0))

    writer = BagWriter(sys.argv[1], chunk_size=4096)
    writer.add_topic("/load_cell/wrench", "geometry_msgs/msg/WrenchStamped")
    for i in range(5_000_000):
        writer.write("/load_cell/wrench", wrench(i), T0 + i * 1000000)
        if i == 3000:
            print("ready", flush=True)
        if i > 3000 and i % 200 == 0:
            time.sleep(0.001)
''')


def test_real_sigkill_then_read_and_recover(tmp_path):
    bag_dir = tmp_path / 'killed'
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, '-c', KILL_SCRIPT, str(bag_dir)], stdout=subprocess.PIPE, env=env)
    try:
        assert proc.stdout.readline().strip() == b'ready'
        time.sleep(0.3)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    assert not (bag_dir / 'metadata.yaml').exists()

    with pytest.warns(BagDamageWarning, match='truncated or unfinished'):
        with BagReader(bag_dir) as reader:
            arr = reader.decode('/load_cell/wrench')
    n = len(arr)
    assert n >= 3000 - 60  # everything but the last unfinished chunk (~56 messages of 4 KiB)
    assert np.array_equal(arr['fx'], np.arange(n, dtype=float))
    assert np.array_equal(arr['fz'], -2.0 * np.arange(n))
    assert np.array_equal(arr['log_time_ns'], T0 + np.arange(n) * 1_000_000)
    assert np.array_equal(arr['stamp_nanosec'], (np.arange(n) % 1000) * 1_000_000)

    result = subprocess.run([sys.executable, '-m', 'crane_stiffness.bag.recover', str(bag_dir)],
                            capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == 0, result.stderr
    info = yaml.safe_load((bag_dir / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    saved = info['message_count']
    assert n <= saved <= n + 60  # plus any whole block of a chunk cut by the kill
    assert 'recovered' in result.stdout and f'{saved} messages' in result.stdout
    rosbags_read = read_with_rosbags(bag_dir)['/load_cell/wrench']
    assert [v[3] for _, v in rosbags_read] == list(map(float, range(saved)))
    assert len(read_with_mcap_ros2([bag_dir / 'killed_0.mcap'])['/load_cell/wrench']) == saved


# ------------------------------------------------------------------------------------- damage and errors --
def test_corrupt_chunk_is_reported_and_skipped(tmp_path, bag, messages):
    data = bytearray((bag / 'session_0.mcap').read_bytes())
    with McapFile(bag / 'session_0.mcap') as f:
        victim = f.chunks[3]
    middle = victim.records_offset + victim.compressed_size // 2
    data[middle:middle + 64] = bytes(64)
    damaged = tmp_path / 'damaged'
    damaged.mkdir()
    shutil.copy(bag / 'metadata.yaml', damaged / 'metadata.yaml')
    (damaged / 'session_0.mcap').write_bytes(bytes(data))

    with pytest.warns(BagDamageWarning, match=f'chunk at offset {victim.offset}'):
        with BagReader(damaged) as reader:
            got = decoded(reader)
    expected = expected_by_topic(messages)
    total = sum(len(v) for v in got.values())
    assert 2500 < total < 3000  # one chunk's messages are missing, nothing else
    for topic, rows in got.items():
        assert set(rows) <= set(expected[topic])  # no garbage

    with pytest.raises(BagCorruptError, match='chunk at offset'):
        with BagReader(damaged, strict=True) as reader:
            reader.decode('/load_cell/wrench')

    report = recover_bag(damaged, backup=False)  # a finished file with a bad chunk is rewritten too
    assert [f.status for f in report.files] == ['recovered'] and report.message_count == total
    assert any(f'chunk at offset {victim.offset}' in p for p in report.files[0].problems)
    assert not (damaged / 'session_0.mcap.bak').exists()
    assert read_with_rosbags(damaged) == got


def test_not_an_mcap_file_and_damaged_metadata_yaml(tmp_path, bag):
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'this is not an mcap file at all')
    with pytest.raises(BagFormatError, match='not an MCAP file'):
        BagReader(junk)
    copy = tmp_path / 'copy'
    shutil.copytree(bag, copy)
    (copy / 'metadata.yaml').write_text('rosbag2_bagfile_information: [unclosed')
    with pytest.warns(BagDamageWarning, match='metadata.yaml is unreadable'):
        with BagReader(copy) as reader:
            assert reader.message_count == 3000


def test_missing_topic_names_the_topics_present(bag):
    with BagReader(bag) as reader:
        with pytest.raises(TopicNotFoundError) as info:
            reader.decode('/load_cel/wrench')
    text = str(info.value)
    assert "'/load_cel/wrench'" in text and '/load_cell/wrench [geometry_msgs/msg/WrenchStamped]' in text
    assert '/crane/winches [sensor_msgs/msg/JointState]' in text


def test_unsupported_type_and_joint_state_without_arrays(tmp_path):
    with BagWriter(tmp_path / 'misc') as writer:
        writer.add_topic('/note', 'std_msgs/msg/String')
        writer.add_topic('/winches', 'sensor_msgs/msg/JointState')
        writer.write('/note', serialize(String(data='hello')), T0)
        for i in range(3):
            j = JointState(name=JOINTS, position=[float(i + k) for k in range(6)])
            if i == 1:
                j.effort = [1.5] * 6
            writer.write('/winches', serialize(j), T0 + i)
    with BagReader(tmp_path / 'misc') as reader:
        with pytest.raises(UnsupportedTypeError, match='std_msgs/msg/String'):
            reader.decode('/note')
        assert [m.data for m in reader.messages(['/note'])] == [serialize(String(data='hello'))]
        js = reader.decode('/winches')
    assert js['name'].tolist() == [[n.encode() for n in JOINTS]] * 3
    assert np.array_equal(js['position'], np.arange(3)[:, None] + np.arange(6)[None, :])
    assert np.isnan(js['velocity']).all()
    assert np.isnan(js['effort'][[0, 2]]).all() and np.array_equal(js['effort'][1], [1.5] * 6)


def test_writer_misuse(tmp_path):
    with BagWriter(tmp_path / 'w') as writer:
        with pytest.raises(BagWriterError, match='was not added'):
            writer.write('/nope', b'\x00\x01\x00\x00', T0)
        with pytest.raises(BagWriterError, match='compression'):
            BagWriter(tmp_path / 'other', compression='gzip')
    with pytest.raises(BagWriterError, match='closed'):
        writer.write('/nope', b'', T0)
    with pytest.raises(BagExistsError):
        BagWriter(tmp_path / 'w')


def test_qos_profiles_in_integer_form_are_normalized(tmp_path):
    humble_style = '- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: 9223372036\n' \
                   '    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: 1\n' \
                   '  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n' \
                   '  avoid_ros_namespace_conventions: false'
    with BagWriter(tmp_path / 'q') as writer:
        writer.add_topic('/setpoint', 'std_msgs/msg/Float64', humble_style)
    info = yaml.safe_load((tmp_path / 'q' / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    qos = info['topics_with_message_count'][0]['topic_metadata']['offered_qos_profiles'][0]
    assert (qos['history'], qos['reliability'], qos['durability'], qos['liveliness']) == (
        'unknown', 'reliable', 'volatile', 'automatic')


def test_message_definition_rules(tmp_path):
    share = tmp_path / 'share' / 'rig_msgs' / 'msg'
    share.mkdir(parents=True)
    (share / 'Sample.msg').write_text('Header header\nPoint[] points\nstring<=8 tag\nwstring w\nuint8 A=1\n')
    (share / 'Point.msg').write_text('float64 x\n')
    prefixes = [Path(p) for p in os.environ['AMENT_PREFIX_PATH'].split(os.pathsep) if p]  # a sourced ROS adds more
    text = message_definition('rig_msgs/msg/Sample', [tmp_path, *prefixes])
    headers = [line for line in text.split('\n') if line.startswith('MSG: ')]
    assert headers == ['MSG: rig_msgs/Point', 'MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time']
    assert text.startswith('Header header\n') and f'\n\n{SEPARATOR}\nMSG: rig_msgs/Point\nfloat64 x\n' in text


def test_reader_works_without_ros(bag):
    code = textwrap.dedent(f'''
        import sys
        sys.modules["rclpy"] = None  # any import of rclpy now fails
        from crane_stiffness.bag import BagReader
        with BagReader({str(bag)!r}) as reader:
            arrays = reader.decode_topics(["/load_cell/wrench", "/crane/winches"])
        assert "rclpy" not in sys.modules or sys.modules["rclpy"] is None
        print(len(arrays["/load_cell/wrench"]), len(arrays["/crane/winches"]))
    ''')
    env = {k: v for k, v in os.environ.items() if not k.startswith(('AMENT', 'ROS'))}
    env['PYTHONPATH'] = str(REPO)
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ['1200', '200']
