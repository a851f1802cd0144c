"""A Modbus TCP analog-input device on this machine, on pymodbus's server: a LabJack or an ADAM-style module.

:class:`ModbusDevice` serves one :class:`~crane_stiffness.drivers.modbus.Channel`: every read of its registers
(holding or input, function 3 or 4: the block is shared, as on a LabJack) first asks ``source()`` for the current
reading [m] (None: no value yet, answered "server device busy" as a device still settling does) and writes it encoded
as the channel says (float32 volts in either word order, int16 counts, …; raw =
(metres − offset) / gain). Registers ``0 .. registers-1`` exist; others answer "illegal data address"; other unit
ids get an exception response. ``fail_with`` (a Modbus
exception code, 0 = none) makes every read fail, for tests.

The server runs on its own asyncio loop in a thread; port 0 picks a free port (:attr:`ModbusDevice.port`).
Pure Python, no ROS.
"""
from __future__ import annotations

import asyncio
import logging
import threading
from typing import TYPE_CHECKING, Callable, cast

from crane_stiffness.drivers.errors import DriverError, ParameterError
from crane_stiffness.drivers.modbus import Channel

if TYPE_CHECKING:  # pymodbus is imported where the server starts
    from pymodbus.constants import ExcCodes
    from pymodbus.server import ModbusTcpServer


class ModbusDevice:
    """Emulated Modbus TCP analog-input device (see the module docstring). A context manager."""

    def __init__(self, source: Callable[[], float | None], *, channel: Channel = Channel(), host: str = '127.0.0.1',
                 port: int = 0, unit_id: int = 1, registers: int = 64) -> None:
        """Args:
            source: Returns the current reading [m], or None while there is none yet (reads answer exception 6,
                "server device busy").
            channel: Register, data type, word order and scaling of the served value.
            host, port: Where to listen (port 0: a free port).
            unit_id: The Modbus unit (device) id it answers to, 1..247.
            registers: Size of the register block starting at 0.
        """
        if not callable(source):
            raise ParameterError('source', source, 'must be a callable returning metres')
        if isinstance(unit_id, bool) or not isinstance(unit_id, int) or not 1 <= unit_id <= 247:
            raise ParameterError('unit_id', unit_id, 'must be in 1..247')
        if channel.register + channel.count > registers:
            raise ParameterError('channel.register', channel.register, f'must lie in the {registers} registers served')
        self.source, self.channel = source, channel
        self.host, self.port, self.unit_id, self.registers = host, port, unit_id, registers
        self.fail_with = 0
        self.reads = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: ModbusTcpServer | None = None
        self._thread: threading.Thread | None = None
        logging.getLogger('pymodbus').setLevel(logging.CRITICAL)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], values: list[int] | list[bool] | None) -> ExcCodes | None:
        from pymodbus.constants import ExcCodes
        self.reads += 1
        if self.fail_with:
            return ExcCodes(self.fail_with)
        ch = self.channel
        if values is None and address <= ch.register + ch.count - 1 and ch.register < address + count:
            value = self.source()
            if value is None:
                return ExcCodes.DEVICE_BUSY
            offset = ch.register - start_address
            registers[offset:offset + ch.count] = ch.encode(float(value))
        return None

    def start(self) -> ModbusDevice:
        """Listen and serve; returns once the port is open. Raises DriverError if it cannot listen."""
        if self._thread is not None:
            return self
        ready = threading.Event()
        failure: list[BaseException] = []

        def run() -> None:
            async def main() -> None:
                from pymodbus.server import ModbusTcpServer
                from pymodbus.simulator import DataType, SimData, SimDevice
                device = SimDevice(id=self.unit_id, action=self._action, simdata=[
                    SimData(0, count=self.registers, values=0, datatype=DataType.REGISTERS)])
                server = ModbusTcpServer(device, address=(self.host, self.port))
                try:
                    await server.serve_forever(background=True)
                except Exception as exc:  # noqa: BLE001 (reported to start())
                    failure.append(exc)
                    ready.set()
                    return
                self._server = server
                self._loop = asyncio.get_running_loop()
                # A listening server's transport is the asyncio.Server of create_server (pymodbus annotates it as
                # a BaseTransport).
                self.port = cast(asyncio.Server, server.transport).sockets[0].getsockname()[1]
                ready.set()
                await server.serving
            asyncio.run(main())

        self._thread = threading.Thread(target=run, name='modbus-device', daemon=True)
        self._thread.start()
        if not ready.wait(5.0) or failure:
            self._thread = None
            raise DriverError(f'Modbus device cannot listen on {self.host}:{self.port}: '
                              f'{failure[0] if failure else "timed out"}')
        return self

    def stop(self) -> None:
        """Close the server and every connection."""
        if self._server is not None and self._loop is not None:
            try:
                asyncio.run_coroutine_threadsafe(self._server.shutdown(), self._loop).result(5.0)
            except (RuntimeError, TimeoutError):
                pass
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self._server = self._loop = self._thread = None

    def __enter__(self) -> ModbusDevice:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port
