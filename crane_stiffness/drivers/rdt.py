"""Raw Data Transfer (RDT): the UDP protocol of ATI Net F/T, Ethernet Axia and OnRobot HEX force/torque sensors.

Pure codec and bookkeeping, no sockets (see :mod:`.rdt_client`) and no ROS.

Request (host → device, UDP port 49152), 8 bytes big-endian ``>HHI``: header 0x1234, command (0x0000 stop,
0x0002 real-time stream, 0x0003 buffered stream, 0x0042 bias), sample count (0 = stream until stopped).

Record (device → host), 36 bytes big-endian ``>III6i``: ``rdt_sequence`` (position of the record in this output
stream; restarts with every stream request), ``ft_sequence`` (the sensor's internal sample counter, running at the
internal rate since power-up), ``status`` (0 = healthy), then Fx Fy Fz Tx Ty Tz in counts. A datagram holds one
record (real-time mode) or several back to back (buffered mode). Force [N] = counts / counts per N, torque [N·m] =
counts / counts per N·m; an ATI box states its factors and units in ``/netftapi2.xml`` (``cfgcpf``, ``cfgcpt``,
``scfgfu``, ``scfgtu``); OnRobot's are fixed (:data:`ONROBOT`). Both sequence numbers wrap at 2³².
"""
from __future__ import annotations

import math
import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.drivers.errors import DeviceResponseError, ParameterError, ProtocolError

RDT_PORT = 49152
HEADER = 0x1234
CMD_STOP = 0x0000
CMD_REALTIME = 0x0002
CMD_BUFFERED = 0x0003
CMD_BIAS = 0x0042
#: Stream commands by the name the nodes' ``command`` parameter takes.
STREAM_COMMANDS = {'realtime': CMD_REALTIME, 'buffered': CMD_BUFFERED}
COMMANDS = (CMD_STOP, CMD_REALTIME, CMD_BUFFERED, CMD_BIAS)

REQUEST = struct.Struct('>HHI')
REQUEST_SIZE = REQUEST.size  # 8
RECORD_DTYPE = np.dtype([('rdt_sequence', '>u4'), ('ft_sequence', '>u4'), ('status', '>u4'), ('counts', '>i4', (6,))])
RECORD_SIZE = RECORD_DTYPE.itemsize  # 36
SEQUENCE_MODULUS = 1 << 32


def encode_request(command: int, sample_count: int = 0) -> bytes:
    """The 8-byte request for ``command`` (one of :data:`COMMANDS`) and ``sample_count`` (0 = forever)."""
    if command not in COMMANDS:
        raise ParameterError('command', command, f'must be one of {[hex(c) for c in COMMANDS]}')
    if not 0 <= sample_count < SEQUENCE_MODULUS:
        raise ParameterError('sample_count', sample_count, 'must be in [0, 2**32)')
    return REQUEST.pack(HEADER, command, sample_count)


def decode_request(data: bytes) -> tuple[int, int]:
    """``(command, sample_count)`` of an 8-byte request; raises ProtocolError for anything else."""
    if len(data) != REQUEST_SIZE:
        raise ProtocolError(f'RDT request must be {REQUEST_SIZE} bytes, got {len(data)}')
    header, command, count = REQUEST.unpack(data)
    if header != HEADER:
        raise ProtocolError(f'RDT request header 0x{header:04x}, expected 0x{HEADER:04x}')
    if command not in COMMANDS:
        raise ProtocolError(f'unknown RDT command 0x{command:04x}')
    return command, count


def encode_records(rdt_sequence: ArrayLike, ft_sequence: ArrayLike, status: ArrayLike, counts: ArrayLike) -> bytes:
    """Records back to back (one datagram's payload). Sequences are taken modulo 2³²; ``counts`` has shape (n, 6)
    (or (6,)) and must fit int32. Scalars broadcast over the records."""
    counts = np.atleast_2d(np.asarray(counts))
    if counts.ndim != 2 or counts.shape[1] != 6:
        raise ParameterError('counts', counts.shape, 'must have shape (n, 6)')
    if counts.size and (counts.min() < -2**31 or counts.max() > 2**31 - 1):
        raise ParameterError('counts', 'out of range', 'must fit a signed 32-bit integer')
    out = np.empty(counts.shape[0], dtype=RECORD_DTYPE)
    out['rdt_sequence'] = np.asarray(rdt_sequence, dtype=np.int64) % SEQUENCE_MODULUS
    out['ft_sequence'] = np.asarray(ft_sequence, dtype=np.int64) % SEQUENCE_MODULUS
    out['status'] = np.asarray(status, dtype=np.int64) % SEQUENCE_MODULUS
    out['counts'] = counts
    return out.tobytes()


