"""Writing rosbag2 bags: a directory of MCAP files (profile ``ros2``) and a ``metadata.yaml`` (rosbag2 version 9).

Layout of ``BagWriter('<dir>/<session>')``::

    <dir>/<session>/metadata.yaml        written by close() (and by recover_bag after a crash)
    <dir>/<session>/<session>_0.mcap     then _1, _2, ... when splitting by size or duration

Each MCAP file is chunked (zstd, lz4 or none) and written straight to the operating system, one chunk at a time,
so that a process killed with SIGKILL leaves a file whose complete chunks are all readable (see ``recover.py``).
A write the operating system refuses (disk full, I/O error) stops the writer with :class:`BagWriteFailedError`: the
file is cut back to its last complete record (every chunk before stays readable, as after SIGKILL), and ``close()``
then writes metadata.yaml from what is on disk if there is room, or says that it could not (``salvage``).
Schemas are ``ros2msg`` definitions built from the installed .msg files (``msgdef.py``), channels carry
``offered_qos_profiles`` (a YAML string, ``qos.py``) and ``topic_type_hash`` metadata as rosbag2 Jazzy writes them,
the caller's own description of the recording goes into MCAP Metadata records (``add_metadata``), and metadata.yaml
is laid out and written by ``metadata.py``.

Times are integer nanoseconds since the Unix epoch (``*_ns``); durations in seconds where named ``*_s``.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import IO, Any, cast

from mcap.writer import CompressionType, Writer as McapWriter

from crane_stiffness import __version__

from .index_spool import ChunkIndexSpool, spool_chunk_indexes
from .errors import BagError, BagExistsError, BagWriteFailedError, BagWriterError, os_error_text
from .metadata import (
    METADATA_FILENAME, ROSBAG2_METADATA, FileStats, TopicStats, build_bag_metadata, encode_metadata,
    serialized_bag_metadata,
    write_metadata_yaml,
)
from .msgdef import message_definition, normalize_type, type_description_hash
from .qos import dump_qos_profiles

LIBRARY = f'crane_stiffness/{__version__}'
DEFAULT_CHUNK_SIZE = 1024 * 1024
"""Default uncompressed chunk size in bytes: about 10,000 rig messages, i.e. ~5 s of a 2 kHz recording."""

COMPRESSIONS = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4, 'none': CompressionType.NONE}


# ------------------------------------------------------------------------------------------------------- writer --
class _DirectFile:
    """Unbuffered binary file for the MCAP writer: every write goes to the OS at once (survives SIGKILL)."""

    def __init__(self, path: Path, fsync: bool) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self._pos = 0
        self._fsync = fsync

    def write(self, data: bytes | bytearray | memoryview) -> int:
        view = memoryview(data)
        try:
            while view:
                written = os.write(self._fd, view)
                view = view[written:]
        except OSError:
            # The MCAP writer hands over whole records per write: cutting the file back to where this write began
            # leaves it ending on a record boundary (a reader then sees a file cut after its last complete record)
            # and gives the partial bytes back to a full disk.
            self.cut()
            raise
        self._pos += len(data)
        if self._fsync and len(data):
            os.fsync(self._fd)
        return len(data)

    def tell(self) -> int:
        return self._pos

    def cut(self) -> None:
        """Truncate the file to the end of the last complete write (best effort: the disk may be gone)."""
        if self._fd >= 0:
            try:
                os.ftruncate(self._fd, self._pos)
            except OSError:
                pass

    def flush(self) -> None:
        if self._fsync:
            os.fsync(self._fd)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


@dataclass
class _Topic:
    name: str
    msg_type: str
    definition: str
    type_hash: str
    qos_yaml: str
    count: int = 0


@dataclass
class _OpenFile:
    stats: FileStats
    stream: _DirectFile
    mcap: McapWriter
    index_spool: ChunkIndexSpool | None = None
    schemas: dict[str, int] = field(default_factory=dict)
    channels: dict[str, int] = field(default_factory=dict)
    sequences: dict[str, int] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    """Messages accepted per topic into this file (on disk once their chunk is written)."""
    pending_since_ns: int | None = None


class BagWriter:
    """Write a rosbag2 bag directory of MCAP files. Use as a context manager; ``close()`` writes metadata.yaml.

    Args:
        path: bag directory ``<dir>/<session>``; created, and must not already hold files.
        compression: chunk compression, ``'zstd'``, ``'lz4'`` or ``'none'``.
        chunk_size: uncompressed chunk size in bytes; a chunk is written to disk when it grows past this.
        split_max_bytes: start a new ``<session>_<n>.mcap`` once the current file holds this many bytes.
        split_max_duration_s: start a new file once a message is this many seconds (log time) after the file's first.
        metadata: MCAP Metadata records to write into every file, ``{name: {key: value}}``; non-string values are
            JSON-encoded.
        custom_data: rosbag2 ``custom_data`` for metadata.yaml (strings).
        flush_interval_s: also finish the current chunk once it holds messages this many seconds (log time) old,
            so a slow topic is on disk within that time; None flushes by size only.
        fsync: fsync after every write (survives power loss, not only a killed process); slower.
    """

    def __init__(self, path: str | os.PathLike[str], *, compression: str = 'zstd',
                 chunk_size: int = DEFAULT_CHUNK_SIZE, split_max_bytes: int | None = None,
                 split_max_duration_s: float | None = None,
                 metadata: Mapping[str, Mapping[str, Any]] | None = None,
                 custom_data: Mapping[str, str] | None = None, flush_interval_s: float | None = None,
                 fsync: bool = False) -> None:
        if compression not in COMPRESSIONS:
            raise BagWriterError(f'compression must be one of {sorted(COMPRESSIONS)}, got {compression!r}')
        if chunk_size <= 0:
            raise BagWriterError(f'chunk_size must be positive, got {chunk_size}')
        if split_max_bytes is not None and split_max_bytes < 1024:
            raise BagWriterError(f'split_max_bytes must be at least 1024 (rosbag2 MCAP minimum), got {split_max_bytes}')
        if split_max_duration_s is not None and split_max_duration_s <= 0:
            raise BagWriterError(f'split_max_duration_s must be positive, got {split_max_duration_s}')
        self.path = Path(path)
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            raise BagExistsError(f'bag directory {self.path} already exists and is not empty')
        self.path.mkdir(parents=True, exist_ok=True)
        self.session = self.path.name
        self.compression = compression
        self.chunk_size = int(chunk_size)
        self.split_max_bytes = split_max_bytes
        self._split_ns = None if split_max_duration_s is None else int(round(split_max_duration_s * 1e9))
        self._flush_ns = None if flush_interval_s is None else int(round(flush_interval_s * 1e9))
        self._fsync = fsync
        self.custom_data = dict(custom_data or {})
        self._topics: dict[str, _Topic] = {}
        self._metadata: list[tuple[str, dict[str, str]]] = []
        self._files: list[FileStats] = []
        self._file: _OpenFile | None = None
        self._closed = False
        self.failure: BagWriteFailedError | None = None
        """The write error that stopped the writer, None while every write succeeded."""
        self.lost_messages = 0
        """Messages accepted by :meth:`write` but not on disk because a write error lost their chunk."""
        self.failed_write_on_disk = False
        """After a write error: the message whose :meth:`write` raised is on disk all the same (its chunk was
        written whole; the error came on a record after it). Counted in :attr:`message_count` and its topic."""
        self.failed_write_counted = False
        """After a write error: the message whose :meth:`write` raised had been accepted before the error (a failing
        flush): it is counted on disk or in :attr:`lost_messages`, not refused."""
        self._failed_topic: str | None = None
        self.metadata_path: Path | None = None
        """metadata.yaml once ``close()`` wrote it."""
        self._cut_file: _OpenFile | None = None
        self.salvage: str | None = None
        """After a write error, what ``close()`` could save: messages on disk, messages lost, metadata.yaml."""
        try:
            with self._io('creating', None):
                self._open_file()
        except BagWriteFailedError:
            self._closed = True
            self._salvage()
            raise
        for name, data in (metadata or {}).items():
            self.add_metadata(name, data)

    # -- context manager --
    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()  # keep what was recorded even when the recording loop failed

    # -- properties --
    @property
    def files(self) -> list[Path]:
        """Paths of the .mcap files written so far (the last one may still be open)."""
        return [self.path / f.path for f in self._files]

    @property
    def message_count(self) -> int:
        """Messages written so far, all files."""
        return sum(f.message_count for f in self._files)

    @property
    def topics(self) -> dict[str, str]:
        """Topic name → message type of the topics added."""
        return {t.name: t.msg_type for t in self._topics.values()}

    # -- API --
    def add_topic(self, name: str, msg_type: str, qos_profiles_yaml: str | None = None, *,
                  message_definition_text: str | None = None, type_hash: str | None = None) -> None:
        """Declare a topic before writing to it.

        Args:
            name: topic name, e.g. ``/load_cell/wrench``.
            msg_type: ``pkg/msg/Type`` (``pkg/Type`` accepted).
            qos_profiles_yaml: offered QoS profiles as a YAML string (rosbag2's form; integer policies accepted),
                see :func:`qos_profile` / :func:`dump_qos_profiles`; None (stored as ``[]``) when unknown.
            message_definition_text: ros2msg schema text; looked up from the installed .msg files when None.
            type_hash: ``RIHS01_...`` type hash; looked up from the installed .json when None.
        """
        self._check_open()
        msg_type = normalize_type(msg_type)
        if name in self._topics:
            if self._topics[name].msg_type != msg_type:
                raise BagWriterError(f'topic {name} was added as {self._topics[name].msg_type}, not {msg_type}')
            return
        definition = message_definition(msg_type) if message_definition_text is None else message_definition_text
        topic = _Topic(name=name, msg_type=msg_type, definition=definition,
                       type_hash=type_description_hash(msg_type) if type_hash is None else type_hash,
                       qos_yaml=dump_qos_profiles(qos_profiles_yaml))
        self._topics[name] = topic
        assert self._file is not None
        with self._io('writing', self._file):
            self._register(self._file, topic)

    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """Write an MCAP Metadata record ``name`` → ``{key: value}`` (non-strings JSON-encoded).

        The record goes into the current file and is repeated in every later split file.
        """
        self._check_open()
        encoded = encode_metadata(data)
        self._metadata.append((name, encoded))
        assert self._file is not None
        with self._io('writing', self._file):
            self._file.mcap.add_metadata(name, encoded)

    def write(self, topic: str, data: bytes | bytearray | memoryview, log_time_ns: int,
              publish_time_ns: int | None = None) -> None:
        """Append one serialized (CDR) message.

        Args:
            topic: a topic declared with :meth:`add_topic`.
            data: the serialized message, e.g. from a ``raw=True`` subscription.
            log_time_ns: receive time, ns since the epoch (rosbag2's recv_timestamp; MCAP log_time).
            publish_time_ns: send time, ns since the epoch; defaults to ``log_time_ns``.
        """
        self._check_open()
        try:
            entry = self._topics[topic]
        except KeyError:
            raise BagWriterError(f'topic {topic} was not added; call add_topic first '
                                 f'(topics: {", ".join(self._topics) or "none"})') from None
        log_time_ns = int(log_time_ns)
        if log_time_ns < 0:
            raise BagWriterError(f'log_time_ns must not be negative, got {log_time_ns}')
        current = self._file
        assert current is not None
        if current.stats.message_count and self._should_split(current, log_time_ns):
            with self._io('finishing', current):
                self._close_file()
            with self._io('creating', None):
                current = self._open_file()
        # the per-message path: a plain try (not ``self._io``, a generator-based context manager per message)
        counted = False
        try:
            sequence = current.sequences[topic] = current.sequences[topic] + 1
            position = current.stream.tell()
            current.mcap.add_message(current.channels[topic], log_time_ns, bytes(data),
                                     log_time_ns if publish_time_ns is None else int(publish_time_ns), sequence)
            current.stats.add(log_time_ns)
            current.counts[topic] = current.counts.get(topic, 0) + 1
            entry.count += 1
            counted = True
            if self._flush_ns is not None:
                if current.stream.tell() != position:
                    current.pending_since_ns = None  # the chunk holding this message was just written
                elif current.pending_since_ns is None:
                    current.pending_since_ns = log_time_ns  # first message of a new chunk
                elif log_time_ns - current.pending_since_ns >= self._flush_ns:
                    current.mcap.flush()
                    current.pending_since_ns = None
        except OSError as exc:
            if self.failure is None:
                self._failed_topic, self.failed_write_counted = topic, counted
            raise self._fail('writing', current, exc) from exc

    def flush(self) -> None:
        """Finish the chunk in progress and hand it to the OS, so everything written so far survives a crash."""
        self._check_open()
        assert self._file is not None
        with self._io('writing', self._file):
            self._file.mcap.flush()
        self._file.pending_since_ns = None

    def close(self) -> dict[str, Any] | None:
        """Finish the current file (summary, footer) and write metadata.yaml. Idempotent.

        After a write error (``failure``) the file is left as the error cut it (every complete chunk readable) and
        metadata.yaml is written from the messages actually on disk, if the disk allows; ``salvage`` says what was
        saved. A write error during close itself is raised as :class:`BagWriteFailedError` after that salvage.

        Returns:
            the ``rosbag2_bagfile_information`` mapping written, or None if already closed or if metadata.yaml could
            not be written after an earlier write error.
        """
        if self._closed:
            return None
        self._closed = True
        if self.failure is None:
            try:
                with self._io('finishing', self._file):
                    self._close_file()
            except BagWriteFailedError:
                self._salvage()
                raise
        if self.failure is not None:
            return self._salvage()
        info = self._bag_metadata()
        try:
            self.metadata_path = write_metadata_yaml(self.path, info)
        except OSError as exc:
            self.failure = BagWriteFailedError(
                f'writing {self.path / METADATA_FILENAME} failed: {os_error_text(exc)}; every .mcap file of the bag is '
                f'complete: run `crane-stiffness recover {self.path}` once there is room',
                self.path / METADATA_FILENAME,
                exc.errno)
            raise self.failure from exc
        return info

    # -- internals --
    def _check_open(self) -> None:
        if self.failure is not None:
            raise BagWriterError(f'bag {self.path} stopped at a write error: {self.failure}')
        if self._closed:
            raise BagWriterError(f'bag {self.path} is closed')

    @contextmanager
    def _io(self, action: str, opened: _OpenFile | None) -> Iterator[None]:
        """Turn an OSError of the block into the writer's failure (see :meth:`_fail`)."""
        try:
            yield
        except OSError as exc:
            raise self._fail(action, opened, exc) from exc

    def _fail(self, action: str, opened: _OpenFile | None, exc: OSError) -> BagWriteFailedError:
        """Record ``exc`` as the writer's failure (first error only): stop, cut the file back to its last complete
        record, keep what is on disk. Returns the error to raise."""
        if self.failure is not None:
            return self.failure
        target = self.path / opened.stats.path if opened is not None else (
            self.path / self._files[-1].path if self._files else self.path)
        where = f'; the file ends at byte {opened.stream.tell()}, after its last complete record' \
            if opened is not None else ''
        self.failure = BagWriteFailedError(
            f'{action} {target} failed: {os_error_text(exc)}; recording stopped{where}', target, exc.errno)
        failed = opened if opened is not None else self._file
        if failed is not None:
            failed.stream.cut()
            failed.stream.close()
            if failed.index_spool is not None:
                failed.index_spool.close()
            self._cut_file = failed
        return self.failure

    def _salvage(self) -> dict[str, Any] | None:
        """After a write error: count what is on disk in the file the error cut, then try metadata.yaml."""
        opened, self._file = self._cut_file or self._file, None
        if opened is not None:
            opened.stream.close()
        lost = self._recount_cut_file(opened) if opened is not None else 0
        self.lost_messages = lost
        on_disk = self.message_count
        info = self._bag_metadata()
        try:
            self.metadata_path = write_metadata_yaml(self.path, info)
            meta = f'wrote {self.metadata_path}'
            written: dict[str, Any] | None = info
        except OSError as exc:
            written = None  # metadata.yaml not written
            meta = (f'metadata.yaml NOT written ({os_error_text(exc)}): run `crane-stiffness recover {self.path}` once '
                    'there is room')
        saved = (' (the message being written when the error came among them: its chunk went out whole)'
                 if self.failed_write_on_disk else '')
        self.salvage = (f'{on_disk} message(s) on disk in complete chunks{saved}, {lost} lost with the chunk being '
                        f'written; {meta}')
        return written

    def _recount_cut_file(self, opened: _OpenFile) -> int:
        """Set the stats of the file a write error cut to what is readable in it; returns the messages lost."""
        from .mcapfile import McapFile  # the reader's view of the cut file, as a user will read it
        path = self.path / opened.stats.path
        disk: dict[str, int] = {}
        start = end = None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter('ignore')  # the cut end is expected; it is reported by ``salvage``
                with McapFile(path) as cut:
                    for cid, count in cut.channel_counts.items():
                        channel = cut.channels.get(cid)
                        if channel is not None:
                            disk[channel.topic] = disk.get(channel.topic, 0) + count
                    start, end = cut.start_ns, cut.end_ns
        except (BagError, OSError):
            # nothing readable (not even the header): every message of the file is lost, and the file would make
            # the whole bag unreadable
            try:
                path.unlink(missing_ok=True)
                self._files = [f for f in self._files if f is not opened.stats]
            except OSError:
                pass
        lost = 0
        for topic in set(opened.counts) | set(disk):
            accepted, kept = opened.counts.get(topic, 0), disk.get(topic, 0)
            # kept > accepted: the message whose write raised went out whole with its chunk (the error came on a
            # later record); it is in the bag, so it is counted, and the caller must not count it as refused.
            self._topics[topic].count += kept - accepted
            lost += max(0, accepted - kept)
            self.failed_write_on_disk |= topic == self._failed_topic and kept > accepted
        opened.stats.message_count = sum(disk.values())
        opened.stats.start_ns, opened.stats.end_ns = (start, end) if disk else (None, None)
        return lost

    def _should_split(self, current: _OpenFile, log_time_ns: int) -> bool:
        if self.split_max_bytes is not None and current.stream.tell() >= self.split_max_bytes:
            return True
        start = current.stats.start_ns
        return self._split_ns is not None and start is not None and log_time_ns - start >= self._split_ns

    def _bag_metadata(self) -> dict[str, Any]:
        topics = [TopicStats(name=t.name, msg_type=t.msg_type, offered_qos_profiles=t.qos_yaml,
                             type_description_hash=t.type_hash, message_count=t.count)
                  for t in self._topics.values()]
        return build_bag_metadata(self._files, topics, custom_data=self.custom_data)

    def _open_file(self) -> _OpenFile:
        stats = FileStats(path=f'{self.session}_{len(self._files)}.mcap')
        stream = _DirectFile(self.path / stats.path, self._fsync)
        # McapWriter's annotation asks for an IO; it only calls write() and tell(), which _DirectFile has.
        mcap = McapWriter(cast(IO[bytes], stream), chunk_size=self.chunk_size,
                          compression=COMPRESSIONS[self.compression], enable_crcs=True)
        # Chunk indexes on disk until the summary: the library's list grows ~15 MB per hour of 0.5 s chunks.
        opened = _OpenFile(stats=stats, stream=stream, mcap=mcap, index_spool=spool_chunk_indexes(mcap, str(self.path)))
        self._files.append(stats)
        self._file = opened  # before the first write, so that a write error finds the file to cut
        mcap.start(profile='ros2', library=LIBRARY)
        for topic in self._topics.values():
            self._register(opened, topic)
        for name, data in self._metadata:
            mcap.add_metadata(name, data)
        return opened

    def _register(self, opened: _OpenFile, topic: _Topic) -> None:
        schema_id = opened.schemas.get(topic.msg_type)
        if schema_id is None:
            schema_id = opened.mcap.register_schema(topic.msg_type, 'ros2msg', topic.definition.encode('utf-8'))
            opened.schemas[topic.msg_type] = schema_id
        opened.channels[topic.name] = opened.mcap.register_channel(
            topic.name, 'cdr', schema_id,
            {'offered_qos_profiles': topic.qos_yaml, 'topic_type_hash': topic.type_hash})
        opened.sequences[topic.name] = 0

    def _close_file(self) -> None:
        opened, self._file = self._file, None
        if opened is None:
            return
        try:
            # rosbag2 Jazzy stores the bag metadata known so far in each file it closes.
            opened.mcap.add_metadata(ROSBAG2_METADATA, serialized_bag_metadata(self._bag_metadata()))
            opened.mcap.finish()
        finally:
            opened.stream.close()
            if opened.index_spool is not None:
                opened.index_spool.close()
