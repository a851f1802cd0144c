"""Chunk indexes of an MCAP file being written, kept on disk instead of in memory until the summary is written.

The ``mcap`` library's writer keeps one :class:`mcap.records.ChunkIndex` object per chunk in a list until
``finish()`` writes them into the summary section. The recorder writes a chunk at least every ``flush_interval_s``
(0.5 s by default, so that a crash loses little), so that list grows by 7,200 objects, about 15 MB of Python
objects, per hour of recording, and a lab records all day. :class:`ChunkIndexSpool` stands in for that list: each
index appended is serialised at once (the bytes the summary will hold, ~130 bytes) into an unnamed temporary file,
and read back record by record when the summary is written. Memory stays flat however long the file.

:func:`spool_chunk_indexes` installs it in a writer; the test pins it to the library's writer (the file reads back
with the same chunk indexes, memory flat over thousands of chunks). Pure Python, no ROS.
"""
from __future__ import annotations

import struct
import tempfile
from collections.abc import Iterator
from typing import Any

from mcap.data_stream import RecordBuilder
from mcap.records import ChunkIndex

_HEADER = struct.Struct('<BQ')   # an MCAP record: opcode (1 byte), length of the content (8 bytes)
#: The private attribute of mcap.writer.Writer holding its chunk indexes (name-mangled ``__chunk_indices``).
_WRITER_ATTRIBUTE = '_Writer__chunk_indices'


class _Record:
    """One serialised record, written as is into the summary (what ``ChunkIndex.write`` would have written)."""

    __slots__ = ('data',)

    def __init__(self, data: bytes) -> None:
        self.data = data

    def write(self, builder: RecordBuilder) -> None:
        builder.write(self.data)


class ChunkIndexSpool:
    """A list of chunk indexes that lives in a temporary file: ``append`` serialises, iteration reads back."""

    def __init__(self, directory: str | None = None) -> None:
        """``directory``: where the unnamed file lives (the bag's own directory: the same disk, so a full disk is
        the recording's write error, not a surprise elsewhere); None = the system's temporary directory."""
        self._file = tempfile.TemporaryFile(prefix='.chunk_index_', dir=directory)
        self._builder = RecordBuilder()
        self._count = 0

    def append(self, index: ChunkIndex) -> None:
        index.write(self._builder)
        self._file.write(self._builder.end())
        self._count += 1

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[_Record]:
        self._file.flush()
        self._file.seek(0)
        for _ in range(self._count):
            header = self._file.read(_HEADER.size)
            _, length = _HEADER.unpack(header)
            yield _Record(header + self._file.read(length))
        self._file.seek(0, 2)  # appends go on at the end

    def close(self) -> None:
        try:
            self._file.close()
        except OSError:  # its unflushed bytes on a full disk: the file is being discarded, nothing is lost
            pass


def spool_chunk_indexes(writer: Any, directory: str | None = None) -> ChunkIndexSpool | None:
    """Replace ``writer``'s in-memory chunk index list (an ``mcap.writer.Writer`` before ``start()``) by a
    :class:`ChunkIndexSpool` in ``directory``; None (nothing changed) if this version of the library keeps them
    elsewhere."""
    current = getattr(writer, _WRITER_ATTRIBUTE, None)
    if not isinstance(current, list) or current:
        return None
    spool = ChunkIndexSpool(directory)
    setattr(writer, _WRITER_ATTRIBUTE, spool)
    return spool
