"""The plot's messages (dicts for JSON): the force–displacement points of the current fit segment, decimated for
display only (the estimator fits every pair), the fit line of each branch with its 95 % band, the model's prediction
as a line, the live estimate and the status. Pure numpy, no ROS.

Units: displacement x in m (rad for a moment axis), force y in N (N·m), stiffness in N/m (N·m/rad), stamps in s.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from crane_stiffness.estimation.branch import BRANCHES
from crane_stiffness.estimation.fit_lines import FIT_LINE_FIELDS, band
from crane_stiffness.estimation.live import PAIR_FIELDS, VALUE_FIELDS
from crane_stiffness.contract.status import NAMES, overall, read_level
from crane_stiffness.view import jsonschema as js
from crane_stiffness.view.errors import ViewError

#: Points along each drawn fit line and band.
LINE_POINTS = 21
_STAMP, _X, _Y, _BRANCH, _SEGMENT = (PAIR_FIELDS.index(f) for f in PAIR_FIELDS)


def _num(value: float) -> float | None:
    """A float for JSON (NaN and Inf are not JSON: None)."""
    return float(value) if math.isfinite(value) else None


class PointBuffer:
    """The fitted pairs of the current segment for display: every ``stride``-th pair, the stride doubling (and every
    other point kept) whenever more than ``capacity`` are held; a new segment starts afresh."""

    def __init__(self, capacity: int) -> None:
        if capacity < 2:
            raise ViewError(f'max_points = {capacity}: must be >= 2')
        self.capacity = int(capacity)
        self.segment = math.nan
        self.stride = 1
        self.seen = 0  # pairs of this segment received
        self.rows = np.empty((0, len(PAIR_FIELDS)))

    def add(self, data: Sequence[float]) -> None:
        """Rows × PAIR_FIELDS, row-major (a /stiffness/fitted_pairs message's data)."""
        rows = np.asarray(data, dtype=float).reshape(-1, len(PAIR_FIELDS))
        if not rows.size:
            return
        segments = rows[:, _SEGMENT]
        changed = np.flatnonzero(segments != np.r_[self.segment, segments[:-1]])
        if changed.size:  # a new segment: its pairs alone
            rows = rows[changed[-1]:]
            self.segment, self.stride, self.seen = float(rows[0, _SEGMENT]), 1, 0
            self.rows = np.empty((0, len(PAIR_FIELDS)))
        index = self.seen + np.arange(len(rows))
        self.seen += len(rows)
        self.rows = np.vstack([self.rows, rows[index % self.stride == 0]])
        while len(self.rows) > self.capacity:
            self.rows = self.rows[::2]
            self.stride *= 2

    def message(self, fit_lines: Sequence[float] | None = None, prediction: float = math.nan) -> dict[str, Any]:
        """``{segment, stride, pairs, loading: [{t, x, y, fit, lower, upper, prediction}], unloading: [...]}``: the
        points of each branch, each with its branch's fit line and 95 % band and the prediction line at its x (None
        where there is none), so an XY plot of one message draws points, fit and prediction on one x path."""
        out: dict[str, Any] = {'segment': _num(self.segment), 'stride': self.stride, 'pairs': self.seen}
        lines = _rows(fit_lines, FIT_LINE_FIELDS) if fit_lines is not None else {}
        for i, branch in enumerate(BRANCHES):
            rows = self.rows[self.rows[:, _BRANCH] == i]
            x = rows[:, _X]
            nan = np.full(len(x), np.nan)
            fit, lower, upper = band(lines[branch], x) if branch in lines else (nan, nan, nan)
            pred = _prediction_at(prediction, fit_lines, x)
            out[branch] = [{'t': t, 'x': xi, 'y': y, 'fit': _num(f), 'lower': _num(lo), 'upper': _num(hi),
                            'prediction': _num(p)}
                           for t, xi, y, f, lo, hi, p in zip(rows[:, _STAMP].tolist(), x.tolist(),
                                                             rows[:, _Y].tolist(), fit.tolist(), lower.tolist(),
                                                             upper.tolist(), pred.tolist())]
        return out


def _prediction_at(prediction: float, fit_lines: Sequence[float] | None, x: np.ndarray) -> np.ndarray:
    """The prediction line (slope ``prediction``, through the loading fit's centroid, else the origin) at ``x``."""
    x0, y0 = 0.0, 0.0
    if fit_lines is not None:
        row = _rows(fit_lines, FIT_LINE_FIELDS)[BRANCHES[0]]
        if math.isfinite(row['x_mean']) and math.isfinite(row['stiffness']):
            x0, y0 = row['x_mean'], row['stiffness'] * row['x_mean'] + row['intercept']
    return y0 + prediction * (x - x0)


def _rows(data: Sequence[float], fields: Sequence[str]) -> dict[str, dict[str, float]]:
    n = len(fields)
    if len(data) != n * len(BRANCHES):
        raise ViewError(f'{len(data)} values: expected {len(BRANCHES)} rows of {n}')
    return {b: dict(zip(fields, map(float, data[i * n:(i + 1) * n]))) for i, b in enumerate(BRANCHES)}


def fit_lines_message(data: Sequence[float]) -> dict[str, Any]:
    """Each branch's line and 95 % band as polylines ``[{x, y}]`` over its window's x range, from a
    /stiffness/fit_lines message's data (rows × FIT_LINE_FIELDS); a branch without a fit has empty lines."""
    out: dict[str, Any] = {}
    for branch, row in _rows(data, FIT_LINE_FIELDS).items():
        entry: dict[str, Any] = {k: _num(row[k]) for k in ('stiffness', 'intercept', 'x_mean', 'n')}
        if all(math.isfinite(v) for v in row.values()) and row['n'] > 2 and row['stderr'] >= 0:
            x = np.linspace(row['x_min'], row['x_max'], LINE_POINTS)
            line, lower, upper = band(row, x)
            for name, y in (('line', line), ('lower', lower), ('upper', upper)):
                entry[name] = [{'x': a, 'y': b} for a, b in zip(x.tolist(), y.tolist())]
        else:
            entry.update(line=[], lower=[], upper=[])
        out[branch] = entry
    return out


def prediction_message(prediction: float, fit_lines: Sequence[float] | None,
                       x_range: tuple[float, float] | None) -> dict[str, Any]:
    """The model's prediction as a line of slope ``prediction`` over ``x_range`` (m), through the loading fit's
    centroid (so its slope reads against the fit's), else through the origin; no line without a prediction."""
    out: dict[str, Any] = {'stiffness': _num(prediction), 'line': []}
    if not math.isfinite(prediction) or x_range is None:
        return out
    x = np.asarray(x_range, dtype=float)
    out['line'] = [{'x': a, 'y': b} for a, b in zip(x.tolist(), _prediction_at(prediction, fit_lines, x).tolist())]
    return out


def estimate_message(values: Sequence[float], uncertainty: Mapping[str, Mapping[str, str]] | None = None
                     ) -> dict[str, Any]:
    """The live estimate per branch from a /stiffness/estimate_values message's data (rows × VALUE_FIELDS), with
    each branch's measurement uncertainty from its status on /stiffness/estimate (``uncertainty``: {branch: the
    status's key/values}, :func:`branch_uncertainty`): U [k's unit], U_low and U_high = k ∓ U (the expanded interval
    beside ci95_*, the repeatability), coverage_factor, En, prediction_U (None: not stated) and statistical_only
    (True: no calibration counted in U)."""
    rows = _rows(values, VALUE_FIELDS)
    out: dict[str, Any] = {}
    for b, row in rows.items():
        entry: dict[str, Any] = {k: _num(row[k]) for k in _ESTIMATE_FIELDS}
        kv = (uncertainty or {}).get(b, {})
        big_u = _number(kv.get('U'))
        entry.update(U=_num(big_u), U_low=_num(row['stiffness'] - big_u), U_high=_num(row['stiffness'] + big_u),
                     coverage_factor=_num(_number(kv.get('coverage_factor'))), En=_num(_number(kv.get('En'))),
                     prediction_U=_num(_number(kv.get('prediction_U'))),
                     statistical_only=kv.get('statistical_only') == 'true')
        out[b] = entry
    return out


def _number(text: str | None) -> float:
    """A status value as a number (NaN when absent or not a number)."""
    try:
        return float(text) if text is not None else math.nan
    except ValueError:
        return math.nan


def branch_uncertainty(statuses: Sequence[tuple[str, Mapping[str, str]]]) -> dict[str, dict[str, str]]:
    """{branch: key/values} of the branch statuses of /stiffness/estimate ((name, key/values) per status; a branch
    status is named '<node>: loading' or '<node>: unloading')."""
    return {name.rsplit(': ', 1)[-1]: dict(values) for name, values in statuses
            if name.rsplit(': ', 1)[-1] in BRANCHES}


def status_message(statuses: Sequence[tuple[str, int, str]], axis: tuple[str, str] | None = None
                   ) -> dict[str, Any]:
    """The estimator's status (/stiffness/estimate: (name, level, message) per status, as published) as text and
    level: each status, its level read back (:func:`~crane_stiffness.contract.status.read_level`: WAITING for a part
    that has
    not begun), and the overall level (:func:`~crane_stiffness.contract.status.overall`: the worst of the parts, a
    waiting
    part never worse than those running). ``axis``: (fitted axis, stiffness unit) as the estimator's status names
    them ('' until known)."""
    levels = [read_level(published, message) for _, published, message in statuses]
    items = [{'name': name, 'level': lvl, 'level_name': NAMES.get(lvl, str(lvl)), 'message': message}
             for (name, _, message), lvl in zip(statuses, levels)]
    level = overall(levels)
    text = '\n'.join(f'{i["name"]}: {i["level_name"]} {i["message"]}' for i in items)
    axis_name, unit = axis if axis is not None else ('', '')
    return {'level': level, 'level_name': NAMES.get(level, str(level)), 'text': text, 'statuses': items,
            'axis': axis_name, 'unit': unit}


def wires_message(names: Sequence[str], lengths: Sequence[float], tensions: Sequence[float],
                  slack_n: float) -> dict[str, Any]:
    """Wire lengths [m] and tensions [N] from /crane/wire_states, and which are slack (tension <= ``slack_n``)."""
    return {'wires': [{'name': n, 'length': _num(float(length)), 'tension': _num(float(t)), 'slack': not t > slack_n}
                      for n, length, t in zip(names, lengths, tensions)]}


_POINTS = js.array(js.obj({'x': js.NUMBER, 'y': js.NUMBER}))
_XY_POINTS = js.array(js.obj({k: js.NUMBER for k in ('t', 'x', 'y', 'fit', 'lower', 'upper', 'prediction')}))
_ESTIMATE_FIELDS = ('stiffness', 'ci95_low', 'ci95_high', 'r2', 'n', 'prediction', 'relative_error', 'current',
                    'sample_stamp')
_UNCERTAINTY_FIELDS = ('U', 'U_low', 'U_high', 'coverage_factor', 'En', 'prediction_U')
#: JSON schemas of the derived channels: every field the messages carry, typed: what Foxglove's panels offer as
#: paths (e.g. ``/live_view/estimate.loading.stiffness``); a field without a type makes the apps refuse the channel.
SCHEMAS: dict[str, dict[str, Any]] = {
    'xy': js.obj({'segment': js.NUMBER, 'stride': js.INTEGER, 'pairs': js.INTEGER, 'loading': _XY_POINTS,
                  'unloading': _XY_POINTS}, 'crane_stiffness.ForceDisplacement'),
    'fit_lines': js.obj({b: js.obj({'stiffness': js.NUMBER, 'intercept': js.NUMBER, 'x_mean': js.NUMBER,
                                    'n': js.NUMBER, 'line': _POINTS, 'lower': _POINTS, 'upper': _POINTS})
                         for b in BRANCHES}, 'crane_stiffness.FitLines'),
    'prediction': js.obj({'stiffness': js.NUMBER, 'line': _POINTS}, 'crane_stiffness.PredictionLine'),
    'estimate': js.obj({b: js.obj({**{k: js.NUMBER for k in _ESTIMATE_FIELDS + _UNCERTAINTY_FIELDS},
                                   'statistical_only': js.BOOLEAN}) for b in BRANCHES},
                       'crane_stiffness.Estimate'),
    'status': js.obj({'level': js.INTEGER, 'level_name': js.STRING, 'text': js.STRING,
                      'statuses': js.array(js.obj({'name': js.STRING, 'level': js.INTEGER, 'level_name': js.STRING,
                                                   'message': js.STRING})),
                      'axis': js.STRING, 'unit': js.STRING}, 'crane_stiffness.Status'),
    'wires': js.obj({'wires': js.array(js.obj({'name': js.STRING, 'length': js.NUMBER, 'tension': js.NUMBER,
                                               'slack': js.BOOLEAN}))}, 'crane_stiffness.Wires'),
}
