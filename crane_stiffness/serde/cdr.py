"""Encoding and decoding of the few small CDR messages the project handles itself, without rosidl.

The bulk decoder (:mod:`crane_stiffness.serde.bulk`) covers the rig's fixed-layout streams; these are the rest:
std_msgs/String (program state), std_msgs/Float64MultiArray (the estimator's values), std_msgs/Float64, and stamped
messages (synthetic sessions; the recorder's header stamps; and the stiffness estimator, which takes its 1 kHz sensor
streams serialized: decoding the header and the floats here costs a few µs, building the rclpy message object about
25 µs). XCDR1: a 4-byte encapsulation header (``00 01 00 00`` little endian, ``00 00 ..`` big endian), then the
fields, each aligned to its size relative to the first byte after the header.
"""
from __future__ import annotations

import struct
from typing import Sequence

import numpy as np

from .errors import CdrError

ENCAPSULATION = b'\x00\x01\x00\x00'
_U32 = struct.Struct('<I')


def _align(pos: int, size: int) -> int:
    """Next position aligned to ``size`` relative to the byte after the encapsulation header (offset 4)."""
    return pos + (-(pos - 4)) % size


def _check_header(data: bytes) -> None:
    if len(data) < 4 or data[1] != 1:
        raise CdrError('not a little-endian CDR message')


def _u32(data: bytes, pos: int) -> tuple[int, int]:
    pos = _align(pos, 4)
    if pos + 4 > len(data):
        raise CdrError('message ends inside a uint32')
    return _U32.unpack_from(data, pos)[0], pos + 4


def _string(data: bytes, pos: int) -> tuple[str, int]:
    size, pos = _u32(data, pos)
    if size < 1 or pos + size > len(data) or data[pos + size - 1] != 0:
        raise CdrError('bad string field')
    return data[pos:pos + size - 1].decode('utf-8', 'replace'), pos + size


def decode_string(data: bytes) -> str:
    """std_msgs/String → its text."""
    _check_header(data)
    return _string(data, 4)[0]


def encode_string(text: str) -> bytes:
    raw = text.encode('utf-8') + b'\0'
    return ENCAPSULATION + _U32.pack(len(raw)) + raw


def decode_float64(data: bytes) -> float:
    """std_msgs/Float64 (either byte order) → its value."""
    if len(data) < 12 or data[0] != 0 or data[1] > 1:
        raise CdrError('not a CDR std_msgs/Float64')
    return struct.unpack_from('<d' if data[1] == 1 else '>d', data, 4)[0]


def encode_float64(value: float) -> bytes:
    return ENCAPSULATION + struct.pack('<d', float(value))


_HEADER = {True: struct.Struct('<iII'), False: struct.Struct('>iII')}
_DOUBLES: dict[tuple[int, bool], struct.Struct] = {}


def decode_stamped(data: bytes, count: int) -> tuple[int, int, tuple[float, ...]]:
    """A message of ``std_msgs/Header`` then ``count`` float64 fields (WrenchStamped: 6, PointStamped: 3) →
    (header stamp sec, nanosec, the floats). Either byte order (the encapsulation header says which); a few µs, for
    subscribers taking serialized messages at high rates.

    Raises:
        CdrError: not CDR, or too short for the header, its frame_id and ``count`` floats.
    """
    if len(data) < 16 or data[0] != 0 or data[1] > 1:
        raise CdrError('not a CDR message with a std_msgs/Header')
    little = data[1] == 1
    sec, nanosec, size = _HEADER[little].unpack_from(data, 4)
    pos = 16 + size
    pos += (-(pos - 4)) % 8
    fmt = _DOUBLES.get((count, little))
    if fmt is None:
        fmt = _DOUBLES[(count, little)] = struct.Struct(('<' if little else '>') + 'd' * count)
    if size < 1 or nanosec >= 1_000_000_000 or pos + 8 * count > len(data):
        raise CdrError(f'bad header or fewer than {count} float64 fields after it')
    return sec, nanosec, fmt.unpack_from(data, pos)


_STAMP = struct.Struct('<iI')


def header_stamp_ns(data: bytes) -> int | None:
    """The header stamp of a serialized stamped message (little-endian CDR), ns; None when unset or unreadable."""
    if len(data) < 12 or data[1] != 1:
        return None
    sec, nanosec = _STAMP.unpack_from(data, 4)
    if sec < 0 or nanosec >= 1_000_000_000 or (sec == 0 and nanosec == 0):
        return None
    return sec * 1_000_000_000 + nanosec


