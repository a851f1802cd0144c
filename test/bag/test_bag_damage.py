"""Bag I/O under damage: a copy cut in the middle of a chunk, a real writer process killed with SIGKILL, a corrupt
chunk, a file that is not MCAP, damaged metadata, misuse, and the reader without ROS."""
from __future__ import annotations

import os
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

from crane_stiffness.bag import (
    BagCorruptError, BagDamageWarning, BagExistsError, BagFormatError, BagReader, BagWriter, BagWriterError,
    McapFile, TopicNotFoundError, UnsupportedTypeError, recover_bag,
)
from crane_stiffness.bag.msgdef import SEPARATOR, message_definition
from crane_stiffness.bag.session_metadata import read_session

from sensor_msgs.msg import JointState
from std_msgs.msg import String

from helpers import PATIENCE_S, REPO, run_without_ros
from helpers.bags import (JOINTS, RIG, T0, decoded, expected_by_topic, read_with_mcap_ros2, read_with_rosbags,
                          serialize)


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
        proc.wait(timeout=PATIENCE_S)
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
                            capture_output=True, text=True, env=env, timeout=PATIENCE_S)
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
    result = run_without_ros(f'''
        from crane_stiffness.bag import BagReader
        with BagReader({str(bag)!r}) as reader:
            arrays = reader.decode_topics(["/load_cell/wrench", "/crane/winches"])
        print(len(arrays["/load_cell/wrench"]), len(arrays["/crane/winches"]))
    ''')
    assert result.stdout.split() == ['1200', '200']
