"""The project's own CDR decoders against rclpy's serializer (the estimator takes its sensor streams serialized)."""
from __future__ import annotations

import struct

import pytest
from geometry_msgs.msg import PointStamped, WrenchStamped
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64

from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.serde import CdrError, SerdeError, decode_float64, decode_stamped, header_stamp_ns, stamp_seconds


def _wrench(frame: str, sec: int, nanosec: int, values) -> WrenchStamped:
    msg = WrenchStamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    f, m = msg.wrench.force, msg.wrench.torque
    f.x, f.y, f.z, m.x, m.y, m.z = values
    return msg


@pytest.mark.parametrize('frame', ['', 'a', 'lc', 'abc', 'load', 'cell_', 'load_cell', 'ft_sensor_link_12'])
def test_decode_stamped_equals_rclpy_for_every_frame_id_length(frame):
    values = (1.5, -2.25e-3, 9.81, 1e-300, -0.0, 12345.678)
    data = serialize_message(_wrench(frame, 1_795_000_123, 999_999_999, values))
    assert decode_stamped(data, 6) == (1_795_000_123, 999_999_999, values)
    point = PointStamped()
    point.header.frame_id = frame
    point.header.stamp.sec, point.header.stamp.nanosec = -5, 7
    point.point.x, point.point.y, point.point.z = 2.5e-4, -1.0, 3.0
    assert decode_stamped(serialize_message(point), 3) == (-5, 7, (2.5e-4, -1.0, 3.0))


def test_decode_stamped_big_endian_and_float64():
    frame = b'lvdt\0'
    # XCDR1 big endian: 00 00 00 00, then sec, nanosec, the string, padding to 8 (relative to offset 4), doubles.
    body = struct.pack('>iII', 12, 34, len(frame)) + frame
    body += b'\0' * ((-len(body)) % 8)
    data = b'\x00\x00\x00\x00' + body + struct.pack('>3d', 0.125, -7.0, 1e-9)
    assert decode_stamped(data, 3) == (12, 34, (0.125, -7.0, 1e-9))
    assert decode_float64(serialize_message(Float64(data=-3.75))) == -3.75
    assert decode_float64(b'\x00\x00\x00\x00' + struct.pack('>d', 0.5)) == 0.5


def test_malformed_messages_raise_cdr_error():
    good = serialize_message(_wrench('load_cell', 1, 2, (0.0,) * 6))
    for bad in (b'', b'\x00\x01\x00\x00', good[:-1], b'\x07' + good[1:], good[:12] + struct.pack('<I', 10_000)
                + good[16:]):
        with pytest.raises(CdrError):
            decode_stamped(bad, 6)
    nanosec_too_big = good[:8] + struct.pack('<I', 1_000_000_000) + good[12:]
    with pytest.raises(CdrError):
        decode_stamped(nanosec_too_big, 6)
    with pytest.raises(CdrError):
        decode_float64(b'\x00\x01\x00\x00\x00')


def test_header_stamp_ns_and_the_error_hierarchy():
    data = serialize_message(_wrench('load_cell', 1_700_000_000, 123_456_789, (0.0,) * 6))
    assert header_stamp_ns(data) == 1_700_000_000_123_456_789
    assert header_stamp_ns(serialize_message(_wrench('load_cell', 0, 0, (0.0,) * 6))) is None  # unset
    assert header_stamp_ns(data[:8]) is None and header_stamp_ns(b'\x00\x00' + data[2:]) is None
    assert stamp_seconds(1_700_000_000, 123_456_789) == 1_700_000_000 + 123_456_789 * 1e-9
    assert issubclass(CdrError, SerdeError) and issubclass(CdrError, CraneStiffnessError)
    assert issubclass(CdrError, ValueError)  # existing 'except ValueError' keeps catching it
