"""Every valid MCAP layout is read exactly, and what cannot be read is refused with a BagError naming the file.

Files come from writers that are not this package's: the ``mcap`` package's Writer across the product of its options,
the ``rosbags`` rosbag2 writer, and record streams built here record by record (with ``mcap.records``) for the layouts
no writer option produces: messages outside chunks beside indexed chunks, channels only inside chunks, no summary,
an empty chunk, padded records, unknown opcodes, an unknown compression, a message on an undefined channel. Each
valid file must give exactly the written messages (topic, log time, bytes; in log-time order) through
``BagReader.messages()``, the bulk ``decode_topics`` and ``topics``, and the same as the independent ``mcap`` reader's
``iter_messages`` wherever that reader can read the file.
"""
from __future__ import annotations

import itertools
import struct
import zlib
from pathlib import Path

import lz4.frame
import pytest
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.reader import make_reader
from mcap.records import (
    Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Message, MessageIndex, Schema, Statistics, SummaryOffset,
)
from mcap.writer import CompressionType, IndexType, Writer

from crane_stiffness.bag import BagError, BagFormatError, BagReader, BagUnsupportedError
from crane_stiffness.bag.msgdef import message_definition

from helpers.bags import TOPICS, make_messages, values_of, values_of_row

MAGIC = b'\x89MCAP0\r\n'
MESSAGES = make_messages(n_fast=24, n_slow=4)
"""(topic, log time, rclpy message, CDR bytes) on five topics, distinct log times."""
EXPECTED = sorted(((t, log, data) for t, log, _, data in MESSAGES), key=lambda m: m[1])
#: The order the messages are written in: not log-time order (every fifth message comes three later), so chunks
#: overlap in time and the reader must merge them.
WRITE_ORDER = sorted(range(len(MESSAGES)), key=lambda i: i + (3.5 if i % 5 == 0 else 0))


def _definition(msg_type: str) -> bytes:
    return message_definition(msg_type).encode()


# ------------------------------------------------------------------------------------------------ checking --
def read_exactly(path: Path) -> list[str]:
    """What differs between the written messages and what BagReader gives (empty when exact)."""
    errors = []
    with BagReader(path) as reader:
        if reader.problems:
            errors.append(f'problems {reader.problems}')
        got = [(m.topic, m.log_time_ns, m.data) for m in reader.messages()]
        if got != EXPECTED:
            errors.append(f'messages(): {len(got)} messages, expected {len(EXPECTED)}'
                          + ('' if len(got) != len(EXPECTED) else ' (different order or content)'))
        topics = {t: (i.msg_type, i.count) for t, i in reader.topics.items()}
        counts = {t: sum(1 for m in EXPECTED if m[0] == t) for t in TOPICS}
        if topics != {t: (TOPICS[t], counts[t]) for t in TOPICS}:
            errors.append(f'topics {topics}')
        arrays = reader.decode_topics(list(TOPICS))
        part = [(m.topic, m.log_time_ns) for m in reader.messages(['/program/setpoint', '/crane/winches'],
                                                                    start_ns=EXPECTED[10][1], end_ns=EXPECTED[45][1])]
    for topic, msg_type in TOPICS.items():
        want = [(log, values_of(msg_type, msg)) for t, log, msg, _ in sorted(MESSAGES, key=lambda m: m[1])
                if t == topic]
        have = [(int(row['log_time_ns']), values_of_row(msg_type, row)) for row in arrays[topic]]
        if have != want:
            errors.append(f'decode {topic}: {len(have)} rows, expected {len(want)}')
    if part != [(t, log) for t, log, _ in EXPECTED[10:45] if t in ('/program/setpoint', '/crane/winches')]:
        errors.append('messages(topics, start_ns, end_ns) differ')
    return errors


def independent(path: Path) -> list[tuple[str, int, bytes]] | None:
    """The messages as the ``mcap`` package's reader gives them, None where it cannot read the file."""
    try:
        with open(path, 'rb') as stream:
            return [(c.topic, m.log_time, m.data) for _, c, m in make_reader(stream).iter_messages()]
    except Exception:  # it cannot read some valid layouts (channels only in chunks, no summary, ...)
        return None


