"""Each branch's measured stiffness with its GUM uncertainty and its agreement with the model (E_n), for the offline
analysis of a session. Pure: no ROS import.

The measured k of a branch is the fit of its hold means when there is one (its Type A: n_holds − 2 degrees of
freedom, honest under coloured noise and drift), else the fit of its samples; the calibrations are those the load
cell and LVDT nodes declared and the recorder stored (:mod:`crane_stiffness.uncertainty.measurement`). The model's
prediction for the recorded geometry along the axis carries the uncertainty of the crane's inputs (default
``config/uncertainty_lab.yaml``) by the GUM's law of propagation alone: its Monte Carlo (~0.5 s) would add about 10 %
to an hour's analysis, and for this model the linear interval is the wider one (docs/uncertainty.md), so E_n is not
flattered by it.
"""
from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from crane_stiffness.analysis.load import SessionData
from crane_stiffness.analysis.results import ModelSummary, Step
from crane_stiffness.contract.axes import AXES
from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.estimation.branch import BRANCHES, LOADING
from crane_stiffness.estimation.fit import LineFit
from crane_stiffness.estimation.live_pairs import LivePairs
from crane_stiffness.params.geometry import geometry_from_params
from crane_stiffness.uncertainty.agreement import en_number
from crane_stiffness.uncertainty.budget import json_ready
from crane_stiffness.uncertainty.crane_inputs import input_names, load_uncertainty_file
from crane_stiffness.uncertainty.measurement import SlopeStatistics, measured_stiffness
from crane_stiffness.uncertainty.prediction import predict_stiffness

#: The crane inputs' uncertainties unless the caller names a file (in the package's config/).
DEFAULT_UNCERTAINTY_FILE = 'uncertainty_lab.yaml'
LOAD_CELL_NODES = ('load_cell', '/load_cell', 'netft', '/netft')
LVDT_NODES = ('lvdt', '/lvdt', 'modbus_lvdt', '/modbus_lvdt', 'lvdt_array', '/lvdt_array')


def _node(data: SessionData, names: tuple[str, ...]) -> dict[str, Any] | None:
    for name in names:
        if isinstance(data.sensors.get(name), dict):
            return data.sensors[name]
    return None


def _usable(fit: LineFit | None) -> bool:
    return fit is not None and fit.n >= 3 and math.isfinite(float(fit.stderr)) and float(fit.stderr) > 0.0


def _cross_load_ratio(data: SessionData, axis: str) -> float:
    """The largest commanded load on the other axes of the axis' kind over the axis' largest (0 without commands)."""
    c = data.command
    if c is None or c.size == 0:
        return 0.0
    kind = AXES[:3] if axis.startswith('f') else AXES[3:]
    peak = {a: float(np.nanmax(np.abs(c[a].astype(float)))) for a in kind}
    if not peak[axis] > 0.0:
        return 0.0
    return max(v for a, v in peak.items() if a != axis) / peak[axis]


def _prediction(data: SessionData, model: ModelSummary, uncertainty_file: str | os.PathLike | None,
                problems: list[str]) -> tuple[dict[str, Any], float, float] | None:
    """The prediction's dict, and its value and U in LVDT reading units; None (with a problem) when it fails."""
    from crane_stiffness.params.files import config_path
    assert data.geometry_params is not None  # a model summary comes from a recorded geometry
    try:
        geometry = geometry_from_params(data.geometry_params)
        path = config_path(str(uncertainty_file) if uncertainty_file is not None else DEFAULT_UNCERTAINTY_FILE)
        entries = load_uncertainty_file(path)
        if uncertainty_file is None:  # the lab file, for whatever crane: keep its entries this crane has
            known = set(input_names(geometry))
            entries = {name: entry for name, entry in entries.items() if name in known}
        prediction = predict_stiffness(geometry, model.axis, uncertainty=entries, monte_carlo_run=False)
    except (CraneStiffnessError, ValueError) as exc:
        problems.append(f"the model's prediction with its uncertainty failed: {exc}")
        return None
    scale = model.lvdt_scale
    return ({'axis': model.axis, 'unit': model.unit, 'lvdt_scale': scale, 'uncertainty_file': str(path),
             'method': 'GUM law of propagation (linear)', 'uncertainty': json_ready(prediction.to_dict())},
            prediction.value * scale, prediction.U * abs(scale))


