"""Synthetic 6×6 sessions: the (wrench, pose deflection) pairs a load cell and a pose sensor give over a multi-axis
load program on the simulated rig, from the nonlinear model, with seeded sensor noise. No ROS, no bag: the pairs as
the identification takes them (crane_stiffness.full6.identify).

The rig is quasi-static, as the simulated one: at every instant of a held step the platform rests at the model's
equilibrium under that step's wrench (crane_stiffness.model.solve_batch, from the rest pose under W). Pairs come at
the pose sensor's rate on the grid k/rate of the program's clock, from each step's start plus its settling time to
its end, labelled with the step. Each pair's wrench is the true one plus the load cell's bias and white noise of
the pair (the mean of the load cell's samples in one pose period: crane_stiffness.full6.design.NoiseLevels); each
deflection the true one plus the pose sensor's bias and white noise. Units N, N·m, m, rad; fixed frame, z down.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.full6.deflection import pose_deflection
from crane_stiffness.full6.design import LAB_NOISE, NoiseLevels
from crane_stiffness.full6.program import HeldStep, held_steps
from crane_stiffness.model import CraneGeometry, rest_pose, solve_batch, tangent_stiffness
from crane_stiffness.sim.program import LoadProgram

#: The load cell's bias before a tare (config/sensors.yaml) [N, N·m].
LOAD_CELL_BIAS = (0.05, -0.03, 0.08, 0.001, -0.001, 0.0005)


@dataclass(frozen=True)
class ModelResponses:
    """The truth behind a session: the program's held steps, the model's deflection at each (k, 6) [m, rad], the
    wires slack at each (k, 6) (bool), and the exact tangent K (6, 6) at the rest pose."""

    geometry: CraneGeometry
    steps: list[HeldStep]
    deflection: NDArray[np.float64]
    slack: NDArray[np.bool_]
    tangent: NDArray[np.float64]

    @property
    def wrenches(self) -> NDArray[np.float64]:
        """The steps' wrenches (k, 6) [N, N·m]."""
        return np.array([s.wrench for s in self.steps])


def model_responses(geometry: CraneGeometry, program: LoadProgram, settle_s: float) -> ModelResponses:
    """The nonlinear model's quasi-static response to every held step of ``program`` (after ``settle_s``)."""
    steps = held_steps(program, settle_s)
    rest = rest_pose(geometry)
    eq = solve_batch(geometry, np.array([s.wrench for s in steps]))
    d = pose_deflection(eq.displacement, eq.rotation, rest.displacement, rest.rotation)
    return ModelResponses(geometry, steps, d, eq.slack.copy(), tangent_stiffness(geometry, rest))


@dataclass(frozen=True)
class Full6Session:
    """Measured pairs: wrench (n, 6) [N, N·m], deflection (n, 6) [m, rad], step labels (n,), time_s (n,) [s] from
    the program start; and the truth."""

    wrench: NDArray[np.float64]
    deflection: NDArray[np.float64]
    step: NDArray[np.int64]
    time_s: NDArray[np.float64]
    truth: ModelResponses


def synthetic_pairs(truth: ModelResponses, *, noise: NoiseLevels = LAB_NOISE, seed: int = 0,
                    wrench_bias: ArrayLike = LOAD_CELL_BIAS, pose_bias: ArrayLike = (0.0,) * 6) -> Full6Session:
    """One seeded session over ``truth`` (module docstring): noise per pair from ``noise``, constant biases
    ``wrench_bias`` (6,) [N, N·m] and ``pose_bias`` (6,) [m, rad]."""
    rate = noise.pair_rate_hz
    times, labels = [], []
    for s in truth.steps:
        k = np.arange(np.ceil(s.start_s * rate - 1e-9), np.ceil(s.end_s * rate - 1e-9))
        times.append(k / rate)
        labels.append(np.full(k.size, s.index, dtype=np.int64))
    t = np.concatenate(times)
    step = np.concatenate(labels)
    rng = np.random.default_rng(seed)
    n = t.size
    w = truth.wrenches[step] + np.asarray(wrench_bias, dtype=float) + rng.standard_normal((n, 6)) * noise.wrench_std
    d = truth.deflection[step] + np.asarray(pose_bias, dtype=float) + rng.standard_normal((n, 6)) * noise.pose_std
    return Full6Session(w, d, step, t, truth)





