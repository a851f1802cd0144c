"""The 6×6 identification: the compliance C and the stiffness K = C⁻¹ from (wrench, pose deflection) pairs, with
errors in both variables, a 95 % interval for every entry, and a status.

**Model.** d = C·w + offset, with w (6,) the measured wrench [fx, fy, fz, mx, my, mz] (N, N·m), d (6,) the measured
deflection [u_x, u_y, u_z, θ_x, θ_y, θ_z] (m, rad; crane_stiffness.full6.deflection), fixed frame, z down; C (6, 6)
[m/N, m/(N·m), rad/N, rad/(N·m)], row i the displacement i, column j the load j; K = C⁻¹ as in
crane_stiffness.model.stiffness. The offset (6,) absorbs a tare error of the load cell and the pose zero. C is fitted
without imposing symmetry, so its asymmetry is left as a check of reciprocity. Pairs carry the label of their load
step (crane_stiffness.full6.statistics).

**Method: the multivariate method-of-moments estimator with known measurement-error covariance** (Fuller,
*Measurement Error Models*, 1987, §2.2 and §4.1; the six-axis form of crane_stiffness.estimation.fit's line). Both
sensors are noisy: the wrench by u (covariance Σ_uu per pair), the deflection by e_d. Ordinary least squares of d on
w would attenuate C by the share of the wrench's scatter that is noise; the estimator removes it::

    C = (S_dw − (n − 1)·Σ_eu) · M⁻¹,    M = S_ww − (n − 1)·Σ_uu,    offset = d̄ − C·w̄,

with the centred scatter S of the n pairs. Σ_uu (and the noise cross-covariance Σ_ue) is the pure error: the scatter
of the pairs within their steps, where the true load is constant, over n − k degrees of freedom (k steps); or given
(``wrench_noise``: the load cell's specification, Σ_ue = 0), which is the right choice when the load itself wanders
within a step (an actuator hunting), since that moves the pose too and is not measurement noise. The residual
v = d − C·w − offset has, per pair, the pure-error covariance Σ_v = [−C I]·S_within·[−C I]ᵀ / (n − k).

**Intervals: delta method.** Row j of C is the coefficient vector β_j of a regression of d_j on w; Fuller's
theorem 2.2.1, for several responses::

    Cov(β_j, β_k) = Σ_v[j,k]·M⁻¹ + (n − 1)·M⁻¹·(Σ_uu·Σ_v[j,k] + σ_k·σ_jᵀ)·M⁻¹,    σ_j = Σ_ue[:, j] − Σ_uu·β_j,

(36 × 36 over row-major vec C). K's covariance follows from dK = −K·dC·K: Cov(vec K) = J·Cov(vec C)·Jᵀ with
J = −K ⊗ Kᵀ. Both are multiplied by the lack-of-fit ratio below when it exceeds 1 (a Birge ratio: the scatter of
the step means, not the sensors' noise alone, then sets the precision). Every entry's interval is its estimate
± t·stderr with Student's t at ``confidence`` (0.95) on n − k degrees of freedom. K2 (crane_stiffness.full6.reference)
is the mean of its four signed entries, with its interval from the same covariance.

**Status** (levels of crane_stiffness.contract.status):

- WAITING: no pairs yet.
- ERROR, *undetermined* — the pairs cannot determine C: fewer than :data:`MIN_STEPS` distinct steps (six compliances
  and an offset per row need seven, the lack-of-fit test one more); no pure error (one pair a step, or deflections
  that do not scatter within their steps: noise-free or averaged data); the
  load on an axis that does not spread beyond its noise (M_jj < MIN_RELIABILITY·S_jj, the line fit's rule); or the
  condition number of the wrench design above :data:`MAX_CONDITION`: the ratio of the largest to the smallest
  eigenvalue of M scaled to unit diagonal (M_ij / sqrt(M_ii·M_jj), unit-free, 1 for an orthogonal design; 100 means
  a combination of loads the design hardly varies, whose compliance is known only a tenth as well as the design's
  spread per axis promises). The numbers are still given where M can be inverted.
- WARN, *nonlinear* — the window is not linear: the lack-of-fit statistic T = Σ_k n_k·r̄_kᵀ·Σ_v⁻¹·r̄_k (r̄_k the mean
  residual of step k) against χ² with 6·(k − 7) degrees of freedom has p < :data:`LACK_OF_FIT_P`. A wire that goes
  slack on a step, a load past the linear range, a drifting sensor show here. The ratio T / (6·(k − 7)) is reported
  (about 1 for a linear window).
- OK otherwise.

:func:`identify` fits arrays at once; :class:`ComplianceEstimator` adds the pairs one at a time, as a live estimator
does; both go through :func:`fit_compliance` on the same sufficient statistics, and the tests pin them together.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

from crane_stiffness.contract.axes import AXES
from crane_stiffness.estimation.fit import MIN_RELIABILITY, t_quantile
from crane_stiffness.full6.errors import Full6InputError
from crane_stiffness.full6.reference import k2_weights
from crane_stiffness.full6.statistics import PairAccumulator, PairStatistics, pair_statistics
from crane_stiffness.contract.status import ERROR, NAMES, OK, WAITING, WAITING_PREFIX, WARN

#: Fewest distinct load steps that determine C: seven parameters per row, plus one for the lack-of-fit test.
MIN_STEPS = 8
#: Largest condition number of the unit-diagonal wrench scatter that determines C.
MAX_CONDITION = 100.0
#: A window whose lack-of-fit test has a smaller p-value is non-linear.
LACK_OF_FIT_P = 1e-3
CONFIDENCE = 0.95
# Residual variance per pair below this share of the deflection's variance over the test is rounding, not noise.
_NOISE_FLOOR = 1e-20


@dataclass(frozen=True)
class ComplianceFit:
    """The result of the 6×6 identification (module docstring for the method and the status).

    Attributes:
        compliance: C (6, 6) [m/N, m/(N·m), rad/N, rad/(N·m)]; stiffness: K = C⁻¹ (6, 6) [N/m, N/rad, N·m/rad].
        offset: d − C·w at zero load (6,) [m, rad].
        compliance_cov, stiffness_cov: covariances of row-major vec C and vec K (36, 36), inflation included.
        compliance_stderr, stiffness_stderr: standard errors (6, 6).
        compliance_low, compliance_high, stiffness_low, stiffness_high: the intervals' ends (6, 6).
        k2, k2_stderr, k2_low, k2_high: the side–tilt coupling K2 [N/rad] and its interval.
        n: pairs; n_steps: distinct steps; dof: n − n_steps, the pure error's degrees of freedom.
        condition: condition number of the unit-diagonal wrench scatter (inf when singular).
        lack_of_fit: T / (6·(k − 7)); lack_of_fit_dof: 6·(k − 7); lack_of_fit_p: its p-value.
        inflation: max(1, lack_of_fit), the factor applied to the covariances.
        residual_cov: Σ_v (6, 6), the residual's pure-error covariance per pair [m², m·rad, rad²].
        wrench_noise: Σ_uu (6, 6) used [N², N²·m, N²·m²].
        confidence: of the intervals.
        level: status level (crane_stiffness.contract.status); message: one line for people.
    """

    compliance: NDArray[np.float64]
    stiffness: NDArray[np.float64]
    offset: NDArray[np.float64]
    compliance_cov: NDArray[np.float64]
    stiffness_cov: NDArray[np.float64]
    compliance_stderr: NDArray[np.float64]
    stiffness_stderr: NDArray[np.float64]
    compliance_low: NDArray[np.float64]
    compliance_high: NDArray[np.float64]
    stiffness_low: NDArray[np.float64]
    stiffness_high: NDArray[np.float64]
    k2: float
    k2_stderr: float
    k2_low: float
    k2_high: float
    n: int
    n_steps: int
    dof: int
    condition: float
    lack_of_fit: float
    lack_of_fit_dof: int
    lack_of_fit_p: float
    inflation: float
    residual_cov: NDArray[np.float64]
    wrench_noise: NDArray[np.float64]
    confidence: float
    level: int
    message: str

    @property
    def ok(self) -> bool:
        return self.level == OK

    def covers_compliance(self, compliance: ArrayLike) -> NDArray[np.bool_]:
        """Which intervals of C (6, 6) hold the entries of ``compliance`` (6, 6)."""
        c = np.asarray(compliance, dtype=float)
        return (self.compliance_low <= c) & (c <= self.compliance_high)

    def covers_stiffness(self, stiffness: ArrayLike) -> NDArray[np.bool_]:
        """Which intervals of K (6, 6) hold the entries of ``stiffness`` (6, 6)."""
        k = np.asarray(stiffness, dtype=float)
        return (self.stiffness_low <= k) & (k <= self.stiffness_high)


def _wrench_noise(value: ArrayLike | None) -> NDArray[np.float64] | None:
    if value is None:
        return None
    a = np.asarray(value, dtype=float)
    if a.shape == (6,) and np.all(np.isfinite(a) & (a >= 0.0)):
        return np.diag(a * a)
    if a.shape == (6, 6) and np.all(np.isfinite(a)) and np.allclose(a, a.T) \
            and np.all(np.linalg.eigvalsh(a) >= -1e-12 * max(1e-300, float(np.abs(a).max()))):
        return a
    raise Full6InputError('wrench_noise', a.tolist(), 'must be None (estimated from the steps), six standard '
                          'deviations >= 0 [N, N·m] or a symmetric positive semi-definite 6×6 covariance')


def _undetermined(stats: PairStatistics, m: NDArray[np.float64] | None, s_ww: NDArray[np.float64]
                  ) -> tuple[str, float]:
    """(reason or '', condition number)."""
    k, n = len(stats.steps), stats.n
    if m is None:
        return f'{k} distinct steps of {n} pairs leave no pure error (every step needs two pairs or more)', math.nan
    diag = np.diag(m)
    spread = np.diag(s_ww)
    low = np.flatnonzero(~(diag >= MIN_RELIABILITY * spread) | ~(spread > 0.0))
    scale = np.sqrt(np.where(diag > 0.0, diag, np.nan))
    eig = np.linalg.eigvalsh(m / np.outer(scale, scale)) if not low.size else np.array([0.0, 1.0])
    condition = float(eig[-1] / eig[0]) if eig[0] > 0.0 else math.inf
    if k < MIN_STEPS:
        return f'{k} distinct steps, at least {MIN_STEPS} needed', condition
    if low.size:
        return f'the load on {AXES[int(low[0])]} does not spread beyond its noise', condition
    if not condition <= MAX_CONDITION:
        return f'the wrench design\'s condition number {condition:.4g} exceeds {MAX_CONDITION:g}', condition
    return '', condition


def _covariance(c: NDArray[np.float64], minv: NDArray[np.float64], sigma_v: NDArray[np.float64],
                s_uu: NDArray[np.float64], s_ue: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """Cov of row-major vec C (36, 36): Fuller's theorem 2.2.1 for six responses (module docstring)."""
    first = minv + (n - 1) * minv @ s_uu @ minv
    g = minv @ (s_ue - s_uu @ c.T)  # column j: M⁻¹·σ_j
    return np.kron(sigma_v, first) + (n - 1) * np.einsum('ak,bj->jakb', g, g).reshape(36, 36)


