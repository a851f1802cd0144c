"""The RDT driver core (receiver + pipeline) against the RDT device emulator on 127.0.0.1: values, stamps, lost and
reordered records, status words, bias and tare, averaging, buffered mode, netftapi2.xml, and the clear errors for a
wrong address or a silent device, and reconnecting after the device restarts."""
from __future__ import annotations

import socket
import time

import numpy as np
import pytest

from helpers import PATIENCE_S
from crane_stiffness.devices.rdt_device import RdtDevice
from crane_stiffness.drivers import rdt
from crane_stiffness.drivers.errors import DeviceAddressError, DeviceSilentError
from crane_stiffness.drivers.rdt_client import RdtReceiver, fetch_netftapi2
from crane_stiffness.drivers.rdt_pipeline import RdtPipeline

WRENCH = np.array([1.5, -2.25, 30.0, 0.125, -0.0625, 0.01])
CAL = rdt.Calibration(1e6, 1e6)
#: The receiver's silence limit (and pause before asking again) in the restart test [s]: what it must notice.
SILENT_AFTER_S = 0.2


def collect(receiver: RdtReceiver, pipeline: RdtPipeline, until, timeout_s: float = PATIENCE_S):
    """Drain and process until ``until(stamps)`` holds; returns all stamps and wrenches."""
    stamps, wrench = [], []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        batch = pipeline.process(receiver.drain())
        stamps.append(batch.stamps_ns)
        wrench.append(batch.wrench)
        s = np.concatenate(stamps)
        if until(s):
            break
        time.sleep(0.005)
    return np.concatenate(stamps), np.concatenate(wrench) if wrench else np.zeros((0, 6))


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def test_stream_values_and_stamps_from_the_sample_counter():
    with RdtDevice(lambda: WRENCH, sample_rate_hz=7000.0, start_counter=2**32 - 3000) as dev:
        t_before = time.time_ns()
        with RdtReceiver('127.0.0.1', dev.port) as rx:
            rx.start(wait_s=PATIENCE_S)
            pipe = RdtPipeline(CAL, 7000.0)
            stamps, wrench = collect(rx, pipe, lambda s: s.size >= 3500)
        t_after = time.time_ns()
    assert stamps.size >= 3500
    np.testing.assert_allclose(wrench, np.tile(WRENCH, (stamps.size, 1)), atol=1e-6)  # 1 count = 1e-6 N
    assert rx.kernel_timestamps
    # Stamps: on the counter's grid (1/7000 s apart), strictly increasing, inside the wall-clock span of the run.
    gaps = np.diff(stamps)
    assert np.all(gaps >= 1e9 / 7000 / 2 - 1)  # never closer than half a period, even while the clock settles
    assert np.median(gaps) == pytest.approx(1e9 / 7000, abs=1000)
    assert t_before < stamps[0] and stamps[-1] < t_after
    c = pipe.counters()
    assert c['records_lost'] == 0 and c['records_out_of_order'] == 0 and c['malformed_datagrams'] == 0
    assert c['clock_resets'] == 0  # the counter wrapped past 2**32 without a reset


def test_dropped_and_reordered_records_are_counted():
    def drop(seq: int) -> bool:
        return seq % 50 == 0
    with RdtDevice(lambda: WRENCH, sample_rate_hz=5000.0, drop=drop, reorder_every=7) as dev:
        with RdtReceiver('127.0.0.1', dev.port) as rx:
            rx.start(wait_s=PATIENCE_S)
            pipe = RdtPipeline(CAL, 5000.0)
            stamps, _ = collect(rx, pipe, lambda s: s.size >= 3000)
            rx.stop()  # ends the stream; what was received is drained below
            stamps2, _ = collect(rx, pipe, lambda s: True)  # one drain
    c = pipe.counters()
    highest = c['records_received'] + c['records_lost'] - c['records_duplicate']  # the highest rdt_sequence seen
    expected_lost = sum(drop(s) for s in range(1, highest + 1))
    print('counters', c, 'expected lost', expected_lost)
    assert expected_lost >= 50
    # Exactly the dropped ones, plus the record held back to reorder if the stream stopped before it was sent.
    assert expected_lost <= c['records_lost'] <= expected_lost + 1
    assert c['records_out_of_order'] > 0                        # every 7th datagram came after its successor
    assert c['records_delivered'] + c['records_late_dropped'] == c['records_received']
    assert np.all(np.diff(np.concatenate([stamps, stamps2])) > 0)  # delivered in order all the same


def test_status_word_is_reported_and_the_records_dropped():
    with RdtDevice(lambda: WRENCH, sample_rate_hz=2000.0, status=0x80010000) as dev:
        with RdtReceiver('127.0.0.1', dev.port) as rx:
            rx.start(wait_s=PATIENCE_S)
            pipe = RdtPipeline(CAL, 2000.0)
            collect(rx, pipe, lambda s: pipe.status_records >= 200)
            assert pipe.last_status == 0x80010000 and pipe.delivered_records == 0
            assert pipe.dropped_status == pipe.status_records
            keep = RdtPipeline(CAL, 2000.0, drop_status_mask=0)  # deliver them anyway
            stamps, _ = collect(rx, keep, lambda s: s.size >= 100)
            assert stamps.size >= 100 and keep.status_records >= stamps.size


