"""Reading rosbag2 MCAP bags without ROS, with a fast bulk decoder for the rig's fixed-layout message types.

:class:`BagReader` opens a bag directory (through its metadata.yaml, or by scanning ``*.mcap`` when metadata.yaml is
missing, as after a crash) or a single .mcap file. It parses MCAP itself (:class:`McapFile`): the summary when the
file was finished, otherwise a scan of the records that are on disk, so a file cut short by SIGKILL gives every
complete chunk. Damage is reported with :class:`~.errors.BagDamageWarning` (or raised when ``strict=True``) and the
readable part is used.

Bulk decoding (:meth:`BagReader.decode`) works a chunk at a time: decompress, take the message offsets from the
chunk's MessageIndex records, then gather the CDR fields of all messages of a channel at once with numpy. CDR
(XCDR1, little endian): a 4-byte encapsulation header ``00 01 00 00``, then the fields, each aligned to its size
relative to the byte after the header. A ``std_msgs/Header`` is ``int32 sec, uint32 nanosec, uint32 n, n bytes of
frame_id including the NUL``, so the float64 fields after it start at ``4 + align8(12 + n)``; messages are grouped by
``n`` so that a changing frame_id is decoded correctly, and each message's length and NUL are checked.

Times are integer nanoseconds since the epoch (``*_ns``); ``stamp_s`` is the header stamp in seconds (float64).
This module must not import rclpy (the analysis machine may have no ROS).
"""

from __future__ import annotations

import heapq
import itertools
import mmap
import re
import struct
import warnings
import zlib
from collections.abc import Collection, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, NamedTuple

import numpy as np

from crane_stiffness.serde.bulk import SUPPORTED_TYPES, Decoder, gather, new_decoder

from .errors import (
    BagCorruptError, BagDamageWarning, BagFormatError, BagNotFoundError, TopicNotFoundError,
    UnsupportedTypeError,
)
from .metadata import METADATA_FILENAME, read_metadata_yaml

MAGIC = b'\x89MCAP0\r\n'
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_MESSAGE_INDEX, OP_CHUNK_INDEX = range(1, 9)
OP_ATTACHMENT, OP_ATTACHMENT_INDEX, OP_STATISTICS, OP_METADATA, OP_METADATA_INDEX = range(9, 14)
OP_SUMMARY_OFFSET, OP_DATA_END = 14, 15
MESSAGE_HEADER_SIZE = 31
"""Bytes of an MCAP Message record before its data: opcode, length, channel, sequence, log and publish time."""

_U16 = struct.Struct('<H')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')
_RECORD_HEAD = struct.Struct('<BQ')
_FOOTER = struct.Struct('<QQI')
_CHUNK_HEAD = struct.Struct('<QQQI')
_STATS_HEAD = struct.Struct('<QHIIIIQQ')

_MESSAGE_REC = np.dtype({
    'names': ['op', 'length', 'channel', 'sequence', 'log_time', 'publish_time'],
    'formats': ['u1', '<u8', '<u2', '<u4', '<u8', '<u8'],
    'offsets': [0, 1, 9, 11, 15, 23], 'itemsize': MESSAGE_HEADER_SIZE,
})
# ------------------------------------------------------------------------------------------------ MCAP records --
@dataclass(frozen=True)
class SchemaRecord:
    """An MCAP Schema: ``name`` is the type (``pkg/msg/Type``), ``data`` its ros2msg text."""

    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class ChannelRecord:
    """An MCAP Channel: one topic; ``metadata`` holds offered_qos_profiles and topic_type_hash."""

    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


@dataclass
class ChunkRef:
    """Where one chunk's records are in a file; ``index`` maps channel id → offset of its MessageIndex record.

    A run of un-chunked top-level messages is described the same way with ``loose=True`` and no compression.
    """

    offset: int
    records_offset: int
    compressed_size: int
    uncompressed_size: int
    crc: int
    compression: str
    start_ns: int
    end_ns: int
    index: dict[int, int] | None = None
    counts: dict[int, int] = field(default_factory=dict)
    loose: bool = False


class RawMessage(NamedTuple):
    """One serialized message: topic, log (receive) time in ns since the epoch, CDR bytes."""

    topic: str
    log_time_ns: int
    data: bytes


@dataclass(frozen=True)
class TopicInfo:
    """A topic of a bag: type, number of messages, and what is needed to republish it."""

    name: str
    msg_type: str
    count: int
    offered_qos_profiles: str = ''
    type_description_hash: str = ''
    message_definition: str = ''


def _read_str(body: bytes, pos: int) -> tuple[str, int]:
    (size,) = _U32.unpack_from(body, pos)
    pos += 4
    if pos + size > len(body):
        raise ValueError('string runs past the end of its record')
    return body[pos:pos + size].decode('utf-8'), pos + size


