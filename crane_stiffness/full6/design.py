"""Designed multi-axis load programs for the 6×6 identification, and the naive one-axis-at-a-time program they are
compared with.

**What is fitted** (:mod:`crane_stiffness.full6.identify`): pairs of wrench w (6,) [N, N·m] and pose deflection
d (6,) [m, rad] (:mod:`crane_stiffness.full6.deflection`), fixed frame, z down, with d = C·w + offset; each pair's
residual noise is e = e_d − C·e_w with covariance Σ_e = Σ_d + C·Σ_w·Cᵀ (6, 6) (:class:`NoiseLevels`: white wrench
and pose noise per pair). A program holds n wrenches w_k, each for ``hold_s`` seconds of which the last
``hold_s − settle_s`` give m = ⌊pair_rate·(hold_s − settle_s)⌋ pairs, between two zero-load baselines.

**The criterion: D-optimal on the compliance.** The information matrix of the 36 compliance entries (row-major
vec C, the offset eliminated) is ``I = Σ_e⁻¹ ⊗ M`` with the wrench scatter M = Σ_k m_k·(w_k − w̄)(w_k − w̄)ᵀ
(6, 6) over all held steps, baselines included. The design maximises ``log det I = 6·(log det M − log det Σ_e)``:
it minimises the volume of the joint confidence ellipsoid of C. Σ_e, given by the noise levels and the model's
compliance, does not depend on the design, so the optimum does not depend on the noise levels (they set the value
of log det I and the predicted intervals, :meth:`LoadDesign.predicted_stderr`), nor on the units of the axes (the
criterion is invariant under a rescaling of the wrench): it trades the axes against each other through the peak
loads and the slack margins alone.

**The designed program** holds fold-over pairs +v, −v (the response's even-order terms cancel in the fit, so C is
the tangent's to third order in the load), each v inside the admissible set of
:mod:`crane_stiffness.full6.admissible` (every wrench keeps its slack factor >= the safety factor, and
|v_j| <= peak_j). The set is a convex polytope to first order, and the D-optimal design of a first-order model is
supported on its vertices: n/2 vertices are chosen by Fedorov exchange (``starts`` random starts, the best kept),
and its D-efficiency against the best continuous design on the same vertices (multiplicative algorithm, to
1e-6 of the Kiefer–Wolfowitz bound) is reported, 1 at best. Each pair is played as +v then −v (the path between
them passes through zero), with the sign that keeps the transition from the previous pair farthest from slack;
:func:`~crane_stiffness.full6.admissible.check_steps` then checks steps and transitions, and refuses the design if
any breaks the rule.

**The naive program** loads each axis in turn, +peak then −peak, fx … mz, repeated to the same number of steps,
with the same hold, settle and baselines (so the same test time) and the same peak loads.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.full6.admissible import (DEFAULT_SAFETY_FACTOR, SlackFactors, admissible_vertices, check_steps,
                                              slack_factors)
from crane_stiffness.full6.errors import Full6InputError
from crane_stiffness.full6.reference import reference_at_rest
from crane_stiffness.model import CraneGeometry

CRITERIA = ('D-optimal', 'naive')
#: Fewest steps of a designed program: six fold-over pairs, so that the wrenches span the six axes.
MIN_DESIGN_STEPS = 12
# The exchange stops when a sweep improves log det by less than this.
_EXCHANGE_TOL = 1e-10
_MULTIPLICATIVE_ITER = 20000
_MULTIPLICATIVE_TOL = 1e-6


@dataclass(frozen=True)
class NoiseLevels:
    """White noise of one (wrench, pose) pair: standard deviations wrench_std (6,) [N, N·m] and pose_std (6,)
    [m, rad] per axis, pairs at ``pair_rate_hz`` [Hz]."""

    wrench_std: NDArray[np.float64]
    pose_std: NDArray[np.float64]
    pair_rate_hz: float

    @classmethod
    def from_sensors(cls, load_cell_std: ArrayLike, load_cell_rate_hz: float, pose_std: ArrayLike,
                     pose_rate_hz: float) -> 'NoiseLevels':
        """Pairs at the pose sensor's rate, each wrench the mean of the load cell's samples of one pose period:
        its noise the load cell's divided by sqrt(load_cell_rate_hz / pose_rate_hz)."""
        if not (pose_rate_hz > 0.0 and load_cell_rate_hz >= pose_rate_hz):
            raise Full6InputError('pose_rate_hz', pose_rate_hz, 'must be > 0 and at most the load cell rate')
        w = np.asarray(load_cell_std, dtype=float).reshape(6) / math.sqrt(load_cell_rate_hz / pose_rate_hz)
        return cls(w, np.asarray(pose_std, dtype=float).reshape(6), float(pose_rate_hz))

    def residual_covariance(self, compliance: ArrayLike) -> NDArray[np.float64]:
        """Σ_e = Σ_d + C·Σ_w·Cᵀ (6, 6) [m², m·rad, rad²] of one pair's residual d − C·w."""
        c = np.asarray(compliance, dtype=float)
        return np.diag(self.pose_std ** 2) + c @ np.diag(self.wrench_std ** 2) @ c.T


