"""The model's whole 6×6 prediction with its uncertainty: the crane's measured inputs through the exact tangent
stiffness K at the rest pose, all 36 entries at once (JCGM 102), its compliance C = K⁻¹ and K2; and E_n of a
measured matrix against it, entry by entry. No ROS.

The one-axis prediction (crane_stiffness.uncertainty.prediction) takes the same inputs (a, b, h, W, the wire,
length offsets, centre-of-mass offset: crane_stiffness.uncertainty.crane_inputs) through the same compiled batch of
rest tangents (crane_stiffness.model.draws.rest_stiffness_draws) and keeps one axis; here every entry is kept:

- **Monte Carlo (JCGM 102)**: ``trials`` cranes drawn from the inputs' distributions, K of each; the mean and the
  covariance of vec K (36, 36, row-major), each entry's standard deviation and probabilistically symmetric 95 %
  interval, and the same for C and K2.
- **The law of propagation** beside it: central differences (2N + 1 cranes) give ∂vec K/∂x and
  Cov(vec K) = J·diag(u²)·Jᵀ.

The value stated is the nominal crane's tangent (what ``crane-stiffness stiffness`` prints); its expanded uncertainty
for E_n is U = 1.96 × the Monte Carlo's standard deviation (ν = ∞: the inputs' uncertainties are Type B, known
exactly): where one rectangular input dominates (E along the diagonal) the distribution is flatter than a normal and
its 95 % interval narrower than ±1.96 u, so this U is the wider one and E_n is not flattered.
E_n = (K_measured − K_model) / √(U_measured² + U_model²) per entry (ISO 13528); |E_n| ≤ 1 agrees.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.model.draws import rest_stiffness_draws
from crane_stiffness.model.equilibrium import rest_pose
from crane_stiffness.model.geometry import CraneGeometry
from crane_stiffness.model.stiffness import tangent_stiffness
from crane_stiffness.uncertainty.budget import DEFAULT_COVERAGE, DEFAULT_STEP, coverage_factor
from crane_stiffness.uncertainty.crane_inputs import crane_inputs
from crane_stiffness.uncertainty.errors import UncertaintyError
from crane_stiffness.uncertainty.inputs import InputQuantity
from crane_stiffness.uncertainty.matrix import k2_gradient
from crane_stiffness.uncertainty.montecarlo import draw_inputs
from crane_stiffness.uncertainty.prediction import draw_fields

#: Cranes drawn by default (~20 µs each on the compiled path).
TRIALS = 5_000


def _tangents(geometry: CraneGeometry, names: Sequence[str], x: NDArray[np.float64]) -> NDArray[np.float64]:
    """K (M, 6, 6) of the cranes whose inputs ``names`` take the values x (N, M)."""
    return rest_stiffness_draws(geometry, **draw_fields(geometry, dict(zip(names, x)), x.shape[1]))


@dataclass(frozen=True)
class MatrixPrediction:
    """The model's K, C and K2 with their uncertainty (module docstring).

    Attributes:
        stiffness, compliance: the nominal crane's tangent K and C = K⁻¹ (6, 6).
        stiffness_u, compliance_u: the Monte Carlo's standard deviation per entry (6, 6).
        stiffness_low, stiffness_high: its probabilistically symmetric interval per entry of K (6, 6).
        stiffness_u_linear: the law of propagation's u per entry of K (6, 6).
        stiffness_cov: Cov of row-major vec K from the Monte Carlo (36, 36); k2, k2_u: K2 [N/rad] and its u.
        k: the coverage factor of U (ν = ∞); trials: cranes drawn; inputs: the input quantities.
    """

    stiffness: NDArray[np.float64]
    compliance: NDArray[np.float64]
    stiffness_u: NDArray[np.float64]
    compliance_u: NDArray[np.float64]
    stiffness_low: NDArray[np.float64]
    stiffness_high: NDArray[np.float64]
    stiffness_u_linear: NDArray[np.float64]
    stiffness_cov: NDArray[np.float64]
    k2: float
    k2_u: float
    k: float
    trials: int
    inputs: tuple[InputQuantity, ...]

    @property
    def stiffness_U(self) -> NDArray[np.float64]:
        """Expanded uncertainty per entry of K, k·u (6, 6)."""
        return self.k * self.stiffness_u

    @property
    def compliance_U(self) -> NDArray[np.float64]:
        return self.k * self.compliance_u

    @property
    def k2_U(self) -> float:
        return self.k * self.k2_u

    def to_dict(self, covariance: bool = False) -> dict[str, Any]:
        out: dict[str, Any] = {
            'method': 'exact tangent at rest of cranes drawn from the inputs (JCGM 102 Monte Carlo); U = k u, '
                      'nu = inf', 'trials': self.trials, 'k': self.k,
            'stiffness': {'value': self.stiffness.tolist(), 'u': self.stiffness_u.tolist(),
                          'U': self.stiffness_U.tolist(), 'u_linear': self.stiffness_u_linear.tolist(),
                          'interval': [self.stiffness_low.tolist(), self.stiffness_high.tolist()]},
            'compliance': {'value': self.compliance.tolist(), 'u': self.compliance_u.tolist(),
                           'U': self.compliance_U.tolist()},
            'k2': {'value': self.k2, 'u': self.k2_u, 'U': self.k2_U},
            'inputs': [q.to_dict() | {'name': q.name} for q in self.inputs]}
        if covariance:
            out['stiffness_covariance'] = self.stiffness_cov.tolist()
        return out


def predict_matrix(geometry: CraneGeometry, *, uncertainty: Mapping[str, Mapping[str, Any]] | None = None,
                   inputs: Sequence[InputQuantity] | None = None, trials: int = TRIALS, seed: int | None = 0,
                   coverage: float = DEFAULT_COVERAGE, step: float = DEFAULT_STEP) -> MatrixPrediction:
    """The model's 6×6 prediction with its uncertainty (module docstring); ``uncertainty`` / ``inputs`` as
    :func:`crane_stiffness.uncertainty.prediction.predict_stiffness` takes them."""
    quantities = list(inputs) if inputs is not None else crane_inputs(geometry, uncertainty)
    names = [q.name for q in quantities]
    n = len(quantities)
    k_nominal = tangent_stiffness(geometry, rest_pose(geometry))
    c_nominal = np.linalg.inv(k_nominal)
    x0 = np.array([q.value for q in quantities])
    h = np.array([step * q.u if q.u > 0.0 else step * 1e-6 * max(abs(q.value), 1.0) for q in quantities])
    points = np.repeat(x0[:, None], 2 * n, axis=1)
    points[np.arange(n), np.arange(n)] += h
    points[np.arange(n), n + np.arange(n)] -= h
    kk = _tangents(geometry, names, points).reshape(2 * n, 36)
    jac = (kk[:n] - kk[n:]) / (2.0 * h[:, None])  # (n, 36)
    u = np.array([q.u for q in quantities])
    u_linear = np.sqrt(((jac * u[:, None]) ** 2).sum(axis=0)).reshape(6, 6)
    rng = np.random.default_rng(seed)
    draws = _tangents(geometry, names, draw_inputs(quantities, trials, rng))
    if not np.all(np.isfinite(draws)):
        raise UncertaintyError('a drawn crane has no finite rest tangent: the inputs reach outside the model')
    vec_k = draws.reshape(trials, 36)
    vec_c = np.linalg.inv(draws).reshape(trials, 36)
    order = np.sort(vec_k, axis=0)
    q = int(coverage * trials + 0.5)
    r = max(1, int(0.5 * (trials - q) + 0.5))
    k2 = vec_k @ k2_gradient()
    return MatrixPrediction(
        k_nominal, c_nominal, vec_k.std(axis=0, ddof=1).reshape(6, 6), vec_c.std(axis=0, ddof=1).reshape(6, 6),
        order[r - 1].reshape(6, 6), order[min(r + q, trials) - 1].reshape(6, 6), u_linear,
        np.cov(vec_k, rowvar=False), float(k_nominal.reshape(36) @ k2_gradient()), float(k2.std(ddof=1)),
        coverage_factor(math.inf, coverage), trials, tuple(quantities))


def en_matrix(measured: ArrayLike, measured_U: ArrayLike, reference: ArrayLike, reference_U: ArrayLike
              ) -> NDArray[np.float64]:
    """E_n per entry: (measured − reference) / √(U_measured² + U_reference²); NaN where both U are 0."""
    m, r = np.asarray(measured, dtype=float), np.asarray(reference, dtype=float)
    scale = np.hypot(np.asarray(measured_U, dtype=float), np.asarray(reference_U, dtype=float))
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(scale > 0.0, (m - r) / scale, math.nan)


__all__ = ['MatrixPrediction', 'TRIALS', 'en_matrix', 'predict_matrix']