def _read_str_map(body: bytes, pos: int) -> tuple[dict[str, str], int]:
    (size,) = _U32.unpack_from(body, pos)
    pos += 4
    end = pos + size
    if end > len(body):
        raise ValueError('map runs past the end of its record')
    out: dict[str, str] = {}
    while pos < end:
        key, pos = _read_str(body, pos)
        out[key], pos = _read_str(body, pos)
    return out, end


def _read_id_map(body: bytes, pos: int) -> tuple[dict[int, int], int]:
    (size,) = _U32.unpack_from(body, pos)
    pos += 4
    if pos + size > len(body) or size % 10:
        raise ValueError('index map runs past the end of its record')
    out = {}
    for item in range(pos, pos + size, 10):
        out[_U16.unpack_from(body, item)[0]] = _U64.unpack_from(body, item + 2)[0]
    return out, pos + size


def _parse_schema(body: bytes) -> SchemaRecord:
    (sid,) = _U16.unpack_from(body, 0)
    name, pos = _read_str(body, 2)
    encoding, pos = _read_str(body, pos)
    (size,) = _U32.unpack_from(body, pos)
    if pos + 4 + size > len(body):
        raise ValueError('schema data runs past the end of its record')
    return SchemaRecord(sid, name, encoding, bytes(body[pos + 4:pos + 4 + size]))


def _parse_channel(body: bytes) -> ChannelRecord:
    cid, sid = struct.unpack_from('<HH', body, 0)
    topic, pos = _read_str(body, 4)
    encoding, pos = _read_str(body, pos)
    meta, _ = _read_str_map(body, pos)
    return ChannelRecord(cid, sid, topic, encoding, meta)


def _parse_metadata(body: bytes) -> tuple[str, dict[str, str]]:
    name, pos = _read_str(body, 0)
    data, _ = _read_str_map(body, pos)
    return name, data


def _parse_chunk_head(buf: Any, offset: int, record_length: int) -> ChunkRef:
    """Chunk record at ``offset`` whose body is ``record_length`` bytes (raises ValueError/struct.error if bad)."""
    body_start = offset + 9
    head = bytes(buf[body_start:body_start + min(record_length, 64 + 256)])
    start_ns, end_ns, usize, crc = _CHUNK_HEAD.unpack_from(head, 0)
    compression, pos = _read_str(head, _CHUNK_HEAD.size)
    (csize,) = _U64.unpack_from(head, pos)
    records_offset = body_start + pos + 8
    if records_offset + csize > body_start + record_length:
        raise ValueError('chunk records run past the end of the chunk record')
    return ChunkRef(offset, records_offset, csize, usize, crc, compression, start_ns, end_ns)


def _walk(data: bytes | memoryview, start: int, end: int) -> Iterator[tuple[int, int, int]]:
    """(opcode, record offset, body length) of the records in ``data[start:end]``; stops at a cut record."""
    pos = start
    unpack = _RECORD_HEAD.unpack_from
    while pos + 9 <= end:
        opcode, length = unpack(data, pos)
        if pos + 9 + length > end:
            return
        yield opcode, pos, length
        pos += 9 + length


