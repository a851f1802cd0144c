"""Analog inputs over Modbus TCP: register decoding, scaling to metres, and a poller on pymodbus's client.

Register layouts (16-bit registers, each big-endian on the wire as Modbus defines):

- LabJack T-series: AIN0, AIN1, … are FLOAT32 volts at holding registers 0, 2, …, most significant word first
  (``data_type='float32', word_order='big'``).
- Industrial modules (ADAM-6017 style): int16 (or uint16) counts of the input range at one register per channel,
  scaled to engineering units by the caller (``data_type='int16'``, ``gain`` = units per count).
- 32-bit values from other devices may put the least significant word first (``word_order='little'``).

The reading in metres is ``gain · raw + offset`` (raw: volts, counts, … as the register holds it). No ROS here.
"""
from __future__ import annotations

import logging
import math
import socket
import struct
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

from crane_stiffness.drivers.errors import (DeviceAddressError, DeviceBusyError, DeviceResponseError,
                                            DeviceSilentError, ParameterError)

if TYPE_CHECKING:  # pymodbus is imported where a connection opens
    from pymodbus.client import ModbusTcpClient

MODBUS_TCP_PORT = 502
#: data type → (registers, struct format of the value's bytes, most significant word first)
DATA_TYPES: dict[str, tuple[int, str]] = {
    'float32': (2, '>f'), 'int32': (2, '>i'), 'uint32': (2, '>I'), 'int16': (1, '>h'), 'uint16': (1, '>H'),
}
WORD_ORDERS = ('big', 'little')
REGISTER_TYPES = ('holding', 'input')
#: Modbus exception codes (the standard's names).
EXCEPTION_NAMES = {1: 'illegal function', 2: 'illegal data address', 3: 'illegal data value',
                   4: 'server device failure', 5: 'acknowledge', 6: 'server device busy',
                   10: 'gateway path unavailable', 11: 'gateway target device failed to respond'}
#: "server device busy": not an error of the request, the device has no value yet (DeviceBusyError).
DEVICE_BUSY = 6


def register_count(data_type: str) -> int:
    """Registers one value of ``data_type`` occupies (1 or 2)."""
    try:
        return DATA_TYPES[data_type][0]
    except KeyError:
        raise ParameterError('data_type', data_type, f'must be one of {", ".join(DATA_TYPES)}') from None


def _check_word_order(word_order: str) -> None:
    if word_order not in WORD_ORDERS:
        raise ParameterError('word_order', word_order, f'must be one of {", ".join(WORD_ORDERS)}')


def decode_registers(registers: Sequence[int], data_type: str, word_order: str = 'big') -> float:
    """The value held in ``registers`` (16-bit unsigned each) as ``data_type``; ``word_order`` 'big' = most
    significant word first. Raises ParameterError for a wrong register count or a value outside 0..65535."""
    n = register_count(data_type)
    _check_word_order(word_order)
    if len(registers) != n:
        raise ParameterError('registers', list(registers), f'{data_type} takes {n} register(s)')
    if any(not 0 <= int(r) <= 0xFFFF for r in registers):
        raise ParameterError('registers', list(registers), 'each must be in 0..65535')
    words = list(registers) if word_order == 'big' else list(registers)[::-1]
    return float(struct.unpack(DATA_TYPES[data_type][1], struct.pack(f'>{n}H', *words))[0])


def encode_value(value: float, data_type: str, word_order: str = 'big') -> list[int]:
    """Registers holding ``value`` as ``data_type`` (inverse of :func:`decode_registers`). Integer types round to
    the nearest count and saturate at the type's range, as an ADC does."""
    n = register_count(data_type)
    _check_word_order(word_order)
    fmt = DATA_TYPES[data_type][1]
    if data_type != 'float32':
        bits = 16 * n
        lo, hi = (0, (1 << bits) - 1) if fmt[-1].isupper() else (-(1 << (bits - 1)), (1 << (bits - 1)) - 1)
        value = min(max(round(value), lo), hi) if math.isfinite(value) else (hi if value > 0 else lo)
    words = list(struct.unpack(f'>{n}H', struct.pack(fmt, value)))
    return words if word_order == 'big' else words[::-1]