def assert_exact(path: Path, outside_chunks: list[int] = ()) -> None:  # type: ignore[assignment]
    """Exactly the messages; the ``mcap`` reader's the same, but for the messages ``outside_chunks`` (indexes into
    MESSAGES) in a file with chunk indexes, which that reader does not look for (it reads only indexed chunks)."""
    errors = read_exactly(path)
    assert not errors, f'{path.name}: ' + '; '.join(errors)
    theirs = independent(path)
    if theirs is not None:
        left_out = {MESSAGES[i][1] for i in outside_chunks}
        assert sorted(theirs, key=lambda m: m[1]) == [m for m in EXPECTED if m[1] not in left_out]


# --------------------------------------------------------------------------------- the mcap package's writer --
def write_with_mcap(path: Path, **options: object) -> Path:
    """The messages written by mcap's Writer; each channel (and schema) registered at its first message, so with
    chunking it is defined inside the chunk that first uses it."""
    with open(path, 'wb') as stream:
        writer = Writer(stream, **options)  # type: ignore[arg-type]
        writer.start('ros2', 'mcap writer test')
        schemas: dict[str, int] = {}
        channels: dict[str, int] = {}
        for i in WRITE_ORDER:
            topic, log, _, data = MESSAGES[i]
            if topic not in channels:
                msg_type = TOPICS[topic]
                if msg_type not in schemas:
                    schemas[msg_type] = writer.register_schema(msg_type, 'ros2msg', _definition(msg_type))
                channels[topic] = writer.register_channel(topic, 'cdr', schemas[msg_type],
                                                          {'offered_qos_profiles': ''})
            writer.add_message(channels[topic], log_time=log, data=data, publish_time=log, sequence=i)
        writer.finish()
    return path


INDEX_TYPES = [IndexType.NONE, IndexType.CHUNK, IndexType.MESSAGE, IndexType.CHUNK | IndexType.MESSAGE,
               IndexType.ALL]
FLAGS = ['repeat_channels', 'repeat_schemas', 'use_statistics', 'use_summary_offsets', 'enable_crcs',
         'enable_data_crcs']


def writer_options(use_chunking: bool, compression: CompressionType) -> list[dict[str, object]]:
    """Every combination of the Writer's other options (chunk sizes: one chunk, and a chunk every few messages)."""
    sizes = [1 << 20, 600] if use_chunking else [1 << 20]
    out = []
    for size, index_types, flags in itertools.product(sizes, INDEX_TYPES, itertools.product([False, True],
                                                                                             repeat=len(FLAGS))):
        out.append(dict(use_chunking=use_chunking, compression=compression, chunk_size=size,
                        index_types=index_types, **dict(zip(FLAGS, flags))))
    return out


@pytest.mark.parametrize('use_chunking,compression', [
    (False, CompressionType.NONE), (True, CompressionType.NONE), (True, CompressionType.LZ4),
    (True, CompressionType.ZSTD)], ids=['unchunked', 'chunks-none', 'chunks-lz4', 'chunks-zstd'])
def test_every_mcap_writer_option_combination_reads_exactly(tmp_path, use_chunking, compression):
    failures, compared = [], 0
    for n, options in enumerate(writer_options(use_chunking, compression)):
        path = write_with_mcap(tmp_path / f'f{n}.mcap', **options)
        errors = read_exactly(path)
        theirs = independent(path)
        if theirs is not None:
            compared += 1
            if sorted(theirs, key=lambda m: m[1]) != EXPECTED:
                errors.append('the mcap reader gives other messages')
        if errors:
            failures.append(f'{options}: {"; ".join(errors)}')
        path.unlink()
    assert not failures, f'{len(failures)} layouts read wrong, e.g.\n' + '\n'.join(failures[:5])
    assert compared > 0


def test_chunk_indexes_without_channels_in_the_summary(tmp_path):
    """The class of files that read as empty: chunked, chunk indexes in the summary, channels only in chunks."""
    path = write_with_mcap(tmp_path / 'no_repeat.mcap', chunk_size=600, compression=CompressionType.ZSTD,
                           index_types=IndexType.ALL, repeat_channels=False, repeat_schemas=False)
    assert independent(path) is None  # the mcap package's reader itself cannot read it
    assert_exact(path)


