"""A bag copied by the independent ``rosbags`` writer into rosbag2's other storages and compressions.

:func:`copy_bag` reads a bag with ``rosbags``' own reader and writes its messages (same topics, types, definitions,
QoS, log times and bytes) with ``rosbags``' rosbag2 Writer: sqlite3 or MCAP storage, no compression or zstd per file
(``.mcap.zstd``/``.db3.zstd``) or per message. The session metadata records of this package are not copied (rosbag2
has no place for them in sqlite3): the copy is a bag as another lab's recorder would leave it.
"""
from __future__ import annotations

from collections.abc import Collection
from pathlib import Path

from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin

STORAGES = {'sqlite3': StoragePlugin.SQLITE3, 'mcap': StoragePlugin.MCAP}
COMPRESSIONS = {'': None, 'file': CompressionMode.FILE, 'message': CompressionMode.MESSAGE}


def copy_bag(source: Path, target: Path, *, storage: str = 'sqlite3', compression: str = '',
             topics: Collection[str] | None = None, version: int = 9) -> Path:
    """Copy the bag ``source`` (directory) to ``target`` (a new directory) with the ``rosbags`` writer.

    Args:
        storage: ``'sqlite3'`` or ``'mcap'``.
        compression: ``''``, ``'file'`` or ``'message'`` (zstd).
        topics: the topics copied (default all).
        version: metadata.yaml version (rosbags writes 8 or 9).
    """
    writer = Writer(target, version=version, storage_plugin=STORAGES[storage])  # type: ignore[arg-type]
    mode = COMPRESSIONS[compression]
    if mode is not None:
        writer.set_compression(mode, CompressionFormat.ZSTD)
    with Reader(source) as reader, writer:
        connections = [c for c in reader.connections if topics is None or c.topic in topics]
        out = {}
        for conn in connections:
            qos = conn.ext.offered_qos_profiles if hasattr(conn.ext, 'offered_qos_profiles') else []
            out[conn.id] = writer.add_connection(conn.topic, conn.msgtype, msgdef=conn.msgdef.data,
                                                 rihs01=conn.digest, offered_qos_profiles=qos)
        for conn, timestamp, data in reader.messages(connections=connections):
            writer.write(out[conn.id], timestamp, data)
    return target
