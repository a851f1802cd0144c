"""The precision a load program promises before it is run: the predicted 95 % half-width of every entry of C and K
and of K2 (from :meth:`crane_stiffness.full6.design.LoadDesign.predicted_covariance`), and two programs side by side
(the D-optimal against the naive one with the same peaks and test time).

Half-widths are t·stderr (Student's t at ``confidence`` on the program's pure-error degrees of freedom, as the fit's
intervals, crane_stiffness.full6.identify), in the units of the entries: C [m/N, m/(N·m), rad/N, rad/(N·m)],
K [N/m, N/rad, N·m/m, N·m/rad], K2 [N/rad]. A ratio naive / designed above 1 means the designed program's interval
is that many times narrower.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from crane_stiffness.estimation.fit import t_quantile
from crane_stiffness.full6.design import LoadDesign
from crane_stiffness.full6.identify import CONFIDENCE
from crane_stiffness.full6.reference import k2_weights


@dataclass(frozen=True)
class PredictedPrecision:
    """Predicted half-widths of one program: compliance (6, 6), stiffness (6, 6), k2; n pairs and dof behind them,
    and the model's K (6, 6) and K2 the half-widths are relative to."""

    compliance: NDArray[np.float64]
    stiffness: NDArray[np.float64]
    k2: float
    n: int
    dof: int
    model_stiffness: NDArray[np.float64]
    model_k2: float

    @property
    def relative_stiffness(self) -> NDArray[np.float64]:
        """Half-widths of K's diagonal relative to the model's diagonal (6,) [-]."""
        return np.diag(self.stiffness) / np.abs(np.diag(self.model_stiffness))


def predicted_precision(design: LoadDesign, confidence: float = CONFIDENCE) -> PredictedPrecision:
    """The predicted 95 % (``confidence``) half-widths of ``design`` (module docstring)."""
    cov_c = design.predicted_covariance()
    k = np.asarray(np.linalg.inv(design.model_compliance), dtype=np.float64)
    jac = -np.kron(k, k.T)
    cov_k = jac @ cov_c @ jac.T
    n = 2 * design.pairs(design.baseline_s) + design.n_steps * design.pairs(design.hold_s)
    dof = n - design.n_steps - 2
    t = t_quantile(dof, confidence)
    g = k2_weights().ravel()
    return PredictedPrecision(t * np.sqrt(np.diag(cov_c)).reshape(6, 6), t * np.sqrt(np.diag(cov_k)).reshape(6, 6),
                              t * math.sqrt(float(g @ cov_k @ g)), n, dof, k, float(g @ k.ravel()))


@dataclass(frozen=True)
class DesignComparison:
    """Two programs' predicted precision: ratios naive / designed of the half-widths of C (6, 6), K (6, 6) and K2,
    and their geometric means over the 36 entries of C and of K."""

    designed: PredictedPrecision
    naive: PredictedPrecision
    compliance_ratio: NDArray[np.float64]
    stiffness_ratio: NDArray[np.float64]
    k2_ratio: float
    compliance_mean_ratio: float
    stiffness_mean_ratio: float


def compare_designs(designed: LoadDesign, naive: LoadDesign, confidence: float = CONFIDENCE) -> DesignComparison:
    """``designed`` against ``naive`` (module docstring)."""
    a, b = predicted_precision(designed, confidence), predicted_precision(naive, confidence)
    c_ratio, k_ratio = b.compliance / a.compliance, b.stiffness / a.stiffness
    return DesignComparison(a, b, c_ratio, k_ratio, b.k2 / a.k2, float(np.exp(np.mean(np.log(c_ratio)))),
                            float(np.exp(np.mean(np.log(k_ratio)))))


__all__ = ['DesignComparison', 'PredictedPrecision', 'compare_designs', 'predicted_precision']