def decode_float64_multiarray(data: bytes) -> tuple[list[tuple[str, int, int]], np.ndarray]:
    """std_msgs/Float64MultiArray → (layout dims as (label, size, stride), data as a float64 array)."""
    _check_header(data)
    count, pos = _u32(data, 4)
    if count > 64:
        raise CdrError('implausible number of layout dimensions')
    dims = []
    for _ in range(count):
        label, pos = _string(data, pos)
        size, pos = _u32(data, pos)
        stride, pos = _u32(data, pos)
        dims.append((label, size, stride))
    _, pos = _u32(data, pos)  # data_offset
    n, pos = _u32(data, pos)
    if n:
        pos = _align(pos, 8)
    if pos + 8 * n > len(data):
        raise CdrError('float64 array runs past the end of the message')
    return dims, np.frombuffer(data, dtype='<f8', count=n, offset=pos).copy()


def encode_float64_multiarray(values: Sequence[float], dims: Sequence[tuple[str, int, int]] = ()) -> bytes:
    out = bytearray(ENCAPSULATION)

    def pad(size: int) -> None:
        out.extend(b'\0' * ((-(len(out) - 4)) % size))

    def u32(value: int) -> None:
        pad(4)
        out.extend(_U32.pack(value))

    u32(len(dims))
    for label, size, stride in dims:
        raw = label.encode('utf-8') + b'\0'
        u32(len(raw))
        out.extend(raw)
        u32(size)
        u32(stride)
    u32(0)
    u32(len(values))
    if len(values):
        pad(8)
        out.extend(np.asarray(values, dtype='<f8').tobytes())
    return bytes(out)


def encode_stamped(stamp_ns: np.ndarray, frame_id: str, values: np.ndarray) -> tuple[bytes, int]:
    """CDR of many messages ``std_msgs/Header`` + float64 fields (WrenchStamped, PointStamped, PoseStamped).

    Args:
        stamp_ns: header stamps, ns (int64), shape (n,).
        frame_id: the header's frame_id.
        values: float64 fields, shape (n, k).

    Returns:
        (all messages concatenated, size of each message in bytes).
    """
    values = np.asarray(values, dtype=float)
    n = len(frame_id.encode('utf-8')) + 1
    start = 4 + ((12 + n + 7) & ~7)
    size = start + 8 * values.shape[1]
    dtype = np.dtype({'names': ['enc', 'sec', 'nsec', 'slen', 'frame', 'values'],
                      'formats': ['<u4', '<i4', '<u4', '<u4', f'S{n}', ('<f8', (values.shape[1],))],
                      'offsets': [0, 4, 8, 12, 16, start], 'itemsize': size})
    rec = np.zeros(len(stamp_ns), dtype)
    rec['enc'] = 0x100  # bytes 00 01 00 00
    stamp_ns = np.asarray(stamp_ns, dtype=np.int64)
    rec['sec'] = stamp_ns // 1_000_000_000
    rec['nsec'] = stamp_ns % 1_000_000_000
    rec['slen'] = n
    rec['frame'] = frame_id.encode('utf-8')
    rec['values'] = values
    return rec.tobytes(), size


def decode_diagnostic_array(data: bytes) -> list[tuple[int, str, str, str, dict[str, str]]]:
    """diagnostic_msgs/DiagnosticArray → [(level, name, message, hardware_id, {key: value})] per status."""
    _check_header(data)
    pos = 4 + 8  # stamp: int32 sec, uint32 nanosec
    if pos > len(data):
        raise CdrError('DiagnosticArray too short')
    _, pos = _string(data, pos)  # frame_id
    count, pos = _u32(data, pos)
    out = []
    for _ in range(count):
        if pos >= len(data):
            raise CdrError('DiagnosticStatus runs past the end of the message')
        level = data[pos]
        pos += 1
        name, pos = _string(data, pos)
        message, pos = _string(data, pos)
        hardware_id, pos = _string(data, pos)
        n, pos = _u32(data, pos)
        values = {}
        for _ in range(n):
            key, pos = _string(data, pos)
            values[key], pos = _string(data, pos)
        out.append((level, name, message, hardware_id, values))
    return out
