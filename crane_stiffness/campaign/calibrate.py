"""``crane-stiffness calibrate DIR``: the model's uncertain parameters fitted to a whole campaign by nonlinear least
squares on the exact model. No ROS.

**Data.** Each session's hold means (crane_stiffness.analysis.analyze: the settled part of every hold of the
program): the mean load F_i and the mean LVDT reading d_i, with their standard errors from the samples of the hold.

**Model.** For parameters θ the session's crane is its nominal one (the recorded geometry at its W and l0) with

- ``k``: the wires' axial stiffness E·A times a factor (for every session: one wire, one E·A; k = E·A / l0),
- ``weight`` (optional): W times a factor, one for the campaign (``scale``), one per nominal weight hung
  (``per-weight``) or one per session (``per-session``),
- ``height`` (optional): an offset of the unloaded height, one per wire length set up,

and its LVDT reading at load F_i is the nonlinear model's equilibrium under F_i along the series' axis
(crane_stiffness.model.solve_batch, the compiled solver) from the loaded rest pose, times the LVDT's reading per
unit motion (the recorded measuring arrangement), plus the session's own zero (a nuisance per session, solved in
closed form at every θ: variable projection). Residual: (d_i − model) / σ_i, with σ_i² = se(d_i)² + (se(F_i) /
K_i)², K_i the model's exact tangent along the axis (crane_stiffness.model.tangent_stiffness): the noise of the
force counted in displacement units, both noises in the weight.

**Sessions of the series full** (:class:`~crane_stiffness.campaign.rows.MatrixSession`) add their measured 6×6
compliance C (the offline fit of the bag, crane_stiffness.analysis.full6) against the model's, C(θ) = K(θ)⁻¹ with
K(θ) the exact tangent at the rest pose of the session's crane under θ: residual Σ^(−1/2)·(vec C − vec C(θ)), Σ the
36×36 covariance of the measured vec C, so its 36 entries count with their own precision and correlations (no zero:
a compliance has none). One designed test determines E·A on its own, and with W and the height the set-ups tell
apart what no single series can (the vertical and the tilt compliances depend on k, the side ones on W and h).

**Fit and intervals.** scipy's trust-region least squares; the covariance (Jᵀ J)⁻¹ at the optimum (central
differences) scaled by χ²/dof, the noise's scale estimated from the fit (the holds' standard errors give only the
relative weights: a model error or correlated noise then widens the intervals rather than hiding); 95 % intervals
with Student's t on dof = holds − parameters − sessions; correlations; residuals per session.

**Refusal.** Before fitting, the data are checked to determine every parameter asked for: enough holds, each
parameter moving the model (a non-zero column of the Jacobian) and no combination of them the data cannot tell
apart (the smallest singular value of the column-normalised Jacobian, with the sessions' zeros projected out).
:class:`~crane_stiffness.campaign.errors.CalibrationError` names the parameter(s) and why.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from crane_stiffness.campaign.errors import CalibrationError
from crane_stiffness.campaign.rows import (Calibration, CalibrationSession, Full6Row, MatrixSession, Parameter,
                                           SessionRow)

Session = CalibrationSession | MatrixSession

WEIGHT_MODES = ('none', 'scale', 'per-weight', 'per-session')
#: Smallest singular value of the normalised Jacobian relative to the largest for the parameters to count as
#: determined (below it a combination of them moves the model by less than 1e-6 of the best-determined one).
MIN_RELATIVE_SINGULAR_VALUE = 1e-6
#: Largest standard error of a factor (k, W) and of a height offset [m] the data may leave for the parameter to
#: count as determined (from the Jacobian at the nominal model and the holds' stated noise, before fitting).
MAX_FACTOR_STDERR = 0.05
MAX_HEIGHT_STDERR_M = 0.01
#: Relative step of the central differences (parameters are factors near 1, offsets in m).
STEP = 1e-5


def session_from_analysis(session: str, series: str, nominal: dict[str, Any], analysis: dict[str, Any]
                          ) -> CalibrationSession | None:
    """A :class:`CalibrationSession` from a session's analysis (its JSON: steps, model.lvdt_scale); None without
    usable holds."""
    steps = [s for s in analysis.get('steps', []) if s.get('n') and s['n'] > 1
             and s.get('force_mean') is not None and s.get('displacement_mean') is not None
             and s.get('force_std') is not None and s.get('displacement_std') is not None]
    if len(steps) < 3:
        return None
    n = np.array([s['n'] for s in steps], dtype=float)
    model = analysis.get('model') or {}
    return CalibrationSession(
        session=session, series=series, nominal=dict(nominal), lvdt_scale=float(model.get('lvdt_scale') or 1.0),
        force=np.array([s['force_mean'] for s in steps], dtype=float),
        force_se=np.array([s['force_std'] for s in steps], dtype=float) / np.sqrt(n),
        displacement=np.array([s['displacement_mean'] for s in steps], dtype=float),
        displacement_se=np.array([s['displacement_std'] for s in steps], dtype=float) / np.sqrt(n))


def matrix_session(session: str, nominal: dict[str, Any], analysis: dict[str, Any]) -> MatrixSession | None:
    """A :class:`MatrixSession` from a session's full6.json (compliance value and covariance); None when the fit
    gave no numbers."""
    cov = analysis.get('compliance_covariance')
    value = (analysis.get('compliance') or {}).get('value')
    if cov is None or value is None:
        return None
    c = np.asarray(value, dtype=float).reshape(36)
    cov = np.asarray(cov, dtype=float)
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(cov))):
        return None
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    if not vals.min() > 0.0:
        return None
    return MatrixSession(session=session, nominal=dict(nominal), compliance=c,
                         whiten=(vecs / np.sqrt(vals)) @ vecs.T)


def _points(s: Session) -> int:
    return len(s.compliance) if isinstance(s, MatrixSession) else len(s.force)


class _Model:
    """The parameters' layout and the model's LVDT readings (or compliances) for a vector of them."""

    def __init__(self, sessions: Sequence[Session], weight: str, height: bool) -> None:
        if weight not in WEIGHT_MODES:
            raise CalibrationError(f'weight = {weight!r}: must be one of {", ".join(WEIGHT_MODES)}')
        self.sessions = list(sessions)
        self.names = ['k']
        self.units = ['-']
        self.descriptions = ["factor on the wires' E·A (k = E·A / l0) over the nominal"]
        self.weight_index: list[int | None] = [None] * len(sessions)
        self.height_index: list[int | None] = [None] * len(sessions)
        if weight == 'scale':
            self._add('W', '-', 'factor on every weight W over the nominal')
            self.weight_index = [1] * len(sessions)
        elif weight in ('per-weight', 'per-session'):
            keys: dict[Any, int] = {}
            for i, s in enumerate(sessions):
                key = round(float(s.nominal['geometry.weight']), 9) if weight == 'per-weight' else s.session
                if key not in keys:
                    keys[key] = len(self.names)
                    label = f'W {key:g} N' if weight == 'per-weight' else f'W of {key}'
                    self._add(label, '-', f'factor on {label} over the nominal')
                self.weight_index[i] = keys[key]
        if height:
            heights: dict[float, int] = {}
            for i, s in enumerate(sessions):
                h = round(float(s.nominal['geometry.height']), 9)
                if h not in heights:
                    heights[h] = len(self.names)
                    self._add(f'height {h:.4g} m', 'm', f'offset of the unloaded height {h:.4g} m')
                self.height_index[i] = heights[h]
        self.start = np.array([0.0 if u == 'm' else 1.0 for u in self.units])
        #: Largest standard error a parameter may have before the fit for the data to count as determining it.
        self.limits = [MAX_HEIGHT_STDERR_M if u == 'm' else MAX_FACTOR_STDERR for u in self.units]
        self.steps = np.array([STEP * 1e-2 if u == 'm' else STEP for u in self.units])

    def _add(self, name: str, unit: str, description: str) -> None:
        self.names.append(name)
        self.units.append(unit)
        self.descriptions.append(description)

    def params(self, i: int, theta: np.ndarray) -> dict[str, Any]:
        """geometry.* of session ``i`` under ``theta``."""
        p = dict(self.sessions[i].nominal)
        if p.get('geometry.wire_stiffness'):
            p['geometry.wire_stiffness'] = p['geometry.wire_stiffness'] * theta[0]
        else:
            p['geometry.youngs_modulus'] = p['geometry.youngs_modulus'] * theta[0]
        w, h = self.weight_index[i], self.height_index[i]
        if w is not None:
            p['geometry.weight'] = p['geometry.weight'] * theta[w]
        if h is not None:
            p['geometry.height'] = p['geometry.height'] + theta[h]
        return p

    def readings(self, i: int, theta: np.ndarray) -> np.ndarray:
        """The model's LVDT reading at each hold's load of session ``i`` (from the loaded rest pose)."""
        from crane_stiffness.analysis.sweep import displacement_along, unit
        from crane_stiffness.model import rest_pose, solve_batch
        from crane_stiffness.params.geometry import geometry_from_params
        s = self.sessions[i]
        assert isinstance(s, CalibrationSession)
        g = geometry_from_params(self.params(i, theta))
        rest = rest_pose(g, xtol=1e-13)
        batch = solve_batch(g, s.force[:, None] * unit(s.series)[None, :], xtol=1e-13)
        return s.lvdt_scale * np.array([displacement_along(s.series, batch[j], rest) for j in range(len(batch))])

    def compliance(self, i: int, theta: np.ndarray) -> np.ndarray:
        """The model's vec C (36,) of session ``i``: the exact tangent's inverse at its rest pose."""
        from crane_stiffness.full6.reference import reference_at_rest
        from crane_stiffness.params.geometry import geometry_from_params
        return reference_at_rest(geometry_from_params(self.params(i, theta))).compliance.reshape(36)

    @property
    def zeros(self) -> int:
        """The sessions with a zero of their own (the one-axis ones: their LVDT's zero)."""
        return sum(1 for s in self.sessions if not isinstance(s, MatrixSession))

    def tangents(self, theta: np.ndarray) -> list[float]:
        """Each session's model stiffness along its series' axis (NaN for a session of the series full)."""
        from crane_stiffness.model import axis_stiffness, rest_pose, tangent_stiffness
        from crane_stiffness.params.geometry import geometry_from_params
        out = []
        for i, s in enumerate(self.sessions):
            if isinstance(s, MatrixSession):
                out.append(math.nan)
                continue
            g = geometry_from_params(self.params(i, theta))
            out.append(axis_stiffness(tangent_stiffness(g, rest_pose(g)), s.series) / s.lvdt_scale)
        return out


def _weights(model: _Model) -> list[np.ndarray]:
    """1/σ of every hold: the displacement's and the force's standard errors (the force's through the tangent);
    a session of the series full: its whitening matrix."""
    out = []
    for s, k in zip(model.sessions, model.tangents(model.start)):
        if isinstance(s, MatrixSession):
            out.append(s.whiten)
            continue
        sigma = np.sqrt(s.displacement_se ** 2 + (s.force_se / k) ** 2)
        floor = max(float(np.median(sigma[sigma > 0])) if (sigma > 0).any() else 1e-12, 1e-15)
        out.append(1.0 / np.maximum(sigma, floor * 1e-3))
    return out


def _residuals(model: _Model, weights: list[np.ndarray], theta: np.ndarray) -> np.ndarray:
    """Normalised residuals with each session's zero solved in closed form (weighted mean of its misfit)."""
    parts = []
    for i, (s, w) in enumerate(zip(model.sessions, weights)):
        if isinstance(s, MatrixSession):
            parts.append(w @ (s.compliance - model.compliance(i, theta)))
            continue
        misfit = s.displacement - model.readings(i, theta)
        zero = float(np.sum(w ** 2 * misfit) / np.sum(w ** 2))
        parts.append(w * (misfit - zero))
    return np.concatenate(parts)


def _jacobian(model: _Model, weights: list[np.ndarray], theta: np.ndarray) -> np.ndarray:
    cols = []
    for j, h in enumerate(model.steps):
        up, down = theta.copy(), theta.copy()
        up[j] += h
        down[j] -= h
        cols.append((_residuals(model, weights, up) - _residuals(model, weights, down)) / (2 * h))
    return np.column_stack(cols)


def _amount(value: float, unit: str) -> str:
    return f'{value:.2g} m' if unit == 'm' else f'{100 * value:.2g} %'


def check_determined(model: _Model, jac: np.ndarray, n_points: int) -> None:
    """CalibrationError naming the parameter(s) the data cannot determine."""
    n_params = len(model.names)
    dof = n_points - n_params - model.zeros
    if dof < 1:
        raise CalibrationError(f'the data cannot determine {n_params} parameter(s) ({", ".join(model.names)}): '
                               f'{n_points} hold(s) in {len(model.sessions)} session(s) leave {dof} degree(s) of '
                               'freedom after the parameters and each session\'s zero')
    norms = np.linalg.norm(jac, axis=0)
    scale = norms.max() if norms.size else 0.0
    dead = [model.names[j] for j in range(n_params) if not norms[j] > 1e-12 * max(scale, 1e-300)]
    if dead:
        raise CalibrationError(f'the data cannot determine {", ".join(dead)}: no session\'s readings depend on it')
    _, sv, vt = np.linalg.svd(jac / norms, full_matrices=False)
    if sv[-1] >= MIN_RELATIVE_SINGULAR_VALUE * sv[0]:
        # Determined in principle; to within what? The interval the fit would give with the noise as stated.
        se = np.sqrt(np.diag(np.linalg.inv(jac.T @ jac)))
        loose = [f'{name} only to ±{_amount(e, unit)} (1 σ; more than {_amount(limit, unit)})'
                 for name, e, unit, limit in zip(model.names, se, model.units, model.limits) if not e <= limit]
        if loose:
            raise CalibrationError('the data cannot determine ' + '; '.join(loose) + ': leave it out, or add '
                                   'sessions that depend on it more (other series, weights or lengths)')
    if sv[-1] < MIN_RELATIVE_SINGULAR_VALUE * sv[0]:
        direction = vt[-1]
        involved = [model.names[j] for j in np.argsort(-np.abs(direction)) if abs(direction[j]) > 0.2]
        raise CalibrationError(
            f'the data cannot determine {" and ".join(involved)} apart: a combination of them changes the model '
            f'by {sv[-1] / sv[0]:.1e} of the best-determined parameter (sessions of more series, weights or lengths '
            'would tell them apart)')


def calibrate(sessions: Sequence[Session], *, weight: str = 'none', height: bool = False
              ) -> Calibration:
    """Fit the campaign's model parameters (see the module docstring). Raises CalibrationError."""
    from scipy.optimize import least_squares
    from scipy.stats import t as student_t
    if not sessions:
        raise CalibrationError('no session with at least 3 holds (or a 6x6 compliance) to calibrate on')
    model = _Model(sessions, weight, height)
    weights = _weights(model)
    n_points = sum(_points(s) for s in sessions)
    check_determined(model, _jacobian(model, weights, model.start), n_points)
    # Factors kept within 0.2 .. 5 of the nominal (the model has no equilibrium far outside), offsets within 10 %.
    lower = np.where(np.array(model.units) == 'm', -0.1, 0.2)
    upper = np.where(np.array(model.units) == 'm', 0.1, 5.0)
    fit = least_squares(lambda th: _residuals(model, weights, th), model.start, method='trf', bounds=(lower, upper),
                        diff_step=model.steps / np.maximum(np.abs(model.start), 1.0), x_scale='jac',
                        xtol=1e-12, ftol=1e-12)
    theta = fit.x
    jac = _jacobian(model, weights, theta)
    res = _residuals(model, weights, theta)
    dof = n_points - len(theta) - model.zeros
    chi2 = float(res @ res)
    try:
        cov = np.linalg.inv(jac.T @ jac) * (chi2 / dof)
    except np.linalg.LinAlgError:
        raise CalibrationError(f'the data cannot determine {", ".join(model.names)} (singular normal matrix)') \
            from None
    se = np.sqrt(np.diag(cov))
    q = float(student_t.ppf(0.975, dof))
    corr = cov / np.outer(se, se)
    parameters = [Parameter(n, float(v), float(e), float(v - q * e), float(v + q * e), u, d)
                  for n, v, e, u, d in zip(model.names, theta, se, model.units, model.descriptions)]
    per_session = []
    offset = 0
    calibrated = model.tangents(theta)
    nominal = model.tangents(model.start)
    for i, s in enumerate(sessions):
        r = res[offset:offset + _points(s)]
        offset += _points(s)
        slope = (math.nan if isinstance(s, MatrixSession) or len(s.force) < 2 else
                 float(np.polyfit(s.displacement, s.force, 1)[0]))
        per_session.append({'session': s.session, 'series': s.series, 'holds': _points(s),
                            'rms_normalised_residual': float(np.sqrt(np.mean(r ** 2))),
                            'measured_hold_slope': slope, 'nominal_tangent': nominal[i],
                            'calibrated_tangent': calibrated[i]})
    return Calibration(parameters=parameters, correlation=corr.tolist(), chi2=chi2, dof=dof, sessions=per_session,
                       wire=_wire(sessions, model, theta))


def _wire(sessions: Sequence[Session], model: _Model, theta: np.ndarray) -> dict[str, float]:
    """E·A [N] and k at each length [N/m], nominal and calibrated."""
    from crane_stiffness.params.geometry import geometry_from_params
    out: dict[str, float] = {}
    for i, s in enumerate(sessions):
        g0 = geometry_from_params(s.nominal)
        g1 = geometry_from_params(model.params(i, theta))
        out['EA_nominal_N'] = g0.k * g0.l0
        out['EA_calibrated_N'] = g1.k * g1.l0
        out[f'k_nominal_l{g0.l0:.4g}_N_per_m'] = g0.k
        out[f'k_calibrated_l{g0.l0:.4g}_N_per_m'] = g1.k
    return out


def calibrate_campaign(out: Any, *, weight: str = 'none', height: bool = False, only_ok: bool = False,
                       formats: Sequence[str] = ('png',), reports: Sequence[str] = ('md', 'html')
                       ) -> tuple[Calibration, list[str]]:
    """Calibrate on the analysed sessions of the campaign in ``out`` (``campaign analyze`` first) and write
    ``out/calibration/``: calibration.json, report, and the campaign figures with the calibrated model beside the
    nominal one. Returns (the calibration, the files written)."""
    import json
    from pathlib import Path

    from crane_stiffness.campaign import figures, full_figures
    from crane_stiffness.campaign.analyze import ANALYSIS_FILES, campaign_rows, full_rows
    from crane_stiffness.analysis.report import write_blocks
    from crane_stiffness.campaign.report import calibration_blocks
    out = Path(out)
    _, rows, missing = campaign_rows(out)
    full = full_rows(out)
    sessions: list[Session] = []
    for r in rows:
        s = session_from_analysis(r.session, r.series, r.nominal,
                                  json.loads((Path(r.analysis) / ANALYSIS_FILES['one_axis']).read_text()))
        if s is not None and (r.ok or not only_ok):
            sessions.append(s)
    for f in full:
        m = matrix_session(f.session, f.nominal, json.loads((Path(f.analysis) / ANALYSIS_FILES['full']).read_text()))
        if m is not None and (f.ok or not only_ok):
            sessions.append(m)
    if not sessions:
        raise CalibrationError(f'{out}: no analysed session with holds or a 6x6 compliance to calibrate on (run '
                               '`crane-stiffness campaign analyze` first)'
                               + (f'; missing: {", ".join(missing)}' if missing else ''))
    result = calibrate(sessions, weight=weight, height=height)
    target = out / 'calibration'
    target.mkdir(parents=True, exist_ok=True)
    factors = {p.name: p.value for p in result.parameters}
    index = {s.session: i for i, s in enumerate(sessions)}

    def calibrated(nominal: dict[str, Any]) -> dict[str, Any]:
        """The calibrated crane of a set-up: k and the campaign-wide W factor; a height offset of its length."""
        p = dict(nominal)
        key = 'geometry.wire_stiffness' if p.get('geometry.wire_stiffness') else 'geometry.youngs_modulus'
        p[key] = p[key] * factors['k']
        p['geometry.weight'] = p['geometry.weight'] * factors.get('W', 1.0)
        p['geometry.height'] = p['geometry.height'] + factors.get(f'height {p["geometry.height"]:.4g} m', 0.0)
        return p
    files = []
    if any(r.session in index for r in rows):
        files += figures.write_campaign_figures([r for r in rows if r.session in index], target, formats,
                                                calibrated=calibrated, suffix='_calibrated')
    if any(f.session in index for f in full):
        files += full_figures.write_full_figures([f for f in full if f.session in index], target, formats,
                                                 calibrated=calibrated, suffix='_calibrated')
    left_out: list[SessionRow | Full6Row] = []
    left_out.extend(r for r in rows if r.session not in index)
    left_out.extend(f for f in full if f.session not in index)
    (target / 'calibration.json').write_text(json.dumps(
        {**result.to_dict(), 'sessions_used': [s.session for s in sessions],
         'sessions_left_out': [r.session for r in left_out], 'weight_mode': weight,
         'height': height}, indent=1, allow_nan=False))
    files.append(str(target / 'calibration.json'))
    files += write_blocks(calibration_blocks(result, left_out,
                                             [Path(f).name for f in files if f.endswith(tuple(formats))]),
                          target, 'report', reports, 'calibration')
    return result, files
