"""Reading rosbag2 bags without ROS, with a fast bulk decoder for the rig's fixed-layout message types.

:class:`BagReader` opens a bag directory (through its metadata.yaml, or by scanning its ``*.mcap``/``*.db3`` files,
also ``*.zstd``, when metadata.yaml is missing, as after a crash) or a single file. Each file is opened by its
storage (``storage.py``): an MCAP file is a :class:`~.mcapfile.McapFile` (any layout the MCAP specification allows;
a file cut short by SIGKILL gives every complete chunk), a rosbag2 sqlite3 file a :class:`~.sqlitefile.Sqlite3File`;
rosbag2's zstd compression (``compression_mode: file`` or ``message``) is undone on the way. What cannot be read
exactly raises a :class:`~.errors.BagError` naming the file and the reason; no message is skipped silently. Only
files inside the bag directory are read: a metadata.yaml entry with ``..``, an absolute path or a symlink leading
out raises :class:`~.errors.BagPathError` (``metadata.file_in_bag``). Damage is reported with
:class:`~.errors.BagDamageWarning` (or raised when ``strict=True``) and the readable part is used.

Bulk decoding (:meth:`BagReader.decode`) works a chunk at a time: decompress, gather the messages of a channel at
once (:meth:`~.mcapfile.McapFile.chunk_messages`), then decode their CDR fields with numpy
(:mod:`crane_stiffness.serde.bulk`).

Times are integer nanoseconds since the epoch (``*_ns``); ``stamp_s`` is the header stamp in seconds (float64).
This module must not import rclpy (the analysis machine may have no ROS).
"""

from __future__ import annotations

import heapq
import itertools
from collections import deque
from concurrent.futures import ThreadPoolExecutor
import re
import threading
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from types import TracebackType
from typing import Any, NamedTuple

import numpy as np

from crane_stiffness.serde.bulk import SUPPORTED_TYPES, Decoder, new_decoder

from .chunks import ChunkMessages, ChunkRef, in_file_order
from .errors import (
    BagCorruptError, BagDamageWarning, BagNotFoundError, BagUnsupportedError, TopicNotFoundError,
    UnsupportedTypeError,
)
from .metadata import METADATA_FILENAME, ROSBAG2_METADATA, file_in_bag, read_metadata_yaml
from .storage import BagFile, TemporaryCopy, check_compression, decompress_messages, open_bag_file


#: The message encoding the readers hand out (RawMessage.data) and decode, and the schema encodings whose type
#: names the bulk decoders know.
MESSAGE_ENCODING = 'cdr'
SCHEMA_ENCODINGS = ('ros2msg', 'ros2idl')
#: File names a bag directory without metadata.yaml is read from (rosbag2's storages, compressed or not).
BAG_FILE_PATTERNS = ('*.mcap', '*.db3', '*.mcap.zstd', '*.db3.zstd')

#: Chunks read and decompressed ahead of the bulk decoder, and the threads doing it (BagReader._read_ahead).
READ_AHEAD_CHUNKS = 4
READ_THREADS = 2


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
    message_encoding: str = MESSAGE_ENCODING
    """How the messages are serialized (``cdr`` for ROS 2)."""
    schema_encoding: str = 'ros2msg'
    """What the type's definition is written in (``ros2msg``; empty when the bag has no schema)."""


# -------------------------------------------------------------------------------------------------- bag reader --
def _file_order(path: Path) -> tuple[str, int]:
    match = re.match(r'^(.*?)(?:_(\d+))?\.(?:mcap|db3)(?:\.zstd)?$', path.name)
    assert match
    return match.group(1), int(match.group(2) or 0)


