"""rosbag2 bag reading and writing, pure Python; reading needs no ROS.

- :class:`BagWriter` (``writer.py``): a rosbag2 bag directory of chunked MCAP files plus metadata.yaml (v9),
  crash-safe chunk by chunk, split by size or duration, the caller's metadata as MCAP Metadata records.
- :class:`BagReader` (``reader.py``): topics, metadata records, raw messages, and a fast bulk decoder of the rig's
  fixed-layout types into numpy structured arrays (the CDR decoders are :mod:`crane_stiffness.serde.bulk`). It reads
  any bag rosbag2 or another writer leaves: MCAP in any layout the MCAP specification allows, sqlite3 (``.db3``,
  metadata.yaml versions 4-9), zstd compression per file or per message; what it cannot read exactly raises a
  :class:`BagError` naming the file and the reason (:class:`BagUnsupportedError`: a compression or encoding it
  does not know), never a message skipped silently.
- ``storage.py``: which storage a file is (by its first bytes), :class:`~.storage.BagFile` (what the reader reads of
  a file, whatever its storage) and rosbag2's compression modes.
- :class:`McapFile` (``mcapfile.py``): one MCAP file's structure and chunks, its records read by the ``mcap``
  package (schemas and channels learned wherever they are; messages in and outside chunks; padding and unknown
  opcodes skipped); a file cut short gives every complete chunk.
- :class:`Sqlite3File` (``sqlitefile.py``): one rosbag2 sqlite3 file, read with the standard library's ``sqlite3``.
- ``metadata.py``: metadata.yaml (rosbag2 v9) and MCAP metadata values; ``qos.py``: offered QoS profiles.
- :func:`recover_bag` (``recover.py``): rewrite files left unfinished by a crash and (re)write metadata.yaml.
- ``session_metadata.py``: the session record, what a recording says about itself (program, geometry, nodes'
  parameters, campaign entry) in its bag's metadata records; imported on its own (it reads the load program).
- ``msgdef.py``: ros2msg schema text and type hashes from the installed .msg files.
- ``errors.py``: the exceptions (all :class:`BagError`) and :class:`BagDamageWarning`.
"""

from typing import TYPE_CHECKING

from .errors import (
    BagCorruptError, BagDamageWarning, BagError, BagExistsError, BagFormatError, BagNotFoundError, BagPathError,
    BagUnsupportedError, BagWriteFailedError, BagWriterError,
    MessageDefinitionError, TopicNotFoundError, UnsupportedTypeError,
)
from .mcapfile import McapFile
from .qos import dump_qos_profiles, normalize_qos_profiles, qos_profile
from .reader import SUPPORTED_TYPES, BagReader, RawMessage, TopicInfo
from .sqlitefile import Sqlite3File
from .writer import BagWriter

if TYPE_CHECKING:  # imported when first asked for (__getattr__ below); named here for type checkers
    from .recover import RecoveryReport, recover_bag


def __getattr__(name: str) -> object:
    # recover.py is also run as ``python -m crane_stiffness.bag.recover``: import it only when asked for, so that
    # runpy does not find it already imported.
    if name in ('recover_bag', 'RecoveryReport'):
        from . import recover
        return getattr(recover, name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')

__all__ = [
    'BagCorruptError', 'BagDamageWarning', 'BagError', 'BagExistsError', 'BagFormatError', 'BagNotFoundError',
    'BagPathError', 'BagUnsupportedError', 'BagWriteFailedError',
    'BagReader', 'BagWriter', 'BagWriterError', 'McapFile', 'MessageDefinitionError', 'RawMessage', 'RecoveryReport',
    'Sqlite3File',
    'SUPPORTED_TYPES', 'TopicInfo', 'TopicNotFoundError', 'UnsupportedTypeError', 'dump_qos_profiles',
    'normalize_qos_profiles', 'qos_profile', 'recover_bag',
]
