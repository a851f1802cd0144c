"""Bag I/O: write rig messages serialized by rclpy, read them back with our reader and two independent readers.

Independent readers: ``rosbags`` (AnyReader: metadata.yaml + MCAP, own CDR decoder) and ``mcap_ros2`` (parses the
ros2msg schema text we wrote). Crash safety and damage: test_bag_damage.py.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from crane_stiffness.bag import (
    BagDamageWarning, BagReader, BagWriter, McapFile,
)
from crane_stiffness.bag.msgdef import SEPARATOR, type_description_hash
from crane_stiffness.bag.session_metadata import SESSION_METADATA, read_session

from std_msgs.msg import Float64

from helpers.bags import (RIG, T0, TOPICS, decoded, expected_by_topic, make_messages, serialize,
                          read_with_mcap_ros2, read_with_rosbags, write_bag)


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
