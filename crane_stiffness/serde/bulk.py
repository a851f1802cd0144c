"""Bulk CDR decoding of the rig's fixed-layout message types into numpy columns, many messages at once.

A decoder takes a uint8 buffer (e.g. a decompressed MCAP chunk), the byte offset of each message's CDR data in it
and each message's length, and gathers the fields of all messages with numpy. CDR (XCDR1, little endian): a 4-byte
encapsulation header ``00 01 00 00``, then the fields, each aligned to its size relative to the byte after the
header. A ``std_msgs/Header`` is ``int32 sec, uint32 nanosec, uint32 n, n bytes of frame_id including the NUL``, so
the float64 fields after it start at ``4 + align8(12 + n)``; messages are grouped by ``n`` so that a changing
frame_id is decoded correctly, and each message's length and NUL are checked. A message without the expected layout
is marked invalid instead of raising.

:func:`new_decoder` gives the decoder of a type (:data:`SUPPORTED_TYPES`); its ``decode`` returns (columns, valid),
and ``to_array`` turns the columns of all messages into one structured array (``stamp_s`` by
:func:`~.stamps.stamp_seconds`). This module must not import rclpy.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Callable

import numpy as np

from crane_stiffness.contract.axes import AXES

from .stamps import stamp_seconds

_CDR_HEADER = np.dtype({
    'names': ['e0', 'e1', 'sec', 'nanosec', 'slen'], 'formats': ['u1', 'u1', '<i4', '<u4', '<u4'],
    'offsets': [0, 1, 4, 8, 12], 'itemsize': 16,
})


def gather(buf: np.ndarray, offsets: np.ndarray, dtype: Any) -> np.ndarray:
    """Copy ``dtype`` items starting at arbitrary byte ``offsets`` of the uint8 array ``buf`` (one numpy gather)."""
    dt = np.dtype(dtype)
    if dt.subdtype is not None:  # ('<f8', (k,)): gather records of one field, then unwrap to shape (n, k)
        return gather(buf, offsets, np.dtype([('v', dt)]))['v']
    if buf.size < dt.itemsize:  # only possible when no row is valid: gather zeros at the clamped offsets
        buf = np.concatenate([buf, np.zeros(dt.itemsize, np.uint8)])
    # Rows of raw bytes copied into one contiguous block, then viewed as the items: twice as fast as indexing an
    # unaligned view of ``dtype`` itself (numpy then copies field by field).
    rows = np.lib.stride_tricks.as_strided(buf, shape=(buf.size - dt.itemsize + 1, dt.itemsize), strides=(1, 1),
                                           writeable=False)[offsets]
    return rows.view(dt).reshape(np.shape(offsets))


def _align(value: Any, alignment: int) -> Any:
    """``value`` (an int or an int array) rounded up to a multiple of ``alignment`` (a power of two)."""
    return (value + (alignment - 1)) & ~(alignment - 1)


def _gather_strings(buf: np.ndarray, start: np.ndarray, length: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Fixed-width bytes array of the strings ``buf[start:start+length]`` (rows not ``valid`` stay empty)."""
    lengths = np.unique(length[valid]) if valid.any() else np.zeros(0, np.int64)
    width = max(1, int(lengths.max()) if lengths.size else 1)
    out = np.zeros(start.shape, dtype=f'S{width}')
    for size in lengths.tolist():
        if size <= 0:
            continue
        sel = valid & (length == size)
        out[sel] = gather(buf, start[sel], f'S{size}')
    return out