# ------------------------------------------------------------------------------------------------- MCAP file --
class McapFile:
    """Structure of one MCAP file: schemas, channels, chunks, metadata records; robust to truncation.

    Args:
        path: the .mcap file.
        strict: raise :class:`BagCorruptError` on damage instead of warning (truncation always only warns).
        verify_crc: check each chunk's CRC32 when it has one.
    """

    def __init__(self, path: str | Path, *, strict: bool = False, verify_crc: bool = True) -> None:
        self.path = Path(path)
        self.strict = strict
        self.verify_crc = verify_crc
        self.problems: list[str] = []
        self.schemas: dict[int, SchemaRecord] = {}
        self.channels: dict[int, ChannelRecord] = {}
        self.chunks: list[ChunkRef] = []
        self.metadata: list[tuple[str, dict[str, str]]] = []
        self.channel_counts: dict[int, int] = {}
        self.profile = ''
        self.library = ''
        self.complete = False
        """True when the file has a valid footer (the writer finished it)."""
        self.readable_end = 0
        """Offset up to which the file's records could be read."""
        self.partial_chunk: int | None = None
        """Offset of a chunk record cut short by the end of the file (its start is on disk)."""
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self._zstd: Any = None
        try:
            self._file = open(self.path, 'rb')
        except FileNotFoundError:
            raise BagNotFoundError(f'MCAP file {self.path} does not exist') from None
        try:
            size = self.path.stat().st_size
            if size < len(MAGIC) or self._file.read(len(MAGIC)) != MAGIC:
                raise BagFormatError(f'{self.path} is not an MCAP file (bad or missing magic bytes)')
            self._buf: Any = mmap.mmap(self._file.fileno(), 0, access=mmap.ACCESS_READ)
            self.size = size
            self._read_header()
            if not self._read_summary():
                self._scan()
        except BaseException:
            self.close()
            raise

    # -- lifetime --
    def close(self) -> None:
        """Release the file; arrays returned earlier stay valid (they are copies)."""
        buf = getattr(self, '_buf', None)
        if buf is not None:
            try:
                buf.close()
            except BufferError:  # a view is still alive somewhere; the GC will release the map
                pass
            self._buf = None
        if getattr(self, '_file', None) is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> McapFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- problems --
    def _problem(self, message: str, *, corrupt: bool = True) -> None:
        text = f'{self.path}: {message}'
        self.problems.append(text)
        if corrupt and self.strict:
            raise BagCorruptError(text)
        warnings.warn(text, BagDamageWarning, stacklevel=4)

    # -- structure --
    def _read_header(self) -> None:
        try:
            opcode, length = _RECORD_HEAD.unpack_from(self._buf, 8)
            if opcode == OP_HEADER and 17 + length <= self.size:
                head = bytes(self._buf[17:17 + length])
                self.profile, pos = _read_str(head, 0)
                self.library, _ = _read_str(head, pos)
        except (struct.error, ValueError, UnicodeDecodeError):
            pass  # reported by the scan if the file is damaged there

    def _read_summary(self) -> bool:
        buf, size = self._buf, self.size
        footer = size - 8 - 29
        if footer < 8 or buf[size - 8:size] != MAGIC or buf[footer] != OP_FOOTER:
            return False
        if _U64.unpack_from(buf, footer + 1)[0] != 20:
            return False
        summary_start, _, crc = _FOOTER.unpack_from(buf, footer + 9)
        if summary_start == 0:
            return False
        if not 8 <= summary_start <= footer:
            self._problem(f'footer points to an impossible summary offset {summary_start}; scanning instead')
            return False
        if crc and zlib.crc32(buf[summary_start:footer + 9 + 16]) != crc:
            self._problem('summary checksum mismatch; scanning the file instead')
            return False
        chunk_indexes: list[tuple[int, int, dict[int, int], int]] = []
        metadata_offsets: list[tuple[int, int]] = []
        stats = None
        summary = bytes(buf[summary_start:footer])
        try:
            for opcode, pos, length in _walk(summary, 0, len(summary)):
                body = summary[pos + 9:pos + 9 + length]
                if opcode == OP_SCHEMA:
                    schema = _parse_schema(body)
                    self.schemas[schema.id] = schema
                elif opcode == OP_CHANNEL:
                    channel = _parse_channel(body)
                    self.channels[channel.id] = channel
                elif opcode == OP_STATISTICS:
                    stats = _STATS_HEAD.unpack_from(body, 0)
                    self.channel_counts, _ = _read_id_map(body, _STATS_HEAD.size)
                elif opcode == OP_CHUNK_INDEX:
                    start_ns, end_ns, offset, length_ = struct.unpack_from('<QQQQ', body, 0)
                    index, pos2 = _read_id_map(body, 32)
                    (index_length,) = _U64.unpack_from(body, pos2)
                    chunk_indexes.append((offset, length_, index if index_length else {}, index_length))
                elif opcode == OP_METADATA_INDEX:
                    offset, length_ = struct.unpack_from('<QQ', body, 0)
                    metadata_offsets.append((offset, length_))
        except (struct.error, ValueError, UnicodeDecodeError) as exc:
            self._problem(f'unreadable summary ({exc}); scanning the file instead')
            self.schemas.clear()
            self.channels.clear()
            self.channel_counts = {}
            return False
        if not chunk_indexes and (stats is None or stats[0] > 0):
            self.schemas.clear()  # un-chunked file, or a summary without chunk indexes: scan
            self.channels.clear()
            self.channel_counts = {}
            return False
        for offset, length_, index, _ in sorted(chunk_indexes):
            try:
                if buf[offset] != OP_CHUNK or offset + length_ > size:
                    raise ValueError('no chunk record at the indexed offset')
                chunk = _parse_chunk_head(buf, offset, length_ - 9)
            except (IndexError, struct.error, ValueError, UnicodeDecodeError) as exc:
                self._problem(f'chunk at offset {offset} is unreadable ({exc}); its messages are skipped')
                continue
            chunk.index = dict(index) if index else None
            self.chunks.append(chunk)
        for offset, length_ in metadata_offsets:
            try:
                if buf[offset] != OP_METADATA:
                    raise ValueError('no metadata record at the indexed offset')
                self.metadata.append(_parse_metadata(bytes(buf[offset + 9:offset + length_])))
            except (IndexError, struct.error, ValueError, UnicodeDecodeError) as exc:
                self._problem(f'metadata record at offset {offset} is unreadable ({exc})')
        if stats is not None:
            self.start_ns, self.end_ns = (stats[6], stats[7]) if stats[0] else (None, None)
        else:
            self._count_from_indexes()
            self._times_from_chunks()
        self.complete = True
        self.readable_end = size
        return True

    def _scan(self) -> None:
        buf, size = self._buf, self.size
        pos = 8
        loose: list[int] = []  # [start, end] of the current run of top-level messages
        last_chunk: ChunkRef | None = None
        stopped = ''
        in_summary = False
        while pos < size:
            if pos + 9 > size:
                stopped = 'cut'
                break
            opcode, length = _RECORD_HEAD.unpack_from(buf, pos)
            end = pos + 9 + length
            if opcode == 0 or 0x10 <= opcode < 0x80:
                stopped = 'corrupt'
                break
            if end > size:
                if opcode == OP_CHUNK:
                    self.partial_chunk = pos
                stopped = 'cut'
                break
            if opcode in (OP_MESSAGE, OP_SCHEMA, OP_CHANNEL) and not in_summary and (opcode == OP_MESSAGE or loose):
                if not loose:
                    loose[:] = [pos, end]
                loose[1] = end
            elif loose:
                self._add_loose(loose)
                loose = []
            try:
                if opcode == OP_HEADER:
                    head = bytes(buf[pos + 9:end])
                    self.profile, p2 = _read_str(head, 0)
                    self.library, _ = _read_str(head, p2)
                elif opcode == OP_SCHEMA:
                    schema = _parse_schema(bytes(buf[pos + 9:end]))
                    self.schemas[schema.id] = schema
                elif opcode == OP_CHANNEL:
                    channel = _parse_channel(bytes(buf[pos + 9:end]))
                    self.channels[channel.id] = channel
                elif opcode == OP_CHUNK and not in_summary:
                    last_chunk = _parse_chunk_head(buf, pos, length)
                    self.chunks.append(last_chunk)
                elif opcode == OP_MESSAGE_INDEX and last_chunk is not None and not in_summary:
                    channel_id, records = struct.unpack_from('<HI', buf, pos + 9)
                    if 6 + records > length or records % 16:
                        raise ValueError('message index longer than its record')
                    if last_chunk.index is None:
                        last_chunk.index = {}
                    last_chunk.index[channel_id] = pos
                    last_chunk.counts[channel_id] = records // 16
                elif opcode == OP_METADATA and not in_summary:
                    self.metadata.append(_parse_metadata(bytes(buf[pos + 9:end])))
                elif opcode == OP_DATA_END:
                    in_summary = True
                elif opcode == OP_FOOTER:
                    self.complete = True
                    pos = end
                    break
            except (struct.error, ValueError, UnicodeDecodeError) as exc:
                if opcode == OP_CHUNK:
                    self._problem(f'chunk at offset {pos} is unreadable ({exc}); its messages are skipped')
                else:
                    self._problem(f'record (opcode {opcode:#04x}) at offset {pos} is unreadable ({exc})')
            pos = end
        if loose:
            self._add_loose(loose)
        self.readable_end = pos
        if stopped == 'corrupt':
            self._problem(f'unreadable bytes at offset {pos} (opcode {buf[pos]:#04x}); the {size - pos} bytes '
                          f'from there on are ignored')
        elif stopped == 'cut' or not self.complete:
            self._problem(
                f'file is truncated or unfinished (no footer): read {len(self.chunks)} complete chunk(s), '
                f'ignored the last {size - pos} byte(s) from offset {pos}'
                '; `python -m crane_stiffness.bag.recover` rewrites it as a valid file', corrupt=False)
        self._discover_channels()
        self._times_from_chunks()

    def _add_loose(self, run: list[int]) -> None:
        start, end = run
        self.chunks.append(ChunkRef(start, start, end - start, end - start, 0, '', 0, 2**64 - 1, loose=True))

    def _discover_channels(self) -> None:
        """Find schemas/channels inside chunks (where writers put them) and count messages of un-indexed chunks."""
        for chunk in self.chunks:
            if chunk.index is not None and set(chunk.index) <= set(self.channels):
                continue
            data = self.chunk_data(chunk)
            if data is None:
                continue
            table, others = self._chunk_layout(chunk, data, None)
            raw = data.tobytes() if others else b''
            for opcode, pos, length in others:
                try:
                    if opcode == OP_SCHEMA:
                        schema = _parse_schema(raw[pos + 9:pos + 9 + length])
                        self.schemas[schema.id] = schema
                    elif opcode == OP_CHANNEL:
                        channel = _parse_channel(raw[pos + 9:pos + 9 + length])
                        self.channels[channel.id] = channel
                except (struct.error, ValueError, UnicodeDecodeError) as exc:
                    self._problem(f'record in chunk at offset {chunk.offset} is unreadable ({exc})')
            if chunk.index is None:
                chunk.counts = {cid: len(offsets) for cid, offsets in table.items()}
                if chunk.loose and table:
                    times = [gather(data, offsets, '<u8') for offsets in
                             [o + 15 for o in table.values()]]
                    merged = np.concatenate(times)
                    chunk.start_ns, chunk.end_ns = int(merged.min()), int(merged.max())
        self._count_from_indexes()

    def _count_from_indexes(self) -> None:
        counts: dict[int, int] = {}
        for chunk in self.chunks:
            for cid, count in chunk.counts.items():
                counts[cid] = counts.get(cid, 0) + count
            if chunk.index is not None and not chunk.counts:
                for cid, pos in chunk.index.items():
                    (records,) = _U32.unpack_from(self._buf, pos + 11)
                    chunk.counts[cid] = records // 16
                    counts[cid] = counts.get(cid, 0) + records // 16
        self.channel_counts = counts

    def _times_from_chunks(self) -> None:
        real = [c for c in self.chunks if c.counts or c.index is None]
        real = [c for c in real if not (c.loose and c.end_ns == 2**64 - 1)]
        if real:
            self.start_ns = min(c.start_ns for c in real)
            self.end_ns = max(c.end_ns for c in real)

    # -- chunk contents --
    def chunk_data(self, chunk: ChunkRef) -> np.ndarray | None:
        """The chunk's uncompressed records as a uint8 array, or None (with a warning) when damaged."""
        raw = self._buf[chunk.records_offset:chunk.records_offset + chunk.compressed_size]
        try:
            if chunk.compression == '':
                data = raw
            elif chunk.compression == 'zstd':
                if self._zstd is None:
                    import zstandard
                    self._zstd = zstandard.ZstdDecompressor()
                data = self._zstd.decompress(raw, max_output_size=chunk.uncompressed_size)
            elif chunk.compression == 'lz4':
                import lz4.frame
                data = lz4.frame.decompress(raw)
            else:
                self._problem(f'chunk at offset {chunk.offset} uses unsupported compression '
                              f'{chunk.compression!r}; skipped')
                return None
        except Exception as exc:  # zstd/lz4 raise their own error types on damaged input
            self._problem(f'chunk at offset {chunk.offset} does not decompress ({exc}); its messages are skipped')
            return None
        if len(data) != chunk.uncompressed_size:
            self._problem(f'chunk at offset {chunk.offset} decompressed to {len(data)} bytes, '
                          f'expected {chunk.uncompressed_size}; its messages are skipped')
            return None
        if self.verify_crc and chunk.crc and zlib.crc32(data) != chunk.crc:
            self._problem(f'chunk at offset {chunk.offset} fails its CRC check; its messages are skipped')
            return None
        return np.frombuffer(data, dtype=np.uint8)

    def _index_offsets(self, pos: int) -> np.ndarray:
        channel_id, records = struct.unpack_from('<HI', self._buf, pos + 9)
        raw = self._buf[pos + 15:pos + 15 + records]
        pairs = np.frombuffer(raw, dtype='<u8').reshape(-1, 2)
        return np.sort(pairs[:, 1].astype(np.int64))

    def _chunk_layout(self, chunk: ChunkRef, data: np.ndarray, channels: Collection[int] | None
                      ) -> tuple[dict[int, np.ndarray], list[tuple[int, int, int]]]:
        """Message offsets per channel in ``data`` (file order), and the other records (opcode, offset, length).

        The other records are only looked for when ``channels`` is None.
        """
        size = data.size
        if chunk.index is not None:
            table = {cid: self._index_offsets(pos) for cid, pos in chunk.index.items()
                     if channels is None or cid in channels}
            if channels is not None:
                return table, []
            if not table:
                return table, list(_walk(data.tobytes(), 0, size))
            offsets = np.sort(np.concatenate(list(table.values())))
            offsets = offsets[offsets + 9 <= size]
            ends = offsets + 9 + gather(data, offsets + 1, '<u8').astype(np.int64)
            starts = np.concatenate([[0], ends])
            stops = np.concatenate([offsets, [size]])
            gaps = [(int(a), int(b)) for a, b in zip(starts, stops) if b > a]
            others: list[tuple[int, int, int]] = []
            if gaps:
                raw = data.tobytes()
                for a, b in gaps:
                    others.extend(r for r in _walk(raw, a, b) if r[0] != OP_MESSAGE)
            return table, others
        raw = data.tobytes()
        found: dict[int, list[int]] = {}
        others = []
        for opcode, pos, length in _walk(raw, 0, size):
            if opcode == OP_MESSAGE and length >= 22:
                cid = _U16.unpack_from(raw, pos + 9)[0]
                if channels is None or cid in channels:
                    found.setdefault(cid, []).append(pos)
            elif channels is None:
                others.append((opcode, pos, length))
        return {cid: np.asarray(v, dtype=np.int64) for cid, v in found.items()}, others

    def message_headers(self, chunk: ChunkRef, data: np.ndarray, channels: Collection[int] | None
                        ) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Per channel: (valid record offsets, their 31-byte MCAP message headers), damaged entries dropped."""
        table, _ = self._chunk_layout(chunk, data, channels)
        result = {}
        for cid, offsets in table.items():
            inside = (offsets >= 0) & (offsets + MESSAGE_HEADER_SIZE <= data.size)
            head = gather(data, np.where(inside, offsets, 0), _MESSAGE_REC)
            ok = (inside & (head['op'] == OP_MESSAGE) & (head['channel'] == cid) & (head['length'] >= 22)
                  & (offsets + 9 + head['length'].astype(np.int64) <= data.size))
            if not ok.all():
                self._problem(f'{int((~ok).sum())} message index entries of channel {cid} in chunk at offset '
                              f'{chunk.offset} do not point at messages; those messages are skipped')
                offsets, head = offsets[ok], head[ok]
            result[cid] = (offsets, head)
        return result

    def iter_chunk_messages(self, chunk: ChunkRef, data: np.ndarray, channels: Collection[int] | None = None
                            ) -> Iterator[tuple[int, int, int, int, bytes]]:
        """(channel id, sequence, log_time_ns, publish_time_ns, data) of a chunk's messages in file order."""
        heads = self.message_headers(chunk, data, channels)
        if not heads:
            return
        offsets = np.concatenate([o for o, _ in heads.values()])
        head = np.concatenate([h for _, h in heads.values()])
        order = np.argsort(offsets, kind='stable')
        raw = data.tobytes()
        for off, rec in zip(offsets[order].tolist(), head[order].tolist()):
            _, length, cid, seq, log, pub = rec
            yield cid, seq, log, pub, raw[off + MESSAGE_HEADER_SIZE:off + 9 + length]

    def partial_chunk_messages(self) -> list[tuple[int, int, int, int, bytes]]:
        """Complete messages at the start of a chunk cut short by the end of the file (for recovery)."""
        if self.partial_chunk is None:
            return []
        buf, pos = self._buf, self.partial_chunk
        try:
            start_ns, end_ns, usize, _ = _CHUNK_HEAD.unpack_from(buf, pos + 9)
            compression, p2 = _read_str(bytes(buf[pos + 9 + _CHUNK_HEAD.size:pos + 9 + _CHUNK_HEAD.size + 260]), 0)
            records_offset = pos + 9 + _CHUNK_HEAD.size + p2 + 8
            raw = bytes(buf[records_offset:self.size])
            if compression == '':
                data = raw
            elif compression == 'zstd':
                import zstandard
                data = zstandard.ZstdDecompressor().decompressobj().decompress(raw)
            elif compression == 'lz4':
                import lz4.frame
                data = lz4.frame.LZ4FrameDecompressor().decompress(raw)
            else:
                return []
        except Exception:  # whatever is left of the chunk is not decodable: nothing to save
            return []
        out = []
        for opcode, p, length in _walk(data, 0, min(len(data), usize)):
            if opcode == OP_MESSAGE and length >= 22:
                cid, seq, log, pub = struct.unpack_from('<HIQQ', data, p + 9)
                out.append((cid, seq, log, pub, data[p + MESSAGE_HEADER_SIZE:p + 9 + length]))
        return out