def decode_records(data: bytes | bytearray | memoryview) -> NDArray[Any]:
    """The records of one or more datagram payloads joined together: a structured array of :data:`RECORD_DTYPE`
    (fields ``rdt_sequence``, ``ft_sequence``, ``status``, ``counts`` (n, 6)), decoded in one numpy call.
    Raises ProtocolError unless the length is a multiple of 36 bytes."""
    if len(data) % RECORD_SIZE:
        raise ProtocolError(f'RDT payload of {len(data)} bytes is not a whole number of {RECORD_SIZE}-byte records')
    return np.frombuffer(data, dtype=RECORD_DTYPE)


# --- calibration --------------------------------------------------------------------------------------------------

#: Newtons per force unit, keyed by the unit's name lower-cased without '-', '.', '·' and spaces.
FORCE_UNITS_N = {'n': 1.0, 'kn': 1000.0, 'lbf': 4.4482216152605, 'lb': 4.4482216152605,
                 'klbf': 4448.2216152605, 'kgf': 9.80665, 'gf': 0.00980665}
#: Newton-metres per torque unit (same key normalisation).
TORQUE_UNITS_NM = {'nm': 1.0, 'nmm': 1e-3, 'knm': 1000.0, 'lbfin': 0.1129848290276167, 'lbin': 0.1129848290276167,
                   'lbfft': 1.3558179483314004, 'lbft': 1.3558179483314004, 'kgfcm': 0.0980665,
                   'ozin': 0.007061551814}


def _unit_key(name: str) -> str:
    return ''.join(c for c in name.lower() if c not in '-.·* _')


def unit_scale(name: str, torque: bool) -> float:
    """SI value (N or N·m) of one ``name`` unit (e.g. 'lbf', 'N-mm'); raises ParameterError for an unknown one."""
    table = TORQUE_UNITS_NM if torque else FORCE_UNITS_N
    try:
        return table[_unit_key(name)]
    except KeyError:
        raise ParameterError('torque unit' if torque else 'force unit', name,
                             f'unknown; known: {", ".join(sorted(table))}') from None


@dataclass(frozen=True)
class Calibration:
    """Counts per SI unit: ``counts_per_force`` [counts/N], ``counts_per_torque`` [counts/(N·m)], both > 0."""

    counts_per_force: float
    counts_per_torque: float
    _divisors: NDArray[np.float64] = field(init=False, repr=False, compare=False)  # set by __post_init__

    def __post_init__(self) -> None:
        for name in ('counts_per_force', 'counts_per_torque'):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ParameterError(name, v, 'must be a finite number > 0 [counts per N or N·m]')
        divisors = np.array([self.counts_per_force] * 3 + [self.counts_per_torque] * 3)
        divisors.flags.writeable = False
        object.__setattr__(self, '_divisors', divisors)

    @property
    def divisors(self) -> NDArray[np.float64]:
        """[cpf, cpf, cpf, cpt, cpt, cpt] (read-only)."""
        return self._divisors

    def to_si(self, counts: ArrayLike) -> NDArray[np.float64]:
        """Counts (…, 6) → [Fx Fy Fz] N, [Tx Ty Tz] N·m."""
        return np.asarray(counts, dtype=np.float64) / self.divisors

    def to_counts(self, wrench: ArrayLike) -> NDArray[np.int64]:
        """SI wrench (…, 6) → counts rounded to the nearest integer and saturated at the int32 range (what a
        device's ADC path does at overload)."""
        counts = np.rint(np.asarray(wrench, dtype=np.float64) * self.divisors)
        return np.clip(counts, -2**31, 2**31 - 1).astype(np.int64)

    @classmethod
    def from_units(cls, counts_per_force_unit: float, counts_per_torque_unit: float, force_unit: str,
                   torque_unit: str) -> Calibration:
        """From a device's factors in its own units (e.g. 1e6 counts per lbf, 1e6 counts per lbf-in)."""
        return cls(counts_per_force_unit / unit_scale(force_unit, torque=False),
                   counts_per_torque_unit / unit_scale(torque_unit, torque=True))


