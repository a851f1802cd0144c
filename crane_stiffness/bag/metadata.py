"""A bag's description: metadata.yaml (rosbag2 version 9) and the string values of MCAP Metadata records.

:func:`build_bag_metadata` lays out the ``rosbag2_bagfile_information`` mapping from per-file and per-topic counts
(:class:`FileStats`, :class:`TopicStats`); :func:`write_metadata_yaml` writes it atomically and
:func:`read_metadata_yaml` reads it back. MCAP Metadata record values are strings: :func:`encode_metadata` keeps
strings and JSON-encodes everything else, :func:`decode_metadata` undoes that for JSON objects and arrays.
"""
from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import BagPathError, BagWriterError
from .qos import normalize_qos_profiles
from .yamlfmt import dump_yaml, load_yaml

METADATA_FILENAME = 'metadata.yaml'
METADATA_VERSION = 9
ROS_DISTRO = 'jazzy'
ROSBAG2_METADATA = 'rosbag2'
"""Name of the MCAP Metadata record in which rosbag2 stores its serialized bag metadata."""


@dataclass
class FileStats:
    """Counts of one .mcap file of a bag, for metadata.yaml. Times in ns since the epoch."""

    path: str
    message_count: int = 0
    start_ns: int | None = None
    end_ns: int | None = None

    def add(self, log_time_ns: int) -> None:
        """Count one message logged at ``log_time_ns``."""
        self.message_count += 1
        if self.start_ns is None or log_time_ns < self.start_ns:
            self.start_ns = log_time_ns
        if self.end_ns is None or log_time_ns > self.end_ns:
            self.end_ns = log_time_ns


@dataclass
class TopicStats:
    """One topic of a bag, for metadata.yaml."""

    name: str
    msg_type: str
    offered_qos_profiles: str = ''
    type_description_hash: str = ''
    message_count: int = 0
    serialization_format: str = 'cdr'


def build_bag_metadata(files: Sequence[FileStats], topics: Sequence[TopicStats], *,
                       custom_data: Mapping[str, str] | None = None, ros_distro: str = ROS_DISTRO,
                       compression_format: str = '', compression_mode: str = '') -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping (version 9), keys in rosbag2's order.

    ``compression_format``/``compression_mode`` describe rosbag2's own file/message compression and stay empty:
    MCAP chunk compression is internal to the storage files, as with rosbag2's MCAP storage options.
    """
    starts = [f.start_ns for f in files if f.start_ns is not None]
    ends = [f.end_ns for f in files if f.end_ns is not None]
    start = min(starts) if starts else 0
    duration = (max(ends) - start) if ends else 0
    return {
        'version': METADATA_VERSION,
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': sum(f.message_count for f in files),
        'topics_with_message_count': [
            {
                'topic_metadata': {
                    'name': t.name,
                    'type': t.msg_type,
                    'serialization_format': t.serialization_format,
                    'offered_qos_profiles': normalize_qos_profiles(t.offered_qos_profiles),
                    'type_description_hash': t.type_description_hash,
                },
                'message_count': t.message_count,
            }
            for t in topics
        ],
        'compression_format': compression_format,
        'compression_mode': compression_mode,
        'relative_file_paths': [f.path for f in files],
        'files': [
            {
                'path': f.path,
                'starting_time': {'nanoseconds_since_epoch': f.start_ns or 0},
                'duration': {'nanoseconds': (f.end_ns - f.start_ns)
                             if f.start_ns is not None and f.end_ns is not None else 0},  # set together
                'message_count': f.message_count,
            }
            for f in files
        ],
        'custom_data': dict(custom_data) if custom_data else None,
        'ros_distro': ros_distro,
    }


def serialized_bag_metadata(info: Mapping[str, Any]) -> dict[str, str]:
    """The value of the :data:`ROSBAG2_METADATA` record that rosbag2 Jazzy writes into each file it closes (rosbag2
    reads the metadata version from it to parse the channels' QoS strings)."""
    return {'serialized_metadata': dump_yaml(info)}


def write_metadata_yaml(bag_dir: Path, info: Mapping[str, Any]) -> Path:
    """Write ``<bag_dir>/metadata.yaml`` atomically (temporary file, then rename); return its path."""
    path = Path(bag_dir) / METADATA_FILENAME
    tmp = path.with_name(METADATA_FILENAME + '.tmp')
    try:
        tmp.write_text(dump_yaml({'rosbag2_bagfile_information': dict(info)}) + '\n', encoding='utf-8')
        os.replace(tmp, path)
    except BaseException:
        # a failed write (a full disk) leaves no partial metadata.yaml.tmp behind (best effort: the disk may be gone)
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise
    return path


def file_in_bag(bag_dir: Path, name: object, source: str) -> Path:
    """``<bag_dir>/<name>`` for a file name a bag gives (metadata.yaml's ``relative_file_paths``, a file found in
    the directory), refusing anything that leads outside the bag directory.

    A bag is data from elsewhere: a name with ``..``, an absolute path, or a symlink whose target is outside the
    directory would make a reader (analyze, the player, recover) read another directory's files as this bag's.

    Raises:
        BagPathError: naming ``source`` (where the name came from), the name and the rule.
    """
    bag_dir = Path(bag_dir)
    rule = f'a bag reads only files inside its directory {bag_dir}'
    if not isinstance(name, str) or not name or '\0' in name:
        raise BagPathError(f'{source}: file name {name!r} is not a file name; {rule}')
    if os.path.isabs(name):
        raise BagPathError(f'{source}: file {name!r} is an absolute path; {rule}')
    if '..' in name.replace('\\', '/').split('/'):  # also with Windows separators (a bag made elsewhere)
        raise BagPathError(f'{source}: file {name!r} leads out of the bag with ..; {rule}')
    path = bag_dir / name
    real_dir = bag_dir.resolve()
    real = path.resolve()
    if real != real_dir and real_dir not in real.parents:
        raise BagPathError(f'{source}: file {name!r} is a link to {real}, outside the bag; {rule}')
    return path


def read_metadata_yaml(bag_dir: Path) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of ``<bag_dir>/metadata.yaml``.

    Raises:
        OSError, yaml.YAMLError, KeyError or TypeError: missing, not YAML, or not a rosbag2 metadata file.
    """
    loaded = load_yaml((Path(bag_dir) / METADATA_FILENAME).read_text(encoding='utf-8'))
    info = loaded['rosbag2_bagfile_information']
    if not isinstance(info, dict):
        raise TypeError('rosbag2_bagfile_information is not a mapping')
    return info


def encode_metadata(data: Mapping[str, Any]) -> dict[str, str]:
    """MCAP metadata values must be strings: keep strings, JSON-encode everything else."""
    out: dict[str, str] = {}
    for key, value in data.items():
        if not isinstance(key, str):
            raise BagWriterError(f'metadata keys must be strings, got {key!r}')
        out[key] = value if isinstance(value, str) else json.dumps(value, default=str)
    return out


def decode_metadata(record: Mapping[str, str]) -> dict[str, Any]:
    """An MCAP metadata record with its JSON objects and arrays decoded; every other value stays the string."""
    out: dict[str, Any] = {}
    for key, value in record.items():
        try:
            decoded = json.loads(value)
        except ValueError:
            decoded = value
        out[key] = decoded if isinstance(decoded, (dict, list)) else value
    return out