def _nan_fit(stats: PairStatistics, level: int, message: str, condition: float, noise: NDArray[np.float64],
             confidence: float) -> ComplianceFit:
    nan6, nan36 = np.full((6, 6), np.nan), np.full((36, 36), np.nan)
    return ComplianceFit(nan6, nan6, np.full(6, np.nan), nan36, nan36, nan6, nan6, nan6, nan6, nan6, nan6,
                         math.nan, math.nan, math.nan, math.nan, stats.n, len(stats.steps), stats.n - len(stats.steps),
                         condition, math.nan, 0, math.nan, math.nan, nan6, noise, confidence, level, message)


def fit_compliance(stats: PairStatistics, *, wrench_noise: ArrayLike | None = None,
                   confidence: float = CONFIDENCE) -> ComplianceFit:
    """The :class:`ComplianceFit` of pairs summed in ``stats``.

    Args:
        stats: from :func:`~crane_stiffness.full6.statistics.pair_statistics` or a
            :class:`~crane_stiffness.full6.statistics.PairAccumulator`.
        wrench_noise: None: the wrench noise from the scatter within steps; else per pair six standard deviations
            [N, N·m] or a 6×6 covariance.
        confidence: of the intervals, in (0, 1).
    """
    if not 0.0 < confidence < 1.0:
        raise Full6InputError('confidence', confidence, 'must be in (0, 1)')
    given = _wrench_noise(wrench_noise)
    n, k = stats.n, len(stats.steps)
    dof = n - k
    if n == 0:
        return _nan_fit(stats, WAITING, f'{WAITING_PREFIX}no pairs yet', math.nan,
                        np.full((6, 6), np.nan) if given is None else given, confidence)
    s, within = stats.scatter, stats.within
    pure = within / dof if dof > 0 else None
    if given is not None:
        s_uu, s_ue = given, np.zeros((6, 6))
    elif pure is not None:
        s_uu, s_ue = pure[:6, :6], pure[:6, 6:]
    else:
        s_uu, s_ue = np.full((6, 6), np.nan), np.full((6, 6), np.nan)
    m = s[:6, :6] - (n - 1) * s_uu if pure is not None else None
    reason, condition = _undetermined(stats, m, s[:6, :6])
    if m is None or pure is None or not np.all(np.linalg.eigvalsh(m) > 0.0):
        return _nan_fit(stats, ERROR, f'undetermined: {reason}', condition, s_uu, confidence)
    minv = np.asarray(np.linalg.inv(m), dtype=np.float64)
    c = (s[6:, :6] - (n - 1) * s_ue.T) @ minv
    offset = stats.mean[6:] - c @ stats.mean[:6]
    proj = np.hstack([-c, np.eye(6)])
    sigma_v = proj @ within @ proj.T / dof
    lof_dof = 6 * (k - 7)
    spread = np.diag(stats.between())[6:] / n  # the deflections' variance over the test
    if not (np.all(np.diag(sigma_v) > (_NOISE_FLOOR * spread)) and np.all(np.linalg.eigvalsh(sigma_v) > 0.0)):
        reason = reason or ('the deflections do not scatter within their steps: no noise to weigh the fit and its '
                            'intervals by (pairs of raw sensor samples are needed)')
        lof_dof = 0
    if lof_dof > 0:
        t_stat = float(np.trace(np.linalg.solve(sigma_v, proj @ stats.between() @ proj.T)))
        ratio, p = t_stat / lof_dof, float(special.chdtrc(lof_dof, t_stat))
    else:
        ratio, p = math.nan, math.nan
    inflation = max(1.0, ratio) if math.isfinite(ratio) else 1.0
    cov_c = inflation * _covariance(c, minv, sigma_v, s_uu, s_ue, n)
    stiffness = np.asarray(np.linalg.inv(c), dtype=np.float64)
    jac = -np.kron(stiffness, stiffness.T)
    cov_k = jac @ cov_c @ jac.T
    se_c = np.sqrt(np.diag(cov_c)).reshape(6, 6)
    se_k = np.sqrt(np.diag(cov_k)).reshape(6, 6)
    t = t_quantile(dof, confidence)
    g = k2_weights().ravel()
    k2 = float(g @ stiffness.ravel())
    k2_se = float(math.sqrt(g @ cov_k @ g))
    if reason:
        level, message = ERROR, f'undetermined: {reason}'
    elif p < LACK_OF_FIT_P:
        level, message = WARN, (f'nonlinear: the step means scatter {ratio:.3g} times as much as the sensors\' '
                                f'noise explains (lack of fit over {k} steps, p = {p:.2g} < {LACK_OF_FIT_P:g})')
    else:
        level, message = OK, (f'{NAMES[OK]}: {k} steps, {n} pairs, condition {condition:.3g}, lack of fit '
                              f'{ratio:.3g} (p = {p:.2g})')
    return ComplianceFit(c, stiffness, offset, cov_c, cov_k, se_c, se_k, c - t * se_c, c + t * se_c,
                         stiffness - t * se_k, stiffness + t * se_k, k2, k2_se, k2 - t * k2_se, k2 + t * k2_se,
                         n, k, dof, condition, ratio, lof_dof, p, inflation, sigma_v, s_uu, confidence, level, message)


