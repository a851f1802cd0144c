"""Pure driver code: RDT request/record codec, calibration and netftapi2.xml, sequence accounting, Modbus registers."""
from __future__ import annotations

import struct

import numpy as np
import pytest

from crane_stiffness.drivers import modbus, rdt
from crane_stiffness.drivers.errors import DeviceResponseError, ParameterError, ProtocolError
from crane_stiffness.errors import CraneStiffnessError


# --- RDT codec ----------------------------------------------------------------------------------------------------

def test_request_bytes_match_the_rdt_layout():
    assert rdt.encode_request(rdt.CMD_REALTIME) == bytes.fromhex('1234 0002 00000000')
    assert rdt.encode_request(rdt.CMD_BUFFERED, 10) == bytes.fromhex('1234 0003 0000000a')
    assert rdt.encode_request(rdt.CMD_BIAS) == bytes.fromhex('1234 0042 00000000')
    for cmd in rdt.COMMANDS:
        assert rdt.decode_request(rdt.encode_request(cmd, 2**32 - 1)) == (cmd, 2**32 - 1)


@pytest.mark.parametrize('data, text', [(b'\x12\x34\x00\x02', '8 bytes'),
                                        (bytes.fromhex('4321000200000000'), 'header 0x4321'),
                                        (bytes.fromhex('1234000900000000'), 'unknown RDT command 0x0009')])
def test_bad_requests_are_protocol_errors(data, text):
    with pytest.raises(ProtocolError, match=text):
        rdt.decode_request(data)


def test_bad_request_arguments():
    with pytest.raises(ParameterError, match='command'):
        rdt.encode_request(7)
    with pytest.raises(ParameterError, match='sample_count'):
        rdt.encode_request(rdt.CMD_REALTIME, -1)


def test_record_matches_struct_and_round_trips_many_at_once():
    counts = [1, -2, 2**31 - 1, -2**31, 0, 123456]
    one = rdt.encode_records(7, 2**32 + 5, 0x80000000, counts)
    assert one == struct.pack('>III6i', 7, 5, 0x80000000, *counts) and len(one) == rdt.RECORD_SIZE == 36
    rng = np.random.default_rng(0)
    n = 1000
    c = rng.integers(-2**31, 2**31, (n, 6))
    data = rdt.encode_records(np.arange(n) + 2**32 - 3, np.arange(n) * 7, 0, c)
    rec = rdt.decode_records(data)
    assert rec.shape == (n,)
    np.testing.assert_array_equal(rec['counts'], c)
    np.testing.assert_array_equal(rec['rdt_sequence'], (np.arange(n) + 2**32 - 3) % 2**32)  # wraps
    np.testing.assert_array_equal(rec['ft_sequence'], np.arange(n) * 7)
    assert rec['rdt_sequence'][3] == 0
    assert rdt.decode_records(b'').shape == (0,)
    with pytest.raises(ProtocolError, match='35 bytes'):
        rdt.decode_records(data[:35])
    with pytest.raises(ParameterError, match='int32|32-bit'):
        rdt.encode_records(0, 0, 0, [2**31, 0, 0, 0, 0, 0])


def test_calibration_converts_counts_and_units():
    cal = rdt.Calibration(1_000_000.0, 1_000_000.0)
    np.testing.assert_allclose(cal.to_si([1_000_000, -500_000, 0, 2_000_000, 0, 1]), [1.0, -0.5, 0, 2.0, 0, 1e-6])
    np.testing.assert_array_equal(cal.to_counts([1.0, -0.5, 0, 2.0, 0, 1e-6]), [1_000_000, -500_000, 0, 2_000_000,
                                                                               0, 1])
    assert cal.to_counts([1e9, 0, 0, 0, 0, 0])[0] == 2**31 - 1  # saturates like an ADC
    # 1e6 counts per lbf = 1e6 / 4.448 counts per N; 1e3 counts per N-mm = 1e6 counts per N·m.
    imperial = rdt.Calibration.from_units(1e6, 1e6, 'lbf', 'lbf-in')
    assert imperial.counts_per_force == pytest.approx(1e6 / 4.4482216152605)
    assert imperial.counts_per_torque == pytest.approx(1e6 / 0.1129848290276167)
    assert rdt.Calibration.from_units(1e6, 1e3, 'N', 'N-mm').counts_per_torque == pytest.approx(1e6)
    assert rdt.ONROBOT.to_si([10000, 0, 0, 100000, 0, 0]).tolist() == [1.0, 0, 0, 1.0, 0, 0]
    with pytest.raises(ParameterError, match='counts_per_force'):
        rdt.Calibration(0.0, 1.0)
    with pytest.raises(ParameterError, match='force unit'):
        rdt.Calibration.from_units(1, 1, 'stone', 'Nm')


def test_netftapi2_parsing():
    xml = ('<?xml version="1.0"?><netft><prodname>Net F/T</prodname><cfgcpf>1000000</cfgcpf><cfgcpt>1000</cfgcpt>'
           '<scfgfu>N</scfgfu><scfgtu>N-mm</scfgtu><comrdtrate>1000</comrdtrate><runrate>7000</runrate></netft>')
    cfg = rdt.parse_netftapi2(xml)
    assert cfg.calibration == rdt.Calibration(1e6, 1e6)
    assert (cfg.force_unit, cfg.torque_unit, cfg.rdt_rate_hz, cfg.internal_rate_hz, cfg.product) == (
        'N', 'N-mm', 1000.0, 7000.0, 'Net F/T')
    served = rdt.parse_netftapi2(rdt.netftapi2_xml(rdt.Calibration(2e5, 3e6), 7000.0, 7000.0))
    assert served.calibration == rdt.Calibration(2e5, 3e6) and served.rdt_rate_hz == 7000.0
    with pytest.raises(DeviceResponseError, match='no <cfgcpt>'):
        rdt.parse_netftapi2('<netft><cfgcpf>1</cfgcpf></netft>')
    with pytest.raises(DeviceResponseError, match='no force/torque unit'):
        rdt.parse_netftapi2('<netft><cfgcpf>1</cfgcpf><cfgcpt>1</cfgcpt></netft>')
    with pytest.raises(DeviceResponseError, match='not valid XML'):
        rdt.parse_netftapi2('<html>404')
    with pytest.raises(CraneStiffnessError):  # the package's base error catches every driver error
        rdt.parse_netftapi2('<netft><cfgcpf>x</cfgcpf><cfgcpt>1</cfgcpt></netft>')


