"""The live estimate checked offline: the live estimator's last published window and RLS values beside the same fits
recomputed from the bag's pairs (:func:`live_comparison`), and whether the estimator saw what the bag holds. Pure: no
ROS import."""
from __future__ import annotations

import math

import numpy as np

from crane_stiffness.analysis.load import SessionData
from crane_stiffness.analysis.results import COMPARED_FIELDS, WINDOW_FIT_FIELDS, LiveComparison
from crane_stiffness.estimation.branch import BRANCHES, LOADING
from crane_stiffness.estimation.fit import fit_or_none
from crane_stiffness.estimation.rls import RecursiveLeastSquares
from crane_stiffness.estimation.live import VALUE_FIELDS
from crane_stiffness.estimation.live_pairs import LivePairs

#: Pairs of a branch fed to the recursive least squares for the live comparison (its memory is ~1/(1-λ)).
RLS_REPLAY_PAIRS = 20_000


def _window_fit(pairs: LivePairs, cut: int, branch: str, window: int, forgetting: float,
                x_noise: float) -> dict[str, float]:
    """The live estimator's window and RLS fits of ``branch`` over the pairs before ``cut``, the window's counting
    the displacement noise ``x_noise`` the live estimate says it counted."""
    sel = np.flatnonzero(pairs.loading[:cut] == (branch == LOADING))
    nan = math.nan
    out = {k: nan for k in COMPARED_FIELDS}
    if sel.size < 3:
        return out
    last = sel[-window:]
    fit = fit_or_none(pairs.displacement[last], pairs.force[last], x_noise)
    if fit is not None:
        out.update({k: float(getattr(fit, k)) for k in WINDOW_FIT_FIELDS})
    else:  # no estimate (too few pairs, no spread beyond the noise): the noise it was judged with
        out['x_noise'] = x_noise
    rls = RecursiveLeastSquares(forgetting)
    tail = sel[-RLS_REPLAY_PAIRS:]
    for x, y in zip(pairs.displacement[tail].tolist(), pairs.force[tail].tolist()):
        rls.add(x, y)
    result = rls.result()
    out['rls_stiffness'] = nan if result is None else result.stiffness
    return out


def live_comparison(data: SessionData, pairs: LivePairs) -> LiveComparison | None:
    """The last recorded live estimate beside the same window fits of the bag's pairs up to its newest pair (None
    without a recorded live estimate)."""
    if data.live_values is None:
        return None
    log, rows = data.live_values
    s = data.settings
    index = {f: i for i, f in enumerate(VALUE_FIELDS)}
    stamp = float(rows[0, index['sample_stamp']])
    cut = int(np.searchsorted(pairs.stamp, stamp, side='right')) if math.isfinite(stamp) else pairs.stamp.size
    live: dict[str, dict[str, float]] = {}
    offline: dict[str, dict[str, float]] = {}
    worst: dict[str, float] = {}
    for b, branch in enumerate(BRANCHES):
        live[branch] = {f: float(rows[b, index[f]]) for f in COMPARED_FIELDS}
        x_noise = live[branch]['x_noise']
        offline[branch] = _window_fit(pairs, cut, branch, s.window, s.forgetting,
                                      x_noise if math.isfinite(x_noise) and x_noise >= 0.0 else 0.0)
        diffs = []
        for f in WINDOW_FIT_FIELDS:
            a, o = live[branch][f], offline[branch][f]
            if math.isfinite(a) and math.isfinite(o):
                diffs.append(abs(o - a) / max(abs(a), 1e-300) if f not in ('intercept',) else
                             abs(o - a) / max(abs(live[branch]['residual_rms']), abs(a), 1e-300))
            elif math.isfinite(a) != math.isfinite(o):
                diffs.append(math.inf)  # one has a value, the other none: not reproduced
        # no field with a value on either side: neither has an estimate of the branch (e.g. a window in one hold,
        # no spread beyond the noise), which they agree on
        both_none = all(not math.isfinite(live[branch][f]) and not math.isfinite(offline[branch][f])
                        for f in WINDOW_FIT_FIELDS)
        worst[branch] = max(diffs) if diffs else (0.0 if both_none else math.nan)
    comparison = LiveComparison(sample_stamp_s=stamp, log_time_s=log * 1e-9, live=live, offline=offline,
                                max_rel_diff=worst)
    if len(data.live_inputs) == 2:
        (t_a, first), (t_b, last) = data.live_inputs
        try:
            received = int(last['force_received']) - int(first['force_received'])
            paired = int(last['pairs']) - int(first['pairs'])
        except (KeyError, ValueError):
            return comparison
        assert data.force is not None  # a required topic: load_session decoded it
        in_bag = int(((data.force['log_time_ns'] > t_a) & (data.force['log_time_ns'] <= t_b)).sum())
        offline_pairs = int(((pairs.fit_log > t_a) & (pairs.fit_log <= t_b)).sum())
        comparison.inputs = {'from_s': t_a * 1e-9, 'to_s': t_b * 1e-9, 'live_force_received': received,
                             'bag_force_messages': in_bag, 'live_pairs': paired, 'offline_pairs': offline_pairs}
        if data.disp is not None and 'displacement_received' in last and 'displacement_received' in first:
            comparison.inputs['live_displacement_received'] = (int(last['displacement_received'])
                                                               - int(first['displacement_received']))
            comparison.inputs['bag_displacement_messages'] = int(((data.disp['log_time_ns'] > t_a)
                                                                  & (data.disp['log_time_ns'] <= t_b)).sum())
    return comparison


__all__ = ['RLS_REPLAY_PAIRS', 'live_comparison']
