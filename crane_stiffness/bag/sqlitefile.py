"""One rosbag2 sqlite3 file (``.db3``) of a bag, read with the standard library's ``sqlite3``.

rosbag2's sqlite3 storage (ROS 2's default before Iron) keeps the topics in a table ``topics(id, name, type,
serialization_format[, offered_qos_profiles][, type_description_hash])`` and the messages in ``messages(id,
topic_id, timestamp, data)`` (``timestamp`` the log time in ns since the epoch, ``data`` the CDR bytes); newer
versions add ``schema(schema_version, ros_distro)``, ``metadata`` and ``message_definitions(topic_type, encoding,
encoded_message_definition, type_description_hash)``. Every one of these versions is read.

:class:`Sqlite3File` offers the same view as :class:`~.mcapfile.McapFile` (schemas, channels, "chunks",
counts, times), so :class:`~.reader.BagReader` reads both alike: a topic is a channel (its id the topic id), its type
a schema, and a "chunk" is a block of :data:`BLOCK_IDS` consecutive message ids. A block is read with one query
whose aggregates gather each topic's timestamps, lengths and bytes inside SQLite (``group_concat``), so no Python
object is built per message and the bulk decoders see the same :class:`~.chunks.ChunkMessages` as for MCAP.
"""
from __future__ import annotations

import sqlite3
import threading
import warnings
from collections.abc import Collection, Iterator
from pathlib import Path

import numpy as np
from mcap.records import Channel, Schema

from .chunks import ChunkMessages, ChunkRef, in_file_order
from .errors import BagFormatError, BagNotFoundError

SQLITE_MAGIC = b'SQLite format 3\x00'
"""The first 16 bytes of every SQLite database file."""
BLOCK_SHIFT = 14
BLOCK_IDS = 1 << BLOCK_SHIFT
"""Message ids per block: the unit read (and decoded) at once, like an MCAP chunk (small enough that the reader's
read-ahead threads query blocks side by side)."""
MMAP_BYTES = 1 << 31
"""SQLite reads the file through a memory map up to this size (fewer copies than read(); it is read only)."""

# One pass over the block's rows in id order, every value gathered inside SQLite: no Python object per message.
# The timestamps go as differences to the block's first one (fewer digits to print and to parse back).
_BLOCK_QUERY = (
    "SELECT group_concat(topic_id, ' '), group_concat(timestamp - ?, ' '), group_concat(length(data), ' '), "
    "CAST(group_concat(data, '') AS BLOB), count(*) FROM messages WHERE id >= ? AND id < ?")
_BLOCK_TOPICS = ('SELECT topic_id, count(*), min(timestamp), max(timestamp) FROM messages WHERE id >= ? AND id < ? '
                 'GROUP BY topic_id')


def _ints(text: str | None, count: int) -> np.ndarray:
    """``group_concat(..., ' ')`` of integers back to int64 (``count`` of them; numpy's text parser, exact for
    int64, at a third of the cost of splitting into Python strings)."""
    if not count:
        return np.zeros(0, np.int64)
    with warnings.catch_warnings():
        warnings.simplefilter('error')  # numpy warns (and stops) on text that is not all integers: a ValueError here
        try:
            out = np.fromstring(text, dtype=np.int64, sep=' ') if text else np.zeros(0, np.int64)
        except (DeprecationWarning, ValueError) as exc:
            raise ValueError(f'not a list of integers ({exc})') from None
    if out.size != count:
        raise ValueError(f'expected {count} values, got {out.size}')
    return out


