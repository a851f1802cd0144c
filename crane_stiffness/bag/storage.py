"""The storage of a bag's files: which kind a file is, opening it, and rosbag2's compression modes.

A bag file is one of rosbag2's two storages, told by its first bytes (not its name): MCAP
(:class:`~.mcapfile.McapFile`) or SQLite 3 (:class:`~.sqlitefile.Sqlite3File`, ``.db3``). Both offer the same view,
:class:`BagFile`, which :class:`~.reader.BagReader` reads. rosbag2's compression (metadata.yaml
``compression_format: zstd``):

- ``compression_mode: file``: each file is one zstd stream (``.mcap.zstd``, ``.db3.zstd``); it is decompressed into
  a temporary directory (removed on close) and read from there, its messages naming the compressed file;
- ``compression_mode: message``: each message's data is a zstd frame; :func:`decompress_messages` decompresses the
  messages gathered from a chunk in one call (``zstandard``'s ``multi_decompress_to_buffer``).

Anything else raises :class:`~.errors.BagFormatError` (not a bag file) or :class:`~.errors.BagUnsupportedError`
(another compression) naming the file.
"""
from __future__ import annotations

import shutil
import tempfile
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from mcap.records import Channel, Schema

from .chunks import ChunkMessages, ChunkRef
from .errors import BagFormatError, BagNotFoundError, BagUnsupportedError
from .mcapfile import McapFile
from .sqlitefile import SQLITE_MAGIC, Sqlite3File

MCAP_MAGIC = b'\x89MCAP0\r\n'
ZSTD_MAGIC = b'\x28\xb5\x2f\xfd'
COMPRESSION_FORMATS = ('zstd',)
"""rosbag2 compression formats that can be read (metadata.yaml ``compression_format``)."""
COMPRESSION_MODES = ('', 'none', 'file', 'message')


class BagFile(Protocol):
    """What :class:`~.reader.BagReader` reads of one file of a bag, whatever its storage.

    ``channels`` map channel (topic) ids to ``mcap.records.Channel`` (``metadata`` holds ``offered_qos_profiles``
    and ``topic_type_hash``), ``schemas`` schema ids to ``mcap.records.Schema``; ``chunks`` are the units read at
    once, each with its log time range (ns since the epoch) and, when known, the channels in it (``index``).
    """

    path: Path
    strict: bool
    problems: list[str]
    schemas: dict[int, Schema]
    channels: dict[int, Channel]
    chunks: list[ChunkRef]
    metadata: list[tuple[str, dict[str, str]]]
    channel_counts: dict[int, int]
    complete: bool
    start_ns: int | None
    end_ns: int | None

    def chunk_data(self, chunk: ChunkRef, channels: Collection[int] | None = None) -> Any:
        """The chunk's contents as read from disk (None when damaged); thread safe."""

    def chunk_messages(self, chunk: ChunkRef, data: Any, channels: Collection[int] | None = None
                       ) -> dict[int, ChunkMessages]:
        """Per channel: the chunk's messages."""

    def iter_chunk_messages(self, chunk: ChunkRef, data: Any, channels: Collection[int] | None = None
                            ) -> Iterator[tuple[int, int, int, int, bytes]]:
        """(channel id, sequence, log time, publish time, data) in file order."""

    def close(self) -> None:
        """Release the file."""


def file_kind(path: Path) -> str:
    """``'mcap'``, ``'sqlite3'`` or ``'zstd'`` from the first bytes of ``path``; BagFormatError for anything else."""
    try:
        with open(path, 'rb') as stream:
            head = stream.read(16)
    except FileNotFoundError:
        raise BagNotFoundError(f'bag file {path} does not exist') from None
    if head.startswith(MCAP_MAGIC):
        return 'mcap'
    if head.startswith(SQLITE_MAGIC):
        return 'sqlite3'
    if head.startswith(ZSTD_MAGIC):
        return 'zstd'
    raise BagFormatError(f'{path} is not an MCAP file, an SQLite 3 (rosbag2 .db3) file nor a zstd-compressed one '
                         f'(it starts with {head[:8]!r}; bad or missing magic bytes)')