#: OnRobot HEX (fixed by the device): 10000 counts per N, 100000 counts per N·m.
ONROBOT = Calibration(10000.0, 100000.0)


@dataclass(frozen=True)
class NetFtConfig:
    """What the driver needs from an ATI box's ``/netftapi2.xml``."""

    calibration: Calibration
    force_unit: str         #: the box's force unit (``scfgfu``), e.g. 'N', 'lbf'
    torque_unit: str        #: the box's torque unit (``scfgtu``), e.g. 'Nm', 'N-mm', 'lbf-in'
    rdt_rate_hz: float | None       #: RDT output rate (``comrdtrate``) [Hz], if stated
    internal_rate_hz: float | None  #: internal sample rate, the rate of ft_sequence (``runrate``) [Hz], if stated
    product: str                    #: ``prodname``, '' if absent


def parse_netftapi2(text: str | bytes) -> NetFtConfig:
    """Parse an ATI ``netftapi2.xml`` (elements anywhere in the tree; namespaces ignored).

    Raises DeviceResponseError naming what is missing or unreadable.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise DeviceResponseError(f'netftapi2.xml is not valid XML: {exc}') from None
    values = {e.tag.split('}')[-1]: (e.text or '').strip() for e in root.iter()}

    def number(tag: str, required: bool) -> float | None:
        raw = values.get(tag)
        if not raw:  # absent or empty
            if required:
                raise DeviceResponseError(f'netftapi2.xml has no <{tag}>')
            return None
        try:
            return float(raw)
        except ValueError:
            raise DeviceResponseError(f'netftapi2.xml <{tag}> = {raw!r} is not a number') from None

    cpf, cpt = number('cfgcpf', True), number('cfgcpt', True)
    assert cpf is not None and cpt is not None  # required: number() raised otherwise
    fu, tu = values.get('scfgfu', ''), values.get('scfgtu', '')
    if not fu or not tu:
        raise DeviceResponseError('netftapi2.xml states no force/torque unit (scfgfu, scfgtu): set counts_per_force '
                                  'and counts_per_torque [counts per N, N·m] instead')
    try:
        calibration = Calibration.from_units(cpf, cpt, fu, tu)
    except ParameterError as exc:
        raise DeviceResponseError(f'netftapi2.xml: {exc}') from None
    rate = number('comrdtrate', False)
    internal = number('runrate', False)
    return NetFtConfig(calibration, fu, tu, rate if rate and rate > 0 else None,
                       internal if internal and internal > 0 else None, values.get('prodname', ''))


def netftapi2_xml(calibration: Calibration, rdt_rate_hz: float, internal_rate_hz: float,
                  product: str = 'crane_stiffness RDT emulator') -> str:
    """A minimal ``netftapi2.xml`` in N and N·m for ``calibration`` (what the emulator serves)."""
    return (f'<?xml version="1.0"?><netft><prodname>{product}</prodname>'
            f'<cfgcpf>{calibration.counts_per_force:.10g}</cfgcpf><cfgcpt>{calibration.counts_per_torque:.10g}</cfgcpt>'
            f'<scfgfu>N</scfgfu><scfgtu>Nm</scfgtu><comrdtrate>{rdt_rate_hz:.10g}</comrdtrate>'
            f'<runrate>{internal_rate_hz:.10g}</runrate></netft>')


# --- sequence accounting ------------------------------------------------------------------------------------------

class SequenceTracker:
    """Lost, out-of-order and duplicate records of one RDT stream, from ``rdt_sequence``.

    Sequence numbers are unwrapped (2³² rollover) against the highest seen. A gap counts its missing numbers as
    ``lost``; a missing number that arrives later moves from ``lost`` to ``out_of_order`` (it arrived, late); a
    number seen before is a ``duplicate``. Missing numbers are remembered for the last ``window`` numbers; a jump
    of more than ``restart_jump`` backwards or forwards is taken as a new stream (device restarted, or a new stream
    request): the tracker starts again and counts a ``restart``.

    :meth:`update` returns, for records in arrival order, which to deliver (every first arrival numbered above the
    highest of the previous batches: a record that arrives late but within the same batch is still delivered) and
    their unwrapped numbers; a driver delivers those sorted by number and drops the rest (late or duplicate).
    """

    def __init__(self, window: int = 65536, restart_jump: int = 1 << 20) -> None:
        self.window = int(window)
        self.restart_jump = int(restart_jump)
        self.lost = 0
        self.out_of_order = 0
        self.duplicates = 0
        self.restarts = 0
        self.received = 0
        self._last: int | None = None        # highest unwrapped number seen
        self._shift = 0                      # unwrapped ≡ raw + shift (mod 2^32)
        self._resume_after: int | None = None
        self._missing: set[int] = set()
        self.in_order = True  #: the last update's records were all delivered, in order, with no gap

    def reset(self) -> None:
        """Expect a new stream (after a new stream request the device restarts rdt_sequence): the next record
        continues the unwrapped numbering and counts neither as lost nor as a restart."""
        if self._last is not None:
            self._resume_after = self._last
            self._last = None
        self._missing.clear()

    def update(self, sequence: ArrayLike) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
        """Account for records (``rdt_sequence`` in arrival order); returns ``(deliver, unwrapped)``.

        Unwrapped numbers keep increasing across a restart (the new stream continues after the old one's highest),
        so sorting by them orders every delivered record by arrival of its stream.
        """
        seq = np.asarray(sequence, dtype=np.int64)
        n = seq.size
        self.received += n
        if n == 0:
            return np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64)
        if self._last is None:  # first record of a stream: numbered 0 or right after the previous stream's highest
            start = int(seq[0]) - 1 if self._resume_after is None else self._resume_after
            self._shift = start + 1 - int(seq[0])
            self._last = start
        floor = self._last  # highest number delivered by earlier batches
        # Steps from the previous record, wrapped into [-2^31, 2^31).
        steps = np.empty(n, dtype=np.int64)
        steps[0] = seq[0] - (self._last - self._shift) % SEQUENCE_MODULUS
        np.subtract(seq[1:], seq[:-1], out=steps[1:])
        steps += 1 << 31
        steps %= SEQUENCE_MODULUS
        steps -= 1 << 31
        if steps.min() == 1 and steps.max() == 1:  # the common case: in order, nothing missing
            unwrapped = self._last + np.arange(1, n + 1, dtype=np.int64)
            self._last = int(unwrapped[-1])
            self.in_order = True
            return np.ones(n, dtype=bool), unwrapped
        self.in_order = False
        deliver = np.zeros(n, dtype=bool)
        unwrapped = np.empty(n, dtype=np.int64)
        numbers: list[int] = seq.tolist()
        for i, s in enumerate(numbers):
            d = ((s + self._shift - self._last + (1 << 31)) % SEQUENCE_MODULUS) - (1 << 31)
            if abs(d) > self.restart_jump:  # a new stream: continue the numbering after the highest so far
                self.restarts += 1
                self._missing.clear()
                self._shift = self._last + 1 - s
                floor = self._last
                d = 1
            u = self._last + d
            unwrapped[i] = u
            if d > 0:
                if d > 1:
                    self.lost += d - 1
                    if d - 1 <= self.window:
                        self._missing.update(range(self._last + 1, u))
                self._last = u
                deliver[i] = True
            elif u in self._missing:
                self._missing.discard(u)
                self.lost -= 1
                self.out_of_order += 1
                deliver[i] = u > floor
            else:
                self.duplicates += 1
        if len(self._missing) > self.window:
            oldest = self._last - self.window
            self._missing = {m for m in self._missing if m > oldest}
        return deliver, unwrapped

    def as_dict(self) -> dict[str, int]:
        return {'records_received': self.received, 'records_lost': self.lost,
                'records_out_of_order': self.out_of_order, 'records_duplicate': self.duplicates,
                'stream_restarts': self.restarts}
