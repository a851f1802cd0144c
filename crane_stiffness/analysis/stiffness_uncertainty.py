"""Each branch's measured stiffness with its GUM uncertainty and its agreement with the model (E_n), for the offline
analysis of a session; a number far from the model flagged with its likely causes. Pure: no ROS import.

The measured k of a branch is the fit of its hold means when there is one (its Type A: n_holds − 2 degrees of
freedom, honest under coloured noise and drift), else the fit of its samples; the calibrations are those the load
cell and LVDT nodes declared and the recorder stored (:mod:`crane_stiffness.uncertainty.measurement`). The model's
prediction for the recorded geometry along the axis carries the uncertainty of the crane's inputs (default
``config/uncertainty_lab.yaml``) by the GUM's law of propagation, with its Monte Carlo (once per crane and
process); E_n uses the measured k's U and the prediction's U for agreement (the Monte Carlo's where it does not
validate the GUM interval: :func:`~crane_stiffness.uncertainty.prediction.agreement_U`).

Beside each GUM result (both branches and the prediction) stands, unless switched off, JCGM 101's adaptive Monte
Carlo through the same measurement function, seeded (:data:`MONTE_CARLO_SEED`) so that the same bag gives the same
numbers: the branch's calibration effects drawn from their declared distributions and its Type A as a scaled and
shifted t; the prediction's crane inputs through the exact tangent at rest (the compiled batch path,
``model/draws.py``: about 0.3–0.5 s for its 20,000 cranes). Each result's ``monte_carlo`` holds the trials, mean, u,
the probabilistically symmetric and shortest 95 % intervals and the validation of the GUM interval (JCGM 101 section
8: d_low, d_high against the numerical tolerance δ).

A branch whose |E_n| > 1 is flagged (:func:`model_disagreements`): the branch, the measured and predicted values
with their U, the relative difference and the likely causes in the order a lab checks them.
"""
from __future__ import annotations

import functools
import json
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
from crane_stiffness.uncertainty.budget import UncertaintyResult, json_ready
from crane_stiffness.uncertainty.crane_inputs import crane_inputs, input_names, load_uncertainty_file
from crane_stiffness.uncertainty.measurement import SlopeStatistics, measured_stiffness
from crane_stiffness.uncertainty.prediction import agreement_U, predict_stiffness

#: The crane inputs' uncertainties unless the caller names a file (in the package's config/).
DEFAULT_UNCERTAINTY_FILE = 'uncertainty_lab.yaml'
#: The Monte Carlo's seed: the same bag gives the same numbers.
MONTE_CARLO_SEED = 0
#: A measured/predicted ratio within this factor of a power of ten (other than 1) is called "near" it.
DECADE_TOLERANCE = 1.25
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


@functools.lru_cache(maxsize=32)
def _predicted(geometry_params: str, axis: str, entries: str, monte_carlo: bool) -> UncertaintyResult:
    """The model's prediction for a crane (its geometry parameters and inputs' uncertainties as JSON: a campaign's
    sessions of one set-up share one), computed once per process: its Monte Carlo does not depend on the session."""
    geometry = geometry_from_params(json.loads(geometry_params))
    return predict_stiffness(geometry, axis, uncertainty=json.loads(entries), monte_carlo_run=monte_carlo,
                             seed=MONTE_CARLO_SEED)


def _prediction(data: SessionData, model: ModelSummary, uncertainty_file: str | os.PathLike | None,
                problems: list[str], monte_carlo: bool) -> tuple[dict[str, Any], float, float] | None:
    """The prediction's dict, and its value and U in LVDT reading units; None (with a problem) when it fails. A
    file the caller named (``uncertainty_file``) with a bad entry is refused: its error, naming the field, the value
    and the rule, propagates (``analyze`` exits 2) rather than leave E_n out unnoticed."""
    from crane_stiffness.params.files import config_path
    assert data.geometry_params is not None  # a model summary comes from a recorded geometry
    if uncertainty_file is not None:
        geometry = geometry_from_params(data.geometry_params)
        path = config_path(str(uncertainty_file))
        crane_inputs(geometry, load_uncertainty_file(path))  # refused here, naming the field
    try:
        geometry = geometry_from_params(data.geometry_params)
        path = config_path(str(uncertainty_file) if uncertainty_file is not None else DEFAULT_UNCERTAINTY_FILE)
        entries = load_uncertainty_file(path)
        if uncertainty_file is None:  # the lab file, for whatever crane: keep its entries this crane has
            known = set(input_names(geometry))
            entries = {name: entry for name, entry in entries.items() if name in known}
        prediction = _predicted(json.dumps(data.geometry_params, sort_keys=True, default=str), model.axis,
                                json.dumps(entries, sort_keys=True, default=str), monte_carlo)
    except (CraneStiffnessError, ValueError) as exc:
        problems.append(f"the model's prediction with its uncertainty failed: {exc}")
        return None
    scale = model.lvdt_scale
    big_u, source = agreement_U(prediction)
    return ({'axis': model.axis, 'unit': model.unit, 'lvdt_scale': scale, 'uncertainty_file': str(path),
             'method': 'GUM law of propagation (linear)' + (
                 '; Monte Carlo (JCGM 101, adaptive) through the exact tangent' if monte_carlo else ''),
             'uncertainty': json_ready(prediction.to_dict()), 'U_for_En': big_u, 'U_for_En_from': source},
            prediction.value * scale, big_u * abs(scale))