# --- Sessions with imperfect sensors: the six-axis GUM study's fast form (crane_stiffness.uncertainty.matrix) ---

#: The simulated load cell's full scale (config/sensors.yaml) [N, N·m].
LOAD_CELL_FULL_SCALE = (40.0, 40.0, 120.0, 2.0, 2.0, 2.0)
#: Coloured noise of the synthetic GUM sessions, per channel: AR(1) std, its correlation time [s], 1/f std and
#: random-walk drift per sqrt(s), for the wrench [N, N·m] and the deflection [m, rad].
GUM_WRENCH_NOISE: dict[str, Any] = {
    'ar1_std': [0.01] * 3 + [5e-4] * 3, 'ar1_tau_s': 0.1, 'flicker_std': [0.005] * 3 + [2.5e-4] * 3,
    'random_walk': [0.002] * 3 + [1e-4] * 3}
GUM_POSE_NOISE: dict[str, Any] = {
    'ar1_std': [5e-7] * 3 + [5e-6] * 3, 'ar1_tau_s': 0.1, 'flicker_std': [2e-7] * 3 + [2e-6] * 3,
    'random_walk': [2e-8] * 3 + [2e-7] * 3}


def declared_calibrations() -> tuple[dict[str, object], dict[str, object]]:
    """The default declarations of the simulated load cell (with its full scale) and pose sensor, as their nodes'
    parameters (``calibration.*``; crane_stiffness.sim.calibration)."""
    from crane_stiffness.sim.calibration import LOAD_CELL_CALIBRATION_PARAMS, POSE_SENSOR_CALIBRATION_PARAMS
    load_cell: dict[str, object] = {s.name: s.default for s in LOAD_CELL_CALIBRATION_PARAMS}
    load_cell['full_scale'] = list(LOAD_CELL_FULL_SCALE)
    return load_cell, {s.name: s.default for s in POSE_SENSOR_CALIBRATION_PARAMS}


@dataclass(frozen=True)
class SensorErrors:
    """The true calibration errors of one synthetic session: the load cell's sensitivity (6,) and nonlinearity (6,)
    [fractions], misalignment (3,) [rad] and cross-talk (6, 6) [fraction of the receiving axis' full scale per
    full-scale load, 0 on the diagonal]; the pose sensor's frame turned by ``pose_angle`` (3,) [rad]."""

    sensitivity: NDArray[np.float64]
    misalignment: NDArray[np.float64]
    crosstalk: NDArray[np.float64]
    nonlinearity: NDArray[np.float64]
    pose_angle: NDArray[np.float64]

    def read_wrench(self, wrench: NDArray[np.float64]) -> NDArray[np.float64]:
        """The load cell's reading (n, 6) of the true wrench (n, 6), as the declared instrument model says."""
        from crane_stiffness.model.rotation import rotvec_to_matrix
        fs = np.asarray(LOAD_CELL_FULL_SCALE)
        turn = np.kron(np.eye(2), rotvec_to_matrix(self.misalignment).T)
        cross = np.eye(6) + self.crosstalk * fs[:, None] / fs[None, :]
        v = wrench @ (cross @ np.diag(1.0 + self.sensitivity) @ turn).T
        x = v / fs
        return v + self.nonlinearity * fs * (4.0 * x ** 3 - 3.0 * x)

    def read_deflection(self, deflection: NDArray[np.float64]) -> NDArray[np.float64]:
        """The pose sensor's reading (n, 6) of the true deflection (n, 6): its frame turned by ``pose_angle``."""
        from crane_stiffness.model.rotation import rotvec_to_matrix
        return deflection @ np.kron(np.eye(2), rotvec_to_matrix(self.pose_angle)).T


