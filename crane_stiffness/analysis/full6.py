"""Offline 6×6 analysis of a six-axis session: the whole stiffness matrix K and compliance C with 95 % intervals from
a bag, compared with the exact tangent and the paper's eq. (18) at the session's geometry. Pure: no ROS import.

1. **Read** (crane_stiffness.analysis.full6_load): the commands, the load cell's wrench moved to the platform centre
   and the pose sensor's pose; the settings recorded for the ``stiffness6_estimator`` node, else the defaults.
2. **Pairs** (crane_stiffness.full6.pairs.full6_pairs): each pose with the wrench interpolated at its stamp, the
   deflection from the first pose, labelled with the load step in force after ``settle_s``.
3. **Fit** (crane_stiffness.full6.identify.identify): C and K with errors in both variables, an interval on every
   entry, K2 and the status.
4. **Uncertainty** (crane_stiffness.analysis.full6_uncertainty): every entry of K, C and K2 with its GUM
   uncertainty from the step means and the sensors' declared calibrations, the 36×36 covariances, and E_n per entry
   against the model's tangent with its own uncertainty.
5. **Compare** (crane_stiffness.full6.reference.reference_at_rest): per entry of K the relative error against the
   tangent (measured / tangent − 1; None where the tangent's entry is zero, below :data:`ZERO_COUPLING` of the
   geometric mean of its two diagonal entries) and whether the interval holds the tangent's entry (zeros too); the
   same for C; K2 against the tangent's and eq. (18)'s.
6. **Write** ``full6.json`` (:meth:`Full6Analysis.to_dict`), the figures (crane_stiffness.analysis.full6_figures) and
   the report (crane_stiffness.analysis.full6_report).

Matrices are lists of rows: K row i the load [fx, fy, fz, mx, my, mz] (N, N·m), column j the displacement
[u_x, u_y, u_z, θ_x, θ_y, θ_z] (m, rad), fixed frame ``crane_base``, z down; C = K⁻¹ the transpose layout.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from crane_stiffness import __version__
from crane_stiffness.analysis.errors import SessionAnalysisError
from crane_stiffness.analysis.full6_load import FULL6_TOPICS, Full6Data, load_full6
from crane_stiffness.analysis.full6_result import Full6Analysis
from crane_stiffness.analysis.full6_uncertainty import session_matrix_uncertainty
from crane_stiffness.full6.full_scale import with_full_scale
from crane_stiffness.full6.identify import ComplianceFit, identify
from crane_stiffness.full6.pairs import LabelledPairs, full6_pairs
from crane_stiffness.full6.statistics import pair_statistics
from crane_stiffness.full6.reference import (K2_ENTRIES, ZERO_COUPLING, Reference, entry_name, k2_of,
                                            reference_at_rest, relative_error, structural_zeros)
from crane_stiffness.contract.status import NAMES

#: Units of K's entries (row a load, column a displacement); C's are their reciprocals.
FORCE_UNITS = ('N/m', 'N/rad')
MOMENT_UNITS = ('N·m/m', 'N·m/rad')


def stiffness_unit(row: int, column: int) -> str:
    """The unit of K[row, column]: N/m, N/rad, N·m/m or N·m/rad."""
    return (FORCE_UNITS if row < 3 else MOMENT_UNITS)[0 if column < 3 else 1]


def _matrices(value: NDArray[np.float64], low: NDArray[np.float64], high: NDArray[np.float64],
              stderr: NDArray[np.float64]) -> dict[str, Any]:
    return {'value': value.tolist(), 'low': low.tolist(), 'high': high.tolist(), 'stderr': stderr.tolist()}


def _k2(fit: ComplianceFit, ref: Reference | None) -> dict[str, Any]:
    out: dict[str, Any] = {
        'value': fit.k2, 'low': fit.k2_low, 'high': fit.k2_high, 'stderr': fit.k2_stderr,
        'sign': '+' if fit.k2 > 0 else '-' if fit.k2 < 0 else '?', 'unit': 'N/rad',
        'entries': {entry_name(i, j): {'sign': s, 'measured': float(fit.stiffness[i, j]),
                                       'tangent': None if ref is None else float(ref.tangent[i, j])}
                    for i, j, s in K2_ENTRIES}}
    if ref is not None and not math.isfinite(fit.k2):
        out.update(tangent=ref.k2, relative_error_tangent=None, covers_tangent=None, sign_as_tangent=None,
                   paper=None if ref.paper is None else k2_of(ref.paper), relative_error_paper=None)
    elif ref is not None:
        out.update(tangent=ref.k2, relative_error_tangent=fit.k2 / ref.k2 - 1.0,
                   covers_tangent=bool(fit.k2_low <= ref.k2 <= fit.k2_high),
                   sign_as_tangent=bool(np.sign(fit.k2) == np.sign(ref.k2)),
                   paper=None if ref.paper is None else k2_of(ref.paper),
                   relative_error_paper=None if ref.paper is None else fit.k2 / k2_of(ref.paper) - 1.0)
    return out


def _reference(ref: Reference) -> dict[str, Any]:
    return {'tangent': ref.tangent.tolist(), 'compliance': ref.compliance.tolist(),
            'paper': None if ref.paper is None else ref.paper.tolist(),
            'rest_displacement': ref.equilibrium.displacement.tolist(),
            'rest_rotation': ref.equilibrium.rotation.tolist(), 'rest_wire_tensions': ref.equilibrium.wire_tensions}


def _comparison(fit: ComplianceFit, ref: Reference) -> dict[str, Any]:
    k_err = relative_error(fit.stiffness, ref.tangent)
    c_err = relative_error(fit.compliance, ref.compliance)
    paper = None if ref.paper is None else relative_error(fit.stiffness, ref.paper).tolist()
    return {'stiffness_relative_error': k_err.tolist(), 'stiffness_covers': fit.covers_stiffness(ref.tangent),
            'compliance_relative_error': c_err.tolist(), 'compliance_covers': fit.covers_compliance(ref.compliance),
            'stiffness_relative_error_paper': paper,
            'tangent_zero': structural_zeros(ref.tangent),
            'covered': {'stiffness': int(fit.covers_stiffness(ref.tangent).sum()),
                        'compliance': int(fit.covers_compliance(ref.compliance).sum()), 'of': 36}}


def _diagonal(fit: ComplianceFit, ref: Reference | None) -> list[dict[str, Any]]:
    out = []
    for i in range(6):
        k, low, high = (float(m[i, i]) for m in (fit.stiffness, fit.stiffness_low, fit.stiffness_high))
        row: dict[str, Any] = {'entry': entry_name(i, i), 'unit': stiffness_unit(i, i), 'measured': k, 'low': low,
                               'high': high, 'tangent': None, 'relative_error': None, 'covers': None}
        if ref is not None:
            tangent = float(ref.tangent[i, i])
            row['tangent'] = tangent
            if math.isfinite(k):
                row.update(relative_error=k / tangent - 1.0, covers=bool(low <= tangent <= high))
        out.append(row)
    return out


def _status(fit: ComplianceFit, data: Full6Data) -> tuple[str, str]:
    """The fit's level name and message, the samples at full scale said as the live estimator says them."""
    level, message = with_full_scale(fit.level, fit.message, data.saturated)
    return NAMES[level], message


