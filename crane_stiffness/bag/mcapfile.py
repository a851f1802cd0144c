"""One MCAP file of a bag, its records read by the ``mcap`` package; robust to truncation and damage.

The ``mcap`` package reads the records: the header, the summary of a finished file (``SeekingReader.get_summary``),
each raw chunk (``StreamReader(..., emit_chunks=True)`` at the chunk's offset) and, for a file its writer never
finished (killed by SIGKILL), every record on disk in order up to the library's end-of-data error where the file
was cut, so such a file still gives every complete chunk. Damage is reported with
:class:`~.errors.BagDamageWarning` (raised as :class:`~.errors.BagCorruptError` when ``strict``) and the readable
part is used. What is inside a chunk (decompression, the CRC check, the vectorised gather of its messages) is
``chunks.py``.
"""
from __future__ import annotations

import os
import threading
import warnings
import zlib
from collections.abc import Collection, Iterator, Mapping
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import FOOTER_SIZE, SeekingReader
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Message, MessageIndex, Metadata, Schema
from mcap.stream_reader import MAGIC_SIZE, StreamReader, read_magic

from .chunks import (
    COMPRESSIONS, READ_ERRORS, ChunkMessages, ChunkRef, decompress, gather_messages, in_file_order,
    index_offsets, messages_from_records, partial_chunk_messages, records_in,
)
from .errors import BagCorruptError, BagDamageWarning, BagFormatError, BagNotFoundError, BagUnsupportedError

_OPCODES = frozenset(int(op) for op in Opcode)


