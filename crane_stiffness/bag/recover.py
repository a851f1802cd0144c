"""Repair a bag left unfinished by a crash (SIGKILL, power cut) and (re)write its metadata.yaml.

A killed writer leaves its last .mcap without summary and footer, and the bag without metadata.yaml. The complete
chunks are still on disk: :func:`recover_bag` reads every complete message (also those at the start of a chunk the
kill cut short), writes them into a new, valid MCAP file in place of the damaged one (keeping the original as
``<file>.bak`` unless told not to), and writes metadata.yaml from what it found.

Command line (the ``crane-stiffness`` CLI calls the same function)::

    python -m crane_stiffness.bag.recover PATH [--no-backup]

PATH is a bag directory or one .mcap file. Exit status 0 when everything readable was saved, 1 when a file could
not be read at all, 2 on an error.
"""

from __future__ import annotations

import argparse
import os
import shutil
import re
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from mcap.writer import Writer as McapWriter

from .errors import BagError, BagFormatError, BagNotFoundError, BagWriteFailedError, os_error_text
from .mcapfile import McapFile
from .metadata import (
    METADATA_FILENAME, ROSBAG2_METADATA, FileStats, TopicStats, build_bag_metadata, file_in_bag, read_metadata_yaml,
    serialized_bag_metadata, write_metadata_yaml,
)
from .reader import _file_order
from .writer import COMPRESSIONS, DEFAULT_CHUNK_SIZE, LIBRARY


_RECOVER_HINT = '; `python -m crane_stiffness.bag.recover` rewrites it as a valid file'


@dataclass
class FileRecovery:
    """What happened to one .mcap file.

    ``status``: intact (finished by its writer), recovered (rewritten), unreadable (not MCAP), or unfinished
    (damaged but left alone because another file of the directory was asked for).
    """

    path: Path
    status: str
    message_count: int = 0
    chunks_read: int = 0
    partial_messages: int = 0
    """Messages saved from a chunk cut short by the end of the file."""
    bytes_ignored: int = 0
    backup: Path | None = None
    problems: list[str] = field(default_factory=list)


@dataclass
class RecoveryReport:
    """Result of :func:`recover_bag`: per-file outcome, per-topic counts, metadata.yaml written or not."""

    bag_path: Path
    files: list[FileRecovery]
    topics: dict[str, tuple[str, int]]
    """Topic → (type, messages)."""
    start_ns: int | None = None
    end_ns: int | None = None
    metadata_path: Path | None = None

    @property
    def message_count(self) -> int:
        """Messages in the repaired bag."""
        return sum(f.message_count for f in self.files if f.status in ('intact', 'recovered'))

    @property
    def ok(self) -> bool:
        """True when no file was unreadable."""
        return all(f.status in ('intact', 'recovered') for f in self.files)

    def __str__(self) -> str:
        lines = [f'Recovery of {self.bag_path}']
        width = max([len(f.path.name) for f in self.files] + [4])
        for f in self.files:
            text = f'  {f.path.name:<{width}}  {f.status:<10}  {f.message_count:>10} messages'
            if f.status == 'recovered':
                text += f' from {f.chunks_read} complete chunk(s)'
                if f.partial_messages:
                    text += f' + {f.partial_messages} from the cut last chunk'
                if f.bytes_ignored:
                    text += f'; {f.bytes_ignored} unreadable byte(s) dropped'
                text += f'; original kept as {f.backup.name}' if f.backup else '; original replaced'
            lines.append(text)
            lines.extend(f'      ! {p}' for p in f.problems)
        if self.topics:
            lines.append('Topics:')
            tw = max(len(t) for t in self.topics)
            for topic, (msg_type, count) in sorted(self.topics.items()):
                lines.append(f'  {topic:<{tw}}  {msg_type:<36}  {count:>10}')
        span = ((self.end_ns - self.start_ns) / 1e9) if self.start_ns is not None and self.end_ns is not None else 0.0
        lines.append(f'Total: {self.message_count} messages over {span:.3f} s')
        lines.append(f'Wrote {self.metadata_path}' if self.metadata_path else 'metadata.yaml not written')
        return '\n'.join(lines)


def _backup_path(path: Path) -> Path:
    candidate = path.with_name(path.name + '.bak')
    number = 1
    while candidate.exists():
        candidate = path.with_name(f'{path.name}.bak{number}')
        number += 1
    return candidate


