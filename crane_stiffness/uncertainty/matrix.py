"""The whole 6×6 stiffness K, its compliance C = K⁻¹ and the coupling K2 with their GUM uncertainty, entry by entry,
and the covariance of the 36 entries (JCGM 102): the statistics of the fit (Type A) and the sensors' declared
calibrations (Type B, crane_stiffness.uncertainty.calibration6). No ROS.

**Model.** d̄_k = C·w̄_k + o for the step means (w̄_k, d̄_k) of the k held steps of a six-axis test (wrench
[fx fy fz mx my mz] N and N·m, deflection [u_x u_y u_z θ_x θ_y θ_z] m and rad, crane_base, z down; C row i a
displacement, column j a load; K = C⁻¹ row i a load, column j a displacement, as crane_stiffness.full6.identify).

**Type A: the fit of the step means**, not of the pairs. The pairs within a step are thousands of samples whose
noise is coloured (vibration, 1/f, mains hum, drift): the pairs' covariance assumes them independent and is too small
under correlated noise, while a step's mean carries its correlated part whole. The k step means are a handful of
nearly independent points (as the one-axis budget's hold means, crane_stiffness.uncertainty.measurement): least
squares of d̄ on [w̄, 1], each step equally weighted (under coloured noise a mean's error hardly shrinks with its
length), gives C and the residual covariance Σ = RᵀR/(k − 7) of a step mean (R the (k, 6) residuals), so
Cov(vec C) = Σ ⊗ (W̃ᵀW̃)⁻¹ over row-major vec C (W̃ the centred step wrenches) with ν = k − 7 degrees of freedom.
The wrench's own noise, averaged over a step, is a part of the residual; its attenuation of C (a share
u²/spread² ≈ 1e-7 of it on the lab program) is negligible. The measured value is this same fit's C (within a
fraction of its standard error of the pairs' fit, crane_stiffness.full6.identify).

**Type B: the declared calibrations through the same fit.** Each draw of the calibration errors corrects the step
means (:meth:`~.calibration6.CalibrationInputs.correct`) and refits them; the change of C is that draw's Type B
part. The fit is linear, so a draw costs one 7×7 solve.

**Two methods.**

- *Monte Carlo, JCGM 102* (:func:`matrix_uncertainty`'s ``monte_carlo``): per trial vec C = Ĉ + a Type A draw
  (multivariate t with ν = k − 7 and scale Cov_A, JCGM 102 6.5.3 for a regression's coefficients) + the Type B
  change of a calibration draw; K = C⁻¹ and K2 per trial. From the trials: the mean and the covariance of vec K and
  of vec C (36 × 36), each entry's standard uncertainty and its probabilistically symmetric 95 % interval.
- *The law of propagation* (JCGM 100 5.1.2, and JCGM 102 6.2 for the vector output): Cov(vec C) = Cov_A + J·diag(u²)·Jᵀ
  with J = ∂vec C/∂x by central differences of the same refit (step 1 % of each u), Cov(vec K) = G·Cov(vec C)·Gᵀ
  with G = −K ⊗ Kᵀ; per entry u_c, its Type A and Type B parts, ν_eff by Welch–Satterthwaite (Type A ν = k − 7,
  Type B ∞), k = t_95(ν_eff) (GUM G.4.1), U = k·u_c and the interval value ± U. This is the interval reported and
  whose coverage the study measures; the statistical-only interval value ± t_95(ν)·u_A beside it.

The misalignment's effect on K's diagonal is second order (a cosine), so the law of propagation sees none of it; the
Monte Carlo does (1e-5 of the entry for 0.5°, far below the sensitivity's): the two agree to their numerical
tolerance on every entry of the lab program (test/uncertainty/test_matrix.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special  # (not scipy.stats: see crane_stiffness.uncertainty.budget)

from crane_stiffness.uncertainty.budget import DEFAULT_COVERAGE, coverage_factor
from crane_stiffness.uncertainty.calibration6 import CalibrationInputs
from crane_stiffness.uncertainty.errors import InputError, UncertaintyError
from crane_stiffness.uncertainty.montecarlo import draw_inputs

#: Parameters per row of the step means' fit: six compliances and an offset.
PARAMETERS = 7
#: Monte Carlo trials by default (a trial corrects the step means, refits and inverts: 10⁴ take ~0.5 s on one
#: core).
TRIALS = 10_000
#: Central-difference step of the law of propagation, as a share of each input's u.
STEP = 0.01
#: K2's four signed entries (crane_stiffness.full6.reference.K2_ENTRIES): +K[fy,θx], +K[mx,uy], −K[fx,θy], −K[my,ux].
_K2 = np.zeros(36)
for _i, _j, _s in ((1, 3, 1.0), (3, 1, 1.0), (0, 4, -1.0), (4, 0, -1.0)):
    _K2[6 * _i + _j] = 0.25 * _s


def k2_gradient() -> NDArray[np.float64]:
    """The weights (36,) over row-major vec K whose product with vec K is K2 (the mean of its four signed entries)."""
    return _K2.copy()


def _refit(w: NDArray[np.float64], d: NDArray[np.float64]) -> NDArray[np.float64]:
    """C (M, 6, 6) of the least-squares fit d = C·w + o of step means w, d (M, k, 6), steps equally weighted."""
    wc = w - w.mean(axis=-2, keepdims=True)
    dc = d - d.mean(axis=-2, keepdims=True)
    normal = np.swapaxes(wc, -1, -2) @ wc
    return np.swapaxes(np.linalg.solve(normal, np.swapaxes(wc, -1, -2) @ dc), -1, -2)


@dataclass(frozen=True)
class EntryUncertainty:
    """A matrix's entries (shape (6, 6), or () for K2) with their uncertainty.

    Attributes:
        value: the estimate; u_c: combined standard uncertainty (law of propagation); u_a, u_b: its statistical
            (Type A, ν = steps − 7) and calibration (Type B) parts; nu_eff: Welch–Satterthwaite; k: coverage factor;
            U: k·u_c; low, high: value ∓ U; statistical_low, statistical_high: value ∓ t_95(ν)·u_a.
        mc_mean, mc_u, mc_low, mc_high: the Monte Carlo's mean, standard deviation and probabilistically symmetric
            interval (JCGM 102; NaN without one).
        coverage: the intervals' coverage probability.
    """

    value: NDArray[np.float64]
    u_c: NDArray[np.float64]
    u_a: NDArray[np.float64]
    u_b: NDArray[np.float64]
    nu_eff: NDArray[np.float64]
    k: NDArray[np.float64]
    U: NDArray[np.float64]
    statistical_low: NDArray[np.float64]
    statistical_high: NDArray[np.float64]
    mc_mean: NDArray[np.float64]
    mc_u: NDArray[np.float64]
    mc_low: NDArray[np.float64]
    mc_high: NDArray[np.float64]
    coverage: float

    @property
    def low(self) -> NDArray[np.float64]:
        return self.value - self.U

    @property
    def high(self) -> NDArray[np.float64]:
        return self.value + self.U

    def covers(self, truth: ArrayLike) -> NDArray[np.bool_]:
        """Which expanded intervals hold ``truth`` (same shape)."""
        t = np.asarray(truth, dtype=float)
        return (self.low <= t) & (t <= self.high)

    def statistical_covers(self, truth: ArrayLike) -> NDArray[np.bool_]:
        """Which statistical-only intervals hold ``truth``."""
        t = np.asarray(truth, dtype=float)
        return (self.statistical_low <= t) & (t <= self.statistical_high)

    def to_dict(self) -> dict[str, Any]:
        """Every field as (nested) lists; ∞ as 'inf' (strict JSON), NaN as None."""
        def out(a: NDArray[np.float64]) -> Any:
            return _json(np.asarray(a, dtype=float))
        return {'value': out(self.value), 'u_c': out(self.u_c), 'u_a': out(self.u_a), 'u_b': out(self.u_b),
                'nu_eff': out(self.nu_eff), 'k': out(self.k), 'U': out(self.U), 'coverage': self.coverage,
                'interval': [out(self.low), out(self.high)],
                'statistical_interval': [out(self.statistical_low), out(self.statistical_high)],
                'monte_carlo': {'mean': out(self.mc_mean), 'u': out(self.mc_u),
                                'interval': [out(self.mc_low), out(self.mc_high)]}}


def _json(a: NDArray[np.float64]) -> Any:
    if a.ndim == 0:
        v = float(a)
        return 'inf' if v == math.inf else None if math.isnan(v) else v
    return [_json(x) for x in a]


@dataclass(frozen=True)
class MatrixUncertainty:
    """K, C and K2 with their uncertainty (module docstring).

    Attributes:
        stiffness, compliance: :class:`EntryUncertainty` (6, 6) each [K: N/m, N/rad, N·m/m, N·m/rad; C: inverse].
        k2: :class:`EntryUncertainty` of K2 [N/rad] (shape ()).
        stiffness_cov, compliance_cov: Cov of row-major vec K and vec C (36, 36), law of propagation.
        stiffness_cov_mc, compliance_cov_mc: the same from the Monte Carlo (JCGM 102); None without one.
        stiffness_cov_a: Cov of vec K from the Type A alone (36, 36).
        steps: step means fitted; dof: k − 7; trials: Monte Carlo trials (0: none).
        calibration: the Type B inputs (what was counted, left out, and notes).
        residual_cov: Σ, the covariance of a step mean's residual (6, 6) [m², m·rad, rad²].
    """

    stiffness: EntryUncertainty
    compliance: EntryUncertainty
    k2: EntryUncertainty
    stiffness_cov: NDArray[np.float64]
    compliance_cov: NDArray[np.float64]
    stiffness_cov_mc: NDArray[np.float64] | None
    compliance_cov_mc: NDArray[np.float64] | None
    stiffness_cov_a: NDArray[np.float64]
    steps: int
    dof: int
    trials: int
    calibration: CalibrationInputs
    residual_cov: NDArray[np.float64]

    @property
    def statistical_only(self) -> bool:
        return self.calibration.statistical_only

    def derived_uncertainty(self, gradient: ArrayLike, of: str = 'stiffness') -> float:
        """u of a quantity z = g(vec K) (or of vec C, ``of='compliance'``) to first order: √(∇gᵀ V ∇g), ∇g (36,)
        at the estimate, V the law of propagation's covariance."""
        g = np.asarray(gradient, dtype=float).reshape(-1)
        if g.shape != (36,):
            raise InputError('gradient', g.tolist(), 'needs one entry per entry of the 6×6 matrix (36)')
        v = self.stiffness_cov if of == 'stiffness' else self.compliance_cov
        return math.sqrt(max(float(g @ v @ g), 0.0))

    def to_dict(self, covariance: bool = True) -> dict[str, Any]:
        out: dict[str, Any] = {
            'method': 'GUM law of propagation per entry (k from nu_eff), JCGM 102 Monte Carlo beside it; Type A: '
                      'the fit of the step means',
            'type_a': {'source': 'step means', 'steps': self.steps, 'dof': self.dof,
                       'residual_cov': self.residual_cov.tolist()},
            'trials': self.trials, 'statistical_only': self.statistical_only,
            'counted': list(self.calibration.counted), 'left_out': list(self.calibration.left_out),
            'calibration': self.calibration.statement, 'notes': list(self.calibration.notes),
            'inputs': [q.to_dict() | {'name': q.name} for q in self.calibration.inputs],
            'stiffness': self.stiffness.to_dict(), 'compliance': self.compliance.to_dict(), 'k2': self.k2.to_dict()}
        if covariance:
            out['covariance'] = {
                'layout': 'row-major vec: index 6 i + j is entry (i, j)',
                'stiffness': self.stiffness_cov.tolist(), 'compliance': self.compliance_cov.tolist(),
                'stiffness_type_a': self.stiffness_cov_a.tolist(),
                'stiffness_monte_carlo': None if self.stiffness_cov_mc is None else self.stiffness_cov_mc.tolist(),
                'compliance_monte_carlo': None if self.compliance_cov_mc is None else
                self.compliance_cov_mc.tolist()}
        return out