class McapFile:
    """Structure of one MCAP file: schemas, channels, chunks, metadata records; robust to truncation.

    ``schemas`` and ``channels`` map ids to the ``mcap.records`` Schema and Channel records.

    Args:
        path: the .mcap file.
        strict: raise :class:`BagCorruptError` on damage instead of warning (truncation always only warns).
        verify_crc: check each chunk's CRC32 when it has one.
    """

    def __init__(self, path: str | Path, *, strict: bool = False, verify_crc: bool = True,
                 name: str | Path | None = None) -> None:
        self.path = Path(name) if name is not None else Path(path)
        """The file as named in messages (``name``: the compressed file a decompressed copy ``path`` came from)."""
        self._disk = Path(path)
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
        self.statistics = False
        """True when the counts and times come from the summary's Statistics record."""
        self._zstd = threading.local()  # a ZstdDecompressor per thread: one instance is not thread safe
        try:
            self._file: Any = open(self._disk, 'rb')
        except FileNotFoundError:
            raise BagNotFoundError(f'MCAP file {self.path} does not exist') from None
        try:
            self.size = self._disk.stat().st_size
            try:
                reader = SeekingReader(self._file)
            except READ_ERRORS:
                raise BagFormatError(f'{self.path} is not an MCAP file (bad or missing magic bytes)') from None
            try:
                header = reader.get_header()
                self.profile, self.library = header.profile, header.library
            except READ_ERRORS:
                pass  # reported by the scan if the file is damaged there
            if not self._read_summary():
                self._scan()
            self._check_structure()
            self._discover_channels()
            self._check_channels()
            if not self.statistics:
                self._count_from_indexes()
                self._times_from_chunks()
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
        """``size`` bytes (fewer at the end of the file) from ``offset``, without using the file position: chunks
        are read this way, so a player's thread may read them while another reads the same file."""
        return os.pread(self._file.fileno(), size, offset)

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
        except (StopIteration, *READ_ERRORS):
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
        except READ_ERRORS as exc:
            self._problem(f'unreadable summary ({exc}); scanning the file instead')
            return False
        if summary is None:
            return False
        self.schemas, self.channels = dict(summary.schemas), dict(summary.channels)
        indexed: dict[int, int] = {}  # offset of each indexed chunk -> end of its message indexes
        for entry in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            offset, length = entry.chunk_start_offset, entry.chunk_length
            try:
                head = self._chunk_head(offset, length)
            except (StopIteration, *READ_ERRORS) as exc:
                self._problem(f'chunk at offset {offset} is unreadable ({exc}); its messages are skipped')
                continue
            indexed[offset] = offset + length + entry.message_index_length
            self.chunks.append(ChunkRef(
                offset, offset + length - entry.compressed_size, entry.compressed_size, head.uncompressed_size,
                head.compression, head.message_start_time, head.message_end_time, length=length,
                index_length=entry.message_index_length,
                index=dict(entry.message_index_offsets) if entry.message_index_length else None))
        # Everything of the data section the chunk indexes do not cover (schemas, channels and messages outside
        # chunks, metadata records, chunks left out of the index) is read record by record.
        self._scan(stop=footer.summary_start, skip=indexed)
        self.chunks.sort(key=lambda c: c.offset)
        stats = summary.statistics
        if stats is not None:
            self.channel_counts = dict(stats.channel_message_counts)
            if stats.message_count:
                self.start_ns, self.end_ns = stats.message_start_time, stats.message_end_time
        self.statistics = stats is not None
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

    def _scan(self, stop: int | None = None, skip: Mapping[int, int] | None = None) -> None:
        """Read the records on disk in order (the library's StreamReader) from the header on: up to ``stop`` (the
        start of a finished file's summary; None: up to the footer, or where the file was cut), jumping over
        ``skip`` (offset of a chunk the summary indexes → end of its message indexes)."""
        skip = skip or {}
        pos = MAGIC_SIZE
        records = self._records_from(0, skip_magic=False)
        loose: list[int] = []  # [start, end, first log time, last log time] of the current run of loose messages
        loose_counts: dict[int, int] = {}
        last_chunk: ChunkRef | None = None
        stopped = ''
        in_summary = False
        while stop is None or pos < stop:
            if pos in skip:
                if loose:
                    self._add_loose(loose, loose_counts)
                    loose, loose_counts = [], {}
                last_chunk = None
                pos = skip[pos]
                records = self._records_from(pos)
                continue
            head = self._record_head(pos)
            if head is not None and head[0] not in _OPCODES and pos + 9 + head[1] <= self.size:
                # A record of an opcode this reader does not know (a later version's, or private): skipped by its
                # length as the specification says (here, not by the library, to keep ``pos`` on record starts).
                if loose:
                    loose[1] = pos + 9 + head[1]
                pos += 9 + head[1]
                records = self._records_from(pos)
                continue
            try:
                record = next(records)
            except StopIteration:
                break
            except READ_ERRORS as exc:
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
        if stopped == 'corrupt':
            opcode = self._read_at(pos, 1)[0]
            self._problem(f'unreadable bytes at offset {pos} (opcode {opcode:#04x}); the '
                          f'{(stop or self.size) - pos} bytes from there on are ignored')
        elif stop is not None:
            if stopped:
                self._problem(f'data section cut short at offset {pos}, before the summary at offset {stop}')
            return
        elif stopped == 'cut' or not self.complete:
            self._problem(
                f'file is truncated or unfinished (no footer): read {len(self.chunks)} complete chunk(s), '
                f'ignored the last {self.size - pos} byte(s) from offset {pos}'
                '; `python -m crane_stiffness.bag.recover` rewrites it as a valid file', corrupt=False)
        self.readable_end = pos

    def _add_loose(self, run: list[int], counts: dict[int, int]) -> None:
        start, end, first, last = run
        self.chunks.append(ChunkRef(start, start, end - start, end - start, '', first, last, counts=dict(counts),
                                    loose=True))

    def _check_structure(self) -> None:
        """Refuse what cannot be read exactly: a chunk compression this reader does not know, messages on a channel
        no Channel record defines, a channel whose schema no Schema record defines."""
        for chunk in self.chunks:
            if not chunk.loose and chunk.compression not in COMPRESSIONS:
                raise BagUnsupportedError(
                    f'{self.path}: chunk at offset {chunk.offset} uses compression {chunk.compression!r}, which this '
                    f'reader cannot decompress (it reads {", ".join(repr(c) for c in COMPRESSIONS)})')

    def _check_channels(self) -> None:
        for cid, channel in self.channels.items():
            if channel.schema_id and channel.schema_id not in self.schemas:
                raise BagFormatError(f'{self.path}: channel {cid} ({channel.topic}) names schema '
                                     f'{channel.schema_id}, which no Schema record defines')
        for chunk in self.chunks:
            used = [cid for cid, n in chunk.counts.items() if n] + list(chunk.index or ())
            unknown = sorted(set(used) - set(self.channels))
            if unknown:
                where = 'outside chunks' if chunk.loose else 'in the chunk'
                raise BagFormatError(
                    f'{self.path}: messages on channel id(s) {unknown} {where} at offset {chunk.offset}, but no '
                    'Channel record defines them; the messages cannot be attributed to a topic')

    def _discover_channels(self) -> None:
        """Learn the schemas and channels defined only inside chunks (where a writer may put them; a chunk may
        define a channel whose messages come in later chunks) and count the messages of chunks without a message
        index. Chunks are read in file order while a channel or schema in use is still undefined, and every chunk
        without a message index is read; a file whose definitions are all outside chunks reads none here."""
        used = {cid for chunk in self.chunks for cid in chunk.index or ()}
        used |= {cid for chunk in self.chunks for cid, n in chunk.counts.items() if n}

        def missing() -> bool:
            return bool(used - set(self.channels)) or any(
                ch.schema_id and ch.schema_id not in self.schemas for ch in self.channels.values())

        need = missing()
        for chunk in self.chunks:
            if chunk.loose or (chunk.index is not None and not need):
                continue
            data = self.chunk_data(chunk)
            if data is None:
                continue
            try:
                records = records_in(data.tobytes())
            except READ_ERRORS as exc:
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
                used |= set(chunk.counts)
            if need:
                need = missing()

    def _count_from_indexes(self) -> None:
        counts: dict[int, int] = {}
        for chunk in self.chunks:
            if chunk.index is not None and not chunk.counts:
                chunk.counts = {cid: len(o) for cid, o in self._index_offsets(chunk).items()}
            for cid, count in chunk.counts.items():
                counts[cid] = counts.get(cid, 0) + count
        self.channel_counts = counts

    def _times_from_chunks(self) -> None:
        real = [c for c in self.chunks if any(c.counts.values())]
        if real:
            self.start_ns = min(c.start_ns for c in real)
            self.end_ns = max(c.end_ns for c in real)

    # -- chunk contents --
    def chunk_data(self, chunk: ChunkRef, channels: Collection[int] | None = None) -> np.ndarray | None:
        """The chunk's uncompressed records as a uint8 array, or None (with a warning) when damaged. Safe to call
        from several threads at once (reads with pread, a decompressor per thread). ``channels`` is not used (the
        same interface as :class:`~.sqlitefile.Sqlite3File`)."""
        if chunk.loose:
            return np.frombuffer(self._read_at(chunk.records_offset, chunk.compressed_size), dtype=np.uint8)
        try:
            raw = BytesIO(self._read_at(chunk.offset, chunk.length))
            record = next(StreamReader(raw, skip_magic=True, emit_chunks=True).records)
            if not isinstance(record, Chunk):
                raise ValueError('no chunk record at this offset')
        except (StopIteration, *READ_ERRORS) as exc:
            self._problem(f'chunk at offset {chunk.offset} is unreadable ({exc}); its messages are skipped')
            return None
        if record.compression not in COMPRESSIONS:
            raise BagUnsupportedError(f'{self.path}: chunk at offset {chunk.offset} uses compression '
                                      f'{record.compression!r}, which this reader cannot decompress')
        try:
            zstd = getattr(self._zstd, 'decompressor', None)
            if record.compression == 'zstd' and zstd is None:
                import zstandard
                zstd = self._zstd.decompressor = zstandard.ZstdDecompressor()
            data = decompress(record.compression, record.data, record.uncompressed_size, zstd)
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
        offsets, bad = index_offsets(self._read_at(start, chunk.index_length), start, chunk.index)
        for cid in bad:
            self._problem(f'message index of channel {cid} of the chunk at offset {chunk.offset} is unreadable; '
                          'its messages are skipped')
        return offsets

    def chunk_messages(self, chunk: ChunkRef, data: np.ndarray, channels: Collection[int] | None = None
                       ) -> dict[int, ChunkMessages]:
        """Per channel (all, or those in ``channels``): the chunk's messages; damaged index entries are dropped."""
        if chunk.loose or chunk.index is None:
            try:
                return messages_from_records(records_in(data.tobytes()), channels)
            except READ_ERRORS as exc:
                self._problem(f'record in chunk at offset {chunk.offset} is unreadable ({exc}); its messages are '
                              'skipped')
                return {}
        result, bad = gather_messages(data, self._index_offsets(chunk), channels)
        for cid, count in bad.items():
            self._problem(f'{count} message index entries of channel {cid} in chunk at offset {chunk.offset} do not '
                          'point at messages; those messages are skipped')
        return result

    def iter_chunk_messages(self, chunk: ChunkRef, data: np.ndarray, channels: Collection[int] | None = None
                            ) -> Iterator[tuple[int, int, int, int, bytes]]:
        """(channel id, sequence, log_time_ns, publish_time_ns, data) of a chunk's messages in file order."""
        yield from in_file_order(self.chunk_messages(chunk, data, channels))

    def partial_chunk_messages(self) -> list[tuple[int, int, int, int, bytes]]:
        """Complete messages at the start of a chunk cut short by the end of the file (for recovery)."""
        if self.partial_chunk is None:
            return []
        stream = ReadDataStream(BytesIO(self._read_at(self.partial_chunk, self.size - self.partial_chunk)))
        try:
            stream.read1()
            stream.read8()
            chunk = Chunk.read(stream)  # its data is what is left of the records on disk
        except READ_ERRORS:
            return []
        return partial_chunk_messages(chunk)


__all__ = ['McapFile']