def draw_errors(seed: int, load_cell: dict[str, object] | None = None, pose_sensor: dict[str, object] | None = None
                ) -> SensorErrors:
    """True errors drawn from the declarations (default :func:`declared_calibrations`): each component from its
    stated distribution (crane_stiffness.sim.calibration.Stated.draw), one seeded generator per session."""
    from crane_stiffness.sim.calibration import LOAD_CELL_COMPONENTS, POSE_SENSOR_COMPONENTS, calibration_of
    declared_lc, declared_pose = declared_calibrations()
    lc = calibration_of(load_cell or declared_lc, LOAD_CELL_COMPONENTS)
    pose = calibration_of(pose_sensor or declared_pose, POSE_SENSOR_COMPONENTS)
    rng = np.random.default_rng((seed, 6))
    crosstalk = np.zeros((6, 6))
    stated = lc['crosstalk']
    for i in range(6):  # into axis i from each other axis, each bounded by axis i's stated cross-talk
        row = replace(stated, value=np.full(6, stated.value[i])).draw(rng)
        crosstalk[i] = np.where(np.arange(6) == i, 0.0, row) / 100.0
    return SensorErrors(lc['sensitivity'].draw(rng) / 100.0, lc['misalignment'].draw(rng), crosstalk,
                        lc['nonlinearity'].draw(rng) / 100.0, pose['angle'].draw(rng))


def gum_step_means(truth: ModelResponses, errors: SensorErrors, seed: int, *, noise: NoiseLevels = LAB_NOISE,
                   coloured: bool = True) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One session with imperfect sensors, reduced to its step means: the pairs of :func:`synthetic_pairs`
    (white noise of ``noise``, the load cell's bias) read through ``errors`` and, with ``coloured``, carrying the
    coloured noise and drift of :data:`GUM_WRENCH_NOISE` and :data:`GUM_POSE_NOISE` (crane_stiffness.sim.noise,
    sampled at the pairs' instants); returns the measured wrench (k, 6) [N, N·m] and deflection (k, 6) [m, rad] of
    each step, the mean of its pairs."""
    from crane_stiffness.sim.noise import ColouredNoise
    session = synthetic_pairs(truth, noise=noise, seed=seed, wrench_bias=(0.0,) * 6)
    index = np.searchsorted([s.index for s in truth.steps], session.step)
    counts = np.bincount(index, minlength=len(truth.steps))[:, None]
    # The sensors' errors act on each step's constant true load and pose; the noise is averaged over its pairs.
    noise_w = session.wrench - truth.wrenches[index]
    noise_d = session.deflection - truth.deflection[index]
    if coloured:  # sampled on the whole grid k/rate (evenly spaced: one filter run per channel), then picked
        grid = np.rint(session.time_s * noise.pair_rate_hz).astype(np.int64)
        t = np.arange(int(grid.max()) + 1) / noise.pair_rate_hz
        noise_w = noise_w + ColouredNoise(6, **GUM_WRENCH_NOISE, rng=np.random.default_rng((seed, 7))).sample(t)[grid]
        noise_d = noise_d + ColouredNoise(6, **GUM_POSE_NOISE, rng=np.random.default_rng((seed, 8))).sample(t)[grid]

    def means(x: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.zeros((len(truth.steps), 6))
        np.add.at(out, index, x)
        return out / counts
    w = errors.read_wrench(truth.wrenches) + np.asarray(LOAD_CELL_BIAS) + means(noise_w)
    d = errors.read_deflection(truth.deflection) + means(noise_d)
    return w, d


__all__ = ['GUM_POSE_NOISE', 'GUM_WRENCH_NOISE', 'LOAD_CELL_BIAS', 'LOAD_CELL_FULL_SCALE', 'Full6Session',
           'ModelResponses', 'SensorErrors', 'declared_calibrations', 'draw_errors', 'gum_step_means',
           'model_responses', 'synthetic_pairs']