# -------------------------------------------------------------------------------------------------- bag reader --
def _file_order(path: Path) -> tuple[str, int]:
    match = re.match(r'^(.*?)(?:_(\d+))?\.mcap$', path.name)
    assert match
    return match.group(1), int(match.group(2) or 0)


class BagReader:
    """Read a rosbag2 bag directory, or one .mcap file. Use as a context manager.

    Args:
        path: bag directory (with or without metadata.yaml) or a .mcap file.
        strict: raise :class:`~.errors.BagCorruptError` on damaged data instead of warning and skipping it.
        verify_crc: check chunk CRCs (cheap; catches corrupted bytes).
    """

    def __init__(self, path: str | Path, *, strict: bool = False, verify_crc: bool = True) -> None:
        self.path = Path(path)
        self.bag_metadata: dict[str, Any] | None = None
        """The ``rosbag2_bagfile_information`` of metadata.yaml, when present and readable."""
        self._problems: list[str] = []
        self._files: list[McapFile] = []
        if not self.path.exists():
            raise BagNotFoundError(f'bag {self.path} does not exist')
        paths = self._resolve_files(strict)
        try:
            for file_path in paths:
                self._files.append(McapFile(file_path, strict=strict, verify_crc=verify_crc))
        except BaseException:
            self.close()
            raise

    @property
    def problems(self) -> list[str]:
        """Every damage found so far (also reported as BagDamageWarning): bag level, then per file."""
        return self._problems + [p for f in self._files for p in f.problems]

    def _warn(self, message: str) -> None:
        self._problems.append(message)
        warnings.warn(message, BagDamageWarning, stacklevel=3)

    def _resolve_files(self, strict: bool) -> list[Path]:
        if self.path.is_file():
            return [self.path]
        meta_path = self.path / METADATA_FILENAME
        if meta_path.is_file():
            try:
                info = read_metadata_yaml(self.path)
                names = [str(n) for n in info['relative_file_paths']]
                self.bag_metadata = info
            except Exception as exc:  # any YAML or layout problem: fall back to the files on disk
                self._warn(f'{meta_path} is unreadable ({exc}); reading the .mcap files in {self.path} instead')
            else:
                found = [self.path / n for n in names]
                missing = [p for p in found if not p.is_file()]
                if missing:
                    self._warn(f'{meta_path} lists missing file(s) {", ".join(p.name for p in missing)}')
                present = [p for p in found if p.is_file()]
                if present:
                    return present
        files = sorted(self.path.glob('*.mcap'), key=_file_order)
        if not files:
            raise BagNotFoundError(f'{self.path} holds no metadata.yaml and no .mcap file')
        return files

    # -- lifetime --
    def close(self) -> None:
        """Close the files."""
        for mcap_file in getattr(self, '_files', []):
            mcap_file.close()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- overview --
    @property
    def files(self) -> list[Path]:
        """The .mcap files read, in order."""
        return [f.path for f in self._files]

    @property
    def complete(self) -> bool:
        """True when every file was finished by its writer (has a footer)."""
        return all(f.complete for f in self._files)

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topic name → :class:`TopicInfo` (type, message count, QoS, type hash, definition), all files."""
        out: dict[str, TopicInfo] = {}
        for mcap_file in self._files:
            for cid, channel in mcap_file.channels.items():
                schema = mcap_file.schemas.get(channel.schema_id)
                count = mcap_file.channel_counts.get(cid, 0)
                previous = out.get(channel.topic)
                if previous is not None:
                    out[channel.topic] = TopicInfo(previous.name, previous.msg_type, previous.count + count,
                                                   previous.offered_qos_profiles, previous.type_description_hash,
                                                   previous.message_definition)
                    continue
                out[channel.topic] = TopicInfo(
                    name=channel.topic, msg_type=schema.name if schema else '', count=count,
                    offered_qos_profiles=channel.metadata.get('offered_qos_profiles', ''),
                    type_description_hash=channel.metadata.get('topic_type_hash', ''),
                    message_definition=schema.data.decode('utf-8', 'replace') if schema else '')
        return out

    @property
    def message_count(self) -> int:
        """Messages in the readable part of the bag."""
        return sum(sum(f.channel_counts.values()) for f in self._files)

    @property
    def start_ns(self) -> int | None:
        """Log time of the first message, ns since the epoch (None for an empty bag)."""
        times = [f.start_ns for f in self._files if f.start_ns is not None]
        return min(times) if times else None

    @property
    def end_ns(self) -> int | None:
        """Log time of the last message, ns since the epoch (None for an empty bag)."""
        times = [f.end_ns for f in self._files if f.end_ns is not None]
        return max(times) if times else None

    @property
    def duration_ns(self) -> int:
        """end_ns - start_ns (0 for an empty bag)."""
        return (self.end_ns - self.start_ns) if self.start_ns is not None and self.end_ns is not None else 0

    def metadata_records(self, include_rosbag2: bool = False) -> dict[str, dict[str, str]]:
        """MCAP Metadata records, name → {key: value}; a name repeated (e.g. in split files) keeps the last.

        The ``rosbag2`` record (rosbag2's own serialized metadata) is left out unless ``include_rosbag2``.
        """
        out: dict[str, dict[str, str]] = {}
        for mcap_file in self._files:
            for name, data in mcap_file.metadata:
                if include_rosbag2 or name != 'rosbag2':
                    out[name] = dict(data)
        return out

    # -- topics --
    def _channels_for(self, topics: Iterable[str]) -> list[dict[int, str]]:
        wanted = list(topics)
        known = self.topics
        for topic in wanted:
            if topic not in known:
                present = ', '.join(f'{t} [{i.msg_type}]' for t, i in sorted(known.items())) or 'none'
                raise TopicNotFoundError(f'topic {topic!r} is not in bag {self.path}; topics present: {present}')
        return [{cid: ch.topic for cid, ch in f.channels.items() if ch.topic in wanted} for f in self._files]

    def _chunks(self, per_file: list[dict[int, str]], start_ns: int | None, end_ns: int | None
                ) -> Iterator[tuple[McapFile, ChunkRef, dict[int, str]]]:
        for mcap_file, channels in zip(self._files, per_file):
            if not channels:
                continue
            for chunk in mcap_file.chunks:
                if chunk.index is not None and not set(chunk.index) & set(channels):
                    continue
                if not chunk.loose and ((start_ns is not None and chunk.end_ns < start_ns)
                                        or (end_ns is not None and chunk.start_ns >= end_ns)):
                    continue
                yield mcap_file, chunk, channels

    # -- raw messages --
    def messages(self, topics: Iterable[str] | None = None, *, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[RawMessage]:
        """Serialized messages in log-time order, optionally only some topics and ``start_ns <= t < end_ns``."""
        per_file = self._channels_for(self.topics if topics is None else topics)
        heap: list[tuple[int, int, str, bytes]] = []
        order = itertools.count()
        for mcap_file, chunk, channels in self._chunks(per_file, start_ns, end_ns):
            if not chunk.loose:
                while heap and heap[0][0] < chunk.start_ns:
                    log, _, topic, data = heapq.heappop(heap)
                    yield RawMessage(topic, log, data)
            data_array = mcap_file.chunk_data(chunk)
            if data_array is None:
                continue
            for cid, _, log, _, payload in mcap_file.iter_chunk_messages(chunk, data_array, channels):
                if (start_ns is None or log >= start_ns) and (end_ns is None or log < end_ns):
                    heapq.heappush(heap, (log, next(order), channels[cid], payload))
        while heap:
            log, _, topic, data = heapq.heappop(heap)
            yield RawMessage(topic, log, data)

    def __iter__(self) -> Iterator[RawMessage]:
        return self.messages()

    # -- bulk decoding --
    def decode(self, topic: str, *, start_ns: int | None = None, end_ns: int | None = None) -> np.ndarray:
        """All messages of ``topic`` as a numpy structured array, one row per message in log-time order.

        Fields: ``log_time_ns`` (int64, ns since the epoch); for stamped types ``stamp_sec``, ``stamp_nanosec``,
        ``stamp_s`` (float64 s), ``frame_id`` (bytes; ``.astype(str)`` for text); then per type:
        WrenchStamped ``fx fy fz`` [N] ``mx my mz`` [N m]; PointStamped ``x y z``; PoseStamped ``x y z`` and the
        quaternion ``qx qy qz qw``; Float64 ``data``; JointState ``name`` (bytes, per joint), ``position``,
        ``velocity``, ``effort`` (float64 per joint, NaN when absent). Units are those of the publisher (SI on
        the rig: m, N, N m).
        """
        return self.decode_topics([topic], start_ns=start_ns, end_ns=end_ns)[topic]

    def decode_topics(self, topics: Sequence[str], *, start_ns: int | None = None,
                      end_ns: int | None = None) -> dict[str, np.ndarray]:
        """Like :meth:`decode` for several topics in one pass over the file (each chunk decompressed once)."""
        known = self.topics
        per_file = self._channels_for(topics)
        decoders: dict[str, Decoder] = {}
        for topic in topics:
            msg_type = known[topic].msg_type
            decoder = new_decoder(msg_type)
            if decoder is None:
                raise UnsupportedTypeError(f'topic {topic} has type {msg_type}, which the bulk decoder does not '
                                           f'handle (supported: {", ".join(SUPPORTED_TYPES)}); use messages()')
            decoders[topic] = decoder
        parts: dict[str, list[dict[str, np.ndarray]]] = {t: [] for t in topics}
        for mcap_file, chunk, channels in self._chunks(per_file, start_ns, end_ns):
            data = mcap_file.chunk_data(chunk)
            if data is None:
                continue
            for cid, (offsets, head) in mcap_file.message_headers(chunk, data, channels).items():
                if not offsets.size:
                    continue
                topic = channels[cid]
                length = head['length'].astype(np.int64) - 22
                cols, valid = decoders[topic].decode(data, offsets + MESSAGE_HEADER_SIZE, length)
                if not valid.all():
                    text = (f'{mcap_file.path}: {int((~valid).sum())} message(s) of {topic} in chunk at offset '
                            f'{chunk.offset} do not have the {decoders[topic].msg_type} layout; skipped')
                    if mcap_file.strict:
                        raise BagCorruptError(text)
                    self._warn(text)
                    if not valid.any():
                        continue
                cols = {k: v[valid] for k, v in cols.items()}
                cols['log_time_ns'] = head['log_time'][valid].astype(np.int64)
                parts[topic].append(cols)
        return {topic: self._assemble(decoders[topic], parts[topic], start_ns, end_ns) for topic in topics}

    @staticmethod
    def _assemble(decoder: Decoder, parts: list[dict[str, np.ndarray]], start_ns: int | None,
                  end_ns: int | None) -> np.ndarray:
        if not parts:
            return decoder.empty()
        columns = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
        log = columns['log_time_ns']
        keep = np.ones(log.size, bool)
        if start_ns is not None:
            keep &= log >= start_ns
        if end_ns is not None:
            keep &= log < end_ns
        if not keep.all():
            columns = {k: v[keep] for k, v in columns.items()}
            log = columns['log_time_ns']
        if log.size > 1 and not (np.diff(log) >= 0).all():
            order = np.argsort(log, kind='stable')
            columns = {k: v[order] for k, v in columns.items()}
        return decoder.to_array(columns)


__all__ = [
    'BagReader', 'ChannelRecord', 'ChunkRef', 'McapFile', 'RawMessage', 'SUPPORTED_TYPES', 'SchemaRecord',
    'TopicInfo',
]