def session_uncertainty(data: SessionData, pairs: LivePairs, lo: int, hi: int, steps: list[Step],
                        branch_fits: dict[str, LineFit | None], hold_fits: dict[str, LineFit | None],
                        model: ModelSummary | None, problems: list[str],
                        uncertainty_file: str | os.PathLike | None = None) -> dict[str, Any]:
    """{'prediction': …, 'loading': …, 'unloading': …}: each branch's measured k (its fit, the
    :class:`~crane_stiffness.uncertainty.measurement.MeasuredStiffness` dict, the fit's statistical 95 % CI) and
    ``En`` against the prediction when there is one; a branch without a fit is left out."""
    s = data.settings
    axis = s.force_axis
    out: dict[str, Any] = {}
    reference = None
    if model is not None and model.lvdt_scale and math.isfinite(model.tangent_at_rest):
        found = _prediction(data, model, uncertainty_file, problems)
        if found is not None:
            out['prediction'], value, big_u = found
            reference = (value, big_u)
    load_cell, lvdt = _node(data, LOAD_CELL_NODES), _node(data, LVDT_NODES)
    cross = _cross_load_ratio(data, axis)
    loading = pairs.loading[lo:hi]
    for branch in BRANCHES:
        hold, samples = hold_fits.get(branch), branch_fits.get(branch)
        if _usable(hold):
            fit, source = hold, 'hold means'
            chosen = [st for st in steps if st.approach == branch and st.n > 0]
            forces = np.array([st.force_mean for st in chosen])
            displacements = np.array([st.displacement_mean for st in chosen])
        elif _usable(samples):
            fit, source = samples, 'samples'
            mask = loading if branch == LOADING else ~loading
            forces, displacements = pairs.force[lo:hi][mask], pairs.displacement[lo:hi][mask]
        else:
            continue
        assert fit is not None  # _usable
        x_span = float(np.ptp(displacements))
        if s.lever_arm_m > 0.0:  # angles: the LVDT's linearity acts on its reading, the arc on the arm
            x_span *= s.lever_arm_m
        measured = measured_stiffness(
            SlopeStatistics(float(fit.stiffness), float(fit.stderr), float(fit.n - 2), source), axis,
            load_cell=load_cell, lvdt=lvdt, force_span=float(np.ptp(forces)), displacement_span=x_span,
            cross_load_ratio=cross, unit=s.stiffness_unit)
        entry = {'fit': source, **measured.to_dict(), 'ci95': [float(fit.ci95_low), float(fit.ci95_high)]}
        if reference is not None:
            entry['En'] = en_number(measured.result.value, measured.result.U, reference[0], reference[1],
                                    unit=s.stiffness_unit).to_dict()
        out[branch] = entry
    return out


def uncertainty_lines(uncertainty: dict[str, Any], unit: str) -> list[str]:
    """The report's lines, one per branch: 'k = … N/m, U = … N/m (k = 2.xx, 95 %), statistical 95 % CI […]
    (repeatability); model … ± U; E_n = …: agree/disagree', and what the calibration part holds."""
    lines = []
    for branch in BRANCHES:
        entry = uncertainty.get(branch)
        if entry is None:
            continue
        u = entry['uncertainty']
        low, high = entry['ci95']
        line = (f"{branch} ({entry['fit']}): k = {u['value']:.6g} {unit}, U = {u['U']:.4g} {unit} "
                f"(k = {u['k']:.2f}, {100 * u['coverage']:.0f} %), statistical 95 % CI [{low:.6g}, {high:.6g}] "
                '(repeatability)')
        en = entry.get('En')
        if en is not None:
            line += (f"; model {en['reference']:.6g} ± {en['U_reference']:.4g} {unit}; E_n = {en['en']:+.2f}: "
                     f"{'agree' if en['agrees'] else 'disagree'}")
        lines.append(line + f"; {entry['calibration']}")
    return lines


__all__ = ['DEFAULT_UNCERTAINTY_FILE', 'session_uncertainty', 'uncertainty_lines']
