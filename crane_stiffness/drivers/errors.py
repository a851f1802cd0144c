"""Errors raised by the hardware drivers (RDT F/T sensors, Modbus DAQs) and the device emulators."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError, ParameterError


class DriverError(CraneStiffnessError):
    """Base class of the drivers' errors."""


class ProtocolError(DriverError, ValueError):
    """Bytes that are not a valid message of the protocol (wrong length, wrong header, unknown command)."""


class DeviceAddressError(DriverError, ConnectionError):
    """The device's address is wrong: the host name does not resolve, nothing listens at the port (ICMP port
    unreachable / TCP connection refused) or there is no route to it."""


class DeviceSilentError(DriverError, TimeoutError):
    """The address is reachable but the device did not answer within the time allowed."""


class DeviceResponseError(DriverError):
    """The device answered with an error (a Modbus exception response, an unreadable configuration)."""


class DeviceBusyError(DeviceResponseError):
    """The device answered "server device busy" (Modbus exception 6): it is there but has no value yet (booting,
    a channel still settling); the standard's advice is to ask again later."""
__all__ = ['DeviceAddressError', 'DeviceBusyError', 'DeviceResponseError', 'DeviceSilentError', 'DriverError',
           'ParameterError', 'ProtocolError']
