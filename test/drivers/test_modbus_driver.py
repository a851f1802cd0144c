"""The Modbus poller against the pymodbus server emulator on 127.0.0.1: float32 in both word orders, int16 scaling,
input registers, Modbus exceptions, wrong address, a silent device and reconnecting after a restart."""
from __future__ import annotations

import socket
import threading

import pytest

from helpers import PATIENCE_S
from crane_stiffness.devices.modbus_device import ModbusDevice
from crane_stiffness.drivers.errors import DeviceAddressError, DeviceBusyError, DeviceResponseError, DeviceSilentError
from crane_stiffness.drivers.modbus import Channel, ModbusPoller

READING_M = 0.0012345  # what the simulated LVDT reads
#: The driver's answer timeout checked against a device that never answers [s]: no load makes that device answer,
#: so it is a property under test, not a wait for something the machine may delay.
NEVER_ANSWERS_AFTER_S = 0.3


@pytest.mark.parametrize('word_order', ['big', 'little'])
def test_labjack_float32_volts_in_both_word_orders(word_order):
    ch = Channel(register=2, data_type='float32', word_order=word_order, gain=0.002, offset=-0.001)  # AIN1
    with ModbusDevice(lambda: READING_M, channel=ch, unit_id=1) as dev:
        poller = ModbusPoller('127.0.0.1', dev.port, 1, ch)
        r = poller.read()
        assert r.raw == pytest.approx((READING_M + 0.001) / 0.002, rel=1e-7)  # volts on the wire
        assert r.metres == pytest.approx(READING_M, rel=1e-6)
        assert r.start_ns <= r.stamp_ns <= r.end_ns
        # The same registers read with the other word order are not the reading: the orders are told apart.
        other = Channel(register=2, data_type='float32', word_order='little' if word_order == 'big' else 'big',
                        gain=0.002, offset=-0.001)
        assert ModbusPoller('127.0.0.1', dev.port, 1, other).read().metres != pytest.approx(READING_M, rel=1e-3)
        poller.close()


def test_adam_style_int16_counts_scaled_from_input_registers():
    gain = 0.01 / 32767  # ±10 V over int16 counts, 1 mm/V: metres per count
    ch = Channel(register=5, data_type='int16', register_type='input', gain=gain, offset=0.0)
    value = {'m': -0.0042}
    with ModbusDevice(lambda: value['m'], channel=ch, unit_id=3) as dev:
        poller = ModbusPoller('127.0.0.1', dev.port, 3, ch)
        r = poller.read()
        assert r.raw == round(-0.0042 / gain)
        assert r.metres == pytest.approx(-0.0042, abs=gain)
        value['m'] = 0.02  # beyond the int16 range: saturates at +32767 counts
        assert poller.read().raw == 32767.0
        poller.close()


def test_a_device_without_a_value_yet_is_busy_and_waited_for():
    """A source with no value yet (None) answers exception 6, "server device busy": a DeviceBusyError, which a
    driver's first contact waits out like a device still booting, while other exceptions stop it at once."""
    from crane_stiffness.rosnode.device_params import wait_for_device
    value: dict[str, float | None] = {'m': None}
    ch = Channel(register=0)
    with ModbusDevice(lambda: value['m'], channel=ch) as dev:
        poller = ModbusPoller('127.0.0.1', dev.port, 1, ch)
        with pytest.raises(DeviceBusyError, match='exception 6 \\(server device busy\\)'):
            poller.read()
        logged: list[str] = []
        tries = {'n': 0}

        def read():
            tries['n'] += 1
            if tries['n'] == 3:
                value['m'] = READING_M
            return poller.read()
        assert wait_for_device(read, PATIENCE_S, logged.append, retry_interval_s=0.01).metres == \
            pytest.approx(READING_M)
        assert tries['n'] == 3 and len(logged) == 1 and 'server device busy' in logged[0]
        value['m'] = None
        with pytest.raises(DeviceBusyError, match='tried for 0.05 s'):
            wait_for_device(poller.read, 0.05, retry_interval_s=0.01)
        dev.fail_with = 4
        with pytest.raises(DeviceResponseError, match='server device failure'):
            wait_for_device(poller.read, PATIENCE_S, retry_interval_s=0.01)
        poller.close()


def test_exceptions_wrong_address_and_silent_device():
    ch = Channel(register=0)
    with ModbusDevice(lambda: READING_M, channel=ch, registers=8) as dev:
        with pytest.raises(DeviceResponseError, match='exception 2 \\(illegal data address\\).*at 20'):
            ModbusPoller('127.0.0.1', dev.port, 1, Channel(register=20)).read()
        dev.fail_with = 4
        with pytest.raises(DeviceResponseError, match='exception 4 \\(server device failure\\)'):
            ModbusPoller('127.0.0.1', dev.port, 1, ch).read()
        port = dev.port
    with pytest.raises(DeviceAddressError, match=f'no Modbus TCP device at 127.0.0.1:{port} unit 1'):
        ModbusPoller('127.0.0.1', port, 1, ch).open()
    with pytest.raises(DeviceAddressError, match='cannot resolve'):
        ModbusPoller('no-such-daq.invalid', 502, 1, ch).open()
    # A device that accepts the connection and never answers.
    with socket.socket() as listener:
        listener.bind(('127.0.0.1', 0))
        listener.listen(1)
        accepted = []
        t = threading.Thread(target=lambda: accepted.append(listener.accept()), daemon=True)
        t.start()
        poller = ModbusPoller('127.0.0.1', listener.getsockname()[1], 1, ch, timeout_s=NEVER_ANSWERS_AFTER_S)
        with pytest.raises(DeviceSilentError, match='no answer .* within 0.3 s'):
            poller.read()
        t.join(2.0)
        for conn, _ in accepted:
            conn.close()


def test_reconnects_after_the_device_restarts():
    ch = Channel(register=0)
    dev = ModbusDevice(lambda: READING_M, channel=ch).start()
    port = dev.port
    # A stopped device refuses at once: the timeout only bounds the answers of a running one (on the patience).
    poller = ModbusPoller('127.0.0.1', port, 1, ch, timeout_s=PATIENCE_S)
    assert poller.read().metres == pytest.approx(READING_M, rel=1e-6)
    dev.stop()
    with pytest.raises((DeviceSilentError, DeviceAddressError)):
        poller.read()
    dev = ModbusDevice(lambda: 2 * READING_M, channel=ch, port=port).start()
    try:
        assert poller.read().metres == pytest.approx(2 * READING_M, rel=1e-6)
        assert poller.connects == 2
    finally:
        poller.close()
        dev.stop()