def pairs_of(data: Full6Data) -> LabelledPairs:
    """The labelled pairs of a session read by :func:`~crane_stiffness.analysis.full6_load.load_full6`."""
    s = data.settings
    return full6_pairs(data.command_stamp, data.command_wrench, data.wrench_stamp, data.wrench_log, data.wrench,
                       data.pose_stamp, data.pose_log, data.position, data.quaternion, settle_s=s.settle_s,
                       max_gap_s=s.max_gap_s, max_age_s=s.max_age_s)


def analyze_full6(bag_path: str | Path, out_dir: str | Path | None = None, *, formats: Sequence[str] = ('png',),
                  reports: Sequence[str] = ('md',), write_json: bool = True,
                  write_files: bool = True, uncertainty_file: str | Path | None = None) -> Full6Analysis:
    """Analyse a six-axis session (module docstring) and write ``full6.json``, its figures and report into
    ``out_dir`` (default ``out/analysis/<bag name>``; nothing with ``write_files=False``). ``uncertainty_file``:
    the crane inputs' uncertainties for the model's prediction (default config/uncertainty_lab.yaml).

    Raises:
        BagNotFoundError / BagFormatError: no readable bag; TopicNotFoundError: a stream missing (named).
        SessionAnalysisError: no labelled pair (no settled step with both sensors).
    """
    path = Path(bag_path)
    problems: list[str] = []
    data = load_full6(path, problems)
    pairs = pairs_of(data)
    s = data.settings
    if not len(pairs):
        raise SessionAnalysisError(f'{path}: no labelled (wrench, pose) pair: no step of the commands held longer '
                                   f'than settle_s = {s.settle_s:g} s with load-cell samples within '
                                   f'max_gap_s = {s.max_gap_s:g} s of a pose ({data.pose_stamp.size} poses, '
                                   f'{data.wrench_stamp.size} load-cell samples, {data.command_stamp.size} commands)')
    fit = identify(pairs.wrench, pairs.deflection, pairs.step, wrench_noise=s.wrench_noise, confidence=s.confidence)
    ref = reference_at_rest(data.geometry) if data.geometry is not None else None
    if ref is not None and ref.paper is None:
        problems.append('eq. (18) does not describe this geometry (a centre-of-mass offset, unequal wires or a load '
                        'point off the centre): compared with the exact tangent only')
    g = data.geometry
    gum, gum_result = (None, None)
    if fit.n_steps > 0:
        gum, gum_result = session_matrix_uncertainty(pair_statistics(pairs.wrench, pairs.deflection, pairs.step),
                                                     data.sensors, g, problems, uncertainty_file=uncertainty_file)
    result = Full6Analysis(
        bag=str(path), session=str(data.session.get('session') or path.name), notes=str(data.session.get('notes', '')),
        recorded_with=str(data.session.get('software_version', '')), analysed_with=__version__,
        duration_s=((data.end_ns or 0) - (data.start_ns or 0)) * 1e-9, counts=data.counts, dropped=data.dropped,
        geometry=None if g is None else {**g.to_dict(), 'l0': g.l0, 'k': g.k}, settings=s.to_dict(),
        pairs={'n': fit.n, 'steps': fit.n_steps, 'dof': fit.dof, 'poses': int(data.pose_stamp.size),
               'wrench_samples': int(data.wrench_stamp.size), 'commands': int(data.command_stamp.size)},
        status=dict(zip(('level', 'message'), _status(fit, data))), condition=fit.condition,
        lack_of_fit=fit.lack_of_fit, lack_of_fit_p=fit.lack_of_fit_p, inflation=fit.inflation,
        stiffness=_matrices(fit.stiffness, fit.stiffness_low, fit.stiffness_high, fit.stiffness_stderr),
        compliance=_matrices(fit.compliance, fit.compliance_low, fit.compliance_high, fit.compliance_stderr),
        offset=fit.offset.tolist(), k2=_k2(fit, ref), reference=None if ref is None else _reference(ref),
        comparison=None if ref is None else _comparison(fit, ref), diagonal=_diagonal(fit, ref), problems=problems,
        compliance_covariance=fit.compliance_cov.tolist() if np.all(np.isfinite(fit.compliance_cov)) else None,
        uncertainty=gum, fit=fit, model=ref, matrix_uncertainty=gum_result)
    if write_files:
        out = Path(out_dir) if out_dir is not None else Path('out') / 'analysis' / path.name
        out.mkdir(parents=True, exist_ok=True)
        from crane_stiffness.analysis import full6_figures, full6_report
        if np.all(np.isfinite(fit.stiffness)):
            result.files += full6_figures.write_full6_figures(result, out, formats)
        else:
            problems.append('no figures: the fit gave no numbers (status above)')
        result.files += full6_report.write_full6_report(result, out, reports)
        if write_json:
            result.files.append(str(out / 'full6.json'))
            (out / 'full6.json').write_text(json.dumps(result.to_dict(), indent=1, allow_nan=False))
    return result


__all__ = ['FULL6_TOPICS', 'Full6Analysis', 'ZERO_COUPLING', 'analyze_full6', 'pairs_of', 'relative_error',
           'stiffness_unit', 'structural_zeros']
