"""rosbag2's other storage and compressions: sqlite3 (.db3, every schema version, metadata.yaml versions 4-9) and
zstd per file (``.mcap.zstd``/``.db3.zstd``) or per message, written by the independent ``rosbags`` writer or laid out
here as rosbag2's older versions did; read exactly by BagReader (messages, bulk decode, topics). Files that are
neither storage, and compressions that cannot be read, are refused naming the file."""
from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
import yaml
import zstandard

from crane_stiffness.bag import BagFormatError, BagReader, BagUnsupportedError, Sqlite3File
from crane_stiffness.bag.msgdef import message_definition

from helpers.bags import TOPICS, make_messages, values_of, values_of_row

MESSAGES = make_messages(n_fast=120, n_slow=20)
EXPECTED = sorted(((t, log, data) for t, log, _, data in MESSAGES), key=lambda m: m[1])
QOS = '- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n'


def assert_exact(path: Path, *, qos: bool = True) -> None:
    with BagReader(path) as reader:
        assert not reader.problems
        assert [(m.topic, m.log_time_ns, m.data) for m in reader.messages()] == EXPECTED
        topics = reader.topics
        arrays = reader.decode_topics(list(TOPICS))
        window = [m.log_time_ns for m in reader.messages(['/crane/winches'], start_ns=EXPECTED[50][1],
                                                         end_ns=EXPECTED[250][1])]
    assert {t: (i.msg_type, i.count) for t, i in topics.items()} == {
        t: (ty, sum(1 for m in EXPECTED if m[0] == t)) for t, ty in TOPICS.items()}
    assert all(i.message_encoding == 'cdr' for i in topics.values())
    if qos:
        assert all('history' in i.offered_qos_profiles for i in topics.values())
    for topic, msg_type in TOPICS.items():
        want = [(log, values_of(msg_type, msg)) for t, log, msg, _ in sorted(MESSAGES, key=lambda m: m[1])
                if t == topic]
        assert [(int(r['log_time_ns']), values_of_row(msg_type, r)) for r in arrays[topic]] == want, topic
    assert window == [log for t, log, _ in EXPECTED[50:250] if t == '/crane/winches']


# ------------------------------------------------------------------------------------- the rosbags writer --
def write_with_rosbags(path: Path, storage: str, compression: str, version: int = 9) -> Path:
    from rosbags.rosbag2 import Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin

    writer = Writer(path, version=version,  # type: ignore[arg-type]
                    storage_plugin=StoragePlugin.SQLITE3 if storage == 'sqlite3' else StoragePlugin.MCAP)
    if compression:
        writer.set_compression(CompressionMode[compression.upper()], CompressionFormat.ZSTD)
    with writer:
        conns = {t: writer.add_connection(t, ty, msgdef=message_definition(ty), rihs01='RIHS01_' + '1' * 64)
                 for t, ty in TOPICS.items()}
        # Written out of log-time order: every seventh message five later.
        order = sorted(range(len(MESSAGES)), key=lambda i: i + (5.5 if i % 7 == 0 else 0))
        for i in order:
            topic, log, _, data = MESSAGES[i]
            writer.write(conns[topic], log, data)
    return path


@pytest.mark.parametrize('version', [8, 9])
@pytest.mark.parametrize('storage,compression', [
    ('sqlite3', ''), ('sqlite3', 'file'), ('sqlite3', 'message'), ('mcap', 'file'), ('mcap', 'message')])
def test_rosbags_bags_read_exactly(tmp_path, storage, compression, version):
    bag = write_with_rosbags(tmp_path / 'bag', storage, compression, version)
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['compression_mode'] == compression and info['version'] == version
    if compression == 'file':
        assert [p.suffix for p in bag.iterdir() if p.name != 'metadata.yaml'] == ['.zstd']
    assert_exact(bag, qos=False)
    with BagReader(bag) as reader:
        assert reader.compression_mode == compression
        assert [p.parent for p in reader.files] == [bag]  # the files as the bag names them
        assert all(p.is_file() for p in reader.files)


