"""One MCAP file of a bag, its records read by the ``mcap`` package; robust to truncation and damage.

The ``mcap`` package reads the records: the header, the summary of a finished file (``SeekingReader.get_summary``),
each raw chunk (``StreamReader(..., emit_chunks=True)`` at the chunk's offset) and, for a file its writer never
finished (killed by SIGKILL), every record on disk in order up to the library's end-of-data error where the file
was cut, so such a file still gives every complete chunk. Damage is reported with
:class:`~.errors.BagDamageWarning` (raised as :class:`~.errors.BagCorruptError` when ``strict``) and the readable
part is used.

Ours is what makes reading fast and safe: decompression with the chunk's CRC check, and the vectorised gather of the
messages inside a decompressed chunk. Their offsets come from the chunk's MessageIndex records, each read as one
numpy array; their 31-byte record headers (length, channel, sequence, log and publish time) are gathered with one
numpy fancy index per channel. The library's ``MessageIndex.read`` and ``Message.read`` build Python objects at
about 2 µs per message, more than the whole bulk decode costs; they are used only where a chunk has no message
index (or for messages outside chunks).
"""
from __future__ import annotations

import struct
import warnings
import zlib
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import FOOTER_SIZE, SeekingReader
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Message, MessageIndex, Metadata, Schema
from mcap.stream_reader import MAGIC_SIZE, StreamReader, breakup_chunk, read_magic

from crane_stiffness.serde.bulk import gather

from .errors import BagCorruptError, BagDamageWarning, BagFormatError, BagNotFoundError

MESSAGE_HEADER_SIZE = 31
"""Bytes of an MCAP Message record before its data: opcode, length, channel, sequence, log and publish time."""

_MESSAGE_HEADER = np.dtype({
    'names': ['op', 'length', 'channel', 'sequence', 'log_time', 'publish_time'],
    'formats': ['u1', '<u8', '<u2', '<u4', '<u8', '<u8'],
    'offsets': [0, 1, 9, 11, 15, 23], 'itemsize': MESSAGE_HEADER_SIZE,
})
_MESSAGE_INDEX_HEAD = np.dtype({
    'names': ['op', 'length', 'channel', 'records_length'], 'formats': ['u1', '<u8', '<u2', '<u4'],
    'offsets': [0, 1, 9, 11], 'itemsize': 15,
})
_READ_ERRORS = (McapError, struct.error, ValueError, IndexError, KeyError, ArithmeticError, EOFError, OSError)
"""What the library (with struct and UTF-8 decoding under it) raises on damaged or cut data."""
_OPCODES = frozenset(int(op) for op in Opcode)
_LOOSE_END = 2**64 - 1


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


def _raw_chunk(data: bytes) -> Chunk:
    """Uncompressed chunk records as a Chunk record, for the library's ``breakup_chunk``."""
    return Chunk(compression='', data=data, message_end_time=0, message_start_time=0, uncompressed_crc=0,
                 uncompressed_size=len(data))