def session_uncertainty(data: SessionData, pairs: LivePairs, lo: int, hi: int, steps: list[Step],
                        branch_fits: dict[str, LineFit | None], hold_fits: dict[str, LineFit | None],
                        model: ModelSummary | None, problems: list[str],
                        uncertainty_file: str | os.PathLike | None = None, monte_carlo: bool = True,
                        prediction_monte_carlo: bool | None = None) -> dict[str, Any]:
    """{'prediction': …, 'loading': …, 'unloading': …}: each branch's measured k (its fit, the
    :class:`~crane_stiffness.uncertainty.measurement.MeasuredStiffness` dict, the fit's statistical 95 % CI) and
    ``En`` against the prediction when there is one; a branch without a fit is left out. ``monte_carlo``: each
    result's ``uncertainty.monte_carlo`` holds JCGM 101's (else None); ``prediction_monte_carlo`` the prediction's
    alone (None: as ``monte_carlo``; computed once per crane and process), which sets E_n's reference U
    (:func:`~crane_stiffness.uncertainty.prediction.agreement_U`)."""
    s = data.settings
    axis = s.force_axis
    out: dict[str, Any] = {}
    reference = None
    if model is not None and model.lvdt_scale and math.isfinite(model.tangent_at_rest):
        found = _prediction(data, model, uncertainty_file, problems,
                            monte_carlo if prediction_monte_carlo is None else prediction_monte_carlo)
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
            cross_load_ratio=cross, unit=s.stiffness_unit, monte_carlo_run=monte_carlo, seed=MONTE_CARLO_SEED)
        entry = {'fit': source, **measured.to_dict(), 'ci95': [float(fit.ci95_low), float(fit.ci95_high)]}
        if reference is not None:
            entry['En'] = {**en_number(measured.result.value, measured.result.U, reference[0], reference[1],
                                       unit=s.stiffness_unit).to_dict(),
                           'U_reference_from': out['prediction']['U_for_En_from']}
        out[branch] = entry
    return out


def monte_carlo_line(result: dict[str, Any], unit: str, scale: float = 1.0) -> str | None:
    """'Monte Carlo (JCGM 101, N draws): [low, high] …; the GUM interval is validated / NOT validated (d_low, d_high
    vs δ)' of a result's dict (``UncertaintyResult.to_dict()``), its numbers times ``scale`` (the prediction's
    LVDT reading per unit displacement); None when no Monte Carlo was run."""
    mc = result.get('monte_carlo')
    if not mc:
        return None
    low, high = sorted(v * scale for v in mc['interval'])
    short_low, short_high = sorted(v * scale for v in mc['shortest'])
    check = mc['validation']
    a = abs(scale)
    line = (f"Monte Carlo (JCGM 101, {mc['trials']} draws): [{low:.6g}, {high:.6g}] {unit} "
            f"(probabilistically symmetric {100 * mc['coverage']:.0f} %; shortest [{short_low:.6g}, "
            f"{short_high:.6g}]), mean {mc['mean'] * scale:.6g}, u = {mc['u'] * a:.4g} {unit}; the GUM interval is "
            f"{'validated' if check['validated'] else 'NOT validated'} (d_low = {check['d_low'] * a:.3g}, "
            f"d_high = {check['d_high'] * a:.3g} vs δ = {check['delta'] * a:.3g} {unit})")
    if not check['validated']:
        gum_low, gum_high = sorted(v * scale for v in result['interval'])
        line += ('; it is the wider one, so conservative' if gum_low <= low and high <= gum_high else
                 '; state the Monte Carlo interval')
    if not mc.get('converged', True):
        line += f"; the adaptive procedure did not settle within {mc['trials']} draws"
    return line