def test_file_compressed_copies_are_removed_on_close(tmp_path):
    bag = write_with_rosbags(tmp_path / 'bag', 'sqlite3', 'file')
    reader = BagReader(bag)
    copies = [c.dir for c in reader._copies]
    assert copies and all(c.is_dir() for c in copies)
    reader.close()
    assert not any(c.exists() for c in copies)


# ---------------------------------------------------------------------- rosbag2's older layouts by hand --
SCHEMAS = {
    # rosbag2 of Foxy: no schema table, topics without QoS.
    'foxy': ('CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, '
             'serialization_format TEXT NOT NULL)', None),
    # Galactic/Humble: schema table, QoS per topic.
    'humble': ('CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, '
               'serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL)', 3),
    # Jazzy: type hashes, message definitions, metadata.
    'jazzy': ('CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, '
              'serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL, '
              'type_description_hash TEXT NOT NULL)', 4),
}


def write_sqlite3(path: Path, layout: str, compress_messages: bool = False) -> Path:
    topics_sql, schema_version = SCHEMAS[layout]
    conn = sqlite3.connect(path)
    conn.execute(topics_sql)
    conn.execute('CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, '
                 'timestamp INTEGER NOT NULL, data BLOB NOT NULL)')
    conn.execute('CREATE INDEX timestamp_idx ON messages (timestamp ASC)')
    if schema_version is not None:
        conn.execute('CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL)')
        conn.execute('INSERT INTO schema VALUES (?, ?)', (schema_version, layout))
    if layout == 'jazzy':
        conn.execute('CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL, '
                     'encoding TEXT NOT NULL, encoded_message_definition TEXT NOT NULL, '
                     'type_description_hash TEXT NOT NULL)')
        for ty in sorted(set(TOPICS.values())):
            conn.execute('INSERT INTO message_definitions(topic_type, encoding, encoded_message_definition, '
                         'type_description_hash) VALUES (?, ?, ?, ?)', (ty, 'ros2msg', message_definition(ty), ''))
    ids = {}
    for n, (topic, ty) in enumerate(TOPICS.items()):
        ids[topic] = n + 3  # ids need not start at 1
        values = [ids[topic], topic, ty, 'cdr'] + ([QOS] if layout != 'foxy' else []) + (
            ['RIHS01_' + '2' * 64] if layout == 'jazzy' else [])
        conn.execute(f'INSERT INTO topics VALUES ({", ".join("?" * len(values))})', values)
    compressor = zstandard.ZstdCompressor()
    # Message ids with gaps and across several blocks of the reader; rows out of log-time order.
    rows = [(10 + 1000 * i + (i % 3), ids[topic], log, compressor.compress(data) if compress_messages else data)
            for i, (topic, log, _, data) in enumerate(sorted(MESSAGES, key=lambda m: -m[1] if m[1] % 3 else m[1]))]
    conn.executemany('INSERT INTO messages VALUES (?, ?, ?, ?)', rows)
    conn.commit()
    conn.close()
    return path


