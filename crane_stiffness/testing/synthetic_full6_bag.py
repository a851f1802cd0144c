"""Synthetic six-axis session bags: what session_recorder writes over a multi-axis load program on a rig with a load
cell and a 6-DOF pose sensor, from the exact tangent of the crane model, with seeded sensor noise. For the tests of
the offline 6×6 analysis (crane_stiffness.analysis.full6) and for benchmarks. Pure: no ROS import (the writer needs
the installed .msg files).

The timeline, on one simulated clock (stamps and log times in ns from ``t0_ns``, the program's start):

- ``/crane/wrench_command`` (WrenchStamped, crane_base): the program sampled at its rate (100 Hz), stamped at the
  instants, logged 0.2 ms later.
- ``/load_cell/wrench`` (WrenchStamped, frame ``load_cell``): samples on the grid k/``load_cell_rate_hz`` (1 kHz): the
  command in effect at the instant (the true load on the platform, at its centre, crane_base; zero before the first
  command) seen from the sensor's mounting (``mount``: the inverse of
  crane_stiffness.estimation.frames.SensorMount.apply), plus the bias :data:`LOAD_CELL_BIAS` and white noise
  ``wrench_noise`` per sample, in the sensor frame. Published in bursts at ``publish_rate_hz`` (100 Hz) as the
  simulated sensors do: log time = the next burst tick + a jitter of 0.05–0.4 ms, the burst's samples 10 µs apart.
- ``/pose_sensor/pose`` (PoseStamped, crane_base): samples on the grid k/``pose_rate_hz`` (250 Hz): the platform
  centre's rest pose under the weight (crane_stiffness.model.rest_pose) displaced by d = C·w + noise, with C = K⁻¹ the
  exact tangent compliance at that rest pose and w the true load at the instant: position = rest position + d[:3]
  [m], rotation = exp([d[3:]]×)·Q0 (the deflection of crane_stiffness.full6.deflection), noise ``pose_noise``
  (2 µm, 20 µrad). Logged 1 ms after the stamp plus a jitter of up to 0.5 ms.

The quasi-static truth is linear (d = C·w exactly, no slack wire), so a fit of the pairs recovers the tangent up to
the noise. The session record holds the rig's geometry, the program and the sensors' parameters (the load cell's
mounting under ``stiffness_estimator``, where the 1-D analysis reads it); ``estimator6`` is recorded as the running
``stiffness6_estimator`` node's parameters (the ``crane_stiffness/node_parameters`` record).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.contract import topics
from crane_stiffness.bag import BagWriter
from crane_stiffness.estimation.frames import SensorMount
from crane_stiffness.model import CraneGeometry, Equilibrium, rest_pose, tangent_stiffness
from crane_stiffness.model.rotation import matrix_to_quaternion
from crane_stiffness.params.geometry import geometry_to_params
from crane_stiffness.serde import encode_stamped
from crane_stiffness.bag.session_metadata import NODE_PARAMETERS_METADATA, SESSION_METADATA, session_metadata
from crane_stiffness.sim.program import LoadProgram
from crane_stiffness.testing.synthetic import T0_NS, offered_qos
from crane_stiffness.testing.synthetic_full6 import LOAD_CELL_BIAS

#: The load cell's white noise per 1 kHz sample (config/sensors.yaml) [N, N·m].
LOAD_CELL_NOISE = (0.01, 0.01, 0.01, 5e-4, 5e-4, 5e-4)
#: The pose sensor's white noise per sample: 2 µm, 20 µrad [m, rad].
POSE_NOISE = (2e-6, 2e-6, 2e-6, 20e-6, 20e-6, 20e-6)
_TOPICS = (topics.WRENCH_COMMAND, topics.LOAD_CELL_WRENCH, topics.POSE_SENSOR_POSE)


@dataclass(frozen=True)
class Full6BagSession:
    """What was written and the truth behind it.

    Attributes:
        path: the bag directory.
        program: the program played; geometry: the crane.
        rest: the rest pose under the weight alone (the pose sensor's zero-load pose).
        tangent: exact tangent K (6, 6) at ``rest`` [N/m, N/rad, N·m/rad]; compliance: C = K⁻¹ (6, 6).
        mount: the load cell's mounting recorded (and its wrenches made with).
        counts: messages written per topic.
    """

    path: Path
    program: LoadProgram
    geometry: CraneGeometry
    rest: Equilibrium
    tangent: NDArray[np.float64]
    compliance: NDArray[np.float64]
    mount: SensorMount
    counts: dict[str, int] = field(default_factory=dict)


def _grid(start_ns: int, end_ns: int, rate_hz: float) -> NDArray[np.int64]:
    """Instants k/rate [ns] (integer ns, as a simulated sensor stamps them) within [start_ns, end_ns]."""
    period = int(round(1e9 / rate_hz))
    return np.arange(-(-start_ns // period), end_ns // period + 1, dtype=np.int64) * period


def _in_effect(cmd_stamp: NDArray[np.int64], cmd_wrench: NDArray[np.float64],
               stamps: NDArray[np.int64]) -> NDArray[np.float64]:
    """The commanded wrench (n, 6) in effect at each instant (zero before the first command)."""
    k = np.searchsorted(cmd_stamp, stamps, side='right') - 1
    return np.where((k >= 0)[:, None], cmd_wrench[np.maximum(k, 0)], 0.0)


def _quaternions(rotvec: NDArray[np.float64], rest_rotation: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quaternions [x, y, z, w] (n, 4) of exp([r]×)·Q0 for rotation vectors r (n, 3) [rad] (Hamilton product)."""
    angle = np.linalg.norm(rotvec, axis=1, keepdims=True)
    axis = np.divide(rotvec, angle, out=np.zeros_like(rotvec), where=angle > 0.0)
    v1, w1 = axis * np.sin(angle / 2.0), np.cos(angle / 2.0)
    q0 = matrix_to_quaternion(np.asarray(rest_rotation, dtype=float))
    v0, w0 = np.broadcast_to(q0[:3], v1.shape), q0[3]
    return np.column_stack([w1 * v0 + w0 * v1 + np.cross(v1, v0), w1[:, 0] * w0 - v1 @ q0[:3]])


def write_full6_session(path: str | Path, program: LoadProgram, geometry: CraneGeometry, *, seed: int = 0,
                        load_cell_rate_hz: float = 1000.0, pose_rate_hz: float = 250.0,
                        publish_rate_hz: float = 100.0, wrench_noise: ArrayLike = LOAD_CELL_NOISE,
                        wrench_bias: ArrayLike = LOAD_CELL_BIAS, pose_noise: ArrayLike = POSE_NOISE,
                        mount: SensorMount | None = None, estimator6: dict[str, Any] | None = None,
                        pre_s: float = 0.5, post_s: float = 0.5, t0_ns: int = T0_NS,
                        notes: str = 'synthetic six-axis session', recorded_geometry: CraneGeometry | None = None,
                        full_scale: ArrayLike | None = None) -> Full6BagSession:
    """Write a synthetic six-axis session bag (module docstring) at ``path`` (a new directory); returns its truth.

    Args:
        program: the multi-axis load program played (e.g. config/program_full6.yaml).
        geometry: the crane; the pose deflects by its exact tangent compliance at its rest pose.
        seed: of the sensor noise and the delivery jitter.
        wrench_noise / wrench_bias: the load cell's white noise per sample and bias (6,) [N, N·m], sensor frame.
        pose_noise: the pose sensor's white noise per sample (6,) [m, rad].
        mount: the load cell's mounting (default at the platform centre, aligned); recorded as the
            stiffness_estimator's sensor_rotation (quaternion), sensor_position, sensor_reaction.
        estimator6: parameters recorded as the stiffness6_estimator node's (None: none recorded).
        pre_s / post_s: sensor data before the program starts and after it ends [s].
        recorded_geometry: the crane the session records (a campaign's nominal one) when it is not the one that
            deflects (default: ``geometry``).
        full_scale: the load cell's full scale (6,) [N, N·m], its frame: readings clipped there, as the simulated
            load cell does (None: no clipping).
    """
    mount = mount if mount is not None else SensorMount()
    rng = np.random.default_rng(seed)
    rest = rest_pose(geometry)
    tangent = tangent_stiffness(geometry, rest)
    compliance = np.linalg.inv(tangent)
    start_ns, end_ns = t0_ns - int(pre_s * 1e9), t0_ns + int((program.duration_s + post_s) * 1e9)
    cmd_t, cmd_wrench = program.sample()
    cmd_stamp = t0_ns + np.round(cmd_t * 1e9).astype(np.int64)
    cmd_log = cmd_stamp + 200_000
    # The load cell: the true load seen from the sensor's mounting, bias and noise, in bursts.
    w_stamp = _grid(start_ns, end_ns, load_cell_rate_hz)
    to_sensor = np.linalg.inv(mount.matrix())
    wrench = _in_effect(cmd_stamp, cmd_wrench, w_stamp) @ to_sensor.T + np.asarray(wrench_bias, dtype=float)
    wrench += rng.standard_normal(wrench.shape) * np.asarray(wrench_noise, dtype=float)
    if full_scale is not None:
        limit = np.asarray(full_scale, dtype=float)
        wrench = np.clip(wrench, -limit, limit)
    burst = int(round(1e9 / publish_rate_hz))
    tick = (w_stamp // burst + 1) * burst
    first = np.concatenate([[0], np.flatnonzero(np.diff(tick)) + 1])
    sizes = np.diff(np.concatenate([first, [w_stamp.size]]))
    w_log = tick + np.repeat(rng.integers(50_000, 400_000, first.size), sizes) \
        + 10_000 * (np.arange(w_stamp.size) - np.repeat(first, sizes))
    # The pose sensor: rest pose plus C·w and noise.
    p_stamp = _grid(start_ns, end_ns, pose_rate_hz)
    d = _in_effect(cmd_stamp, cmd_wrench, p_stamp) @ compliance.T
    d += rng.standard_normal(d.shape) * np.asarray(pose_noise, dtype=float)
    pose = np.column_stack([rest.displacement + d[:, :3], _quaternions(d[:, 3:], rest.rotation)])
    p_log = p_stamp + 1_000_000 + rng.integers(0, 500_000, p_stamp.size)
    encoded = [encode_stamped(cmd_stamp, topics.FRAME_BASE, cmd_wrench), encode_stamped(w_stamp, 'load_cell', wrench),
               encode_stamped(p_stamp, topics.FRAME_BASE, pose)]
    stamps, logs = [cmd_stamp, w_stamp, p_stamp], [cmd_log, w_log, p_log]
    # The records: the rig, the program, the sensors' parameters; the nodes' parameters as they ran.
    mount_params = {'sensor_rotation': matrix_to_quaternion(mount.rotation).tolist(),
                    'sensor_position': mount.position.tolist(), 'sensor_reaction': bool(mount.reaction)}
    recorded = recorded_geometry if recorded_geometry is not None else geometry
    meta = session_metadata(rig={'geometry': geometry_to_params(recorded), 'l0': recorded.l0, 'k': recorded.k},
                            program={**program.to_params(), 'duration_s': program.duration_s, 'source': 'synthetic'},
                            start_time_ns=start_ns, notes=notes, session=Path(path).name,
                            sensors={'stiffness_estimator': mount_params})
    records: dict[str, dict[str, Any]] = {SESSION_METADATA: meta}
    if estimator6 is not None:
        records[NODE_PARAMETERS_METADATA] = {'stiffness6_estimator': dict(estimator6)}
    code = np.concatenate([np.full(s.size, i, dtype=np.int8) for i, s in enumerate(stamps)])
    index = np.concatenate([np.arange(s.size) for s in stamps])
    order = np.argsort(np.concatenate(logs), kind='stable')
    all_logs, all_stamps = np.concatenate(logs)[order].tolist(), np.concatenate(stamps)[order].tolist()
    with BagWriter(path, metadata=records) as writer:
        for topic in _TOPICS:
            writer.add_topic(topic, topics.RIG_TOPICS[topic], offered_qos(topic))
        for c, i, log, stamp in zip(code[order].tolist(), index[order].tolist(), all_logs, all_stamps):
            data, size = encoded[c]
            writer.write(_TOPICS[c], data[i * size:(i + 1) * size], log, stamp)
    counts = {topic: int(s.size) for topic, s in zip(_TOPICS, stamps)}
    return Full6BagSession(Path(path), program, geometry, rest, tangent, compliance, mount, counts)


__all__ = ['Full6BagSession', 'LOAD_CELL_NOISE', 'POSE_NOISE', 'write_full6_session']