def test_hardware_bias_and_software_tare():
    load = {'w': WRENCH.copy()}
    with RdtDevice(lambda: load['w'], sample_rate_hz=2000.0) as dev:
        with RdtReceiver('127.0.0.1', dev.port) as rx:
            rx.start(wait_s=PATIENCE_S)
            pipe = RdtPipeline(CAL, 2000.0, tare_samples=50)
            collect(rx, pipe, lambda s: pipe.tare_count >= 50)
            offset = pipe.tare()
            np.testing.assert_allclose(offset, WRENCH, atol=1e-6)
            _, w = collect(rx, pipe, lambda s: s.size >= 100)
            assert np.abs(w[-50:]).max() < 1e-6              # software tare: zero at the tare load
            pipe.clear_tare()
            rx.bias()                                          # hardware: the device zeroes itself
            _, w = collect(rx, pipe, lambda s: s.size >= 1 and np.abs(pipe.latest_raw).max() < 1e-6)
            assert np.abs(w[-1]).max() < 1e-6
            load['w'] = WRENCH + [1.0, 0, 0, 0, 0, 0]          # 1 N more reads 1 N
            _, w = collect(rx, pipe, lambda s: s.size >= 1 and pipe.latest_raw[0] > 0.5)
            assert w[-1][0] == pytest.approx(1.0, abs=1e-6)
    assert (rdt.CMD_BIAS, 0) in dev.requests


def test_averaging_7_khz_to_1_khz_and_buffered_datagrams():
    rng = np.random.default_rng(3)
    with RdtDevice(lambda n: WRENCH + rng.normal(0, 0.01, (n, 6)), sample_rate_hz=7000.0, records_per_packet=10,
                   batch=True) as dev:
        with RdtReceiver('127.0.0.1', dev.port, command='buffered') as rx:
            rx.start(wait_s=PATIENCE_S)
            pipe = RdtPipeline(CAL, 7000.0, publish_rate_hz=1000.0)
            stamps, w = collect(rx, pipe, lambda s: s.size >= 500)
    assert dev.requests[0] == (rdt.CMD_BUFFERED, 0)
    assert rx.datagrams * 9 < pipe.delivered_records      # ~10 records per datagram
    # One output per millisecond of the host clock, each the mean of ~7 samples (noise / sqrt(7)).
    assert np.median(np.diff(stamps)) == pytest.approx(1e6, abs=2e4)
    assert len(np.unique(stamps // 1_000_000)) == stamps.size
    assert pipe.delivered_records == pytest.approx(7 * stamps.size, rel=0.02)
    assert np.std(w[:, 0]) == pytest.approx(0.01 / np.sqrt(7), rel=0.2)
    np.testing.assert_allclose(w.mean(axis=0), WRENCH, atol=0.002)


def test_netftapi2_calibration_from_the_box():
    cal = rdt.Calibration(1_000_000 / 4.4482216152605, 2e5)
    with RdtDevice(lambda: WRENCH, calibration=cal, http_port=0) as dev:
        cfg = fetch_netftapi2('127.0.0.1', dev.http_port)
        assert cfg.calibration.counts_per_force == pytest.approx(cal.counts_per_force, rel=1e-9)
        assert cfg.calibration.counts_per_torque == pytest.approx(2e5)
        assert cfg.rdt_rate_hz == 7000.0
    with pytest.raises(DeviceAddressError, match='refused'):  # the box is gone
        fetch_netftapi2('127.0.0.1', dev.http_port)


def test_wrong_address_and_silent_device_are_clear_errors():
    port = free_udp_port()  # nothing listens there: the kernel answers ICMP port unreachable
    with pytest.raises(DeviceAddressError, match=f'no RDT device at 127.0.0.1:{port}: port unreachable'):
        RdtReceiver('127.0.0.1', port).start(wait_s=1.0)
    with pytest.raises(DeviceAddressError, match='cannot resolve'):
        RdtReceiver('no-such-sensor.invalid', 49152).start(wait_s=1.0)
    with RdtDevice(lambda: WRENCH) as dev:
        dev.silent = True
        with pytest.raises(DeviceSilentError, match='sent no record within 1.0 s'):
            RdtReceiver('127.0.0.1', dev.port).start(wait_s=1.0)
        assert dev.requests and dev.requests[0][0] == rdt.CMD_REALTIME  # the request did arrive


def test_reconnects_after_the_device_restarts():
    dev = RdtDevice(lambda: WRENCH, sample_rate_hz=2000.0).start()
    try:
        with RdtReceiver('127.0.0.1', dev.port, timeout_s=SILENT_AFTER_S, reconnect_interval_s=SILENT_AFTER_S) as rx:
            rx.start(wait_s=PATIENCE_S)
            pipe = RdtPipeline(CAL, 2000.0)
            before, _ = collect(rx, pipe, lambda s: s.size >= 400)
            dev.stop()                                     # unplugged
            deadline = time.monotonic() + PATIENCE_S       # until the receiver notices (a starved one late)
            while rx.streaming and time.monotonic() < deadline:
                time.sleep(0.01)
            assert not rx.streaming
            dev.start()                                    # back, on the same port, counter from 0, no client
            after, w = collect(rx, pipe, lambda s: s.size >= 400)
            assert rx.streaming and rx.reconnects >= 1 and rx.generation >= 2
            np.testing.assert_allclose(w, np.tile(WRENCH, (after.size, 1)), atol=1e-6)
            assert after[0] > before[-1] and np.all(np.diff(after) > 0)
            assert pipe.counters()['records_lost'] == 0    # a new stream is not a loss
    finally:
        dev.stop()