# --- sequence accounting ------------------------------------------------------------------------------------------

def test_tracker_in_order_across_the_32_bit_wrap():
    t = rdt.SequenceTracker()
    start = 2**32 - 5
    for i in range(0, 100, 10):
        deliver, unwrapped = t.update((start + np.arange(i, i + 10)) % 2**32)
        assert deliver.all()
        np.testing.assert_array_equal(unwrapped, start + np.arange(i, i + 10))
    assert t.as_dict() == {'records_received': 100, 'records_lost': 0, 'records_out_of_order': 0,
                           'records_duplicate': 0, 'stream_restarts': 0}


def test_tracker_counts_lost_late_and_duplicate_records():
    t = rdt.SequenceTracker()
    deliver, u = t.update([1, 2, 3, 6, 5, 8])       # 4 and 7 missing; 5 arrives after 6 but in the same batch
    assert deliver.tolist() == [True, True, True, True, True, True]
    assert (t.lost, t.out_of_order) == (2, 1)
    deliver, u = t.update([4, 9, 9, 7, 10])           # 4 and 7 arrive after later batches were delivered
    assert deliver.tolist() == [False, True, False, False, True]
    assert (t.lost, t.out_of_order, t.duplicates) == (0, 3, 1)
    deliver, u = t.update([10, 20])
    assert deliver.tolist() == [False, True] and t.lost == 9 and t.duplicates == 2
    # A jump of millions, forwards or back, is another stream (the device restarted): the unwrapped numbering
    # continues and nothing counts as lost.
    deliver, u = t.update([5_000_000, 5_000_001, 1, 2])
    assert deliver.all() and t.restarts == 2 and t.lost == 9 and u.tolist() == [21, 22, 23, 24]
    t.reset()  # a new stream request: the next stream starts where it likes, without counting a restart
    deliver, u = t.update([100, 101])
    assert deliver.all() and u.tolist() == [25, 26] and t.lost == 9 and t.restarts == 2


# --- Modbus registers ---------------------------------------------------------------------------------------------

def test_float32_both_word_orders():
    assert modbus.encode_value(1.5, 'float32', 'big') == [0x3FC0, 0x0000]
    assert modbus.encode_value(1.5, 'float32', 'little') == [0x0000, 0x3FC0]
    assert modbus.decode_registers([0x3FC0, 0x0000], 'float32', 'big') == 1.5
    assert modbus.decode_registers([0x0000, 0x3FC0], 'float32', 'little') == 1.5
    v = float(np.float32(-2.718281))
    for order in modbus.WORD_ORDERS:
        assert modbus.decode_registers(modbus.encode_value(v, 'float32', order), 'float32', order) == v
    # The wrong word order reads garbage, not the value: the test tells the orders apart.
    assert modbus.decode_registers([0x3FC0, 0x0000], 'float32', 'little') != 1.5


def test_integer_types_scale_round_and_saturate():
    assert modbus.encode_value(-1, 'int16') == [0xFFFF]
    assert modbus.decode_registers([0xFFFF], 'int16') == -1.0
    assert modbus.decode_registers([0xFFFF], 'uint16') == 65535.0
    assert modbus.encode_value(40000, 'int16') == [0x7FFF]          # saturates like an ADC
    assert modbus.encode_value(-5, 'uint16') == [0]
    assert modbus.decode_registers([0x0001, 0x0000], 'int32', 'little') == 1.0
    assert modbus.decode_registers([0x0001, 0x0000], 'uint32', 'big') == 65536.0
    # An ADAM-style channel: ±10 V over int16, LVDT 1 mm/V → 10 mm / 32767 counts, offset -1 mm.
    ch = modbus.Channel(register=3, data_type='int16', gain=0.01 / 32767, offset=-0.001)
    assert ch.encode(0.004) == [round(0.005 / (0.01 / 32767))]
    assert ch.to_metres(ch.decode(ch.encode(0.004))) == pytest.approx(0.004, abs=0.01 / 32767)
    lab = modbus.Channel(register=2, data_type='float32', gain=0.002, offset=0.0)
    assert lab.to_metres(lab.decode(lab.encode(0.0031))) == pytest.approx(0.0031, rel=1e-7)


@pytest.mark.parametrize('kwargs, field', [({'data_type': 'float64'}, 'data_type'), ({'word_order': 'middle'},
                         'word_order'), ({'register_type': 'coil'}, 'register_type'), ({'register': -1}, 'register'),
                         ({'register': 65535}, 'register'), ({'gain': 0.0}, 'gain'), ({'offset': float('inf')},
                                                                                      'offset')])
def test_bad_channels_are_refused(kwargs, field):
    with pytest.raises(ParameterError, match=field):
        modbus.Channel(**kwargs)


def test_bad_registers_are_refused():
    with pytest.raises(ParameterError, match='2 register'):
        modbus.decode_registers([1], 'float32')
    with pytest.raises(ParameterError, match='0..65535'):
        modbus.decode_registers([70000], 'int16')