def check_compression(path: Path, compression_format: str, compression_mode: str) -> str:
    """The compression mode of a bag (``''``, ``'file'`` or ``'message'``) from its metadata.yaml values;
    :class:`~.errors.BagUnsupportedError` naming the bag for a format or mode that cannot be read."""
    mode = (compression_mode or '').strip().lower()
    fmt = (compression_format or '').strip().lower()
    if mode not in COMPRESSION_MODES:
        raise BagUnsupportedError(f'{path}: compression_mode {compression_mode!r} is not one of rosbag2\'s '
                                  '(none, file, message)')
    if mode in ('', 'none'):
        return ''
    if fmt not in COMPRESSION_FORMATS:
        raise BagUnsupportedError(f'{path}: compression_format {compression_format!r} (mode {mode}) cannot be read '
                                  f'(readable: {", ".join(COMPRESSION_FORMATS)})')
    return mode


class TemporaryCopy:
    """A temporary directory holding the decompressed copy of a file-compressed bag file; :meth:`remove` it."""

    def __init__(self, path: Path) -> None:
        import zstandard

        self.dir = Path(tempfile.mkdtemp(prefix='crane_stiffness_bag_'))
        name = path.name[:-len('.zstd')] if path.name.endswith('.zstd') else path.name + '.raw'
        self.path = self.dir / name
        try:
            with open(path, 'rb') as source, open(self.path, 'wb') as target:
                zstandard.ZstdDecompressor().copy_stream(source, target)
        except zstandard.ZstdError as exc:
            self.remove()
            raise BagFormatError(f'{path} does not decompress as zstd ({exc})') from None
        except BaseException:
            self.remove()
            raise

    def remove(self) -> None:
        """Delete the copy."""
        shutil.rmtree(self.dir, ignore_errors=True)


def open_bag_file(path: Path, *, strict: bool = False, verify_crc: bool = True
                  ) -> tuple[BagFile, TemporaryCopy | None]:
    """The file at ``path`` opened by its storage (MCAP or SQLite 3), and the decompressed copy it was read from
    when ``path`` is zstd-compressed whole (the caller removes it after closing the file)."""
    kind = file_kind(path)
    if kind != 'zstd':
        return _open(kind, path, strict, verify_crc, None), None
    copy = TemporaryCopy(path)
    try:
        inner = file_kind(copy.path)
        if inner == 'zstd':
            raise BagFormatError(f'{path} is zstd-compressed twice')
        return _open(inner, copy.path, strict, verify_crc, path), copy
    except BaseException:
        copy.remove()
        raise


def _open(kind: str, path: Path, strict: bool, verify_crc: bool, name: Path | None) -> BagFile:
    if kind == 'mcap':
        return McapFile(path, strict=strict, verify_crc=verify_crc, name=name)
    return Sqlite3File(path, strict=strict, name=name)


def decompress_messages(found: ChunkMessages, zstd: Any) -> ChunkMessages:
    """The messages of ``found`` with each one's data (a zstd frame, rosbag2's ``compression_mode: message``)
    decompressed; ``zstd`` a ``zstandard.ZstdDecompressor``. All frames go to zstandard in one call."""
    import zstandard

    count = len(found)
    if not count:
        return found
    segments = np.empty((count, 2), '<u8')
    segments[:, 0] = found.data_offset
    segments[:, 1] = found.data_length
    raw = found.buf.tobytes()
    try:
        out = zstd.multi_decompress_to_buffer(zstandard.BufferWithSegments(raw, segments.tobytes()))
        parts = [out[i].tobytes() for i in range(len(out))]
    except zstandard.ZstdError:  # a frame without its content size: one at a time
        try:
            parts = [zstd.decompressobj().decompress(raw[o:o + n])
                     for o, n in zip(found.data_offset.tolist(), found.data_length.tolist())]
        except zstandard.ZstdError as exc:
            raise BagFormatError(f'a message does not decompress as zstd ({exc})') from None
    lengths = np.fromiter(map(len, parts), np.int64, count)
    offsets = np.zeros(count, np.int64)
    np.cumsum(lengths[:-1], out=offsets[1:])
    return ChunkMessages(buf=np.frombuffer(b''.join(parts) or b'\0', dtype=np.uint8), position=found.position,
                         data_offset=offsets, data_length=lengths, log_time=found.log_time,
                         publish_time=found.publish_time, sequence=found.sequence)


__all__ = ['BagFile', 'COMPRESSION_FORMATS', 'TemporaryCopy', 'check_compression', 'decompress_messages', 'file_kind',
           'open_bag_file']
