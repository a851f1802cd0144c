"""Sensor frames: a wrench in a rotated, offset sensor frame moved back to the platform centre in crane_base."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.estimation.errors import ParameterError
from crane_stiffness.estimation.frames import SensorMount, transform_wrench
from crane_stiffness.model.rotation import euler_zxy_to_matrix, matrix_to_quaternion


def sensor_reading(applied: np.ndarray, rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
    """What a sensor at ``position`` (from the platform centre, crane_base) with axes ``rotation`` (sensor →
    crane_base) reads for the wrench ``applied`` about the platform centre: the moment about its own origin, in its
    own axes."""
    f, m = applied[:3], applied[3:]
    m_sensor_origin = m - np.cross(position, f)
    return np.concatenate([rotation.T @ f, rotation.T @ m_sensor_origin])


def test_sensor_turned_90_degrees_about_z_and_50_mm_off_centre_gives_the_aligned_wrench():
    rz90 = euler_zxy_to_matrix(math.pi / 2, 0.0, 0.0)
    position = np.array([0.05, 0.0, 0.0])
    applied = np.array([0.0, 2.0, 0.0, 0.0, 0.0, 0.0])  # 2 N along y at the platform centre
    # By hand: the sensor's x axis points along crane_base y, so it reads fx = 2 N; the force passes 50 mm from
    # its origin, so about its origin the moment is -(r × f) = -(0.05 x̂ × 2 ŷ) = -0.1 N·m about z (its z is z).
    reading = np.array([2.0, 0.0, 0.0, 0.0, 0.0, -0.1])
    np.testing.assert_allclose(sensor_reading(applied, rz90, position), reading, atol=1e-15)
    np.testing.assert_allclose(transform_wrench(reading, rz90, position), applied, atol=1e-15)
    # The same mount as a quaternion, and as the reaction the sensor would see in the load path.
    quat = matrix_to_quaternion(rz90)
    np.testing.assert_allclose(transform_wrench(reading, quat, position), applied, atol=1e-15)
    np.testing.assert_allclose(transform_wrench(-reading, quat, position, reaction=True), applied, atol=1e-15)
    # A frame that ignored the offset would report a spurious -0.1 N·m about z: the test can tell.
    assert transform_wrench(reading, rz90)[5] == pytest.approx(-0.1)


def test_random_mounts_round_trip_batches():
    rng = np.random.default_rng(4)
    for _ in range(20):
        rotation = euler_zxy_to_matrix(*rng.uniform(-math.pi, math.pi, 3))
        position = rng.uniform(-0.2, 0.2, 3)
        applied = rng.normal(0.0, [5, 5, 50, 0.5, 0.5, 0.5], (7, 6))
        readings = np.array([sensor_reading(w, rotation, position) for w in applied])
        mount = SensorMount.from_params({'sensor_rotation': rotation.ravel().tolist(),
                                         'sensor_position': position.tolist(), 'sensor_reaction': False})
        np.testing.assert_allclose(mount.apply(readings), applied, atol=1e-12)
        np.testing.assert_allclose(mount.apply(readings[0]), applied[0], atol=1e-12)
        # the mount's matrix (made once; the live per-sample form) is the function's, sample by sample and batched
        for reaction in (False, True):
            m = SensorMount(rotation, position, reaction)
            direct = transform_wrench(readings, rotation, position, reaction)
            np.testing.assert_allclose(m.apply(readings), direct, rtol=1e-14, atol=1e-14)
            np.testing.assert_allclose([m.apply(w) for w in readings], direct, rtol=1e-14, atol=1e-14)


def test_bad_mounts_are_refused_with_the_field_named():
    with pytest.raises(ParameterError, match='sensor_rotation'):
        SensorMount.from_params({'sensor_rotation': [1.0, 2.0, 3.0]})
    with pytest.raises(ParameterError, match='proper rotation'):
        SensorMount.from_params({'sensor_rotation': np.diag([1.0, 1.0, -1.0]).ravel().tolist()})
    with pytest.raises(ParameterError, match='sensor_position'):
        SensorMount.from_params({'sensor_position': [0.0, math.nan, 0.0]})
    with pytest.raises(ParameterError, match='sensor_reaction'):
        SensorMount.from_params({'sensor_reaction': 1})
    with pytest.raises(ParameterError, match='wrench'):
        transform_wrench(np.zeros(5), np.eye(3))
