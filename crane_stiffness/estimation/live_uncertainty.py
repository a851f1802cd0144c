"""The live estimate's measurement uncertainty: each branch's k with its expanded uncertainty U (GUM, k ≈ 2, 95 %)
beside the fit's statistical interval (the repeatability), and its agreement E_n with the model. Pure, no ROS.

The budget is :func:`crane_stiffness.uncertainty.measurement.measured_stiffness`, the one the offline analysis
states, fed with what the live estimator has:

- **Type A**: the branch window's fit (slope, standard error, n − 2 degrees of freedom), ``source`` 'samples (live
  window)'. The offline analysis prefers the fit of the hold means (honest under drift); live there are no holds yet,
  and the calibrations make nearly all of U (docs/uncertainty.md), so the window's fit stands in for it.
- **Type B**: the load cell's and the LVDT's declared calibrations (their nodes' ``calibration.*``, ``full_scale``
  and ``range_m`` parameters, read over ROS by the node), converted with the spans the window covers (force and
  displacement, max − min) and the commanded cross loads; a missing declaration leaves the result "statistical
  only" for it, named.
- **The model**: the prediction's relative expanded uncertainty U_model / k_model, computed once (the node: GUM
  linear law over the crane's inputs, :func:`crane_stiffness.uncertainty.prediction.predict_stiffness`), times the
  live prediction (the model's tangent along the fitted axis).

It runs when the estimator refreshes its slow outputs (``diagnostics_rate_hz``, with the nonlinearity: each a pass
over the windows), never per sample, its Type B part cached (:class:`LiveBudget`).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from statistics import NormalDist
from typing import Any

import numpy as np

from crane_stiffness.contract.axes import AXES
from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.estimation.fit import t_quantile
from crane_stiffness.uncertainty.agreement import en_number
from crane_stiffness.uncertainty.measurement import SlopeStatistics, measured_stiffness

#: What the Type A of a live budget is.
LIVE_TYPE_A = 'samples (live window)'
#: The normal quantile of a 95 % coverage (ν_eff = ∞), as the budget's coverage factor takes it.
_COVERAGE_95 = NormalDist().inv_cdf(0.975)
#: The likely causes of a measurement far from the model, for the people at the rig.
FAR_CAUSES = ('check the displacement gain and the load cell\'s calibration (gain), the sign of either reading, '
              'the units (m or mm, N or kN), the sensor\'s orientation (sensor_rotation, force_axis) and that '
              'the topics are the right sensors (remapping)')


@dataclass(frozen=True)
class BranchUncertainty:
    """One branch's live k as the GUM states it.

    Attributes:
        value: k [N/m or N·m/rad] (the window's slope).
        U: expanded uncertainty at ``coverage`` (same unit); ``k`` its coverage factor, ``u_c`` the combined standard
            uncertainty, ``nu_eff`` the effective degrees of freedom.
        statistical_only: no calibration component counted (U is the fit's alone); ``calibration`` says what was.
        prediction, U_prediction: the model's value and its U (NaN without them); ``en``: E_n (NaN without them).
    """

    value: float
    U: float
    k: float
    u_c: float
    nu_eff: float
    coverage: float
    statistical_only: bool
    calibration: str
    prediction: float = math.nan
    U_prediction: float = math.nan
    en: float = math.nan
    problem: str = ''

    @property
    def far_from_model(self) -> bool:
        """|E_n| > 1: the measurement and the model disagree beyond both uncertainties."""
        return math.isfinite(self.en) and abs(self.en) > 1.0

    def values(self) -> list[tuple[str, float]]:
        """Named numbers for a status's key/values (NaN where there is none)."""
        return [('U', self.U), ('U_low', self.value - self.U), ('U_high', self.value + self.U),
                ('coverage_factor', self.k), ('u_c', self.u_c), ('nu_eff', self.nu_eff),
                ('prediction_U', self.U_prediction), ('En', self.en)]


def cross_load_ratio(axis: str, low: np.ndarray, high: np.ndarray) -> float:
    """The largest commanded load on the other axes of ``axis``' kind (forces or moments) over the axis' own, from
    the commands' componentwise range (``low``, ``high``, shape (6,)); 0 without commands (the offline form:
    ``analysis.stiffness_uncertainty``, over the session's commands)."""
    if not (np.isfinite(low).all() and np.isfinite(high).all()):
        return 0.0
    peak = np.maximum(np.abs(low), np.abs(high))
    i = AXES.index(axis)
    kind = range(0, 3) if i < 3 else range(3, 6)
    if not peak[i] > 0.0:
        return 0.0
    return float(max(peak[j] for j in kind if j != i) / peak[i])


class LiveBudget:
    """Each branch's k with U and E_n (see the module docstring), the Type B part cached: the full budget
    (:func:`~crane_stiffness.uncertainty.measurement.measured_stiffness`, ~3 ms) runs when what the Type B depends on
    changes (the calibrations, the spans the window covers, the cross load: at a hold, never); otherwise the
    window's new Type A is combined with the cached relative Type B, u_c² = s_k² + (k·r_B)², ν_eff by
    Welch–Satterthwaite from the Type A alone (the Type B components have ν = ∞), k_p = t(⌊ν_eff⌋): the same numbers
    (the budget's sensitivities are ±k, so its relative Type B does not depend on k; ``test_live_uncertainty``
    pins the two together)."""

    def __init__(self) -> None:
        # branch -> (the calibrations, the rest of the key, (statistical_only, its statement, r_B: the relative Type B))
        self._cache: dict[str, tuple[Any, tuple, tuple[bool, str, float]]] = {}

    def clear(self) -> None:
        self._cache.clear()

    def branch(self, branch: str, axis: str, unit: str, stiffness: float, stderr: float, n: int, force_span: float,
               displacement_span: float, *, calibrations: tuple[Mapping[str, Any] | None, Mapping[str, Any] | None],
               cross_load: float = 0.0, prediction: float = math.nan,
               prediction_relative_U: float = math.nan) -> BranchUncertainty | None:
        """``branch``'s k with U and E_n; None when the fit cannot carry a budget (fewer than three pairs, a
        non-finite slope or standard error).

        Args:
            axis, unit: the fitted axis (fx … mz) and its stiffness unit.
            stiffness, stderr, n: the window's fit (N/m or N·m/rad; pairs).
            force_span: the window's force range [N or N·m]; displacement_span: its displacement range as the LVDT
                reads it [m] (an angle times the lever arm).
            calibrations: the load cell's and the LVDT's node parameters (None: not read: every component of that
                sensor left out, named); compared by identity: give a new mapping when they change.
            cross_load: :func:`cross_load_ratio`.
            prediction: the model's stiffness along the axis; prediction_relative_U: its U / value (NaN: unknown).
        """
        if n < 3 or not (math.isfinite(stiffness) and math.isfinite(stderr)) or stiffness == 0.0:
            return None
        key = (axis, unit, force_span, displacement_span, cross_load)
        cached = self._cache.get(branch)
        if cached is not None and cached[0] is calibrations and cached[1] == key:
            statistical_only, text, r_b = cached[2]
            u_c = math.hypot(stderr, stiffness * r_b)
            dof = float(n - 2)
            nu_eff = math.inf if stderr == 0.0 else u_c ** 4 * dof / stderr ** 4
            k = _COVERAGE_95 if math.isinf(nu_eff) else t_quantile(max(1, math.floor(nu_eff)))
            out = BranchUncertainty(stiffness, k * u_c, k, u_c, nu_eff, 0.95, statistical_only, text)
        else:
            try:
                measured = measured_stiffness(SlopeStatistics(stiffness, stderr, float(n - 2), LIVE_TYPE_A), axis,
                                              load_cell=calibrations[0], lvdt=calibrations[1], force_span=force_span,
                                              displacement_span=displacement_span, cross_load_ratio=cross_load,
                                              unit=unit)
            except (CraneStiffnessError, ValueError) as exc:  # a declaration the budget refuses: said, not hidden
                return BranchUncertainty(stiffness, math.nan, math.nan, math.nan, math.nan, 0.95, True,
                                         f'statistical only: the declared calibration was refused ({exc})',
                                         problem=str(exc))
            r = measured.result
            r_b = math.sqrt(sum((row.contribution / r.value) ** 2 for row in r.budget if row.name != 'stiffness_fit'))
            self._cache[branch] = (calibrations, key, (measured.statistical_only, measured.calibration_statement, r_b))
            out = BranchUncertainty(r.value, r.U, r.k, r.u_c, r.nu_eff, r.coverage, measured.statistical_only,
                                    measured.calibration_statement)
        if math.isfinite(prediction) and prediction != 0.0 and math.isfinite(prediction_relative_U) \
                and prediction_relative_U >= 0.0:
            big_u = abs(prediction) * prediction_relative_U
            if out.U > 0.0 or big_u > 0.0:
                en = en_number(out.value, out.U, prediction, big_u, unit=unit).en
                out = replace(out, prediction=prediction, U_prediction=big_u, en=en)
        return out


def statement(b: BranchUncertainty, unit: str) -> str:
    """The status message's part: 'U = 798.8 N/m (k = 1.96, 95 %); E_n = -0.00' and 'statistical only' when no
    calibration is counted."""
    if not math.isfinite(b.U):
        return f'U not stated ({b.calibration})'
    text = f'U = {b.U:.4g} {unit} (k = {b.k:.2f}, {100 * b.coverage:.0f} %)'
    if b.statistical_only:
        text += ', statistical only (no calibration declared by the sensors)'
    if math.isfinite(b.en):
        text += f'; model {b.prediction:.6g} ± {b.U_prediction:.4g} {unit}, E_n = {b.en:+.2f}'
    return text


def far_message(b: BranchUncertainty, unit: str) -> str:
    """The WARN message of a branch whose |E_n| > 1."""
    return (f'far from the model beyond its uncertainty: E_n = {b.en:+.2f} (|E_n| > 1; k = {b.value:.6g} ± '
            f'{b.U:.4g} {unit} against the model\'s {b.prediction:.6g} ± {b.U_prediction:.4g} {unit}): '
            + FAR_CAUSES)


def prediction_relative_uncertainty(geometry_params: Mapping[str, Any], axis: str,
                                    uncertainty_file: str = 'uncertainty_lab.yaml') -> tuple[float, float]:
    """The model's rest stiffness along ``axis`` and its relative expanded uncertainty U / value for E_n, as
    ``analyze`` states it (:func:`~crane_stiffness.uncertainty.prediction.agreement_U`: the GUM's, or its Monte
    Carlo's where that does not validate the GUM interval; ~0.3–1 s, on the node's own thread) over the crane's
    inputs: their values from ``geometry_params`` (the crane_model node's
    ``geometry.*``, i.e. the crane file), their uncertainties from ``uncertainty_file`` (a name in the package's
    config/ or a path; the lab file's entries this crane has, as ``analyze`` takes them). Computed once, not per
    sample. Raises CraneStiffnessError (or ValueError) naming what it could not read."""
    # Imported here: the prediction solves the model (numba's compiled kernels, ~0.4 s of CPU to load in a process
    # that has not yet), which the estimator needs once, not at import (test_node_imports).
    from crane_stiffness.params.files import config_path
    from crane_stiffness.params.geometry import geometry_from_params
    from crane_stiffness.uncertainty.crane_inputs import input_names, load_uncertainty_file
    from crane_stiffness.uncertainty.prediction import agreement_U, predict_stiffness
    geometry = geometry_from_params(dict(geometry_params))
    entries = load_uncertainty_file(config_path(uncertainty_file))
    known = set(input_names(geometry))
    entries = {name: entry for name, entry in entries.items() if name in known}
    result = predict_stiffness(geometry, axis, uncertainty=entries, seed=0)
    return result.value, abs(agreement_U(result)[0] / result.value)


__all__ = ['FAR_CAUSES', 'LIVE_TYPE_A', 'BranchUncertainty', 'LiveBudget', 'cross_load_ratio', 'far_message',
           'prediction_relative_uncertainty', 'statement']