def _from_records(messages: list[Message], channels: Collection[int] | None) -> dict[int, ChunkMessages]:
    """Per channel, the library's Message records as :class:`ChunkMessages` over one buffer of their data."""
    wanted: dict[int, list[tuple[int, Message]]] = {}
    for rank, message in enumerate(messages):
        if channels is None or message.channel_id in channels:
            wanted.setdefault(message.channel_id, []).append((rank, message))
    out = {}
    for cid, items in wanted.items():
        lengths = np.array([len(m.data) for _, m in items], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
        out[cid] = ChunkMessages(
            buf=np.frombuffer(b''.join(m.data for _, m in items) or b'\0', dtype=np.uint8),
            position=np.array([r for r, _ in items], dtype=np.int64), data_offset=starts, data_length=lengths,
            log_time=np.array([m.log_time for _, m in items], dtype=np.uint64),
            publish_time=np.array([m.publish_time for _, m in items], dtype=np.uint64),
            sequence=np.array([m.sequence for _, m in items], dtype=np.uint32))
    return out


class McapFile:
    """Structure of one MCAP file: schemas, channels, chunks, metadata records; robust to truncation.

    ``schemas`` and ``channels`` map ids to the ``mcap.records`` Schema and Channel records.

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
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
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
            self._file: Any = open(self.path, 'rb')
        except FileNotFoundError:
            raise BagNotFoundError(f'MCAP file {self.path} does not exist') from None
        try:
            self.size = self.path.stat().st_size
            try:
                reader = SeekingReader(self._file)
            except _READ_ERRORS:
                raise BagFormatError(f'{self.path} is not an MCAP file (bad or missing magic bytes)') from None
            try:
                header = reader.get_header()
                self.profile, self.library = header.profile, header.library
            except _READ_ERRORS:
                pass  # reported by the scan if the file is damaged there
            if not self._read_summary():
                self._scan()
        except BaseException:
            self.close()
            raise

    # -- lifetime --
    def close(self) -> None:
        """Release the file; arrays returned earlier stay valid (they are copies)."""
        if getattr(self, '_file', None) is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> McapFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- problems and raw access --
    def _problem(self, message: str, *, corrupt: bool = True) -> None:
        text = f'{self.path}: {message}'
        self.problems.append(text)
        if corrupt and self.strict:
            raise BagCorruptError(text)
        warnings.warn(text, BagDamageWarning, stacklevel=4)

    def _read_at(self, offset: int, size: int) -> bytes:
        self._file.seek(offset)
        return self._file.read(size)

    def _records_from(self, offset: int, *, skip_magic: bool = True) -> Iterator[Any]:
        """The library's records from ``offset`` on (chunks raw)."""
        self._file.seek(offset)
        return StreamReader(self._file, skip_magic=skip_magic, emit_chunks=True).records

    # -- structure of a finished file --
    def _read_footer(self) -> Footer | None:
        if self.size < 2 * MAGIC_SIZE + FOOTER_SIZE:
            return None
        try:
            read_magic(ReadDataStream(BytesIO(self._read_at(self.size - MAGIC_SIZE, MAGIC_SIZE))))
            self._file.seek(self.size - MAGIC_SIZE - FOOTER_SIZE)
            record = next(StreamReader(self._file, skip_magic=True, record_size_limit=FOOTER_SIZE).records)
        except (StopIteration, *_READ_ERRORS):
            return None
        return record if isinstance(record, Footer) else None

    def _read_summary(self) -> bool:
        footer = self._read_footer()
        if footer is None or footer.summary_start == 0:
            return False
        crc_end = self.size - MAGIC_SIZE - 4  # the summary CRC covers everything up to the CRC field
        if not MAGIC_SIZE <= footer.summary_start <= self.size - MAGIC_SIZE - FOOTER_SIZE:
            self._problem(f'footer points to an impossible summary offset {footer.summary_start}; scanning instead')
            return False
        if footer.summary_crc and zlib.crc32(
                self._read_at(footer.summary_start, crc_end - footer.summary_start)) != footer.summary_crc:
            self._problem('summary checksum mismatch; scanning the file instead')
            return False
        try:
            self._file.seek(0)
            summary = SeekingReader(self._file).get_summary()
        except _READ_ERRORS as exc:
            self._problem(f'unreadable summary ({exc}); scanning the file instead')
            return False
        stats = summary.statistics if summary is not None else None
        if summary is None or (not summary.chunk_indexes and (stats is None or stats.message_count > 0)):
            return False  # un-chunked file, or a summary without chunk indexes: scan
        self.schemas, self.channels = dict(summary.schemas), dict(summary.channels)
        for entry in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            offset, length = entry.chunk_start_offset, entry.chunk_length
            try:
                head = self._chunk_head(offset, length)
            except (StopIteration, *_READ_ERRORS) as exc:
                self._problem(f'chunk at offset {offset} is unreadable ({exc}); its messages are skipped')
                continue
            self.chunks.append(ChunkRef(
                offset, offset + length - entry.compressed_size, entry.compressed_size, head.uncompressed_size,
                head.compression, head.message_start_time, head.message_end_time, length=length,
                index_length=entry.message_index_length,
                index=dict(entry.message_index_offsets) if entry.message_index_length else None))
        for entry in summary.metadata_indexes:
            try:
                record = next(self._records_from(entry.offset))
                if not isinstance(record, Metadata):
                    raise ValueError('no metadata record at the indexed offset')
                self.metadata.append((record.name, dict(record.metadata)))
            except (StopIteration, *_READ_ERRORS) as exc:
                self._problem(f'metadata record at offset {entry.offset} is unreadable ({exc})')
        if stats is not None:
            self.channel_counts = dict(stats.channel_message_counts)
            if stats.message_count:
                self.start_ns, self.end_ns = stats.message_start_time, stats.message_end_time
        else:
            self._count_from_indexes()
            self._times_from_chunks()
        self.complete = True
        self.readable_end = self.size
        return True

    def _chunk_head(self, offset: int, length: int) -> Chunk:
        """The Chunk record indexed at ``offset`` (``length`` bytes long), read by the library from its first bytes
        only (so its ``data`` is cut short): it must be there and have a readable head."""
        if offset + length > self.size:
            raise ValueError('indexed past the end of the file')
        stream = ReadDataStream(BytesIO(self._read_at(offset, min(length, 9 + 64 + 256))))
        if stream.read1() != Opcode.CHUNK:
            raise ValueError('no chunk record at the indexed offset')
        stream.read8()
        return Chunk.read(stream)

    # -- structure of an unfinished file --
    def _record_head(self, offset: int) -> tuple[int, int] | None:
        """(opcode, body length) of the record at ``offset``, None when fewer than 9 bytes are left."""
        head = self._read_at(offset, 9)
        if len(head) < 9:
            return None
        stream = ReadDataStream(BytesIO(head))
        return stream.read1(), stream.read8()

    def _scan(self) -> None:
        """Read every record on disk in order (the library's StreamReader), up to where the file was cut."""
        pos = MAGIC_SIZE
        records = self._records_from(0, skip_magic=False)
        loose: list[int] = []  # [start, end, first log time, last log time] of the current run of loose messages
        loose_counts: dict[int, int] = {}
        last_chunk: ChunkRef | None = None
        stopped = ''
        in_summary = False
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except _READ_ERRORS as exc:
                head = self._record_head(pos)
                if head is None:
                    stopped = 'cut'
                    break
                opcode, length = head
                if opcode < 0x80 and opcode not in _OPCODES:  # 0 and the reserved opcodes: not a record
                    stopped = 'corrupt'
                    break
                if pos + 9 + length > self.size:
                    if opcode == Opcode.CHUNK:
                        self.partial_chunk = pos
                    stopped = 'cut'
                    break
                if opcode == Opcode.CHUNK:
                    self._problem(f'chunk at offset {pos} is unreadable ({exc}); its messages are skipped')
                else:
                    self._problem(f'record (opcode {opcode:#04x}) at offset {pos} is unreadable ({exc})')
                pos += 9 + length
                records = self._records_from(pos)
                continue
            end = self._file.tell()
            if isinstance(record, (Message, Schema, Channel)) and not in_summary and (
                    isinstance(record, Message) or loose):
                if isinstance(record, Message):
                    if not loose:
                        loose[:] = [pos, end, record.log_time, record.log_time]
                    loose[2], loose[3] = min(loose[2], record.log_time), max(loose[3], record.log_time)
                    loose_counts[record.channel_id] = loose_counts.get(record.channel_id, 0) + 1
                loose[1] = end
            elif loose:
                self._add_loose(loose, loose_counts)
                loose, loose_counts = [], {}
            if isinstance(record, Header):
                self.profile, self.library = record.profile, record.library
            elif isinstance(record, Schema):
                self.schemas[record.id] = record
            elif isinstance(record, Channel):
                self.channels[record.id] = record
            elif isinstance(record, Chunk) and not in_summary:
                size = len(record.data)
                last_chunk = ChunkRef(pos, end - size, size, record.uncompressed_size, record.compression,
                                      record.message_start_time, record.message_end_time, length=end - pos)
                self.chunks.append(last_chunk)
            elif isinstance(record, MessageIndex) and last_chunk is not None and not in_summary:
                if last_chunk.index is None:
                    last_chunk.index, last_chunk.offsets = {}, {}
                assert last_chunk.offsets is not None
                last_chunk.index[record.channel_id] = pos
                last_chunk.counts[record.channel_id] = len(record.records)
                pairs = np.array(record.records, dtype=np.uint64).reshape(-1, 2)
                last_chunk.offsets[record.channel_id] = np.sort(pairs[:, 1].astype(np.int64))
            elif isinstance(record, Metadata) and not in_summary:
                self.metadata.append((record.name, dict(record.metadata)))
            elif isinstance(record, DataEnd):
                in_summary = True
            elif isinstance(record, Footer):
                self.complete = True
                pos = end
                break
            pos = end
        if loose:
            self._add_loose(loose, loose_counts)
        self.readable_end = pos
        if stopped == 'corrupt':
            opcode = self._read_at(pos, 1)[0]
            self._problem(f'unreadable bytes at offset {pos} (opcode {opcode:#04x}); the {self.size - pos} bytes '
                          f'from there on are ignored')
        elif stopped == 'cut' or not self.complete:
            self._problem(
                f'file is truncated or unfinished (no footer): read {len(self.chunks)} complete chunk(s), '
                f'ignored the last {self.size - pos} byte(s) from offset {pos}'
                '; `python -m crane_stiffness.bag.recover` rewrites it as a valid file', corrupt=False)
        self._discover_channels()
        self._times_from_chunks()

    def _add_loose(self, run: list[int], counts: dict[int, int]) -> None:
        start, end, first, last = run
        self.chunks.append(ChunkRef(start, start, end - start, end - start, '', first, last, counts=dict(counts),
                                    loose=True))

    def _discover_channels(self) -> None:
        """Find schemas/channels inside chunks (where writers put them) and count messages of un-indexed chunks."""
        for chunk in self.chunks:
            if chunk.loose or (chunk.index is not None and set(chunk.index) <= set(self.channels)):
                continue
            data = self.chunk_data(chunk)
            if data is None:
                continue
            try:
                records = breakup_chunk(_raw_chunk(data.tobytes()))
            except _READ_ERRORS as exc:
                self._problem(f'record in chunk at offset {chunk.offset} is unreadable ({exc})')
                continue
            for record in records:
                if isinstance(record, Schema):
                    self.schemas[record.id] = record
                elif isinstance(record, Channel):
                    self.channels[record.id] = record
            if chunk.index is None:
                chunk.counts = {}
                for record in records:
                    if isinstance(record, Message):
                        chunk.counts[record.channel_id] = chunk.counts.get(record.channel_id, 0) + 1
        self._count_from_indexes()

    def _count_from_indexes(self) -> None:
        counts: dict[int, int] = {}
        for chunk in self.chunks:
            if chunk.index is not None and not chunk.counts:
                chunk.counts = {cid: len(o) for cid, o in self._index_offsets(chunk).items()}
            for cid, count in chunk.counts.items():
                counts[cid] = counts.get(cid, 0) + count
        self.channel_counts = counts

    def _times_from_chunks(self) -> None:
        real = [c for c in self.chunks if c.counts or c.index is None]
        real = [c for c in real if not (c.loose and c.end_ns == _LOOSE_END)]
        if real:
            self.start_ns = min(c.start_ns for c in real)
            self.end_ns = max(c.end_ns for c in real)

    # -- chunk contents --
    def chunk_data(self, chunk: ChunkRef) -> np.ndarray | None:
        """The chunk's uncompressed records as a uint8 array, or None (with a warning) when damaged."""
        if chunk.loose:
            return np.frombuffer(self._read_at(chunk.records_offset, chunk.compressed_size), dtype=np.uint8)
        try:
            record = next(self._records_from(chunk.offset))
            if not isinstance(record, Chunk):
                raise ValueError('no chunk record at this offset')
        except (StopIteration, *_READ_ERRORS) as exc:
            self._problem(f'chunk at offset {chunk.offset} is unreadable ({exc}); its messages are skipped')
            return None
        try:
            if record.compression == '':
                data = record.data
            elif record.compression == 'zstd':
                if self._zstd is None:
                    import zstandard
                    self._zstd = zstandard.ZstdDecompressor()
                data = self._zstd.decompress(record.data, max_output_size=record.uncompressed_size)
            elif record.compression == 'lz4':
                import lz4.frame
                data = lz4.frame.decompress(record.data)
            else:
                self._problem(f'chunk at offset {chunk.offset} uses unsupported compression '
                              f'{record.compression!r}; skipped')
                return None
        except Exception as exc:  # zstd/lz4 raise their own error types on damaged input
            self._problem(f'chunk at offset {chunk.offset} does not decompress ({exc}); its messages are skipped')
            return None
        if len(data) != record.uncompressed_size:
            self._problem(f'chunk at offset {chunk.offset} decompressed to {len(data)} bytes, '
                          f'expected {record.uncompressed_size}; its messages are skipped')
            return None
        if self.verify_crc and record.uncompressed_crc and zlib.crc32(data) != record.uncompressed_crc:
            self._problem(f'chunk at offset {chunk.offset} fails its CRC check; its messages are skipped')
            return None
        return np.frombuffer(data, dtype=np.uint8)

    def _index_offsets(self, chunk: ChunkRef) -> dict[int, np.ndarray]:
        """Channel id → sorted offsets of its message records in the chunk, from the chunk's MessageIndex records."""
        if chunk.offsets is not None:
            return chunk.offsets
        if not chunk.index:
            return {}
        start = chunk.offset + chunk.length
        region = self._read_at(start, chunk.index_length)
        out = {}
        for cid, pos in chunk.index.items():
            rel = pos - start
            head = np.frombuffer(region, _MESSAGE_INDEX_HEAD, count=1, offset=rel)[0] \
                if 0 <= rel <= len(region) - _MESSAGE_INDEX_HEAD.itemsize else None
            size = int(head['records_length']) if head is not None else -1
            if head is None or head['op'] != Opcode.MESSAGE_INDEX or head['channel'] != cid or size % 16 \
                    or rel + _MESSAGE_INDEX_HEAD.itemsize + size > len(region):
                self._problem(f'message index of channel {cid} of the chunk at offset {chunk.offset} is unreadable; '
                              'its messages are skipped')
                continue
            entries = np.frombuffer(region, '<u8', count=size // 8, offset=rel + _MESSAGE_INDEX_HEAD.itemsize)
            out[cid] = np.sort(entries[1::2].astype(np.int64))
        return out

    def chunk_messages(self, chunk: ChunkRef, data: np.ndarray, channels: Collection[int] | None = None
                       ) -> dict[int, ChunkMessages]:
        """Per channel (all, or those in ``channels``): the chunk's messages; damaged index entries are dropped."""
        if chunk.loose or chunk.index is None:
            try:
                records = breakup_chunk(_raw_chunk(data.tobytes()))
            except _READ_ERRORS as exc:
                self._problem(f'record in chunk at offset {chunk.offset} is unreadable ({exc}); its messages are '
                              'skipped')
                return {}
            return _from_records([r for r in records if isinstance(r, Message)], channels)
        result = {}
        for cid, offsets in self._index_offsets(chunk).items():
            if channels is not None and cid not in channels:
                continue
            inside = (offsets >= 0) & (offsets + MESSAGE_HEADER_SIZE <= data.size)
            head = gather(data, np.where(inside, offsets, 0), _MESSAGE_HEADER)
            ok = (inside & (head['op'] == Opcode.MESSAGE) & (head['channel'] == cid) & (head['length'] >= 22)
                  & (offsets + 9 + head['length'].astype(np.int64) <= data.size))
            if not ok.all():
                self._problem(f'{int((~ok).sum())} message index entries of channel {cid} in chunk at offset '
                              f'{chunk.offset} do not point at messages; those messages are skipped')
                offsets, head = offsets[ok], head[ok]
            result[cid] = ChunkMessages(
                buf=data, position=offsets, data_offset=offsets + MESSAGE_HEADER_SIZE,
                data_length=head['length'].astype(np.int64) - 22, log_time=head['log_time'],
                publish_time=head['publish_time'], sequence=head['sequence'])
        return result

    def iter_chunk_messages(self, chunk: ChunkRef, data: np.ndarray, channels: Collection[int] | None = None
                            ) -> Iterator[tuple[int, int, int, int, bytes]]:
        """(channel id, sequence, log_time_ns, publish_time_ns, data) of a chunk's messages in file order."""
        raws: dict[int, bytes] = {}
        rows = []
        for cid, table in self.chunk_messages(chunk, data, channels).items():
            raw = raws.get(id(table.buf))
            if raw is None:
                raw = raws[id(table.buf)] = table.buf.tobytes()
            for pos, start, size, log, pub, seq in zip(
                    table.position.tolist(), table.data_offset.tolist(), table.data_length.tolist(),
                    table.log_time.tolist(), table.publish_time.tolist(), table.sequence.tolist()):
                rows.append((pos, cid, seq, log, pub, raw[start:start + size]))
        rows.sort(key=lambda row: row[0])
        for _, cid, seq, log, pub, payload in rows:
            yield cid, seq, log, pub, payload

    def partial_chunk_messages(self) -> list[tuple[int, int, int, int, bytes]]:
        """Complete messages at the start of a chunk cut short by the end of the file (for recovery)."""
        if self.partial_chunk is None:
            return []
        stream = ReadDataStream(BytesIO(self._read_at(self.partial_chunk, self.size - self.partial_chunk)))
        try:
            stream.read1()
            stream.read8()
            chunk = Chunk.read(stream)  # its data is what is left of the records on disk
            if chunk.compression == '':
                data = chunk.data
            elif chunk.compression == 'zstd':
                import zstandard
                data = zstandard.ZstdDecompressor().decompressobj().decompress(chunk.data)
            elif chunk.compression == 'lz4':
                import lz4.frame
                data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data)
            else:
                return []
        except Exception:  # whatever is left of the chunk is not decodable: nothing to save
            return []
        out = []
        records = StreamReader(BytesIO(data[:chunk.uncompressed_size]), skip_magic=True).records
        while True:
            try:
                record = next(records)
            except (StopIteration, *_READ_ERRORS):  # the end of what decompressed: a cut record
                break
            if isinstance(record, Message):
                out.append((record.channel_id, record.sequence, record.log_time, record.publish_time, record.data))
        return out


__all__ = ['ChunkMessages', 'ChunkRef', 'MESSAGE_HEADER_SIZE', 'McapFile']