class BagReader:
    """Read a rosbag2 bag directory, or one .mcap file. Use as a context manager.

    Args:
        path: bag directory (with or without metadata.yaml) or one file (.mcap, .db3, or either zstd-compressed).
        strict: raise :class:`~.errors.BagCorruptError` on damaged data instead of warning and skipping it.
        verify_crc: check chunk CRCs (cheap; catches corrupted bytes).
    """

    def __init__(self, path: str | Path, *, strict: bool = False, verify_crc: bool = True) -> None:
        self.path = Path(path)
        self.bag_metadata: dict[str, Any] | None = None
        """The ``rosbag2_bagfile_information`` of metadata.yaml, when present and readable."""
        self._problems: list[str] = []
        self._files: list[BagFile] = []
        self._copies: list[TemporaryCopy] = []
        self.compression_mode = ''
        """rosbag2's compression of the bag: '' (none), 'file' or 'message' (zstd), from metadata.yaml."""
        self._zstd = threading.local()
        if not self.path.exists():
            raise BagNotFoundError(f'bag {self.path} does not exist')
        paths = self._resolve_files(strict)
        try:
            if self.bag_metadata is not None:
                self.compression_mode = check_compression(
                    self.path, str(self.bag_metadata.get('compression_format') or ''),
                    str(self.bag_metadata.get('compression_mode') or ''))
            for file_path in paths:
                opened, copy = open_bag_file(file_path, strict=strict, verify_crc=verify_crc)
                self._files.append(opened)
                if copy is not None:
                    self._copies.append(copy)
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
                found = [file_in_bag(self.path, n, f'{meta_path} relative_file_paths') for n in names]
                missing = [p for p in found if not p.is_file()]
                if missing:
                    self._warn(f'{meta_path} lists missing file(s) {", ".join(p.name for p in missing)}')
                present = [p for p in found if p.is_file()]
                if present:
                    return present
        on_disk = {p for pattern in BAG_FILE_PATTERNS for p in self.path.glob(pattern)}
        files = [file_in_bag(self.path, p.name, f'{self.path}') for p in sorted(on_disk, key=_file_order)]
        if not files:
            raise BagNotFoundError(f'{self.path} holds no metadata.yaml and no bag file '
                                   f'({", ".join(BAG_FILE_PATTERNS)})')
        return files

    # -- lifetime --
    def close(self) -> None:
        """Close the files (and delete the decompressed copies of file-compressed ones)."""
        for bag_file in getattr(self, '_files', []):
            bag_file.close()
        for copy in getattr(self, '_copies', []):
            copy.remove()

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- overview --
    @property
    def files(self) -> list[Path]:
        """The files read, in order (as the bag names them: a compressed file, not its decompressed copy)."""
        return [f.path for f in self._files]

    @property
    def complete(self) -> bool:
        """True when every file was finished by its writer (has a footer)."""
        return all(f.complete for f in self._files)

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topic name → :class:`TopicInfo` (type, message count, QoS, type hash, definition), all files."""
        out: dict[str, TopicInfo] = {}
        for bag_file in self._files:
            for cid, channel in bag_file.channels.items():
                schema = bag_file.schemas.get(channel.schema_id)
                count = bag_file.channel_counts.get(cid, 0)
                previous = out.get(channel.topic)
                if previous is not None:
                    out[channel.topic] = replace(previous, count=previous.count + count)
                    continue
                out[channel.topic] = TopicInfo(
                    name=channel.topic, msg_type=schema.name if schema else '', count=count,
                    offered_qos_profiles=channel.metadata.get('offered_qos_profiles', ''),
                    type_description_hash=channel.metadata.get('topic_type_hash', ''),
                    message_definition=schema.data.decode('utf-8', 'replace') if schema else '',
                    message_encoding=channel.message_encoding, schema_encoding=schema.encoding if schema else '')
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
                if include_rosbag2 or name != ROSBAG2_METADATA:
                    out[name] = dict(data)
        return out

    # -- topics --
    def _channels_for(self, topics: Iterable[str]) -> list[dict[int, str]]:
        """Per file, channel id → topic of the channels of ``topics``; every channel must hold CDR messages."""
        wanted = list(topics)
        known = self.topics
        for topic in wanted:
            if topic not in known:
                present = ', '.join(f'{t} [{i.msg_type}]' for t, i in sorted(known.items())) or 'none'
                raise TopicNotFoundError(f'topic {topic!r} is not in bag {self.path}; topics present: {present}')
        per_file = []
        for bag_file in self._files:
            channels = {}
            for cid, channel in bag_file.channels.items():
                if channel.topic not in wanted:
                    continue
                if channel.message_encoding != MESSAGE_ENCODING:
                    raise BagUnsupportedError(
                        f'{bag_file.path}: topic {channel.topic} (channel {cid}) holds messages encoded as '
                        f'{channel.message_encoding!r}; this reader reads ROS 2 messages ({MESSAGE_ENCODING!r})')
                channels[cid] = channel.topic
            per_file.append(channels)
        return per_file

    def _gather(self, bag_file: BagFile, chunk: ChunkRef, data: Any, channels: dict[int, str]
                ) -> dict[int, ChunkMessages]:
        """Per channel, the chunk's messages, their data decompressed in a message-compressed bag."""
        found = bag_file.chunk_messages(chunk, data, channels)
        if self.compression_mode != 'message':
            return found
        zstd = getattr(self._zstd, 'decompressor', None)
        if zstd is None:
            import zstandard
            zstd = self._zstd.decompressor = zstandard.ZstdDecompressor()
        try:
            return {cid: decompress_messages(messages, zstd) for cid, messages in found.items()}
        except BagUnsupportedError:
            raise
        except Exception as exc:
            raise BagCorruptError(f'{bag_file.path}: a message of the chunk at {chunk.offset} of this '
                                  f'message-compressed bag does not decompress: {exc}') from None

    def _chunks(self, per_file: list[dict[int, str]], start_ns: int | None, end_ns: int | None
                ) -> Iterator[tuple[BagFile, ChunkRef, dict[int, str]]]:
        for bag_file, channels in zip(self._files, per_file):
            if not channels:
                continue
            for chunk in bag_file.chunks:
                if chunk.index is not None and not set(chunk.index) & set(channels):
                    continue
                if not chunk.loose and ((start_ns is not None and chunk.end_ns < start_ns)
                                        or (end_ns is not None and chunk.start_ns >= end_ns)):
                    continue
                yield bag_file, chunk, channels

    # -- raw messages --
    def messages(self, topics: Iterable[str] | None = None, *, start_ns: int | None = None,
                 end_ns: int | None = None) -> Iterator[RawMessage]:
        """Serialized messages in log-time order (equal log times in file order), optionally only some topics and
        ``start_ns <= t < end_ns``. The chunks are read in the order of their first log time, whatever their order
        in the files, and merged."""
        per_file = self._channels_for(self.topics if topics is None else topics)
        heap: list[tuple[int, int, str, bytes]] = []
        order = itertools.count()
        refs = sorted(self._chunks(per_file, start_ns, end_ns), key=lambda ref: ref[1].start_ns)
        for bag_file, chunk, channels in refs:
            while heap and heap[0][0] < chunk.start_ns:
                log, _, topic, data = heapq.heappop(heap)
                yield RawMessage(topic, log, data)
            data_array = bag_file.chunk_data(chunk, channels)
            if data_array is None:
                continue
            for cid, _, log, _, payload in in_file_order(self._gather(bag_file, chunk, data_array, channels)):
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

    def decode_topics(self, topics: Sequence[str], *, start_ns: int | None = None, end_ns: int | None = None,
                      columns: bool = False) -> dict[str, Any]:
        """Like :meth:`decode` for several topics in one pass over the file (each chunk decompressed once). With
        ``columns`` each topic comes as :class:`~crane_stiffness.serde.bulk.Columns` (the same fields, no structured
        array built)."""
        known = self.topics
        per_file = self._channels_for(topics)
        decoders: dict[str, Decoder] = {}
        for topic in topics:
            msg_type = known[topic].msg_type
            if known[topic].schema_encoding not in SCHEMA_ENCODINGS:
                raise BagUnsupportedError(
                    f'{self.path}: topic {topic} has schema encoding {known[topic].schema_encoding!r} (type '
                    f'{msg_type!r}); the bulk decoder reads ROS 2 types ({", ".join(SCHEMA_ENCODINGS)})')
            decoder = new_decoder(msg_type)
            if decoder is None:
                raise UnsupportedTypeError(f'topic {topic} has type {msg_type}, which the bulk decoder does not '
                                           f'handle (supported: {", ".join(SUPPORTED_TYPES)}); use messages()')
            decoders[topic] = decoder
        parts: dict[str, list[dict[str, np.ndarray]]] = {t: [] for t in topics}
        for bag_file, chunk, channels, data in self._read_ahead(self._chunks(per_file, start_ns, end_ns)):
            if data is None:
                continue
            for cid, found in self._gather(bag_file, chunk, data, channels).items():
                if not len(found):
                    continue
                topic = channels[cid]
                cols, valid = decoders[topic].decode(found.buf, found.data_offset, found.data_length)
                if not valid.all():
                    text = (f'{bag_file.path}: {int((~valid).sum())} message(s) of {topic} in chunk at offset '
                            f'{chunk.offset} do not have the {decoders[topic].msg_type} layout; skipped')
                    if bag_file.strict:
                        raise BagCorruptError(text)
                    self._warn(text)
                    if not valid.any():
                        continue
                if valid.all():
                    cols['log_time_ns'] = found.log_time.astype(np.int64)
                else:
                    cols = {k: v[valid] for k, v in cols.items()}
                    cols['log_time_ns'] = found.log_time[valid].astype(np.int64)
                parts[topic].append(cols)
        # Each topic's columns into one structured array: numpy's copies release the GIL, so the big topics (the
        # two sensor streams) are assembled side by side.
        with ThreadPoolExecutor(max_workers=READ_THREADS, thread_name_prefix='bag_assemble') as pool:
            arrays = pool.map(lambda t: self._assemble(decoders[t], parts[t], start_ns, end_ns, columns), topics)
            return dict(zip(topics, arrays))

    @staticmethod
    def _read_ahead(refs: Iterator[tuple[BagFile, ChunkRef, dict[int, str]]], ahead: int = READ_AHEAD_CHUNKS
                    ) -> Iterator[tuple[BagFile, ChunkRef, dict[int, str], Any]]:
        """``refs`` in order, each with its chunk's data (``BagFile.chunk_data``) read and decompressed up to
        ``ahead`` chunks in advance on worker threads: pread, zstd/lz4 and the CRC release the GIL, so on two cores
        decompression overlaps the decoding of the chunk before (a bounded window: an hour's chunks decompressed at
        once would take gigabytes)."""
        with ThreadPoolExecutor(max_workers=READ_THREADS, thread_name_prefix='bag_read') as pool:
            pending: deque = deque()
            for ref in refs:
                pending.append((ref, pool.submit(ref[0].chunk_data, ref[1], ref[2])))
                if len(pending) > ahead:
                    done, future = pending.popleft()
                    yield (*done, future.result())
            while pending:
                done, future = pending.popleft()
                yield (*done, future.result())

    @staticmethod
    def _assemble(decoder: Decoder, parts: list[dict[str, np.ndarray]], start_ns: int | None,
                  end_ns: int | None, as_columns: bool = False) -> Any:
        if not parts:
            return decoder.empty_columns() if as_columns else decoder.empty()
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
        return decoder.to_columns(columns) if as_columns else decoder.to_array(columns)


__all__ = ['BagReader', 'RawMessage', 'SUPPORTED_TYPES', 'TopicInfo']
