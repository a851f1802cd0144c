"""Tests of crane_stiffness.sim.sensors: load cell and LVDT models."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.sim import LoadCellModel, LvdtModel, ParameterError

NOISE = np.array([0.05, 0.05, 0.1, 0.002, 0.002, 0.001])  # N and N·m, a small F/T sensor


def _rot_z(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_load_cell_noise_std_and_bias() -> None:
    bias = np.array([0.5, -0.2, 1.0, 0.01, 0.0, -0.02])
    cell = LoadCellModel(noise_std=NOISE, bias=bias, rng=1)
    wrench, saturated = cell.measure(np.zeros((20_000, 6)))
    assert wrench.shape == (20_000, 6)
    assert not saturated.any()
    np.testing.assert_allclose(wrench.std(axis=0, ddof=1), NOISE, rtol=0.03)
    assert (np.abs(wrench.mean(axis=0) - bias) < 4 * NOISE / math.sqrt(20_000)).all()


def test_load_cell_single_reading_and_seed_reproducible() -> None:
    true = np.array([0.0, 5.0, 60.0, 0.0, 0.0, 0.2])
    a = LoadCellModel(noise_std=NOISE, rng=7).measure(true, 0.0)
    b = LoadCellModel.from_params({'noise_std': NOISE.tolist(), 'seed': 7}).measure(true, 0.0)
    assert a[0].shape == (6,) and a[1].shape == (6,) and a[1].dtype == bool
    np.testing.assert_array_equal(a[0], b[0])


def test_load_cell_drift_and_crosstalk() -> None:
    crosstalk = np.eye(6)
    crosstalk[0, 1] = 0.02  # 2 % of fy leaks into fx
    crosstalk[5, 2] = -0.001  # fz into mz, N·m per N
    cell = LoadCellModel(drift_per_s=[0.01, 0, 0, 0, 0, 0], crosstalk=crosstalk.ravel().tolist())
    reading, _ = cell.measure([0.0, 10.0, 50.0, 0.0, 0.0, 0.0], t_s=30.0)
    np.testing.assert_allclose(reading, [0.2 + 0.3, 10.0, 50.0, 0.0, 0.0, -0.05], atol=1e-12)
    readings, _ = cell.measure(np.zeros((3, 6)), t_s=np.array([0.0, 10.0, 20.0]))
    np.testing.assert_allclose(readings[:, 0], [0.0, 0.1, 0.2], atol=1e-12)


def test_load_cell_quantization() -> None:
    resolution = np.array([0.025, 0.025, 0.05, 0.00125, 0.00125, 0.000625])
    cell = LoadCellModel(noise_std=NOISE, bias=0.013, resolution=resolution, rng=2)
    readings, _ = cell.measure(np.tile([1.0, -2.0, 30.0, 0.1, 0.0, 0.05], (1000, 1)))
    counts = readings / resolution
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    # Rounding adds about resolution²/12 of variance on top of the noise.
    expected = np.sqrt(NOISE ** 2 + resolution ** 2 / 12.0)
    np.testing.assert_allclose(readings.std(axis=0), expected, rtol=0.1)
    # A step below one count is invisible without noise.
    quiet = LoadCellModel(resolution=0.1)
    assert quiet.measure([0.04, 0.06, 0.0, 0.0, 0.0, 0.0])[0][:2].tolist() == [0.0, pytest.approx(0.1)]


def test_load_cell_saturation_flags() -> None:
    full_scale = [50.0, 50.0, 150.0, 3.0, 3.0, 3.0]
    cell = LoadCellModel(full_scale=full_scale)
    reading, saturated = cell.measure([10.0, -70.0, 149.0, 0.0, 3.5, 0.0])
    assert saturated.tolist() == [False, True, False, False, True, False]
    np.testing.assert_allclose(reading, [10.0, -50.0, 149.0, 0.0, 3.0, 0.0])


def test_load_cell_tare_removes_bias() -> None:
    bias = np.array([0.8, -0.4, 2.0, 0.02, -0.01, 0.005])
    cell = LoadCellModel(noise_std=NOISE, bias=bias, drift_per_s=0.0, rng=3)
    samples, _ = cell.measure(np.zeros((500, 6)))
    offset = cell.tare(samples)
    assert (np.abs(offset - bias) < 4 * NOISE / math.sqrt(500)).all()
    loaded, _ = cell.measure(np.tile([0.0, 5.0, 0.0, 0.0, 0.0, 0.1], (5000, 1)))
    assert (np.abs(loaded.mean(axis=0) - [0.0, 5.0, 0.0, 0.0, 0.0, 0.1]) < 6 * NOISE / math.sqrt(500)).all()
    cell.clear_tare()
    np.testing.assert_array_equal(cell.offset, np.zeros(6))


@pytest.mark.parametrize(('params', 'field'), [
    ({'noise_std': -0.1}, 'noise_std'),
    ({'noise_std': [0.1, 0.1]}, 'noise_std'),
    ({'bias': [0, 0, 0, 0, 0, math.nan]}, 'bias'),
    ({'crosstalk': [1.0] * 35}, 'crosstalk'),
    ({'resolution': -1e-3}, 'resolution'),
    ({'full_scale': [50, 50, 0, 3, 3, 3]}, 'full_scale'),
    ({'seed': 'abc'}, 'seed'),
    ({'noise': 0.1}, 'noise'),
])
def test_load_cell_from_params_validation(params: dict, field: str) -> None:
    with pytest.raises(ParameterError) as info:
        LoadCellModel.from_params(params)
    assert info.value.field == field
    assert str(info.value).startswith(f'{field} = ')
    assert isinstance(info.value, ValueError) and isinstance(info.value, CraneStiffnessError)


def test_lvdt_translation_along_and_across_axis() -> None:
    lvdt = LvdtModel(axis=[0.0, 2.0, 0.0], contact_point=[0.0, 0.0657, 0.0])  # axis normalised
    np.testing.assert_allclose(lvdt.axis, [0.0, 1.0, 0.0])
    reading, in_range = lvdt.measure([0.0, 0.004, 0.0], np.eye(3))
    assert reading == pytest.approx(0.004, abs=1e-15)
    assert in_range is True
    assert lvdt.measure([0.003, 0.0, -0.002], np.eye(3))[0] == pytest.approx(0.0, abs=1e-15)


def test_lvdt_reading_with_rotation() -> None:
    # Contact point 66 mm out along x; a yaw φ moves it by r·sin φ along y and r·(cos φ − 1) along x.
    r, phi = 0.066, 0.02
    lvdt_y = LvdtModel(axis=[0, 1, 0], contact_point=[r, 0.0, 0.0])
    lvdt_x = LvdtModel(axis=[1, 0, 0], contact_point=[r, 0.0, 0.0])
    u = np.array([0.001, 0.002, 0.0])
    assert lvdt_y.measure(u, _rot_z(phi))[0] == pytest.approx(0.002 + r * math.sin(phi), rel=1e-12)
    assert lvdt_x.measure(u, _rot_z(phi))[0] == pytest.approx(0.001 + r * (math.cos(phi) - 1.0), rel=1e-12)
    # Tangential LVDT on a radius reads the angle: reading / r ≈ φ for small φ.
    assert lvdt_y.measure(np.zeros(3), _rot_z(1e-3))[0] / r == pytest.approx(1e-3, rel=1e-6)


def test_lvdt_zero_batch_and_range() -> None:
    lvdt = LvdtModel(axis=[0, 1, 0], contact_point=[0.0, 0.05, 0.0], range_m=(-0.005, 0.01))
    lvdt.zero([0.0, 0.002, 0.0], _rot_z(0.01))
    assert lvdt.measure([0.0, 0.002, 0.0], _rot_z(0.01))[0] == pytest.approx(0.0, abs=1e-15)
    u = np.array([[0.0, 0.002 + dy, 0.0] for dy in (-0.01, 0.0, 0.005, 0.02)])
    q = np.repeat(_rot_z(0.01)[None], 4, axis=0)
    reading, in_range = lvdt.measure(u, q)
    np.testing.assert_allclose(reading, [-0.005, 0.0, 0.005, 0.01], atol=1e-15)
    assert in_range.tolist() == [False, True, True, False]


def test_lvdt_noise_and_quantization() -> None:
    lvdt = LvdtModel.from_params({'axis': [0, 1, 0], 'noise_std': 2e-6, 'resolution': 1e-6, 'seed': 4,
                                  'range_m': [-0.025, 0.025]})
    u = np.tile([0.0, 0.00123456, 0.0], (20_000, 1))
    reading, in_range = lvdt.measure(u, np.broadcast_to(np.eye(3), (20_000, 3, 3)))
    assert in_range.all()
    np.testing.assert_allclose(reading / 1e-6, np.round(reading / 1e-6), atol=1e-6)
    assert reading.mean() == pytest.approx(0.00123456, abs=1e-7)
    assert reading.std() == pytest.approx(math.sqrt(2e-6 ** 2 + 1e-12 / 12.0), rel=0.05)


@pytest.mark.parametrize(('params', 'field'), [
    ({}, 'axis'),
    ({'axis': [0, 0, 0]}, 'axis'),
    ({'axis': [0, 1]}, 'axis'),
    ({'axis': [0, 1, 0], 'contact_point': [0, 0, math.inf]}, 'contact_point'),
    ({'axis': [0, 1, 0], 'noise_std': -1e-6}, 'noise_std'),
    ({'axis': [0, 1, 0], 'range_m': [0.01, -0.01]}, 'range_m'),
    ({'axis': [0, 1, 0], 'range_m': 0.01}, 'range_m'),
    ({'axis': [0, 1, 0], 'stroke': 0.01}, 'stroke'),
])
def test_lvdt_from_params_validation(params: dict, field: str) -> None:
    with pytest.raises(ParameterError) as info:
        LvdtModel.from_params(params)
    assert info.value.field == field
    assert isinstance(info.value, ValueError)
