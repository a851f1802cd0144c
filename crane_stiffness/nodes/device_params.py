"""Parameter checks the hardware driver and device emulator nodes share (netft, modbus_lvdt, rdt_emulator,
modbus_emulator): an address, a port, and the parameters a node reads only at start."""
from __future__ import annotations

from typing import Any, Mapping, Sequence

from crane_stiffness.nodes.parameters import check


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