def _coverage_factors(nu: NDArray[np.float64], coverage: float) -> NDArray[np.float64]:
    """:func:`~.budget.coverage_factor` of every ν_eff of ``nu`` in one call of the t quantile (ν truncated, at
    least 1; the normal quantile for ν = ∞): the same numbers, without 36 scalar quantiles per matrix (most of the
    live 6×6 estimator's cost of U otherwise)."""
    coverage_factor(1.0, coverage)  # (checks the coverage)
    q = 0.5 * (1.0 + coverage)
    infinite = np.isinf(nu)
    dof = np.where(infinite, 1.0, np.maximum(1.0, np.floor(nu)))
    return np.asarray(np.where(infinite, special.ndtri(q), special.stdtrit(dof, q)), dtype=np.float64)


def _entries(value: NDArray[np.float64], cov_a: NDArray[np.float64], cov_b: NDArray[np.float64], dof: int,
             coverage: float, mc: NDArray[np.float64] | None, shape: tuple[int, ...]) -> EntryUncertainty:
    """Per entry of vec ``value`` (m,) the GUM's numbers from the diagonals of the Type A and B covariances, and
    the Monte Carlo's from its trials (M, m)."""
    u_a = np.sqrt(np.maximum(np.diag(cov_a), 0.0))
    u_b = np.sqrt(np.maximum(np.diag(cov_b), 0.0))
    u_c = np.hypot(u_a, u_b)
    with np.errstate(divide='ignore', invalid='ignore'):
        # ν_eff = ν·(u_c/u_a)⁴ >= ν (the Type B has ν = ∞), written so that it is ν exactly without a Type B:
        # u_c⁴ / (u_a⁴ / ν) may round to just below ν, and k (ν_eff truncated, GUM G.4.1) jump to t(ν − 1)
        nu = np.where(u_a > 0.0, dof * (u_c / u_a) ** 4, math.inf)
    k = _coverage_factors(nu, coverage)
    t = float(special.stdtrit(dof, 0.5 * (1.0 + coverage)))
    if mc is not None:
        order = np.sort(mc, axis=0)
        trials = order.shape[0]
        q = int(coverage * trials + 0.5)
        r = max(1, int(0.5 * (trials - q) + 0.5))
        mc_mean, mc_u = mc.mean(axis=0), mc.std(axis=0, ddof=1)
        mc_low, mc_high = order[r - 1], order[min(r + q, trials) - 1]
    else:
        mc_mean = mc_u = mc_low = mc_high = np.full(value.shape, math.nan)

    def s(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(a, dtype=float).reshape(shape)
    return EntryUncertainty(s(value), s(u_c), s(u_a), s(u_b), s(nu), s(k), s(k * u_c), s(value - t * u_a),
                            s(value + t * u_a), s(mc_mean), s(mc_u), s(mc_low), s(mc_high), coverage)


def step_means_fit(wrench: ArrayLike, deflection: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                    NDArray[np.float64], int]:
    """The Type A fit of step means wrench (k, 6), deflection (k, 6): (C (6, 6), Cov of row-major vec C (36, 36),
    Σ the residual covariance of a step mean (6, 6), ν = k − 7). Raises UncertaintyError when the steps cannot
    determine C with a Type A (fewer than 8 steps, or wrenches that do not span the six axes)."""
    w = np.asarray(wrench, dtype=float)
    d = np.asarray(deflection, dtype=float)
    if w.ndim != 2 or w.shape[1] != 6 or d.shape != w.shape or not (np.all(np.isfinite(w))
                                                                    and np.all(np.isfinite(d))):
        raise InputError('step means', f'shapes {w.shape}, {d.shape}', 'must both be (k, 6) and finite')
    k = w.shape[0]
    dof = k - PARAMETERS
    if dof < 1:
        raise UncertaintyError(f'{k} step means leave no degrees of freedom for the Type A (at least '
                               f'{PARAMETERS + 1} steps needed)')
    wc = w - w.mean(axis=0)
    normal = wc.T @ wc
    if np.linalg.matrix_rank(normal) < 6:
        raise UncertaintyError('the step means\' wrenches do not span the six axes: C is undetermined')
    c = _refit(w[None], d[None])[0]
    residual = (d - d.mean(axis=0)) - wc @ c.T
    sigma = residual.T @ residual / dof
    return c, np.kron(sigma, np.linalg.inv(normal)), sigma, dof


def matrix_uncertainty(wrench: ArrayLike, deflection: ArrayLike, calibration: CalibrationInputs, *,
                       coverage: float = DEFAULT_COVERAGE, trials: int = TRIALS, seed: int | None = 0,
                       step: float = STEP) -> MatrixUncertainty:
    """K, C and K2 with their uncertainty from the step means (module docstring).

    Args:
        wrench, deflection: the k step means (k, 6) each [N, N·m; m, rad], as measured (uncorrected).
        calibration: the declared calibrations (:func:`~.calibration6.six_axis_inputs`).
        coverage: of the intervals.
        trials: Monte Carlo trials (0: the law of propagation alone).
        seed: the Monte Carlo's seed (same seed, same result).
        step: central-difference step as a share of each input's u.
    """
    if not 0.0 < coverage < 1.0:
        raise InputError('coverage', coverage, 'a coverage probability must lie in (0, 1)')
    if trials != 0 and trials < 2:
        raise InputError('trials', trials, 'must be 0 (no Monte Carlo) or >= 2')
    w = np.asarray(wrench, dtype=float)
    d = np.asarray(deflection, dtype=float)
    c, cov_a_c, sigma, dof = step_means_fit(w, d)
    quantities = calibration.inputs
    n = len(quantities)
    if n:
        h = step * calibration.standard_uncertainties()
        points = np.zeros((2 * n, n))
        points[np.arange(n), np.arange(n)] = h
        points[n + np.arange(n), np.arange(n)] = -h
        cw, cd = calibration.correct(points, w, d)
        refit = _refit(cw, cd).reshape(2 * n, 36)
        jac = ((refit[:n] - refit[n:]) / (2.0 * h[:, None])).T  # (36, n): ∂vec C/∂x
        cov_b_c = (jac * (h / step) ** 2) @ jac.T
    else:
        cov_b_c = np.zeros((36, 36))
    k_matrix = np.asarray(np.linalg.inv(c), dtype=np.float64)
    g = -np.kron(k_matrix, k_matrix.T)
    cov_a_k, cov_b_k = g @ cov_a_c @ g.T, g @ cov_b_c @ g.T
    k2g = k2_gradient()
    mc_k: NDArray[np.float64] | None = None
    mc_c: NDArray[np.float64] | None = None
    mc_k2: NDArray[np.float64] | None = None
    cov_k_mc = cov_c_mc = None
    if trials:
        rng = np.random.default_rng(seed)
        chol = np.linalg.cholesky(cov_a_c + 1e-30 * np.eye(36) * max(float(np.abs(cov_a_c).max()), 1e-300))
        z = rng.standard_normal((trials, 36)) @ chol.T
        z *= np.sqrt(dof / rng.chisquare(dof, trials))[:, None]  # multivariate t_ν (JCGM 102 6.5.3)
        vec_c = c.reshape(36) + z
        if n:
            x = draw_inputs(list(quantities), trials, rng).T
            cw, cd = calibration.correct(x, w, d)
            vec_c = vec_c + (_refit(cw, cd).reshape(trials, 36) - _refit(w[None], d[None]).reshape(1, 36))
        mc_c = vec_c
        mc_k = np.asarray(np.linalg.inv(vec_c.reshape(trials, 6, 6)), dtype=np.float64).reshape(trials, 36)
        mc_k2 = (mc_k @ k2g)[:, None]
        cov_k_mc, cov_c_mc = np.cov(mc_k, rowvar=False), np.cov(mc_c, rowvar=False)
    vec_k = k_matrix.reshape(36)
    k2_value = np.array([float(k2g @ vec_k)])
    k2_a = np.array([[float(k2g @ cov_a_k @ k2g)]])
    k2_b = np.array([[float(k2g @ cov_b_k @ k2g)]])
    return MatrixUncertainty(
        stiffness=_entries(vec_k, cov_a_k, cov_b_k, dof, coverage, mc_k, (6, 6)),
        compliance=_entries(c.reshape(36), cov_a_c, cov_b_c, dof, coverage, mc_c, (6, 6)),
        k2=_entries(k2_value, k2_a, k2_b, dof, coverage, mc_k2, ()),
        stiffness_cov=cov_a_k + cov_b_k, compliance_cov=cov_a_c + cov_b_c, stiffness_cov_mc=cov_k_mc,
        compliance_cov_mc=cov_c_mc, stiffness_cov_a=cov_a_k, steps=int(w.shape[0]), dof=dof,
        trials=int(trials), calibration=calibration, residual_cov=sigma)


__all__ = ['EntryUncertainty', 'MatrixUncertainty', 'PARAMETERS', 'STEP', 'TRIALS', 'k2_gradient',
           'matrix_uncertainty', 'step_means_fit']