def identify(wrench: ArrayLike, deflection: ArrayLike, step: ArrayLike, *, wrench_noise: ArrayLike | None = None,
             confidence: float = CONFIDENCE) -> ComplianceFit:
    """The 6×6 identification of pairs given as arrays: wrench (n, 6) [N, N·m], deflection (n, 6) [m, rad], step
    labels (n,) (integers). See :func:`fit_compliance` for the keywords."""
    return fit_compliance(pair_statistics(wrench, deflection, step), wrench_noise=wrench_noise,
                          confidence=confidence)


class ComplianceEstimator:
    """The streaming form: :meth:`add` one pair at a time (as a live estimator receives them), :meth:`fit` at any
    time. The same result as :func:`identify` on the same pairs."""

    def __init__(self, *, wrench_noise: ArrayLike | None = None, confidence: float = CONFIDENCE) -> None:
        self._noise = None if wrench_noise is None else np.asarray(wrench_noise, dtype=float)
        self._confidence = confidence
        self._acc = PairAccumulator()

    @property
    def n(self) -> int:
        """Pairs added."""
        return self._acc.n

    def add(self, wrench: ArrayLike, deflection: ArrayLike, step: int) -> None:
        """Add one pair: wrench (6,) [N, N·m], deflection (6,) [m, rad], its step label."""
        self._acc.add(wrench, deflection, step)

    def reset(self) -> None:
        """Forget every pair."""
        self._acc.reset()

    def statistics(self) -> PairStatistics:
        """The sufficient statistics of the pairs added so far (their step means: what U is computed from live,
        crane_stiffness.full6.live_uncertainty)."""
        return self._acc.statistics()

    def fit(self, stats: PairStatistics | None = None) -> ComplianceFit:
        """The fit of the pairs added so far (``stats``: their :meth:`statistics`, when the caller has them)."""
        return fit_compliance(self._acc.statistics() if stats is None else stats, wrench_noise=self._noise,
                              confidence=self._confidence)


__all__ = ['CONFIDENCE', 'ComplianceEstimator', 'ComplianceFit', 'LACK_OF_FIT_P', 'MAX_CONDITION', 'MIN_STEPS',
           'fit_compliance', 'identify']
