"""Synthetic test sessions: a bag as session_recorder writes it, from a load program and the crane model (or a
known linear stiffness), for tests and benchmarks. Pure: no ROS import (the writer needs the installed .msg files).

The timeline mimics the rig: the program's commands at its rate (stamped at their instants), load-cell and LVDT
samples on the grid k/sample_rate of one clock (bit-identical stamps, as the simulated sensors make them),
published in bursts at ``publish_rate_hz`` (log time = next burst + jitter), the sensors responding at once to the
command in effect at each sample instant. With ``live=True`` the live estimator's core (LiveStiffness) is run over
the messages in arrival order and its outputs recorded as the stiffness_estimator node publishes them.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from crane_stiffness.contract import topics
from crane_stiffness.bag import BagWriter, dump_qos_profiles, qos_profile
from crane_stiffness.params.geometry import geometry_to_params
from crane_stiffness.contract.axes import AXES
from crane_stiffness.estimation.live import VALUE_FIELDS, LiveStiffness
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.model import CraneGeometry
from crane_stiffness.serde import (encode_float64, encode_float64_multiarray, encode_stamped, encode_string,
                                   stamp_seconds)
from crane_stiffness.bag.session_metadata import CAMPAIGN_KEY, SESSION_METADATA, session_metadata
from crane_stiffness.sim.program import LoadProgram

T0_NS = 1_700_000_000_000_000_000


def offered_qos(topic: str) -> str:
    """The offered QoS of the rig's publishers of ``topic`` as a bag stores it (topics.TOPIC_QOS, rosbag2's YAML)."""
    qos = topics.TOPIC_QOS[topic]
    return dump_qos_profiles([qos_profile(reliability=qos.reliability, durability=qos.durability, depth=qos.depth)])


@dataclass
class SyntheticSession:
    """What was written, and the truth behind it."""

    path: Path
    program: LoadProgram
    axis: str
    geometry: CraneGeometry | None
    stiffness: float | None
    """The linear stiffness the displacements were made with (None: the nonlinear model)."""
    program_start_ns: int
    message_count: int
    counts: dict[str, int] = field(default_factory=dict)
    live_values: np.ndarray | None = None
    """The last live estimate written (rows loading, unloading × VALUE_FIELDS)."""


def _seconds(ns: int) -> float:
    """A stamp in ns as seconds, computed as the nodes do (serde.stamp_seconds), bit for bit."""
    return stamp_seconds(*divmod(ns, 1_000_000_000))


def model_displacement(geometry: CraneGeometry, axis: str, loads: np.ndarray, points: int = 401) -> np.ndarray:
    """Displacement along ``axis`` of the nonlinear model under ``loads`` (quasi-static, interpolated)."""
    from crane_stiffness.analysis.sweep import force_displacement
    loads = np.asarray(loads, dtype=float)
    out = np.zeros(loads.shape)
    for sign in (1.0, -1.0):
        sel = loads * sign > 0
        if not sel.any():
            continue
        peak = float(np.abs(loads[sel]).max())
        curves = force_displacement(geometry, axis, sign * peak, points)
        out[sel] = np.interp(np.abs(loads[sel]), np.abs(curves.load), curves.nonlinear)
    return out


def write_synthetic_session(path: str | Path, program: LoadProgram, *, geometry: CraneGeometry | None = None,
                            axis: str | None = None, stiffness: float | None = None, sample_rate_hz: float = 1000.0,
                            publish_rate_hz: float = 100.0, pre_s: float = 0.5, post_s: float = 0.5,
                            force_noise: float = 0.01, displacement_noise: float = 2e-7, seed: int = 0,
                            estimator: dict[str, Any] | None = None, live: bool = False,
                            chunk_size: int = 1024 * 1024, t0_ns: int = T0_NS, notes: str = 'synthetic session',
                            lvdt: dict[str, Any] | None = None, live_tail_s: float | None = None,
                            sensor: Callable[[np.ndarray], np.ndarray] | None = None,
                            displacement_late_s: float = 0.0, recorded_geometry: CraneGeometry | None = None,
                            campaign: dict[str, Any] | None = None,
                            load_cell: dict[str, Any] | None = None) -> SyntheticSession:
    """Write a synthetic session bag (see the module docstring) and return its truth.

    Args:
        path: bag directory to create.
        program: the load program played.
        geometry: the crane (for the model displacements and the recorded rig); required unless ``stiffness``.
        axis: tested axis (default: the program's first non-zero segment axis).
        stiffness: make displacements ``load / stiffness`` instead of the nonlinear model [N/m or N·m/rad].
        sample_rate_hz / publish_rate_hz: sensor sampling and burst rates.
        pre_s / post_s: sensor data before the program starts and after it ends [s].
        force_noise / displacement_noise: white noise of the load cell [N or N·m] and LVDT [m or rad].
        estimator: stiffness_estimator parameters to record (and to run with ``live``).
        live: record /stiffness/estimate_values and /stiffness/stiffness from LiveStiffness (Python speed: keep
            the session short, or use ``live_tail_s``).
        live_tail_s: run the live estimator over the last this many seconds only (an estimator started late).
        lvdt: the lvdt parameters to record (default: measuring along a force axis at the platform centre).
        sensor: maps the platform wrenches (n, 6) at the centre in crane_base to what the F/T sensor reports in
            its own frame (a rotated, off-centre sensor); default: the platform's wrench as is.
        displacement_late_s: the LVDT's stamps are this much later than the instants measured [s] (a driver's
            latency); the log times follow.
        recorded_geometry: the crane the session records (the nominal one of a campaign) when it is not the one
            the displacements are made with (``geometry``, the true crane).
        campaign: a campaign entry to record (crane_stiffness.bag.session_metadata.CAMPAIGN_KEY).
        load_cell: the load_cell parameters to record (e.g. its full_scale and declared calibration.*); none by
            default.
    """
    if geometry is None and stiffness is None:
        raise ValueError('give a geometry (nonlinear model) or a stiffness (linear truth)')
    if not axis:  # (not `axis or next(...)`: mypy would type that as str | None)
        axis = next((s.axis for s in program.segments if s.target != 0.0), program.segments[0].axis)
    i_axis = AXES.index(axis)
    rng = np.random.default_rng(seed)
    period = int(round(1e9 / sample_rate_hz))
    burst = int(round(1e9 / publish_rate_hz))
    start_ns = t0_ns - int(pre_s * 1e9)
    end_ns = t0_ns + int((program.duration_s + post_s) * 1e9)
    # Commands at the program rate, stamped at their instants.
    cmd_t, cmd_wrench = program.sample()
    cmd_stamp = t0_ns + np.round(cmd_t * 1e9).astype(np.int64)
    cmd_log = cmd_stamp + 200_000
    # Sensor samples on one grid; the command in effect at each instant (zero before the first).
    stamps = np.arange(-(-start_ns // period), end_ns // period + 1, dtype=np.int64) * period
    k = np.searchsorted(cmd_stamp, stamps, side='right') - 1
    wrench = np.where((k >= 0)[:, None], cmd_wrench[np.maximum(k, 0)], 0.0)
    load = wrench[:, i_axis]
    if stiffness is not None:
        true_disp = load / stiffness
    else:
        assert geometry is not None  # checked above: without a stiffness, a geometry is given
        true_disp = model_displacement(geometry, axis, load)
    noise = np.array([force_noise] * 3 + [force_noise * 0.05] * 3)
    force = wrench + rng.normal(size=wrench.shape) * noise
    if sensor is not None:
        force = np.asarray(sensor(force), dtype=float)
    disp = true_disp + rng.normal(size=stamps.size) * displacement_noise
    # Each burst leaves at the next publish tick plus a jitter; its samples follow in order, 10 µs apart.
    tick = (stamps // burst + 1) * burst
    first = np.concatenate([[0], np.flatnonzero(np.diff(tick)) + 1])
    sizes = np.diff(np.concatenate([first, [stamps.size]]))
    position = np.arange(stamps.size) - np.repeat(first, sizes)
    f_log = tick + np.repeat(rng.integers(50_000, 400_000, first.size), sizes) + 10_000 * position
    d_log = tick + np.repeat(rng.integers(50_000, 400_000, first.size), sizes) + 10_000 * position
    f_bytes, f_size = encode_stamped(stamps, 'load_cell', force)
    late_ns = int(round(displacement_late_s * 1e9))
    d_stamps = stamps + late_ns
    d_log = d_log + late_ns
    d_bytes, d_size = encode_stamped(d_stamps, 'lvdt', np.column_stack([disp, np.zeros((stamps.size, 2))]))
    c_bytes, c_size = encode_stamped(cmd_stamp, 'crane_base', cmd_wrench)
    settings = LiveSettings.from_params({**(estimator or {}), 'force_axis': axis})
    est_params = {**(estimator or {}), 'force_axis': axis}
    if lvdt is None and i_axis < 3:
        unit = [0.0, 0.0, 0.0]
        unit[i_axis] = 1.0
        lvdt = {'axis': unit, 'contact_point': [0.0, 0.0, 0.0]}
    # Everything else, as (log, topic, bytes).
    others: list[tuple[int, str, bytes]] = [
        (int(t0_ns - 1_000_000), topics.PROGRAM_STATE, encode_string(json.dumps(
            {'program': program.name, 'state': 'running', 'time_s': 0.0, 'duration_s': program.duration_s}))),
        (int(cmd_log[-1] + 100_000), topics.PROGRAM_STATE, encode_string(json.dumps(
            {'program': program.name, 'state': 'done', 'time_s': program.duration_s,
             'duration_s': program.duration_s}))),
    ]
    prediction = stiffness
    if geometry is not None:
        from crane_stiffness.model import axis_stiffness, rest_pose, tangent_stiffness
        prediction = axis_stiffness(tangent_stiffness(geometry, rest_pose(geometry)), axis)
    assert prediction is not None  # checked above: a geometry or a stiffness is given
    others.append((int(start_ns), topics.PREDICTED_AXIS_STIFFNESS, encode_float64(prediction)))
    last_values = None
    if live:
        core = LiveStiffness(settings)
        core.set_prediction(prediction)
        n = len(VALUE_FIELDS)
        dims = [('branch', 2, 2 * n), ('field', n, n)]
        events = np.concatenate([cmd_log, f_log, d_log])
        kinds = np.concatenate([np.zeros(cmd_log.size, int), np.ones(stamps.size, int), np.full(stamps.size, 2)])
        index = np.concatenate([np.arange(cmd_log.size), np.arange(stamps.size), np.arange(stamps.size)])
        order = np.lexsort((kinds, events))
        if live_tail_s is not None:
            order = order[events[order] >= end_ns - int(live_tail_s * 1e9)]
        for j in order.tolist():
            kind, i, log = kinds[j], index[j], int(events[j])
            if kind == 0:
                core.add_command(_seconds(int(cmd_stamp[i])), cmd_wrench[i], log * 1e-9)
                continue
            stamp_s = _seconds(int(stamps[i]))
            fitted = core.add_force(stamp_s, force[i]) if kind == 1 else \
                core.add_displacement(_seconds(int(d_stamps[i])), disp[i])
            if fitted:
                values = core.values()
                last_values = np.asarray(values).reshape(2, n)
                others.append((log + 30_000, topics.STIFFNESS_VALUES, encode_float64_multiarray(values, dims)))
                k_loading = core.loading_stiffness()
                if k_loading == k_loading:
                    others.append((log + 40_000, topics.STIFFNESS, encode_float64(k_loading)))
    rig = None
    described = recorded_geometry if recorded_geometry is not None else geometry
    if described is not None:
        rig = {'geometry': geometry_to_params(described), 'l0': described.l0, 'k': described.k}
    sensors: dict[str, Any] = {'stiffness_estimator': est_params}
    if lvdt is not None:
        sensors['lvdt'] = lvdt
    if load_cell is not None:
        sensors['load_cell'] = load_cell
    extra: dict[str, Any] = {CAMPAIGN_KEY: campaign} if campaign else {}
    meta = session_metadata(rig=rig, program={**program.to_params(), 'duration_s': program.duration_s,
                                              'source': 'synthetic'},
                            start_time_ns=start_ns, notes=notes, session=Path(path).name, sensors=sensors,
                            **extra)
    # Merge everything in log-time order and write.
    codes = {topics.LOAD_CELL_WRENCH: 0, topics.LVDT_DISPLACEMENT: 1, topics.WRENCH_COMMAND: 2}
    other_log = np.array([o[0] for o in others], dtype=np.int64)
    logs = np.concatenate([f_log, d_log, cmd_log, other_log])
    code = np.concatenate([np.zeros(stamps.size, np.int8), np.ones(stamps.size, np.int8),
                           np.full(cmd_log.size, 2, np.int8), np.full(other_log.size, 3, np.int8)])
    idx = np.concatenate([np.arange(stamps.size), np.arange(stamps.size), np.arange(cmd_log.size),
                          np.arange(other_log.size)])
    order = np.argsort(logs, kind='stable')
    counts: dict[str, int] = {}
    with BagWriter(path, chunk_size=chunk_size, metadata={SESSION_METADATA: meta}) as writer:
        recorded = [topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT, topics.WRENCH_COMMAND, topics.PROGRAM_STATE,
                    topics.PREDICTED_AXIS_STIFFNESS] + ([topics.STIFFNESS_VALUES, topics.STIFFNESS] if live else [])
        for topic in recorded:
            writer.add_topic(topic, topics.RIG_TOPICS[topic], offered_qos(topic))
        write = writer.write
        f_stamp = stamps.tolist()
        c_stamp = cmd_stamp.tolist()
        for c, i, log in zip(code[order].tolist(), idx[order].tolist(), logs[order].tolist()):
            if c == 0:
                write(topics.LOAD_CELL_WRENCH, f_bytes[i * f_size:(i + 1) * f_size], log, f_stamp[i])
            elif c == 1:
                write(topics.LVDT_DISPLACEMENT, d_bytes[i * d_size:(i + 1) * d_size], log, f_stamp[i] + late_ns)
            elif c == 2:
                write(topics.WRENCH_COMMAND, c_bytes[i * c_size:(i + 1) * c_size], log, c_stamp[i])
            else:
                write(others[i][1], others[i][2], log)
        total = writer.message_count
    counts = {topic: int(stamps.size if c < 2 else cmd_log.size) for topic, c in codes.items()}
    for _, topic, _ in others:
        counts[topic] = counts.get(topic, 0) + 1
    return SyntheticSession(path=Path(path), program=program, axis=axis, geometry=geometry, stiffness=stiffness,
                            program_start_ns=t0_ns, message_count=total, counts=counts, live_values=last_values)