def metadata_yaml(bag: Path, files: list[str], version: int, compression: str = '') -> None:
    info = {'version': version, 'storage_identifier': 'sqlite3', 'relative_file_paths': files,
            'duration': {'nanoseconds': EXPECTED[-1][1] - EXPECTED[0][1]},
            'starting_time': {'nanoseconds_since_epoch': EXPECTED[0][1]}, 'message_count': len(EXPECTED),
            'topics_with_message_count': [], 'compression_format': 'zstd' if compression else '',
            'compression_mode': compression.upper()}
    if version >= 5:
        info['files'] = [{'path': f, 'message_count': len(EXPECTED)} for f in files]
    (bag / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': info}))


@pytest.mark.parametrize('layout,version', [('foxy', 4), ('humble', 5), ('humble', 6), ('humble', 7),
                                            ('jazzy', 8), ('jazzy', 9)])
def test_sqlite3_layouts_of_every_rosbag2_version(tmp_path, layout, version):
    bag = tmp_path / 'bag'
    bag.mkdir()
    write_sqlite3(bag / 'bag_0.db3', layout)
    metadata_yaml(bag, ['bag_0.db3'], version)
    assert_exact(bag, qos=layout != 'foxy')
    with Sqlite3File(bag / 'bag_0.db3') as db:
        assert db.schema_version == SCHEMAS[layout][1]
        assert len(db.chunks) > 1  # several blocks, read in order and merged
        definition = db.schemas[1].data.decode()
    assert bool(definition) == (layout == 'jazzy')
    assert_exact(bag / 'bag_0.db3', qos=layout != 'foxy')  # the file alone


@pytest.mark.parametrize('compression', ['message', 'file'])
def test_split_bag_compressed_without_and_with_metadata_yaml(tmp_path, compression):
    """rosbag2's upper-case compression mode; two files; without metadata.yaml the files are found by name."""
    bag = tmp_path / 'bag'
    bag.mkdir()
    write_sqlite3(bag / 'bag_0.db3', 'humble', compress_messages=compression == 'message')
    # The second file: empty of messages, as a split at the very end leaves it.
    conn = sqlite3.connect(bag / 'bag_1.db3')
    conn.execute(SCHEMAS['humble'][0])
    conn.execute('CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER '
                 'NOT NULL, data BLOB NOT NULL)')
    conn.commit()
    conn.close()
    names = ['bag_0.db3', 'bag_1.db3']
    if compression == 'file':
        for name in names:
            raw = (bag / name).read_bytes()
            (bag / f'{name}.zstd').write_bytes(zstandard.ZstdCompressor().compress(raw))
            (bag / name).unlink()
        names = [f'{n}.zstd' for n in names]
    metadata_yaml(bag, names, 6, compression)
    assert_exact(bag)
    if compression == 'file':
        (bag / 'metadata.yaml').unlink()
        assert_exact(bag)


def test_neither_storage_nor_readable_compression_is_refused(tmp_path):
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'bag_0.db3').write_text('not a database')
    with pytest.raises(BagFormatError, match=r'bag_0\.db3 is not an MCAP file, an SQLite 3'):
        BagReader(bag)
    (bag / 'bag_0.db3').unlink()
    conn = sqlite3.connect(bag / 'other.db3')
    conn.execute('CREATE TABLE something(x)')
    conn.commit()
    conn.close()
    with pytest.raises(BagFormatError, match=r'other\.db3 is an SQLite database without the rosbag2 tables'):
        BagReader(bag / 'other.db3')
    write_sqlite3(bag / 'bag_0.db3', 'jazzy')
    metadata_yaml(bag, ['bag_0.db3'], 9, 'message')
    text = (bag / 'metadata.yaml').read_text().replace('compression_format: zstd', 'compression_format: lz4')
    (bag / 'metadata.yaml').write_text(text)
    with pytest.raises(BagUnsupportedError, match=r"bag: compression_format 'lz4'"):
        BagReader(bag)
    (bag / 'broken.db3.zstd').write_bytes(b'\x28\xb5\x2f\xfd' + b'garbage' * 10)
    with pytest.raises(BagFormatError, match=r'broken\.db3\.zstd does not decompress as zstd'):
        BagReader(bag / 'broken.db3.zstd')


def test_message_on_an_undefined_topic_is_refused(tmp_path):
    path = write_sqlite3(tmp_path / 'bag.db3', 'jazzy')
    conn = sqlite3.connect(path)
    conn.execute('INSERT INTO messages(topic_id, timestamp, data) VALUES (99, 1, x\'00\')')
    conn.commit()
    conn.close()
    with pytest.raises(BagFormatError, match=r'bag\.db3: messages with topic_id\(s\) \[99\]'):
        BagReader(path)
