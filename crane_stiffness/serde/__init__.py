"""CDR (de)serialization without rosidl: the only place in the package that reads or writes CDR bytes.

- ``cdr.py``: single messages: std_msgs String/Float64/Float64MultiArray, stamped float messages,
  diagnostic_msgs/DiagnosticArray, and a serialized message's header stamp (:func:`header_stamp_ns`).
- ``bulk.py``: numpy decoders of the rig's fixed-layout types, many messages at once (used by the bag reader).
- ``stamps.py``: :func:`stamp_seconds`, the one rounding of a header stamp to seconds; :func:`stamp_ns` and
  :func:`split_ns`, a stamp to integer nanoseconds and back; ``NS_PER_S``.
- ``errors.py``: :class:`SerdeError` and :class:`CdrError`.

No module here imports rclpy.
"""
from .bulk import SUPPORTED_TYPES
from .cdr import (
    decode_diagnostic_array, decode_float64, decode_float64_multiarray, decode_stamped, decode_string,
    encode_float64, encode_float64_multiarray, encode_stamped, encode_string, header_stamp_ns,
)
from .errors import CdrError, SerdeError
from .stamps import NS_PER_S, split_ns, stamp_ns, stamp_seconds

__all__ = [
    'CdrError', 'NS_PER_S', 'SUPPORTED_TYPES', 'SerdeError', 'decode_diagnostic_array', 'decode_float64',
    'decode_float64_multiarray', 'decode_stamped', 'decode_string', 'encode_float64', 'encode_float64_multiarray',
    'encode_stamped', 'encode_string', 'header_stamp_ns', 'split_ns', 'stamp_ns', 'stamp_seconds',
]