def _cdr_header(buf: np.ndarray, off: np.ndarray, dlen: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Encapsulation + std_msgs/Header of each message: (valid, header fields, frame_id length n incl. NUL, cols)."""
    valid = dlen >= 16
    head = gather(buf, np.where(valid, off, 0), _CDR_HEADER)
    slen = head['slen'].astype(np.int64)
    valid &= (head['e0'] == 0) & (head['e1'] == 1) & (slen >= 1) & (16 + slen <= dlen)
    nul = buf[np.where(valid, off + 15 + slen, 0)]
    valid &= nul == 0
    frame = _gather_strings(buf, off + 16, slen - 1, valid)
    return valid, head, slen, {'stamp_sec': head['sec'], 'stamp_nanosec': head['nanosec'], 'frame_id': frame}


class Columns(dict):
    """Decoded messages as named numpy columns of equal length (``log_time_ns`` first): what a structured array of
    them offers the analysis (``c['stamp_s']``, ``c.size``, ``'x' in c``) without copying every field into records,
    which costs more than the decoding itself for an hour of 1 kHz streams."""

    @property
    def size(self) -> int:
        """The number of messages."""
        return int(self['log_time_ns'].size)

    def __len__(self) -> int:  # the number of messages, as for an array (the column names: keys())
        return self.size


class Decoder:
    """Bulk decoder of one message type: columns of many messages from their byte offsets."""

    msg_type = ''
    value_fields: tuple[tuple[str, Any], ...] = ()
    has_header = True

    def decode(self, buf: np.ndarray, off: np.ndarray, dlen: np.ndarray
               ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Columns of the messages whose CDR data starts at ``buf[off]`` and is ``dlen`` bytes long, and the mask of
        the messages that have this type's layout (the columns' other rows are meaningless)."""
        raise NotImplementedError

    def dtype(self, columns: Mapping[str, np.ndarray]) -> np.dtype:
        """The structured dtype of the decoded rows (``log_time_ns`` first) for columns shaped like ``columns``."""
        fields: list[tuple[Any, ...]] = [('log_time_ns', '<i8')]
        if self.has_header:
            fields += [('stamp_sec', '<i4'), ('stamp_nanosec', '<u4'), ('stamp_s', '<f8'),
                       ('frame_id', columns['frame_id'].dtype)]
        for name, fmt in self.value_fields:
            col = columns.get(name)
            fields.append((name, col.dtype, col.shape[1:]) if col is not None and col.ndim > 1 else (name, fmt))
        return np.dtype(fields)

    def empty(self) -> np.ndarray:
        """The array of no messages."""
        return np.zeros(0, self.dtype({'frame_id': np.zeros(0, 'S1')}))

    def to_columns(self, columns: Mapping[str, np.ndarray]) -> Columns:
        """The decoded ``columns`` (with ``log_time_ns``) as :class:`Columns`, ``log_time_ns`` first and ``stamp_s``
        computed here, in the order of :meth:`dtype`; no copy of the columns."""
        out = Columns(log_time_ns=columns['log_time_ns'])
        for name in (self.dtype(columns).names or ())[1:]:
            if name == 'stamp_s':
                out[name] = stamp_seconds(columns['stamp_sec'], columns['stamp_nanosec'])
            else:
                out[name] = columns[name]
        return out

    def empty_columns(self) -> Columns:
        """The columns of no messages."""
        empty = self.empty()
        return Columns({name: empty[name] for name in empty.dtype.names or ()})

    def to_array(self, columns: Mapping[str, np.ndarray]) -> np.ndarray:
        """One structured array of decoded ``columns`` (with ``log_time_ns``); ``stamp_s`` is computed here."""
        out = np.empty(columns['log_time_ns'].size, self.dtype(columns))
        for key, value in columns.items():
            out[key] = value
        if self.has_header:
            out['stamp_s'] = stamp_seconds(columns['stamp_sec'], columns['stamp_nanosec'])
        return out


class _StampedDoubles(Decoder):
    """A std_msgs/Header followed by float64 fields only (WrenchStamped, PointStamped, PoseStamped)."""

    def __init__(self, msg_type: str, names: Sequence[str]) -> None:
        self.msg_type = msg_type
        self.names = tuple(names)
        self.value_fields = tuple((n, '<f8') for n in names)

    def decode(self, buf: np.ndarray, off: np.ndarray, dlen: np.ndarray
               ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        fast = self._decode_uniform(buf, off, dlen)
        if fast is not None:
            return fast
        valid, _, slen, cols = _cdr_header(buf, off, dlen)
        start = 4 + _align(12 + slen, 8)
        valid &= start + 8 * len(self.names) <= dlen
        values = gather(buf, np.where(valid, off + start, 0), ('<f8', (len(self.names),)))
        for i, name in enumerate(self.names):
            cols[name] = values[:, i]
        return cols, valid


    def _decode_uniform(self, buf: np.ndarray, off: np.ndarray, dlen: np.ndarray
                        ) -> tuple[dict[str, np.ndarray], np.ndarray] | None:
        """The common case in one gather per message: every message of this buffer has the same length and the
        same frame_id length (one sensor), so the whole layout is known from the first. None when it is not."""
        if off.size == 0 or not (dlen == dlen[0]).all() or dlen[0] < 16:
            return None
        first = int(off[0])
        if buf[first] != 0 or buf[first + 1] != 1:
            return None
        slen = int(buf[first + 12:first + 16].view('<u4')[0])
        start = 4 + int(_align(12 + slen, 8))
        n = len(self.names)
        if slen < 1 or start + 8 * n > int(dlen[0]):
            return None
        layout = np.dtype({'names': ['e0', 'e1', 'sec', 'nanosec', 'slen', 'frame', 'nul', 'values'],
                           'formats': ['u1', 'u1', '<i4', '<u4', '<u4', f'S{max(slen - 1, 1)}', 'u1', ('<f8', (n,))],
                           'offsets': [0, 1, 4, 8, 12, 16, 15 + slen, start], 'itemsize': start + 8 * n})
        rows = gather(buf, off, layout)
        valid = (rows['e0'] == 0) & (rows['e1'] == 1) & (rows['slen'] == slen) & (rows['nul'] == 0)
        if not valid.all():
            return None  # a message of another layout among them: the general path says which
        frame = rows['frame'] if slen > 1 else np.zeros(off.size, 'S1')
        cols = {'stamp_sec': rows['sec'], 'stamp_nanosec': rows['nanosec'], 'frame_id': frame}
        values = rows['values']
        for i, name in enumerate(self.names):
            cols[name] = values[:, i]
        return cols, valid


class _Float64(Decoder):
    msg_type = 'std_msgs/msg/Float64'
    value_fields = (('data', '<f8'),)
    has_header = False

    def decode(self, buf: np.ndarray, off: np.ndarray, dlen: np.ndarray
               ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        valid = dlen >= 12
        enc = gather(buf, np.where(valid, off, 0), ('u1', (2,)))
        valid &= (enc[:, 0] == 0) & (enc[:, 1] == 1)
        return {'data': gather(buf, np.where(valid, off + 4, 0), '<f8')}, valid


class _JointState(Decoder):
    """sensor_msgs/JointState with a fixed number of joints (set by the first chunk; 6 on the rig).

    position/velocity/effort are (n, joints) float64, NaN where the message left the array empty.
    """

    msg_type = 'sensor_msgs/msg/JointState'
    value_fields = (('name', 'S1'), ('position', '<f8'), ('velocity', '<f8'), ('effort', '<f8'))

    def __init__(self) -> None:
        self.joints: int | None = None

    def empty(self) -> np.ndarray:
        joints = self.joints or 0
        return np.zeros(0, self.dtype({
            'frame_id': np.zeros(0, 'S1'), 'name': np.zeros((0, joints), 'S1'), 'position': np.zeros((0, joints)),
            'velocity': np.zeros((0, joints)), 'effort': np.zeros((0, joints))}))

    def decode(self, buf: np.ndarray, off: np.ndarray, dlen: np.ndarray
               ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        valid, _, slen, cols = _cdr_header(buf, off, dlen)
        base, limit = off + 4, dlen - 4
        cur = _align(12 + slen, 4)

        def read_u32(cur: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            valid &= cur + 4 <= limit
            return gather(buf, np.where(valid, base + cur, 0), '<u4').astype(np.int64), valid

        count, valid = read_u32(cur, valid)
        cur = cur + 4
        if self.joints is None:
            if not valid.any():
                return cols, valid
            values, counts = np.unique(count[valid], return_counts=True)
            self.joints = int(values[np.argmax(counts)])
        joints = self.joints
        valid &= count == joints
        name_start = np.zeros((off.size, joints), np.int64)
        name_len = np.zeros((off.size, joints), np.int64)
        for j in range(joints):
            cur = np.where(valid, _align(cur, 4), 0)
            size, valid = read_u32(cur, valid)
            name_start[:, j] = base + cur + 4
            name_len[:, j] = size - 1
            cur = cur + 4 + size
            valid &= (size >= 1) & (cur <= limit)
            nul = buf[np.where(valid, base + cur - 1, 0)]
            valid &= nul == 0
        for key in ('position', 'velocity', 'effort'):
            cur = np.where(valid, _align(cur, 4), 0)
            size, valid = read_u32(cur, valid)
            cur = cur + 4
            full = size == joints
            valid &= full | (size == 0)
            if joints:
                at = np.where(full, _align(cur, 8), cur)
                valid &= ~full | (at + 8 * joints <= limit)
                vals = gather(buf, np.where(valid & full, base + at, 0), ('<f8', (joints,)))
                vals[~full] = np.nan
                cur = np.where(full, at + 8 * joints, cur)
            else:
                vals = np.zeros((off.size, 0))
            cols[key] = vals
        names = [_gather_strings(buf, name_start[:, j], name_len[:, j], valid) for j in range(joints)]
        width = max([n.dtype.itemsize for n in names] + [1])
        cols['name'] = np.stack([n.astype(f'S{width}') for n in names], axis=1) if names else \
            np.zeros((off.size, 0), 'S1')
        return cols, valid


_DECODERS: dict[str, Callable[[], Decoder]] = {
    'geometry_msgs/msg/WrenchStamped': lambda: _StampedDoubles(
        'geometry_msgs/msg/WrenchStamped', AXES),
    'geometry_msgs/msg/PointStamped': lambda: _StampedDoubles('geometry_msgs/msg/PointStamped', ('x', 'y', 'z')),
    'geometry_msgs/msg/PoseStamped': lambda: _StampedDoubles(
        'geometry_msgs/msg/PoseStamped', ('x', 'y', 'z', 'qx', 'qy', 'qz', 'qw')),
    'std_msgs/msg/Float64': _Float64,
    'sensor_msgs/msg/JointState': _JointState,
}
SUPPORTED_TYPES = tuple(_DECODERS)
"""Message types the bulk decoder turns into numpy structured arrays."""


def new_decoder(msg_type: str) -> Decoder | None:
    """A fresh decoder of ``msg_type`` (it may keep state across buffers, e.g. JointState's joint count), or None
    when the type is not in :data:`SUPPORTED_TYPES`."""
    factory = _DECODERS.get(msg_type)
    return factory() if factory is not None else None


__all__ = ['Columns', 'Decoder', 'SUPPORTED_TYPES', 'gather', 'new_decoder']
