"""The 6×6 stiffness as the live view shows it (``/live_view/stiffness6``): the latest K the six-axis estimator
published (/stiffness6/stiffness, with its 95 % interval) entry by entry against the model's exact tangent at rest
for the view's geometry (crane_stiffness.full6.reference), the coupling K2 measured, with its interval, and the
tangent's, and the estimator's status (/stiffness6/status); each entry's and K2's expanded uncertainty U (GUM, 95 %)
beside the statistical interval (the repeatability) once the estimator states it (/stiffness6/stiffness_expanded, of
the same fit: :func:`expanded_uncertainty`; K2's U and what U counts from the status). Pure numpy, no ROS.

Rows are the loads fx fy fz mx my mz, columns the displacements u_x u_y u_z θ_x θ_y θ_z (crane_stiffness.contract.axes,
crane_stiffness.full6.reference.DISPLACEMENTS); units as there (N/m, N/rad, N·m/rad). An entry the model has at zero
(crane_stiffness.full6.reference.structural_zeros, the rule the offline analysis uses) has no relative error:
``model_zero`` says so.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from crane_stiffness.contract import stiffness6_layout
from crane_stiffness.contract.axes import AXES
from crane_stiffness.full6.reference import DISPLACEMENTS, k2_of, relative_error, structural_zeros
from crane_stiffness.contract.status import NAMES, read_level
from crane_stiffness.view import jsonschema as js
from crane_stiffness.view.errors import ViewError


def _num(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _k2_interval(values: Mapping[str, str], key: str = 'k2_ci95') -> tuple[float, float]:
    low, _, high = values.get(key, '').partition(' .. ')
    try:
        return float(low), float(high)
    except ValueError:
        return math.nan, math.nan


def _float(values: Mapping[str, str], key: str) -> float:
    try:
        return float(values.get(key, 'nan'))
    except ValueError:
        return math.nan


def expanded_uncertainty(stiffness: Sequence[float] | None, expanded: Sequence[float] | None) -> np.ndarray | None:
    """Each entry's U (6, 6) [its unit] of /stiffness6/stiffness_expanded data ``expanded`` (value, value − U,
    value + U), when it is of the same fit as the /stiffness6/stiffness data ``stiffness`` (the same values: the two
    topics are published together, but arrive one after the other); None otherwise (no U shown rather than the U of
    another fit). ViewError on data not laid out as crane_stiffness.contract.stiffness6_layout says."""
    if stiffness is None or expanded is None:
        return None
    try:
        k, cube = stiffness6_layout.decode(stiffness)[0], stiffness6_layout.decode(expanded)
    except stiffness6_layout.LayoutError as exc:
        raise ViewError(str(exc)) from exc
    if not np.array_equal(cube[0], k, equal_nan=True):
        return None
    return 0.5 * (cube[2] - cube[1])


def stiffness6_message(stiffness: Sequence[float] | None, tangent: np.ndarray,
                       status: tuple[int, str, Mapping[str, str]] | None,
                       uncertainty: np.ndarray | None = None) -> dict[str, Any]:
    """The channel's message. ``stiffness``: the newest /stiffness6/stiffness data (None: no fit yet; laid out as
    crane_stiffness.contract.stiffness6_layout says, ViewError otherwise); ``tangent``: the model's K (6, 6);
    ``status``:
    (published level, message, key-values) of the newest /stiffness6/status (None: none yet). ``fit`` says whether a
    measured K is there; K2 measured is read from it (:func:`~crane_stiffness.full6.reference.k2_of`, what the
    estimator fits), its interval from the status. The statistical interval is the repeatability; ``uncertainty``:
    each entry's expanded uncertainty U (6, 6) [its unit, 95 %] when the six-axis estimator states one for this fit
    (:func:`expanded_uncertainty`; each cell's ``U``, ``U_low``, ``U_high`` = measured ∓ U; K2's from the status's
    ``k2_U``; ``uncertainty``: the status's statement of what U counts, ``statistical_only`` when it counts no
    calibration), else None: the U fields are null and the statement empty (no U stated for this fit)."""
    tangent = np.asarray(tangent, dtype=float)
    zero = structural_zeros(tangent)
    try:
        cube = stiffness6_layout.decode(stiffness) if stiffness is not None else np.full((3, 6, 6), np.nan)
    except stiffness6_layout.LayoutError as exc:
        raise ViewError(str(exc)) from exc
    k, low, high = cube
    relative = relative_error(k, tangent)  # (NaN where the fit is missing: k is NaN then)
    big_u = np.full((6, 6), np.nan) if uncertainty is None else np.asarray(uncertainty, dtype=float).reshape(6, 6)
    rows = [{'load': AXES[i], 'cells': [
        {'displacement': DISPLACEMENTS[j], 'measured': _num(k[i, j]), 'ci95_low': _num(low[i, j]),
         'ci95_high': _num(high[i, j]), 'tangent': float(tangent[i, j]), 'relative_error': _num(relative[i, j]),
         'model_zero': bool(zero[i, j]), 'U': _num(big_u[i, j]), 'U_low': _num(k[i, j] - big_u[i, j]),
         'U_high': _num(k[i, j] + big_u[i, j])} for j in range(6)]} for i in range(6)]
    values = status[2] if status is not None else {}
    k2_low, k2_high = _k2_interval(values)
    k2_u = _float(values, 'k2_U') if uncertainty is not None else math.nan  # (beside the same fit's U only)
    statement = values.get('uncertainty', '') if uncertainty is not None else ''
    k2_measured, k2_tangent = k2_of(k), k2_of(tangent)
    if status is None:
        level, level_name, message = -1, NAMES[-1], ''
    else:
        level = read_level(status[0], status[1])
        level_name, message = NAMES.get(level, str(level)), status[1]
    return {'fit': stiffness is not None, 'level': level, 'level_name': level_name, 'message': message,
            'k2': {'measured': _num(k2_measured), 'ci95_low': _num(k2_low), 'ci95_high': _num(k2_high),
                   'tangent': _num(k2_tangent),
                   'relative_error': _num(k2_measured / k2_tangent - 1.0) if k2_tangent else None,
                   'U': _num(k2_u), 'U_low': _num(k2_measured - k2_u), 'U_high': _num(k2_measured + k2_u)},
            'uncertainty': statement, 'statistical_only': values.get('statistical_only') == 'true' and bool(statement),
            'rows': rows}


#: The channel's JSON schema (every field typed: see crane_stiffness.view.jsonschema).
SCHEMA = js.obj({
    'fit': js.BOOLEAN, 'level': js.INTEGER, 'level_name': js.STRING, 'message': js.STRING,
    'k2': js.obj({k: js.NUMBER for k in ('measured', 'ci95_low', 'ci95_high', 'tangent', 'relative_error', 'U',
                                         'U_low', 'U_high')}),
    'uncertainty': js.STRING, 'statistical_only': js.BOOLEAN,
    'rows': js.array(js.obj({'load': js.STRING, 'cells': js.array(js.obj({
        'displacement': js.STRING, 'measured': js.NUMBER, 'ci95_low': js.NUMBER, 'ci95_high': js.NUMBER,
        'tangent': js.NUMBER, 'relative_error': js.NUMBER, 'model_zero': js.BOOLEAN, 'U': js.NUMBER,
        'U_low': js.NUMBER, 'U_high': js.NUMBER}))}))},
    'crane_stiffness.Stiffness6')

__all__ = ['SCHEMA', 'expanded_uncertainty', 'stiffness6_message']