@dataclass(frozen=True)
class Channel:
    """One analog input: where it is and how its raw value becomes metres (``gain · raw + offset``)."""

    register: int = 0               #: address of the first register (0-based, as on the wire)
    data_type: str = 'float32'
    word_order: str = 'big'
    register_type: str = 'holding'  #: 'holding' (function 3) or 'input' (function 4)
    gain: float = 1.0               #: metres per raw unit (m/V for a LabJack, m/count for int16)
    offset: float = 0.0             #: metres at raw = 0

    def __post_init__(self) -> None:
        register_count(self.data_type)
        _check_word_order(self.word_order)
        if self.register_type not in REGISTER_TYPES:
            raise ParameterError('register_type', self.register_type, f'must be one of {", ".join(REGISTER_TYPES)}')
        if isinstance(self.register, bool) or not isinstance(self.register, int) or not 0 <= self.register:
            raise ParameterError('register', self.register, 'must be an integer >= 0')
        if self.register + self.count > 0x10000:
            raise ParameterError('register', self.register, f'must leave room for {self.count} register(s) below '
                                 '65536')
        for name in ('gain', 'offset'):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ParameterError(name, v, 'must be a finite number')
        if self.gain == 0:
            raise ParameterError('gain', self.gain, 'must be non-zero [m per raw unit]')

    @property
    def count(self) -> int:
        """Registers read per poll."""
        return register_count(self.data_type)

    def to_metres(self, raw: float) -> float:
        return self.gain * raw + self.offset

    def to_raw(self, metres: float) -> float:
        return (metres - self.offset) / self.gain

    def decode(self, registers: Sequence[int]) -> float:
        """Raw value of the registers read."""
        return decode_registers(registers, self.data_type, self.word_order)

    def encode(self, metres: float) -> list[int]:
        """Registers a device shows for a reading of ``metres`` (the emulator's side)."""
        return encode_value(self.to_raw(metres), self.data_type, self.word_order)

    @classmethod
    def from_params(cls, values: Mapping[str, Any]) -> Channel:
        """From flat parameters with the field names above (missing ones take the defaults)."""
        names = ('register', 'data_type', 'word_order', 'register_type', 'gain', 'offset')
        return cls(**{k: values[k] for k in names if k in values})


@dataclass(frozen=True)
class Reading:
    """One poll: the raw register value, the reading [m] and the request's start and end on the host clock [ns]."""

    raw: float
    metres: float
    start_ns: int
    end_ns: int

    @property
    def stamp_ns(self) -> int:
        """The middle of the request: the best estimate of when the device sampled, without its own clock."""
        return (self.start_ns + self.end_ns) // 2


def resolve(host: str, port: int, kind: int = socket.SOCK_STREAM) -> str:
    """The IPv4/IPv6 address of ``host``; raises DeviceAddressError if it does not resolve."""
    try:
        return socket.getaddrinfo(host, port, type=kind)[0][4][0]
    except (socket.gaierror, UnicodeError, ValueError) as exc:
        raise DeviceAddressError(f'cannot resolve device address {host!r}: {exc}') from None