def _rewrite(source: McapFile, result: FileRecovery, stats: FileStats, counts: dict[int, int],
             backup: bool, chunk_size: int) -> None:
    """Copy every readable message of ``source`` into a new valid file that replaces it."""
    compressions = [c.compression for c in source.chunks if not c.loose]
    compression = {'': 'none'}.get(compressions[0], compressions[0]) if compressions else 'zstd'
    if compression not in COMPRESSIONS:
        compression = 'zstd'
    tmp = source.path.with_name(source.path.name + '.recovering')
    try:
        _copy_messages(source, result, stats, counts, tmp, compression, chunk_size)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        # The copy is written beside the original before it replaces it: it needs about the readable part's size.
        needed = source.readable_end
        raise BagWriteFailedError(
            f'cannot rewrite {source.path}: writing {tmp.name} failed: {os_error_text(exc)}; the rewrite needs about '
            f'{needed} bytes ({needed / 2**20:.2f} MiB) free in {source.path.parent} (free now: '
            f'{_free_bytes(source.path.parent)} bytes); the file was left as it was', source.path, exc.errno) from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    result.message_count = stats.message_count
    result.bytes_ignored = source.size - source.readable_end
    source.close()
    if backup:
        result.backup = _backup_path(source.path)
        os.replace(source.path, result.backup)
    os.replace(tmp, source.path)


def _copy_messages(source: McapFile, result: FileRecovery, stats: FileStats, counts: dict[int, int], tmp: Path,
                   compression: str, chunk_size: int) -> None:
    with open(tmp, 'wb') as stream:
        writer = McapWriter(stream, chunk_size=chunk_size, compression=COMPRESSIONS[compression])
        writer.start(profile=source.profile or 'ros2', library=f'{LIBRARY} recover')
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for cid, channel in sorted(source.channels.items()):
            schema = source.schemas.get(channel.schema_id)
            if schema is not None and schema.id not in schema_ids:
                schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            channel_ids[cid] = writer.register_channel(channel.topic, channel.message_encoding,
                                                       schema_ids.get(channel.schema_id, 0), channel.metadata)
        for name, record in source.metadata:
            if name != ROSBAG2_METADATA:
                writer.add_metadata(name, record)
        lost = 0

        def copy(cid: int, seq: int, log: int, pub: int, payload: bytes) -> bool:
            nonlocal lost
            if cid not in channel_ids:
                lost += 1
                return False
            writer.add_message(channel_ids[cid], log, payload, pub, seq)
            stats.add(log)
            counts[cid] = counts.get(cid, 0) + 1
            return True

        for chunk in source.chunks:
            data = source.chunk_data(chunk)
            if data is None:
                continue
            result.chunks_read += 0 if chunk.loose else 1
            for message in source.iter_chunk_messages(chunk, data):
                copy(*message)
        for message in source.partial_chunk_messages():
            result.partial_messages += int(copy(*message))
        if lost:
            result.problems.append(f'{lost} message(s) of channels whose definition was lost were dropped')
        # rosbag2 reads the metadata version from this record to parse the channels' QoS strings (v9 form)
        topics = [TopicStats(name=ch.topic, msg_type=getattr(source.schemas.get(ch.schema_id), 'name', ''),
                             offered_qos_profiles=ch.metadata.get('offered_qos_profiles', ''),
                             type_description_hash=ch.metadata.get('topic_type_hash', ''),
                             message_count=counts.get(cid, 0)) for cid, ch in sorted(source.channels.items())]
        writer.add_metadata(ROSBAG2_METADATA, serialized_bag_metadata(build_bag_metadata([stats], topics)))
        writer.finish()


def _chunks_sound(source: McapFile) -> bool:
    """True when every chunk of a finished file decompresses and passes its CRC (damage is recorded)."""
    return all(source.chunk_data(chunk) is not None for chunk in source.chunks)


def _recover_file(path: Path, backup: bool, chunk_size: int, rewrite: bool = True
                  ) -> tuple[FileRecovery, FileStats, dict[str, TopicStats]]:
    """Recover one file (or, with ``rewrite=False``, only take stock of it: damaged → 'unfinished')."""
    result = FileRecovery(path=path, status='intact')
    stats = FileStats(path=path.name)
    topics: dict[str, TopicStats] = {}
    with warnings.catch_warnings(record=True):
        warnings.simplefilter('always')
        try:
            source = McapFile(path)
        except BagFormatError as exc:
            result.status = 'unreadable'
            result.problems.append(str(exc))
            return result, stats, topics
        try:
            counts: dict[int, int] = {}
            result.problems.extend(p.replace(_RECOVER_HINT, '') for p in source.problems)
            if source.complete and not source.problems and _chunks_sound(source):
                counts = dict(source.channel_counts)
                result.message_count = sum(counts.values())
                result.chunks_read = len(source.chunks)
                stats.message_count = result.message_count
                stats.start_ns, stats.end_ns = source.start_ns, source.end_ns
            elif not rewrite:
                result.status = 'unfinished'
                return result, stats, topics
            else:
                result.status = 'recovered'
                before = len(source.problems)
                _rewrite(source, result, stats, counts, backup, chunk_size)
                result.problems.extend(p.replace(_RECOVER_HINT, '') for p in source.problems[before:])
            for cid, channel in source.channels.items():
                schema = source.schemas.get(channel.schema_id)
                topics[channel.topic] = TopicStats(
                    name=channel.topic, msg_type=schema.name if schema else '',
                    offered_qos_profiles=channel.metadata.get('offered_qos_profiles', ''),
                    type_description_hash=channel.metadata.get('topic_type_hash', ''),
                    message_count=counts.get(cid, 0), serialization_format=channel.message_encoding or 'cdr')
        finally:
            source.close()
    return result, stats, topics


