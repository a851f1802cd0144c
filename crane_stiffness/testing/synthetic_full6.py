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

from dataclasses import dataclass

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


__all__ = ['LOAD_CELL_BIAS', 'Full6Session', 'ModelResponses', 'model_responses', 'synthetic_pairs']