#: The lab's sensors: the load cell of config/sensors.yaml (1 kHz; 0.01 N, 0.0005 N·m) and a pose sensor at 250 Hz
#: with 2 µm and 20 µrad of white noise per axis (a displacement-sensor-grade tracker).
LAB_NOISE = NoiseLevels.from_sensors([0.01, 0.01, 0.01, 5e-4, 5e-4, 5e-4], 1000.0,
                                     [2e-6, 2e-6, 2e-6, 20e-6, 20e-6, 20e-6], 250.0)


@dataclass(frozen=True)
class LoadDesign:
    """A multi-axis load program for the 6×6 identification.

    Attributes:
        criterion: 'D-optimal' or 'naive'.
        steps: the held wrenches (n, 6) [N, N·m] in play order, fixed frame, z down; the program starts and ends
            with a zero-load baseline of ``baseline_s``.
        peaks: the peak load per axis (6,) [N, N·m]: |steps[:, j]| <= peaks[j].
        safety_factor: every step's slack factor is at least this (crane_stiffness.full6.admissible).
        hold_s: time each step is held [s]; settle_s: its first part, left out of the fit [s]; baseline_s: each
            baseline's time [s].
        noise: the pair noise the prediction assumes.
        model_compliance: the model's tangent compliance C at rest (6, 6) the prediction uses.
        slack: the steps' slack factors and first wires.
        efficiency: D-efficiency against the best continuous design on the same candidates (NaN for naive).
    """

    criterion: str
    steps: NDArray[np.float64]
    peaks: NDArray[np.float64]
    safety_factor: float
    hold_s: float
    settle_s: float
    baseline_s: float
    noise: NoiseLevels
    model_compliance: NDArray[np.float64] = field(repr=False)
    slack: SlackFactors = field(repr=False)
    efficiency: float = math.nan

    @property
    def n_steps(self) -> int:
        return int(self.steps.shape[0])

    @property
    def duration_s(self) -> float:
        """The program's length: two baselines and every hold [s]."""
        return 2.0 * self.baseline_s + self.n_steps * self.hold_s

    def pairs(self, seconds: float) -> int:
        """Pairs fitted from a hold of ``seconds`` (its settling time left out)."""
        return int(math.floor(self.noise.pair_rate_hz * (seconds - self.settle_s) + 1e-9))

    def wrench_scatter(self) -> NDArray[np.float64]:
        """M = Σ_k m_k·(w_k − w̄)(w_k − w̄)ᵀ (6, 6) [N², N²·m, N²·m²] over the held steps and both baselines."""
        w = np.vstack([np.zeros((2, 6)), self.steps])
        m = np.array([self.pairs(self.baseline_s)] * 2 + [self.pairs(self.hold_s)] * self.n_steps, dtype=float)
        centred = w - (m @ w) / m.sum()
        return (centred * m[:, None]).T @ centred

    def log_det_information(self) -> float:
        """log det of the information matrix of the 36 compliance entries, 6·(log det M − log det Σ_e), in SI."""
        sign, m = np.linalg.slogdet(self.wrench_scatter())
        _, e = np.linalg.slogdet(self.noise.residual_covariance(self.model_compliance))
        return 6.0 * (m - e) if sign > 0 else -math.inf

    def predicted_covariance(self) -> NDArray[np.float64]:
        """Covariance (36, 36) of row-major vec C predicted for this program: Σ_e ⊗ M⁻¹."""
        return np.kron(self.noise.residual_covariance(self.model_compliance), np.linalg.inv(self.wrench_scatter()))

    def predicted_stderr(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Predicted standard errors (6, 6) of C and of K = C⁻¹ (delta method: dK = −K·dC·K)."""
        cov = self.predicted_covariance()
        k = np.linalg.inv(self.model_compliance)
        jac = -np.kron(k, k.T)
        return (np.sqrt(np.diag(cov)).reshape(6, 6), np.sqrt(np.diag(jac @ cov @ jac.T)).reshape(6, 6))


def _check_timing(n_steps: int, hold_s: float, settle_s: float, baseline_s: float) -> None:
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
        raise Full6InputError('n_steps', n_steps, 'must be an integer >= 1')
    if not (math.isfinite(settle_s) and settle_s >= 0.0):
        raise Full6InputError('settle_s', settle_s, 'must be a finite number >= 0 (s)')
    for name, value in (('hold_s', hold_s), ('baseline_s', baseline_s)):
        if not (math.isfinite(value) and value > settle_s):
            raise Full6InputError(name, value, f'must be a finite number > settle_s = {settle_s:g} s')


def _peaks(peaks: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(peaks, dtype=float).reshape(-1)
    if p.shape != (6,) or not np.all(np.isfinite(p) & (p > 0.0)):
        raise Full6InputError('peaks', np.asarray(peaks).tolist(), 'must be six finite loads > 0 '
                              '[fx, fy, fz N, mx, my, mz N·m]: the program must load all six axes')
    return p


def _exchange(z: NDArray[np.float64], n: int, starts: int, rng: np.random.Generator) -> list[int]:
    """Indices of n rows of z (m, 6) maximising log det Σ z zᵀ: Fedorov exchange from ``starts`` random starts."""
    ridge = 1e-9 * np.eye(6)  # lets a start that does not span the six axes improve
    best: tuple[float, list[int]] = (-math.inf, [])
    for _ in range(starts):
        idx = list(rng.choice(len(z), n, replace=len(z) < n))
        info = z[idx].T @ z[idx]
        last = -math.inf
        for _sweep in range(200):
            for i in range(n):
                rest = info - np.outer(z[idx[i]], z[idx[i]])
                var = np.einsum('ij,jk,ik->i', z, np.linalg.inv(rest + ridge), z)
                j = int(np.argmax(var))
                if var[j] > var[idx[i]] * (1.0 + 1e-12):
                    idx[i] = j
                    info = rest + np.outer(z[j], z[j])
            now = float(np.linalg.slogdet(info + ridge)[1])
            if now - last < _EXCHANGE_TOL:
                break
            last = now
        if now > best[0]:
            best = (now, idx)
    return best[1]


def _continuous_log_det(z: NDArray[np.float64]) -> float:
    """log det of the D-optimal continuous design on the rows of z (m, 6), per unit weight (multiplicative
    algorithm, stopped within _MULTIPLICATIVE_TOL of the equivalence theorem's bound max zᵀM⁻¹z = 6)."""
    w = np.full(len(z), 1.0 / len(z))
    for _ in range(_MULTIPLICATIVE_ITER):
        info = z.T @ (w[:, None] * z)
        var = np.einsum('ij,jk,ik->i', z, np.linalg.inv(info), z)
        if var.max() <= 6.0 * (1.0 + _MULTIPLICATIVE_TOL):
            break
        w *= var / 6.0
    return float(np.linalg.slogdet(z.T @ (w[:, None] * z))[1])


def _play_order(geometry: CraneGeometry, pairs: NDArray[np.float64]) -> NDArray[np.float64]:
    """The steps +v, −v of each pair, each pair's sign chosen so that the transition from the previous pair is the
    farthest from slack (the largest slack factor at its midpoint)."""
    steps = [pairs[0], -pairs[0]]
    for v in pairs[1:]:
        mid = slack_factors(geometry, [(steps[-1] + v) / 2.0, (steps[-1] - v) / 2.0]).factor
        sign = 1.0 if mid[0] >= mid[1] else -1.0
        steps += [sign * v, -sign * v]
    return np.array(steps)


def d_optimal_design(geometry: CraneGeometry, peaks: ArrayLike, *, n_steps: int = 24, hold_s: float = 4.0,
                     settle_s: float = 0.5, baseline_s: float = 2.0,
                     safety_factor: float = DEFAULT_SAFETY_FACTOR, noise: NoiseLevels = LAB_NOISE,
                     starts: int = 20, seed: int = 0) -> LoadDesign:
    """The D-optimal fold-over program (module docstring) of ``n_steps`` (even, >= MIN_DESIGN_STEPS) held wrenches
    within ``peaks`` (6,) [N, N·m] and the slack rule, for ``geometry`` at its rest pose. Deterministic for a seed.

    Raises:
        Full6InputError: a bad argument, named.
        SlackDesignError: the design breaks the slack rule (a transition between pairs, on a crane whose tensions
            are far from affine in the load).
    """
    _check_timing(n_steps, hold_s, settle_s, baseline_s)
    if n_steps % 2 or n_steps < MIN_DESIGN_STEPS:
        raise Full6InputError('n_steps', n_steps, f'must be even and >= {MIN_DESIGN_STEPS} (fold-over pairs +v, '
                              '−v, at least six to span the six axes)')
    p = _peaks(peaks)
    ref = reference_at_rest(geometry)
    vertices = admissible_vertices(geometry, p, safety_factor, equilibrium=ref.equilibrium)
    z = vertices / p
    chosen = _exchange(z, n_steps // 2, starts, np.random.default_rng(seed))
    exact = float(np.linalg.slogdet(z[chosen].T @ z[chosen])[1])
    efficiency = math.exp((exact - 6.0 * math.log(n_steps // 2) - _continuous_log_det(z)) / 6.0)
    steps = _play_order(geometry, vertices[chosen])
    slack = check_steps(geometry, steps, safety_factor, equilibrium=ref.equilibrium)
    return LoadDesign('D-optimal', steps, p, float(safety_factor), float(hold_s), float(settle_s), float(baseline_s),
                      noise, ref.compliance, slack, efficiency)


def naive_design(geometry: CraneGeometry, peaks: ArrayLike, *, n_steps: int = 24, hold_s: float = 4.0,
                 settle_s: float = 0.5, baseline_s: float = 2.0, safety_factor: float = DEFAULT_SAFETY_FACTOR,
                 noise: NoiseLevels = LAB_NOISE) -> LoadDesign:
    """Each axis in turn, +peak then −peak, fx … mz, repeated to ``n_steps`` (a multiple of 12) held wrenches.

    Raises:
        SlackDesignError: a peak load alone breaks the slack rule (naming the step, direction and wire); the
            largest admissible peaks are :func:`crane_stiffness.full6.admissible.axis_peaks`.
    """
    _check_timing(n_steps, hold_s, settle_s, baseline_s)
    if n_steps % 12:
        raise Full6InputError('n_steps', n_steps, 'must be a multiple of 12 (each of six axes + and −)')
    p = _peaks(peaks)
    ref = reference_at_rest(geometry)
    one = np.vstack([np.diag(p), -np.diag(p)]).reshape(2, 6, 6).transpose(1, 0, 2).reshape(12, 6)
    steps = np.tile(one, (n_steps // 12, 1))
    slack = check_steps(geometry, steps, safety_factor, equilibrium=ref.equilibrium)
    return LoadDesign('naive', steps, p, float(safety_factor), float(hold_s), float(settle_s), float(baseline_s),
                      noise, ref.compliance, slack)


__all__ = ['CRITERIA', 'LAB_NOISE', 'LoadDesign', 'MIN_DESIGN_STEPS', 'NoiseLevels', 'd_optimal_design',
           'naive_design']