def recover_bag(path: str | os.PathLike[str], *, backup: bool = True,
                chunk_size: int = DEFAULT_CHUNK_SIZE) -> RecoveryReport:
    """Rewrite unfinished .mcap files of a bag into valid ones and (re)write metadata.yaml.

    Args:
        path: bag directory (every unfinished .mcap in it is repaired), or one .mcap file (only that file is
            repaired; metadata.yaml is then written only when the file sits in a rosbag2 bag directory, i.e. is
            named ``<dir name>_<n>.mcap`` or the directory already has a metadata.yaml, and lists the directory's
            other readable, finished .mcap files too).
        backup: keep each damaged original as ``<file>.bak``; False deletes it after the rewrite.
        chunk_size: uncompressed chunk size in bytes of the rewritten files.

    Returns:
        a :class:`RecoveryReport` (``str()`` of it is a readable summary).
    """
    target = Path(path)
    if not target.exists():
        raise BagNotFoundError(f'{target} does not exist')
    if target.is_dir():
        bag_dir = target
        write_meta = True
    else:
        bag_dir = target.parent
        write_meta = (bag_dir / METADATA_FILENAME).is_file() or bool(
            re.fullmatch(re.escape(bag_dir.name) + r'_\d+\.mcap', target.name))
    files = [file_in_bag(bag_dir, f.name, str(bag_dir)) for f in sorted(bag_dir.glob('*.mcap'), key=_file_order)] \
        if write_meta else [target]
    if not files:
        raise BagNotFoundError(f'{target} holds no .mcap file')
    outcomes = [_recover_file(f, backup, chunk_size, rewrite=target.is_dir() or f == target) for f in files]
    usable = [o for o in outcomes if o[0].status in ('intact', 'recovered')]
    topics: dict[str, TopicStats] = {}
    for _, _, file_topics in usable:
        for name, topic in file_topics.items():
            if name in topics:
                topics[name].message_count += topic.message_count
            else:
                topics[name] = topic
    stats = [o[1] for o in usable]
    starts = [s.start_ns for s in stats if s.start_ns is not None]
    ends = [s.end_ns for s in stats if s.end_ns is not None]
    report = RecoveryReport(bag_path=target, files=[o[0] for o in outcomes],
                            topics={t.name: (t.msg_type, t.message_count) for t in topics.values()},
                            start_ns=min(starts) if starts else None, end_ns=max(ends) if ends else None)
    if write_meta:
        info = build_bag_metadata(stats, list(topics.values()), custom_data=_old_custom_data(bag_dir))
        try:
            report.metadata_path = write_metadata_yaml(bag_dir, info)
        except OSError as exc:
            raise BagWriteFailedError(
                f'cannot write {bag_dir / METADATA_FILENAME}: {os_error_text(exc)}; it needs a few kB free in '
                f'{bag_dir} (free now: {_free_bytes(bag_dir)} bytes); the .mcap files are recovered',
                bag_dir / METADATA_FILENAME, exc.errno) from exc
    return report


def _free_bytes(directory: Path) -> int | str:
    try:
        return shutil.disk_usage(directory).free
    except OSError:
        return 'unknown'


def _old_custom_data(bag_dir: Path) -> dict[str, str] | None:
    """custom_data of an existing metadata.yaml, to keep it (None when there is none or it is damaged)."""
    try:
        data = read_metadata_yaml(bag_dir).get('custom_data')
    except Exception:  # missing or damaged: nothing to keep
        return None
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else None


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry: recover PATH and print the report."""
    parser = argparse.ArgumentParser(prog='python -m crane_stiffness.bag.recover',
                                     description='Repair a bag left unfinished by a crash and rewrite metadata.yaml.')
    parser.add_argument('path', help='bag directory or .mcap file')
    parser.add_argument('--no-backup', action='store_true', help='delete damaged originals instead of keeping .bak')
    args = parser.parse_args(argv)
    try:
        report = recover_bag(args.path, backup=not args.no_backup)
    except (BagError, OSError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    print(report)
    return 0 if report.ok else 1


if __name__ == '__main__':
    sys.exit(main())