class ModbusPoller:
    """Reads one :class:`Channel` of a Modbus TCP device per :meth:`read` (blocking, at most ``timeout_s``).

    :meth:`open` connects (raising DeviceAddressError when nothing accepts the connection). A failed read raises
    DeviceSilentError (no answer in time, or the connection dropped) or DeviceResponseError (a Modbus exception
    response); after a dropped connection the next :meth:`read` connects again. The first reading after the device
    was unreachable (no answer, connection dropped or refused) counts a restart (:attr:`restarts`, described in
    :attr:`last_restart`): a DAQ has no counter to say whether it restarted, so a caller drops what it holds from
    before (e.g. readings to zero on).
    """

    def __init__(self, host: str, port: int = MODBUS_TCP_PORT, unit_id: int = 1, channel: Channel = Channel(),
                 timeout_s: float = 0.5, clock_ns: Callable[[], int] = time.time_ns) -> None:
        if not isinstance(port, int) or isinstance(port, bool) or not 0 < port < 65536:
            raise ParameterError('port', port, 'must be in 1..65535')
        if not isinstance(unit_id, int) or isinstance(unit_id, bool) or not 0 <= unit_id <= 255:
            raise ParameterError('unit_id', unit_id, 'must be in 0..255')
        if not (isinstance(timeout_s, (int, float)) and math.isfinite(timeout_s) and timeout_s > 0):
            raise ParameterError('timeout_s', timeout_s, 'must be a finite number > 0 [s]')
        self.host, self.port, self.unit_id, self.channel = host, port, unit_id, channel
        self.timeout_s = float(timeout_s)
        self._clock = clock_ns
        self._client: ModbusTcpClient | None = None
        self.connects = 0
        self.restarts = 0                      # readings again after the device was unreachable
        self.last_restart = ''
        self._down_since_ns: int | None = None  # first failed attempt of the current outage [ns, host clock]
        logging.getLogger('pymodbus').setLevel(logging.CRITICAL)  # it logs every failure itself; we raise instead

    @property
    def where(self) -> str:
        return f'{self.host}:{self.port} unit {self.unit_id}'

    def open(self) -> None:
        """Connect (again). Raises DeviceAddressError."""
        from pymodbus.client import ModbusTcpClient
        self.close()
        address = resolve(self.host, self.port)
        client = ModbusTcpClient(address, port=self.port, timeout=self.timeout_s, retries=0)
        if not client.connect():
            client.close()
            raise DeviceAddressError(f'no Modbus TCP device at {self.where}: connection refused or unreachable '
                                     '(wrong host or port, or the device is off)')
        self._client = client
        self.connects += 1

    def read(self) -> Reading:
        """One request for the channel's registers; the reading with the request's start and end times."""
        from pymodbus.exceptions import ConnectionException, ModbusException
        if self._client is None:
            try:
                self.open()
            except DeviceAddressError:
                self._went_down()
                raise
        client = self._client
        assert client is not None  # open() connected it, or raised
        ch = self.channel
        fn = client.read_holding_registers if ch.register_type == 'holding' else client.read_input_registers
        start = self._clock()
        try:
            response = fn(ch.register, count=ch.count, device_id=self.unit_id)
        except ConnectionException as exc:
            self.close()
            self._went_down(start)
            raise DeviceSilentError(f'connection to {self.where} lost: {exc}') from None
        except ModbusException as exc:  # ModbusIOException: no answer within timeout_s
            self.close()
            self._went_down(start)
            raise DeviceSilentError(f'no answer from {self.where} within {self.timeout_s} s: {exc}') from None
        end = self._clock()
        if response.isError():
            code: int | None = getattr(response, 'exception_code', None)
            error = DeviceBusyError if code == DEVICE_BUSY else DeviceResponseError
            name = 'unknown' if code is None else EXCEPTION_NAMES.get(code, 'unknown')
            raise error(
                f'{self.where} answered Modbus exception {code} ({name}) to a read '
                f'of {ch.count} {ch.register_type} register(s) at {ch.register}')
        registers = list(response.registers)
        if len(registers) != ch.count:
            raise DeviceResponseError(f'{self.where} returned {len(registers)} registers, asked for {ch.count}')
        raw = ch.decode(registers)
        if self._down_since_ns is not None:
            self.restarts += 1
            self.last_restart = (f'{self.where} answers again after {(start - self._down_since_ns) / 1e9:.1f} s '
                                 'unreachable: readings from before are not used')
            self._down_since_ns = None
        return Reading(raw, ch.to_metres(raw), start, end)

    def _went_down(self, t_ns: int | None = None) -> None:
        if self._down_since_ns is None:
            self._down_since_ns = self._clock() if t_ns is None else t_ns

    def close(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            finally:
                self._client = None
