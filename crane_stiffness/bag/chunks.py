"""The inside of MCAP chunks: where a chunk is, decompressing it, and gathering its messages with numpy.

The ``mcap`` package reads the Chunk records; this module works on their decompressed records. In a chunk with a
message index, the messages of a channel are gathered at once: the MessageIndex records give their offsets (read as
one numpy array each), and one numpy fancy index copies their 31-byte record headers (length, channel, sequence,
log and publish time). The library's ``MessageIndex.read`` and ``Message.read`` build a Python object per message
(~2 µs each, more than the whole bulk decode costs), so they serve only chunks without a message index, messages
outside chunks, and the complete messages at the start of a chunk cut short by a crash.
"""
from __future__ import annotations

import struct
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass, field
from io import BytesIO
from typing import Any

import numpy as np
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.data_stream import ReadDataStream
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader

from crane_stiffness.serde.bulk import gather

READ_ERRORS = (McapError, struct.error, ValueError, IndexError, KeyError, ArithmeticError)
"""What the library (with struct and UTF-8 decoding under it) raises on damaged or cut data."""
COMPRESSIONS = ('', 'zstd', 'lz4')
"""Chunk compressions that can be read."""
MESSAGE_HEADER_SIZE = 31
"""Bytes of an MCAP Message record before its data: opcode, length, channel, sequence, log and publish time."""
_RECORD_HEAD = struct.Struct('<BQ')
_READERS: dict[int, Any] = {Opcode.SCHEMA: Schema.read, Opcode.CHANNEL: Channel.read, Opcode.MESSAGE: Message.read}

_MESSAGE_HEADER = np.dtype({
    'names': ['op', 'length', 'channel', 'sequence', 'log_time', 'publish_time'],
    'formats': ['u1', '<u8', '<u2', '<u4', '<u8', '<u8'],
    'offsets': [0, 1, 9, 11, 15, 23], 'itemsize': MESSAGE_HEADER_SIZE,
})
_MESSAGE_INDEX_HEAD = np.dtype({
    'names': ['op', 'length', 'channel', 'records_length'], 'formats': ['u1', '<u8', '<u2', '<u4'],
    'offsets': [0, 1, 9, 11], 'itemsize': 15,
})


@dataclass
class ChunkRef:
    """Where one chunk is in a file. ``index`` maps channel id → file offset of its MessageIndex record (None when
    the chunk has no index); ``offsets`` holds the message offsets per channel when a scan already read them.

    A run of messages outside chunks is described the same way with ``loose=True`` and no compression.
    """

    offset: int
    records_offset: int
    compressed_size: int
    uncompressed_size: int
    compression: str
    start_ns: int
    end_ns: int
    length: int = 0
    """Bytes of the whole Chunk record (opcode and length included); its MessageIndex records follow it."""
    index_length: int = 0
    """Bytes of the chunk's MessageIndex records."""
    index: dict[int, int] | None = None
    counts: dict[int, int] = field(default_factory=dict)
    offsets: dict[int, np.ndarray] | None = None
    loose: bool = False


@dataclass
class ChunkMessages:
    """The messages of one channel in one chunk, in file order: CDR data at ``buf[data_offset:+data_length]``."""

    buf: np.ndarray
    position: np.ndarray
    """Order of the messages in the chunk (byte offset of their records, or their rank)."""
    data_offset: np.ndarray
    data_length: np.ndarray
    log_time: np.ndarray
    publish_time: np.ndarray
    sequence: np.ndarray

    def __len__(self) -> int:
        return int(self.position.size)


def decompress(compression: str, data: bytes, size: int, zstd: Any = None) -> bytes:
    """Uncompressed records of a chunk (``compression`` in :data:`COMPRESSIONS`); zstd/lz4 raise their own errors on
    damaged input. ``zstd``: a ``zstandard.ZstdDecompressor`` to reuse."""
    if compression == 'zstd':
        if zstd is None:
            import zstandard
            zstd = zstandard.ZstdDecompressor()
        return zstd.decompress(data, max_output_size=size)
    if compression == 'lz4':
        import lz4.frame
        return lz4.frame.decompress(data)
    return data


def records_in(data: bytes) -> list[Any]:
    """The Schema, Channel and Message records of uncompressed chunk records (or of a run of records outside
    chunks), each read by the library from its own body: as the MCAP specification requires, bytes after a record's
    known fields (padding, fields of a later version) are skipped by its length, and records of other or unknown
    opcodes are skipped whole. Raises one of :data:`READ_ERRORS` on a record cut short."""
    out: list[Any] = []
    view = memoryview(data)
    pos, size = 0, len(data)
    while pos < size:
        if pos + 9 > size:
            raise ValueError(f'record header cut short at byte {pos} of {size}')
        opcode, length = _RECORD_HEAD.unpack_from(data, pos)
        end = pos + 9 + length
        if end > size:
            raise ValueError(f'record (opcode {opcode:#04x}) at byte {pos} runs past the end ({end} > {size})')
        if opcode in _READERS:
            stream = ReadDataStream(BytesIO(view[pos + 9:end]))
            out.append(Message.read(stream, length) if opcode == Opcode.MESSAGE else _READERS[opcode](stream))
        pos = end
    return out