class Sqlite3File:
    """Structure of one rosbag2 sqlite3 file: topics as channels and schemas, blocks of messages as chunks.

    Args:
        path: the .db3 file.
        strict: kept for the same interface as :class:`~.mcapfile.McapFile` (an SQLite file is read whole or not).
        name: the path to name in messages when ``path`` is a decompressed copy (a ``.db3.zstd`` file).
    """

    def __init__(self, path: str | Path, *, strict: bool = False, name: str | Path | None = None) -> None:
        self.path = Path(name) if name is not None else Path(path)
        self._disk = Path(path)
        self.strict = strict
        self.problems: list[str] = []
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.chunks: list[ChunkRef] = []
        self.metadata: list[tuple[str, dict[str, str]]] = []
        self.channel_counts: dict[int, int] = {}
        self.complete = True
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.schema_version: int | None = None
        """``schema.schema_version`` of the database (None for the oldest files, which have no such table)."""
        self._local = threading.local()  # one connection per thread: the read-ahead threads query side by side
        self._connections: list[sqlite3.Connection] = []
        self._lock = threading.Lock()
        if not self._disk.is_file():
            raise BagNotFoundError(f'sqlite3 file {self.path} does not exist')
        try:
            self._read_structure()
        except sqlite3.Error as exc:
            self.close()
            raise BagFormatError(f'{self.path} is not a readable rosbag2 sqlite3 file ({exc})') from None
        except BaseException:
            self.close()
            raise

    # -- lifetime --
    def _connection(self) -> sqlite3.Connection:
        conn = getattr(self._local, 'conn', None)
        if conn is None:
            conn = sqlite3.connect(f'{self._disk.resolve().as_uri()}?mode=ro', uri=True, check_same_thread=False)
            conn.execute(f'PRAGMA mmap_size = {MMAP_BYTES}')
            self._local.conn = conn
            with self._lock:
                self._connections.append(conn)
        return conn

    def close(self) -> None:
        """Close the connections."""
        with self._lock:
            for conn in self._connections:
                conn.close()
            self._connections.clear()
        self._local = threading.local()

    def __enter__(self) -> Sqlite3File:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- structure --
    def _read_structure(self) -> None:
        conn = self._connection()
        tables = {row[0] for row in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if not {'topics', 'messages'} <= tables:
            raise BagFormatError(f'{self.path} is an SQLite database without the rosbag2 tables topics and messages '
                                 f'(it has: {", ".join(sorted(tables)) or "none"})')
        if 'schema' in tables:
            row = conn.execute('SELECT schema_version FROM schema').fetchone()
            self.schema_version = int(row[0]) if row else None
        definitions: dict[str, tuple[str, str]] = {}
        if 'message_definitions' in tables:
            for topic_type, encoding, text in conn.execute(
                    'SELECT topic_type, encoding, encoded_message_definition FROM message_definitions ORDER BY id'):
                definitions[topic_type] = (encoding, text)
        columns = [row[1] for row in conn.execute('PRAGMA table_info(topics)')]
        wanted = ['id', 'name', 'type', 'serialization_format', 'offered_qos_profiles', 'type_description_hash']
        present = [c for c in wanted if c in columns]
        schema_ids: dict[str, int] = {}
        for row in conn.execute(f'SELECT {", ".join(present)} FROM topics ORDER BY id'):
            topic = dict(zip(present, row))
            msg_type = str(topic['type'])
            if msg_type not in schema_ids:
                schema_ids[msg_type] = len(schema_ids) + 1
                encoding, text = definitions.get(msg_type, ('', ''))
                self.schemas[schema_ids[msg_type]] = Schema(
                    id=schema_ids[msg_type], name=msg_type, encoding=encoding or 'ros2msg',
                    data=(text or '').encode('utf-8'))
            metadata = {'offered_qos_profiles': str(topic.get('offered_qos_profiles') or '')}
            if topic.get('type_description_hash'):
                metadata['topic_type_hash'] = str(topic['type_description_hash'])
            self.channels[int(topic['id'])] = Channel(
                id=int(topic['id']), topic=str(topic['name']), message_encoding=str(topic['serialization_format']),
                schema_id=schema_ids[msg_type], metadata=metadata)
        blocks: dict[int, ChunkRef] = {}
        lowest, highest, total = conn.execute('SELECT min(id), max(id), count(*) FROM messages').fetchone()
        if total and (highest >> BLOCK_SHIFT) - (lowest >> BLOCK_SHIFT) < 4 * total // BLOCK_IDS + 64:
            rows: list[tuple[int, int, int, int, int]] = []
            for block in range(lowest >> BLOCK_SHIFT, (highest >> BLOCK_SHIFT) + 1):
                rows += [(block, *row) for row in conn.execute(
                    _BLOCK_TOPICS, (block << BLOCK_SHIFT, (block + 1) << BLOCK_SHIFT))]
        else:  # ids spread far apart: one grouping pass instead of a query per (mostly empty) block
            rows = conn.execute(f'SELECT id >> {BLOCK_SHIFT}, topic_id, count(*), min(timestamp), max(timestamp) '
                                'FROM messages GROUP BY 1, 2').fetchall()
        for block, topic_id, count, first, last in rows:
            ref = blocks.get(block)
            if ref is None:
                lo = block << BLOCK_SHIFT
                ref = blocks[block] = ChunkRef(lo, lo, 0, 0, '', first, last, length=BLOCK_IDS, index={})
            assert ref.index is not None
            ref.index[topic_id] = 0
            ref.counts[topic_id] = count
            ref.start_ns, ref.end_ns = min(ref.start_ns, first), max(ref.end_ns, last)
            self.channel_counts[topic_id] = self.channel_counts.get(topic_id, 0) + count
        self.chunks = [blocks[b] for b in sorted(blocks)]
        unknown = sorted(set(self.channel_counts) - set(self.channels))
        if unknown:
            raise BagFormatError(f'{self.path}: messages with topic_id(s) {unknown}, which the topics table does not '
                                 'define; the messages cannot be attributed to a topic')
        if self.chunks:
            self.start_ns = min(c.start_ns for c in self.chunks)
            self.end_ns = max(c.end_ns for c in self.chunks)

    # -- block contents --
    def chunk_data(self, chunk: ChunkRef, channels: Collection[int] | None = None) -> dict[int, ChunkMessages]:
        """Per topic id (all, or those in ``channels``): the block's messages in id order. Safe to call from several
        threads at once (a connection per thread; SQLite runs the query without Python's lock)."""
        topic_text, stamp_text, length_text, data, count = self._connection().execute(
            _BLOCK_QUERY, (chunk.start_ns, chunk.offset, chunk.offset + chunk.length)).fetchone()
        try:
            topic, log_time, length = (_ints(topic_text, count), _ints(stamp_text, count),
                                       _ints(length_text, count))
        except ValueError as exc:
            raise BagFormatError(f'{self.path}: the messages with ids from {chunk.offset} do not read back '
                                 f'({exc})') from None
        blob = bytes(data or b'')
        if int(length.sum()) != len(blob):
            raise BagFormatError(f'{self.path}: the messages with ids from {chunk.offset} hold {len(blob)} bytes, '
                                 f'not the {int(length.sum())} their lengths add up to')
        offset = np.zeros(count, np.int64)
        np.cumsum(length[:-1], out=offset[1:])
        buf = np.frombuffer(blob or b'\0', dtype=np.uint8)
        rank = np.arange(count, dtype=np.int64)
        stamps = (log_time + chunk.start_ns).astype(np.uint64)
        out = {}
        for topic_id in (channels if channels is not None else chunk.counts):
            mine = topic == topic_id
            if not mine.any():
                continue
            out[topic_id] = ChunkMessages(
                buf=buf, position=rank[mine], data_offset=offset[mine], data_length=length[mine],
                log_time=stamps[mine], publish_time=stamps[mine], sequence=np.zeros(int(mine.sum()), np.uint32))
        return out

    def chunk_messages(self, chunk: ChunkRef, data: dict[int, ChunkMessages],
                       channels: Collection[int] | None = None) -> dict[int, ChunkMessages]:
        """Per topic id (all, or those in ``channels``): the block's messages read by :meth:`chunk_data`."""
        return {cid: found for cid, found in data.items() if channels is None or cid in channels}

    def iter_chunk_messages(self, chunk: ChunkRef, data: dict[int, ChunkMessages],
                            channels: Collection[int] | None = None) -> Iterator[tuple[int, int, int, int, bytes]]:
        """(topic id, 0, log_time_ns, log_time_ns, data) of the block's messages in id order."""
        yield from in_file_order(self.chunk_messages(chunk, data, channels))

    def partial_chunk_messages(self) -> list[tuple[int, int, int, int, bytes]]:
        """Nothing: an SQLite file has no chunk cut short (same interface as McapFile)."""
        return []


__all__ = ['BLOCK_IDS', 'SQLITE_MAGIC', 'Sqlite3File']