def uncertainty_lines(uncertainty: dict[str, Any], unit: str) -> list[str]:
    """The report's lines: per branch 'k = … N/m, U = … N/m (k = 2.xx, 95 %), statistical 95 % CI […]
    (repeatability); model … ± U; E_n = …: agree/disagree' and what the calibration part holds; then the model's
    prediction with its U; each followed by its Monte Carlo line when one was run."""
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
        mc = monte_carlo_line(u, unit)
        if mc is not None:
            lines.append(f'{branch}: {mc}')
    prediction = uncertainty.get('prediction')
    if prediction is not None:
        p, scale = prediction['uncertainty'], prediction['lvdt_scale']
        lines.append(f"model prediction (exact tangent at rest along {prediction['axis']}): k = "
                     f"{p['value'] * scale:.6g} {unit}, U = {p['U'] * abs(scale):.4g} {unit} (k = {p['k']:.2f}, "
                     f"{100 * p['coverage']:.0f} %; {prediction['method']})")
        mc = monte_carlo_line(p, unit, scale)
        if mc is not None:
            lines.append(f'model prediction: {mc}')
    return lines


def near_power_of_ten(ratio: float) -> int:
    """n when |ratio| is within :data:`DECADE_TOLERANCE` of 10^n for an n other than 0 (a factor of 10, 100, 1000
    … or its inverse), else 0."""
    if not math.isfinite(ratio) or ratio == 0.0:
        return 0
    exponent = math.log10(abs(ratio))
    n = round(exponent)
    return n if n != 0 and abs(exponent - n) <= math.log10(DECADE_TOLERANCE) else 0


def likely_causes(ratio: float) -> list[str]:
    """What makes a measured stiffness far from the model, in the order a lab checks them, each saying when the
    measured/predicted ``ratio`` points at it."""
    n = near_power_of_ten(ratio)
    gain = ('the displacement gain or units (displacement_gain [m/V], a reading in mm taken as m) or the load\'s '
            'units')
    if n:
        factor = 10 ** abs(n)
        reads = 'large' if n < 0 else 'small'
        gain += (f': the ratio {abs(ratio):.3g} is near {"1/" if n < 0 else ""}{factor}, so the displacement reads '
                 f'about {factor} times too {reads} (or the load {factor} times too '
                 f'{"small" if n < 0 else "large"}): check these first')
    sign = ("the sign or the LVDT's orientation: the displacement gain's sign, the LVDT's axis parameter and its "
            'mounting direction')
    if ratio < 0.0:
        sign += ' (the measured slope is negative: look here first)'
    return [gain, sign,
            "the load cell's axis and frame (force_axis, the sensor's frame and how it is mounted)",
            'the wrong topic mapped (another sensor\'s stream on the load or displacement topic: --wrench-topic, '
            '--displacement-topic)',
            'the crane file (wire E, diameter, l0, W) not describing the crane on the rig']


def model_disagreements(uncertainty: dict[str, Any], unit: str) -> list[str]:
    """One problem line per branch whose |E_n| > 1: the branch, the measured and predicted values with their U, the
    relative difference, E_n and the likely causes in the order to check them."""
    lines = []
    for branch in BRANCHES:
        en = (uncertainty.get(branch) or {}).get('En')
        if en is None or en['agrees']:
            continue
        k, ref = en['measured'], en['reference']
        ratio = k / ref if ref else math.nan
        causes = '; '.join(f'({i}) {cause}' for i, cause in enumerate(likely_causes(ratio), 1))
        lines.append(f"{branch} far from the model: measured k = {k:.6g} ± {en['U_measured']:.4g} {unit} against "
                     f"the model's {ref:.6g} ± {en['U_reference']:.4g} {unit} (U, 95 %), "
                     f"{100 * (k - ref) / ref:+.1f} % (E_n = {en['en']:+.2f}, |E_n| > 1: they disagree). Likely "
                     f'causes, in the order to check them: {causes}')
    return lines


__all__ = ['DEFAULT_UNCERTAINTY_FILE', 'MONTE_CARLO_SEED', 'likely_causes', 'model_disagreements',
           'monte_carlo_line', 'near_power_of_ten', 'session_uncertainty', 'uncertainty_lines']