def index_offsets(region: bytes, region_offset: int, index: Mapping[int, int]
                  ) -> tuple[dict[int, np.ndarray], list[int]]:
    """Per channel, the sorted offsets of its messages in the chunk, from the chunk's MessageIndex records.

    Args:
        region: the bytes of the chunk's MessageIndex records, read from ``region_offset`` of the file.
        index: channel id → file offset of its MessageIndex record.

    Returns:
        the offsets, and the channels whose record is damaged (left out).
    """
    out, bad = {}, []
    for cid, pos in index.items():
        rel = pos - region_offset
        head = np.frombuffer(region, _MESSAGE_INDEX_HEAD, count=1, offset=rel)[0] \
            if 0 <= rel <= len(region) - _MESSAGE_INDEX_HEAD.itemsize else None
        size = int(head['records_length']) if head is not None else -1
        if head is None or head['op'] != Opcode.MESSAGE_INDEX or head['channel'] != cid or size % 16 \
                or rel + _MESSAGE_INDEX_HEAD.itemsize + size > len(region):
            bad.append(cid)
            continue
        entries = np.frombuffer(region, '<u8', count=size // 8, offset=rel + _MESSAGE_INDEX_HEAD.itemsize)
        out[cid] = np.sort(entries[1::2].astype(np.int64), kind='stable')  # in order already: timsort is O(n)
    return out, bad


def gather_messages(data: np.ndarray, offsets: Mapping[int, np.ndarray], channels: Collection[int] | None
                    ) -> tuple[dict[int, ChunkMessages], dict[int, int]]:
    """The messages of each channel (all, or those in ``channels``) at their indexed ``offsets`` in the
    decompressed chunk ``data``: (per channel, number of index entries per channel that do not point at one of its
    messages, left out)."""
    result, bad = {}, {}
    for cid, found in offsets.items():
        if channels is not None and cid not in channels:
            continue
        inside = (found >= 0) & (found + MESSAGE_HEADER_SIZE <= data.size)
        head = gather(data, np.where(inside, found, 0), _MESSAGE_HEADER)
        ok = (inside & (head['op'] == Opcode.MESSAGE) & (head['channel'] == cid) & (head['length'] >= 22)
              & (found + 9 + head['length'].astype(np.int64) <= data.size))
        if not ok.all():
            bad[cid] = int((~ok).sum())
            found, head = found[ok], head[ok]
        result[cid] = ChunkMessages(
            buf=data, position=found, data_offset=found + MESSAGE_HEADER_SIZE,
            data_length=head['length'].astype(np.int64) - 22, log_time=head['log_time'],
            publish_time=head['publish_time'], sequence=head['sequence'])
    return result, bad


def messages_from_records(records: Iterable[Any], channels: Collection[int] | None) -> dict[int, ChunkMessages]:
    """Per channel, the library's Message records among ``records`` as :class:`ChunkMessages`."""
    wanted: dict[int, list[tuple[int, Message]]] = {}
    for rank, message in enumerate(r for r in records if isinstance(r, Message)):
        if channels is None or message.channel_id in channels:
            wanted.setdefault(message.channel_id, []).append((rank, message))
    out = {}
    for cid, items in wanted.items():
        lengths = np.array([len(m.data) for _, m in items], dtype=np.int64)
        out[cid] = ChunkMessages(
            buf=np.frombuffer(b''.join(m.data for _, m in items) or b'\0', dtype=np.uint8),
            position=np.array([r for r, _ in items], dtype=np.int64),
            data_offset=np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64), data_length=lengths,
            log_time=np.array([m.log_time for _, m in items], dtype=np.uint64),
            publish_time=np.array([m.publish_time for _, m in items], dtype=np.uint64),
            sequence=np.array([m.sequence for _, m in items], dtype=np.uint32))
    return out


def in_file_order(tables: Mapping[int, ChunkMessages]) -> list[tuple[int, int, int, int, bytes]]:
    """(channel id, sequence, log time, publish time, data) of the messages of ``tables`` in file order."""
    raws: dict[int, bytes] = {}
    rows = []
    for cid, table in tables.items():
        raw = raws.get(id(table.buf))
        if raw is None:
            raw = raws[id(table.buf)] = table.buf.tobytes()
        for pos, start, size, log, pub, seq in zip(
                table.position.tolist(), table.data_offset.tolist(), table.data_length.tolist(),
                table.log_time.tolist(), table.publish_time.tolist(), table.sequence.tolist()):
            rows.append((pos, cid, seq, log, pub, raw[start:start + size]))
    rows.sort(key=lambda row: row[0])
    return [row[1:] for row in rows]


def partial_chunk_messages(chunk: Chunk) -> list[tuple[int, int, int, int, bytes]]:
    """(channel id, sequence, log time, publish time, data) of the complete messages at the start of a chunk whose
    ``data`` the end of the file cut short (a zstd or lz4 stream decompresses up to the cut)."""
    try:
        if chunk.compression == 'zstd':
            import zstandard
            data = zstandard.ZstdDecompressor().decompressobj().decompress(chunk.data)
        elif chunk.compression == 'lz4':
            import lz4.frame
            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data)
        elif chunk.compression == '':
            data = chunk.data
        else:
            return []
    except Exception:  # whatever is left of the chunk is not decodable: nothing to save
        return []
    out = []
    records = StreamReader(BytesIO(data[:chunk.uncompressed_size]), skip_magic=True).records
    while True:
        try:
            record = next(records)
        except (StopIteration, *READ_ERRORS):  # the end of what decompressed: a cut record
            break
        if isinstance(record, Message):
            out.append((record.channel_id, record.sequence, record.log_time, record.publish_time, record.data))
    return out
