"""Parameter checks the hardware driver and device emulator nodes share (netft, modbus_lvdt, rdt_emulator,
modbus_emulator): an address, a port, the parameters a node reads only at start, and the wait for a device at
start."""
from __future__ import annotations

import time
from typing import Any, Callable, Mapping, Sequence, TypeVar

from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.drivers.errors import DeviceAddressError, DeviceBusyError, DeviceSilentError
from crane_stiffness.rosnode.parameters import check

T = TypeVar('T')

#: The device emulators' limit on how late their physics may arrive (nodes.diagnostics.InputLag).
MAX_INPUT_LAG = ParamSpec('max_input_lag_s', 0.1, 'WARN on /diagnostics when the physics this device serves (applied '
                          'wrench or pose) arrived later than this after its stamp: a starved machine, the device '
                          'serving stale readings [s]', above=0.0)


def check_address(values: Mapping[str, Any], host: str = 'host', ports: Sequence[str] = ('port',),
                  allow_zero: bool = False) -> None:
    """``host`` a non-empty address or name; each of ``ports`` in 1..65535 (0 too with ``allow_zero``: a free
    port). Raises ValueError naming the parameter."""
    check(isinstance(values[host], str) and values[host] != '', host, values[host],
          'must be a non-empty address or host name')
    low = 0 if allow_zero else 1
    for name in ports:
        check(low <= values[name] < 65536, name, values[name],
              'must be in 0..65535 (0 = a free port)' if allow_zero else 'must be in 1..65535')


def check_start_only(values: Mapping[str, Any], current: Mapping[str, Any], names: Sequence[str]) -> None:
    """Refuse a change of a parameter read only at start (the device's address, its calibration …): ``current``
    holds the values the node runs with (empty while it starts). Raises ValueError with the reason."""
    if not current:
        return
    for name in names:
        check(values[name] == current[name], name, values[name],
              f'is read at start only (now {current[name]!r}): restart the node to change it')


def wait_for_device(action: Callable[[], T], wait_s: float, log: Callable[[str], None] | None = None,
                    retry_interval_s: float = 0.25) -> T:
    """``action()`` (a first contact with a device: a read, a request), tried again every ``retry_interval_s``
    while it raises DeviceAddressError or DeviceSilentError (nothing there yet: the device still booting, or its
    emulator still starting when every node of a launch starts at once) or DeviceBusyError (there, but no value yet)
    until ``wait_s`` has passed; then the last error is raised with the time waited. Any other DeviceResponseError (a
    device that answers wrongly) is raised at once.
    ``log`` gets one line when the first attempt fails."""
    deadline = time.monotonic() + wait_s
    first = True
    while True:
        try:
            return action()
        except (DeviceAddressError, DeviceSilentError, DeviceBusyError) as exc:
            if time.monotonic() + retry_interval_s > deadline:
                raise type(exc)(f'{exc} (tried for {wait_s:g} s: wait_for_device_s)') from None
            if first and log is not None:
                log(f'{exc}; trying again for up to {wait_s:g} s (wait_for_device_s)')
            first = False
            time.sleep(retry_interval_s)