def test_rosbags_mcap_writer(tmp_path):
    from rosbags.rosbag2 import Writer as RosbagsWriter
    from rosbags.rosbag2.enums import StoragePlugin

    with RosbagsWriter(tmp_path / 'bag', version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {t: writer.add_connection(t, ty, msgdef=message_definition(ty), rihs01='RIHS01_' + '0' * 64)
                 for t, ty in TOPICS.items()}
        for i in WRITE_ORDER:
            topic, log, _, data = MESSAGES[i]
            writer.write(conns[topic], log, data)
    assert_exact(tmp_path / 'bag')
    assert_exact(next((tmp_path / 'bag').glob('*.mcap')))


# ------------------------------------------------------------------------------- record streams by hand --
def record(rec: object, pad: int = 0) -> bytes:
    """One record's bytes; ``pad`` zero bytes after its fields (counted in its length, as the spec allows)."""
    builder = RecordBuilder()
    rec.write(builder)  # type: ignore[attr-defined]
    raw = builder.end()
    if pad:
        length = struct.unpack_from('<Q', raw, 1)[0] + pad
        raw = raw[:1] + struct.pack('<Q', length) + raw[9:] + bytes(pad)
    return raw


def unknown_record(opcode: int, body: bytes = b'future record') -> bytes:
    return struct.pack('<BQ', opcode, len(body)) + body


SCHEMA_IDS = {ty: n + 1 for n, ty in enumerate(sorted(set(TOPICS.values())))}
CHANNEL_IDS = {topic: n + 1 for n, topic in enumerate(TOPICS)}


def schema_record(msg_type: str) -> Schema:
    return Schema(id=SCHEMA_IDS[msg_type], name=msg_type, encoding='ros2msg', data=_definition(msg_type))


def channel_record(topic: str, encoding: str = 'cdr') -> Channel:
    return Channel(id=CHANNEL_IDS[topic], topic=topic, message_encoding=encoding,
                   schema_id=SCHEMA_IDS[TOPICS[topic]], metadata={})


def definitions(topics: list[str] | None = None) -> list[object]:
    topics = list(TOPICS) if topics is None else topics
    types = sorted({TOPICS[t] for t in topics})
    return [schema_record(ty) for ty in types] + [channel_record(t) for t in topics]


def message_record(i: int, channel_id: int | None = None) -> Message:
    topic, log, _, data = MESSAGES[i]
    return Message(channel_id=CHANNEL_IDS[topic] if channel_id is None else channel_id, sequence=i, log_time=log,
                   publish_time=log, data=data)


class HandFile:
    """An MCAP file laid out record by record."""

    def __init__(self, pad: int = 0) -> None:
        self.pad = pad
        self.data = bytearray(MAGIC)
        self.chunk_indexes: list[ChunkIndex] = []
        self.add(Header(profile='ros2', library='by hand'))

    def add(self, *records: object) -> int:
        start = len(self.data)
        for rec in records:
            self.data += rec if isinstance(rec, bytes) else record(rec, 0 if isinstance(rec, Message) else self.pad)
        return start

    def chunk(self, records: list[object], compression: str = 'zstd', message_index: bool = True,
              extra: bytes = b'') -> None:
        """A chunk of ``records`` (its message indexes after it; a chunk index for the summary)."""
        inner = bytearray()
        offsets: dict[int, list[tuple[int, int]]] = {}
        for rec in records:
            if isinstance(rec, Message):
                offsets.setdefault(rec.channel_id, []).append((rec.log_time, len(inner)))
            inner += rec if isinstance(rec, bytes) else record(rec, 0 if isinstance(rec, Message) else self.pad)
        inner += extra
        raw = bytes(inner)
        packed = {'zstd': lambda b: zstandard.ZstdCompressor().compress(b), 'lz4': lz4.frame.compress,
                  '': lambda b: b}.get(compression, lambda b: b'\x00' * 16)(raw)
        times = [r.log_time for r in records if isinstance(r, Message)]
        chunk = Chunk(compression=compression, data=packed, message_start_time=min(times, default=0),
                      message_end_time=max(times, default=0), uncompressed_crc=zlib.crc32(raw),
                      uncompressed_size=len(raw))
        start = self.add(chunk)
        length = len(self.data) - start
        index_offsets = {}
        if message_index:
            for cid, entries in offsets.items():
                index_offsets[cid] = self.add(MessageIndex(channel_id=cid, records=entries))
        self.chunk_indexes.append(ChunkIndex(
            message_start_time=chunk.message_start_time, message_end_time=chunk.message_end_time,
            chunk_start_offset=start, chunk_length=length, message_index_offsets=index_offsets,
            message_index_length=len(self.data) - start - length, compression=compression,
            compressed_size=len(packed), uncompressed_size=len(raw)))

    def finish(self, summary: list[object] | None = None, *, offsets: bool = False) -> bytes:
        """Data end, the ``summary`` records (None: no summary section), summary offsets, footer, magic."""
        self.add(DataEnd(data_section_crc=0))
        summary_start = summary_offset_start = 0
        if summary is not None:
            summary_start = len(self.data)
            groups: dict[int, list[int]] = {}
            for rec in summary:
                pos = self.add(rec)
                opcode = rec[0] if isinstance(rec, bytes) else self.data[pos]
                groups.setdefault(opcode, []).append(pos)
            if offsets:
                summary_offset_start = len(self.data)
                ends = sorted(p for ps in groups.values() for p in ps) + [summary_offset_start]
                for opcode, positions in groups.items():
                    end = ends[ends.index(positions[-1]) + 1]
                    self.add(SummaryOffset(group_opcode=opcode, group_start=positions[0],
                                           group_length=end - positions[0]))
        footer = record(Footer(summary_start=summary_start, summary_offset_start=summary_offset_start,
                               summary_crc=0))
        self.data += footer + MAGIC
        return bytes(self.data)


def statistics(chunks: int = 0) -> Statistics:
    counts: dict[int, int] = {}
    for topic, _, _ in EXPECTED:
        counts[CHANNEL_IDS[topic]] = counts.get(CHANNEL_IDS[topic], 0) + 1
    return Statistics(message_count=len(EXPECTED), schema_count=len(SCHEMA_IDS), channel_count=len(CHANNEL_IDS),
                      attachment_count=0, metadata_count=0, chunk_count=chunks, message_start_time=EXPECTED[0][1],
                      message_end_time=EXPECTED[-1][1], channel_message_counts=counts)


def thirds() -> list[list[int]]:
    n = len(WRITE_ORDER)
    return [WRITE_ORDER[:n // 3], WRITE_ORDER[n // 3:2 * n // 3], WRITE_ORDER[2 * n // 3:]]


def write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def test_messages_outside_chunks_beside_indexed_chunks(tmp_path):
    """A third of the messages in the data section outside any chunk, between two indexed chunks; the summary
    repeats the definitions and indexes only the chunks."""
    first, loose, last = thirds()
    f = HandFile()
    f.add(*definitions())
    f.chunk([message_record(i) for i in first])
    f.add(*(message_record(i) for i in loose))
    f.chunk([message_record(i) for i in last], compression='lz4')
    assert_exact(write(tmp_path / 'loose.mcap', f.finish(definitions() + f.chunk_indexes + [statistics(2)])), loose)


def test_channels_only_in_chunks_and_no_summary_channels(tmp_path):
    """Each channel defined in the chunk that first uses it; the summary has chunk indexes and nothing else."""
    f = HandFile()
    defined: set[str] = set()
    for part in thirds():
        records: list[object] = []
        for i in part:
            topic = MESSAGES[i][0]
            if topic not in defined:
                defined.add(topic)
                records += [schema_record(TOPICS[topic]), channel_record(topic)]
            records.append(message_record(i))
        f.chunk(records)
    assert_exact(write(tmp_path / 'chunk_channels.mcap', f.finish(list(f.chunk_indexes))))


@pytest.mark.parametrize('message_index', [True, False])
def test_no_summary_section(tmp_path, message_index):
    """Footer summary_start 0: chunks (with and without message indexes) and loose messages, definitions in the
    data section."""
    first, loose, last = thirds()
    f = HandFile()
    f.add(*definitions())
    f.chunk([message_record(i) for i in first], compression='', message_index=message_index)
    f.add(*(message_record(i) for i in loose))
    f.chunk([message_record(i) for i in last], message_index=message_index)
    assert_exact(write(tmp_path / 'no_summary.mcap', f.finish(None)))


def test_empty_chunk_and_no_indexes_at_all(tmp_path):
    f = HandFile()
    f.add(*definitions())
    f.chunk([])
    for part in thirds():
        f.chunk([message_record(i) for i in part], message_index=False)
    f.chunk([], compression='lz4')
    assert_exact(write(tmp_path / 'empty_chunk.mcap', f.finish(definitions() + [statistics(5)])))
    g = HandFile()
    g.add(*definitions())
    g.chunk([])
    for part in thirds():
        g.chunk([message_record(i) for i in part])
    assert_exact(write(tmp_path / 'empty_indexed.mcap', g.finish(definitions() + g.chunk_indexes)))


@pytest.mark.parametrize('offsets', [False, True])
def test_padded_records_and_unknown_opcodes_are_skipped(tmp_path, offsets):
    """Every record but messages carries padding after its fields; records of unknown opcodes (a future one, 0x42,
    and a private one, 0x90) stand in the data section, inside chunks and in the summary."""
    first, loose, last = thirds()
    f = HandFile(pad=13)
    f.add(unknown_record(0x42))
    f.add(*definitions())
    f.add(unknown_record(0x90, b''))
    f.chunk([unknown_record(0x42)] + [message_record(i) for i in first] + [unknown_record(0x90)])
    f.add(*(message_record(i) for i in loose))
    f.chunk([message_record(i) for i in last], compression='', extra=unknown_record(0x43))
    summary = definitions() + [unknown_record(0x91)] + f.chunk_indexes + [statistics(2)]
    assert_exact(write(tmp_path / 'padded.mcap', f.finish(summary, offsets=offsets)), loose)


def test_unknown_chunk_compression_is_refused_naming_file_and_compression(tmp_path):
    f = HandFile()
    f.add(*definitions())
    f.chunk([message_record(i) for i in WRITE_ORDER], compression='brotli')
    for summary in (definitions() + f.chunk_indexes, None):
        path = write(tmp_path / 'brotli.mcap', HandFile.finish(_copy(f), summary))
        with pytest.raises(BagUnsupportedError, match=r"brotli\.mcap.*'brotli'"):
            BagReader(path)


def _copy(f: HandFile) -> HandFile:
    g = HandFile.__new__(HandFile)
    g.pad, g.data, g.chunk_indexes = f.pad, bytearray(f.data), list(f.chunk_indexes)
    return g


@pytest.mark.parametrize('where', ['chunk', 'loose', 'chunk-no-index'])
def test_message_on_an_undefined_channel_is_refused(tmp_path, where):
    f = HandFile()
    f.add(*definitions())
    records = [message_record(i) for i in WRITE_ORDER[:10]] + [message_record(11, channel_id=77)]
    if where == 'loose':
        f.add(*records)
    else:
        f.chunk(records, message_index=where == 'chunk')
    for n, summary in enumerate((definitions() + f.chunk_indexes, None)):
        path = write(tmp_path / f'undefined{n}.mcap', HandFile.finish(_copy(f), summary))
        with pytest.raises(BagFormatError, match=rf'undefined{n}\.mcap.*channel id\(s\) \[77\]'):
            BagReader(path)


def test_other_encodings_are_refused_not_misread(tmp_path):
    """A channel of JSON messages cannot be handed out as CDR, a type described in another schema language cannot
    be bulk-decoded: both raise, naming the file, topic and encoding."""
    f = HandFile()
    json_schema = Schema(id=9, name='geometry_msgs/msg/WrenchStamped', encoding='jsonschema', data=b'{}')
    f.add(*definitions(), json_schema, Channel(id=9, topic='/json', message_encoding='json', schema_id=9,
                                               metadata={}),
          Channel(id=10, topic='/other_schema', message_encoding='cdr', schema_id=9, metadata={}))
    f.chunk([message_record(i) for i in WRITE_ORDER] + [
        Message(channel_id=9, sequence=0, log_time=EXPECTED[0][1], publish_time=0, data=b'{}'),
        Message(channel_id=10, sequence=0, log_time=EXPECTED[1][1], publish_time=0, data=MESSAGES[0][3])])
    path = write(tmp_path / 'encodings.mcap', f.finish(None))
    with BagReader(path) as reader:
        assert reader.topics['/json'].message_encoding == 'json'
        assert [(m.topic, m.log_time_ns, m.data) for m in reader.messages(list(TOPICS))] == EXPECTED
        with pytest.raises(BagUnsupportedError, match=r"encodings\.mcap: topic /json .*'json'"):
            list(reader.messages())
        with pytest.raises(BagUnsupportedError, match=r"/other_schema has schema encoding 'jsonschema'"):
            reader.decode('/other_schema')
        assert isinstance(BagUnsupportedError('x'), BagError)


def test_summary_offsets_point_at_groups(tmp_path):
    """A hand-written file with summary offsets is a valid file for the independent reader too."""
    f = HandFile()
    f.add(*definitions())
    for part in thirds():
        f.chunk([message_record(i) for i in part])
    path = write(tmp_path / 'offsets.mcap', f.finish(definitions() + f.chunk_indexes + [statistics(3)],
                                                      offsets=True))
    assert independent(path) is not None
    assert_exact(path)
