"""How often a campaign's 95 % intervals cover the truth, quantity by quantity, with a binomial interval on that
fraction: the check that the intervals the rig and ``analyze`` state mean what they say (a coverage study is a
campaign of many seeded sessions of one set-up: ``config/campaign_coverage.yaml``, ``campaign_coverage_gum.yaml``,
``campaign_coverage_full.yaml``).

The truth of a session is the **true** crane's exact tangent at rest along the series' axis (in the LVDT's reading
units, as the campaign's rows): the crane the simulated rig ran (the plan's ``true``, recorded as the session's
campaign entry ``true_geometry``; the nominal crane's tangent when the two are the same), never anything the
analysis read. The quantities of a one-axis series, per branch (loading, unloading):

- ``k <series> <branch>``: the samples' fit's 95 % interval (the live estimator's, statistical only);
- ``k <series> <branch>, repeatability``: the 95 % interval of the fit the measurement uncertainty starts from
  (the hold means' when there are holds: ``analyze``'s "statistical 95 % CI (repeatability)"), statistical only;
- ``k <series> <branch>, GUM U``: the expanded interval k ± U (the fit and the sensors' declared calibrations,
  :mod:`crane_stiffness.uncertainty.measurement`);

and per session ``prediction <series>, GUM U`` (the model's prediction of the nominal crane ± its U, as E_n uses it)
and ``prediction <series>, Monte Carlo`` (the prediction's JCGM 101 95 % interval, for a set-up of
:data:`MONTE_CARLO_SESSIONS` sessions or more): how often the model's interval holds the true crane's tangent. For
the series full: each of the 36 entries of K against the tangent and of C = K⁻¹ against the tangent's inverse, and
the coupling K2 against the tangent's. Each session counts once per quantity: a session without that interval (no
fit) is left out of its total. The fraction's interval is Clopper–Pearson's (exact, two-sided 95 %): a fraction
whose interval leaves out 0.95 is a departure to explain.
Reads the analyses ``campaign analyze`` wrote; no ROS.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from crane_stiffness.contract.axes import AXES
from crane_stiffness.campaign.rows import Full6Row, SessionRow

#: The intervals' nominal coverage.
NOMINAL = 0.95
#: Sessions of one set-up from which the prediction's Monte Carlo interval (~1 s per set-up) is computed and counted.
MONTE_CARLO_SESSIONS = 10
#: The deflections the columns of K (and rows of C) stand for.
DEFLECTIONS = ('ux', 'uy', 'uz', 'thx', 'thy', 'thz')


@dataclass(frozen=True)
class Coverage:
    """One quantity's coverage over the campaign's sessions."""

    quantity: str
    covered: int
    total: int

    @property
    def fraction(self) -> float:
        return self.covered / self.total if self.total else math.nan

    @property
    def interval(self) -> tuple[float, float]:
        """The fraction's Clopper–Pearson 95 % interval."""
        return binomial_interval(self.covered, self.total)

    @property
    def consistent(self) -> bool:
        """The nominal 0.95 lies in the fraction's interval."""
        low, high = self.interval
        return low <= NOMINAL <= high


def binomial_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper–Pearson) two-sided interval of a binomial fraction ``k`` of ``n`` at ``level``."""
    from scipy.stats import beta
    if n <= 0 or not 0 <= k <= n:
        raise ValueError(f'k = {k}, n = {n}: need 0 <= k <= n and n >= 1')
    alpha = 1.0 - level
    low = 0.0 if k == 0 else float(beta.ppf(alpha / 2, k, n - k + 1))
    high = 1.0 if k == n else float(beta.ppf(1 - alpha / 2, k + 1, n - k))
    return low, high


def _count(counts: dict[str, list[int]], quantity: str, covers: Any) -> None:
    if covers is None:
        return
    tally = counts.setdefault(quantity, [0, 0])
    tally[0] += int(bool(covers))
    tally[1] += 1


def true_tangent(row: SessionRow, model: dict[str, Any]) -> float:
    """The truth of a one-axis session: the true crane's exact tangent at rest along the series' axis, in the LVDT's
    reading units (the analysis' own nominal tangent when the true crane is the nominal one)."""
    scale = _float(model.get('lvdt_scale', 1.0))
    if not row.true or row.true == row.nominal:
        return _float(model.get('tangent_at_rest')) * scale
    from crane_stiffness.params.geometry import geometry_from_params
    from crane_stiffness.uncertainty.prediction import point_prediction
    return point_prediction(geometry_from_params(row.true), row.series) * scale


def _covers(interval: Any, truth: float) -> bool | None:
    """Whether ``interval`` ([low, high], finite) holds ``truth``; None without an interval or a truth."""
    if not isinstance(interval, (list, tuple)) or len(interval) != 2:
        return None
    low, high = _float(interval[0]), _float(interval[1])
    if not (math.isfinite(low) and math.isfinite(high) and math.isfinite(truth)):
        return None
    return low <= truth <= high


def prediction_intervals(analysis: dict[str, Any], nominal: dict[str, Any], cache: dict[str, Any]
                         ) -> dict[str, list[float] | None]:
    """The prediction's intervals in the LVDT's reading units: 'GUM U' (value ± U, as E_n uses it) and 'Monte Carlo'
    (JCGM 101's 95 % interval: the analysis' own when it ran one, else computed here, seed 0, once per crane
    ``nominal`` (the ``geometry.*`` parameters the analysis modelled) and uncertainty file)."""
    prediction = ((analysis.get('uncertainty') or {}).get('prediction')) or {}
    result = prediction.get('uncertainty') or {}
    scale = _float(prediction.get('lvdt_scale', 1.0))
    if not result:
        return {'GUM U': None, 'Monte Carlo': None}
    value, big_u = _float(result.get('value')), _float(result.get('U'))
    gum = sorted([(value - big_u) * scale, (value + big_u) * scale])
    mc = (result.get('monte_carlo') or {}).get('interval')
    if mc is None:
        key = set_up_key(nominal, prediction)
        if key not in cache:
            cache[key] = _monte_carlo_interval(nominal, prediction)
        mc = cache[key]
    return {'GUM U': gum, 'Monte Carlo': None if mc is None else sorted(_float(v) * scale for v in mc)}


def set_up_key(nominal: dict[str, Any], prediction: dict[str, Any]) -> str:
    """The prediction's set-up: the crane modelled, the axis and the uncertainty file."""
    return json.dumps([nominal, prediction.get('axis'), prediction.get('uncertainty_file')], sort_keys=True,
                      default=str)


def _monte_carlo_interval(nominal: dict[str, Any], prediction: dict[str, Any]) -> list[float] | None:
    """The prediction's Monte Carlo 95 % interval for the crane ``nominal`` (None when it cannot be had)."""
    from crane_stiffness.errors import CraneStiffnessError
    from crane_stiffness.params.geometry import geometry_from_params
    from crane_stiffness.campaign.true_draw import uncertainty_entries
    from crane_stiffness.uncertainty.prediction import predict_stiffness
    if not nominal or not prediction.get('uncertainty_file'):
        return None
    try:
        geometry = geometry_from_params(nominal)
        entries = uncertainty_entries(prediction['uncertainty_file'], geometry)
        mc = predict_stiffness(geometry, prediction['axis'], uncertainty=entries, seed=0).monte_carlo
    except (CraneStiffnessError, OSError, ValueError):
        return None
    return None if mc is None else [float(v) for v in mc['interval']]


def campaign_coverage(rows: Sequence[SessionRow], full: Sequence[Full6Row]) -> list[Coverage]:
    """Every quantity's coverage over the analysed sessions (the rows ``campaign analyze`` made; each row's
    analysis file is read for its intervals, the row's true crane for the truth)."""
    counts: dict[str, list[int]] = {}
    cache: dict[str, Any] = {}
    analyses = [json.loads((Path(row.analysis) / 'analysis.json').read_text()) for row in rows]
    sessions: dict[str, int] = {}  # per set-up of the prediction
    for row, analysis in zip(rows, analyses):
        prediction = (analysis.get('uncertainty') or {}).get('prediction') or {}
        if prediction:
            key = set_up_key(row.nominal, prediction)
            sessions[key] = sessions.get(key, 0) + 1
    for row, analysis in zip(rows, analyses):
        model = analysis.get('model') or {}
        truth = true_tangent(row, model)
        prediction = (analysis.get('uncertainty') or {}).get('prediction') or {}
        if prediction and sessions.get(set_up_key(row.nominal, prediction), 0) < MONTE_CARLO_SESSIONS:
            cache.setdefault(set_up_key(row.nominal, prediction), None)  # a set-up of a few sessions: no study
        uncertainty = analysis.get('uncertainty') or {}
        for branch in ('loading', 'unloading'):
            fit = (analysis.get('branch_fits') or {}).get(branch) or {}
            _count(counts, f'k {row.series} {branch}', _covers([fit.get('ci95_low'), fit.get('ci95_high')], truth))
            entry = uncertainty.get(branch) or {}
            _count(counts, f'k {row.series} {branch}, repeatability', _covers(entry.get('ci95'), truth))
            _count(counts, f'k {row.series} {branch}, GUM U',
                   _covers((entry.get('uncertainty') or {}).get('interval'), truth))
        if uncertainty.get('prediction'):
            for method, interval in prediction_intervals(analysis, row.nominal, cache).items():
                _count(counts, f'prediction {row.series}, {method}', _covers(interval, truth))
    for quantity in [q for q in counts if q.endswith(', Monte Carlo')]:
        if counts[quantity][1] < MONTE_CARLO_SESSIONS:  # no study: not worth its Monte Carlo runs
            del counts[quantity]
    for frow in full:
        analysis = json.loads((Path(frow.analysis) / 'full6.json').read_text())
        truths = true_matrices(frow, analysis)
        if truths is None:
            continue
        for name, key in (('K', 'stiffness'), ('C', 'compliance')):
            matrices = analysis.get(key) or {}
            covers = _inside([matrices.get('low'), matrices.get('high')], truths[name])
            if covers is not None:
                _count_matrix(counts, '', name, covers)
        k2 = analysis.get('k2') or {}
        _count(counts, 'K2', _covers([k2.get('low'), k2.get('high')], truths['K2']))
        _count_gum(counts, analysis, truths)
        _count_prediction(counts, analysis, truths)
    return [Coverage(q, c, n) for q, (c, n) in counts.items()]


def _entry_label(name: str, i: int, j: int) -> str:
    """K[<load>,<deflection>] or C[<deflection>,<load>]."""
    return f'{name}[{AXES[i]},{DEFLECTIONS[j]}]' if name == 'K' else f'{name}[{DEFLECTIONS[i]},{AXES[j]}]'


def _count_matrix(counts: dict[str, list[int]], prefix: str, name: str, covers: list[list[bool]],
                  per_entry: bool = True) -> None:
    """A 6×6 ``covers`` of K or C (``name``) counted entry by entry under '<prefix> K[<load>,<deflection>]', or
    pooled under '<prefix> K (36 pooled)'."""
    lead = f'{prefix} ' if prefix else ''
    for i in range(6):
        for j in range(6):
            _count(counts, f'{lead}{_entry_label(name, i, j)}' if per_entry else f'{lead}{name} (36 pooled)',
                   covers[i][j])


def true_matrices(row: Full6Row, analysis: dict[str, Any]) -> dict[str, Any] | None:
    """The truth of a six-axis session: the true crane's exact tangent K at rest, C = K⁻¹ and K2 (the analysis' own
    nominal reference when the true crane is the nominal one; None without either)."""
    if row.true and row.true != row.nominal:
        import numpy as np
        from crane_stiffness.full6.reference import k2_of
        from crane_stiffness.model.equilibrium import rest_pose
        from crane_stiffness.model.stiffness import tangent_stiffness
        from crane_stiffness.params.geometry import geometry_from_params
        geometry = geometry_from_params(row.true)
        k = tangent_stiffness(geometry, rest_pose(geometry))
        return {'K': k.tolist(), 'C': np.linalg.inv(k).tolist(), 'K2': k2_of(k)}
    reference = analysis.get('reference') or {}
    if not reference:
        return None
    return {'K': reference.get('tangent'), 'C': reference.get('compliance'),
            'K2': _float((analysis.get('k2') or {}).get('tangent'))}


def _inside(interval: Any, truth: Any) -> list[list[bool]] | None:
    """Entry by entry, whether [low, high] (two 6×6 lists, or two numbers) holds ``truth``; None when missing."""
    import numpy as np
    if not interval or truth is None:
        return None
    low, high, t = (np.asarray(x, dtype=float) for x in (interval[0], interval[1], truth))
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        return None
    return ((low <= t) & (t <= high)).tolist()


def _count_gum(counts: dict[str, list[int]], analysis: dict[str, Any], truth: dict[str, Any],
               kinds: tuple[str, ...] = ('U',), per_entry: bool = True) -> None:
    """The six-axis session's GUM intervals (full6.json's ``uncertainty``, crane_stiffness.analysis.full6_uncertainty)
    against the truth (:func:`true_matrices`). Per entry (``per_entry``): 'U K[..]' of K (the expanded interval
    value ± U), 'U C[..]', and 'U K2', 'stat K2' (the statistical-only interval). Pooled over the 36 entries (not
    ``per_entry``): '<kind> K (36 pooled)', '<kind> C (36 pooled)' for each of ``kinds``: 'U', 'stat' (value ± t·u_a),
    'MC' (the JCGM 102 Monte Carlo's interval)."""
    u = analysis.get('uncertainty') or {}
    if not u:
        return
    for name, key in (('K', 'stiffness'), ('C', 'compliance')):
        entries = u.get(key) or {}
        intervals = {'U': entries.get('interval'), 'stat': entries.get('statistical_interval'),
                     'MC': (entries.get('monte_carlo') or {}).get('interval')}
        for kind in kinds:
            covers = _inside(intervals[kind], truth[name])
            if covers is None:
                continue
            _count_matrix(counts, kind, name, covers, per_entry)
    if per_entry:
        k2 = u.get('k2') or {}
        for kind, interval in (('U', k2.get('interval')), ('stat', k2.get('statistical_interval'))):
            covers = _inside(interval, truth['K2'])
            if covers is not None:
                _count(counts, f'{kind} K2', covers)


def _prediction_intervals(analysis: dict[str, Any]) -> dict[str, Any]:
    """The model's 6×6 prediction's intervals (full6.json's ``uncertainty.prediction``,
    crane_stiffness.uncertainty.prediction6): 'U K' and 'U C' (value ± U per entry, as E_n uses them), 'MC K' (the
    Monte Carlo's probabilistically symmetric 95 % interval per entry) and 'U K2'; {} without a prediction."""
    import numpy as np
    prediction = (analysis.get('uncertainty') or {}).get('prediction') or {}
    if not prediction:
        return {}
    out: dict[str, Any] = {}
    for name, key in (('K', 'stiffness'), ('C', 'compliance')):
        part = prediction.get(key) or {}
        if part.get('value') is not None and part.get('U') is not None:
            value, big_u = np.asarray(part['value'], dtype=float), np.asarray(part['U'], dtype=float)
            out[f'U {name}'] = [(value - big_u).tolist(), (value + big_u).tolist()]
    interval = (prediction.get('stiffness') or {}).get('interval')
    if interval is not None:
        out['MC K'] = interval
    k2 = prediction.get('k2') or {}
    if k2.get('value') is not None and k2.get('U') is not None:
        out['U K2'] = [_float(k2['value']) - _float(k2['U']), _float(k2['value']) + _float(k2['U'])]
    return out


def _count_prediction(counts: dict[str, list[int]], analysis: dict[str, Any], truth: dict[str, Any],
                      per_entry: bool = True) -> None:
    """The model's 6×6 prediction (of the nominal crane) against the true crane's tangent: per entry 'prediction U
    K[..]', 'prediction MC K[..]', 'prediction U C[..]' and 'prediction U K2'; pooled (not ``per_entry``)
    'prediction <kind> K (36 pooled)', 'prediction U C (36 pooled)'."""
    for kind, interval in _prediction_intervals(analysis).items():
        method, name = kind.split()
        if name == 'K2':
            if per_entry:
                _count(counts, 'prediction U K2', _covers(interval, truth['K2']))
            continue
        covers = _inside(interval, truth[name])
        if covers is None:
            continue
        _count_matrix(counts, f'prediction {method}', name, covers, per_entry)


def pooled_gum_coverage(full: Sequence[Full6Row]) -> list[Coverage]:
    """Pooled over the 36 entries of K and of C, the sessions' expanded ('U'), statistical-only ('stat') and
    Monte Carlo ('MC') intervals that hold the truth, and the model's prediction's (see :func:`_count_gum`,
    :func:`_count_prediction`). A pooled count's 36 entries of one session share its calibration errors (and its
    true crane), so its binomial interval is narrower than it should be; the per-entry counts of
    :func:`campaign_coverage` are the exact ones."""
    counts: dict[str, list[int]] = {}
    for frow in full:
        analysis = json.loads((Path(frow.analysis) / 'full6.json').read_text())
        truth = true_matrices(frow, analysis)
        if truth is None:
            continue
        _count_gum(counts, analysis, truth, ('U', 'MC', 'stat'), per_entry=False)
        _count_prediction(counts, analysis, truth, per_entry=False)
    return [Coverage(q, c, n) for q, (c, n) in counts.items()]


def _float(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def write_coverage(coverage: Sequence[Coverage], target: Path, formats: Sequence[str] = ('png',),
                   full: Sequence[Full6Row] = ()) -> list[str]:
    """``coverage.csv`` and the figure ``coverage.<fmt>`` (each quantity's fraction with its interval against
    0.95) in ``target``, and for a six-axis study's GUM intervals (the analyses of ``full``) the pooled fractions
    ``coverage_gum_pooled.csv`` (:func:`pooled_gum_coverage`) and ``coverage_gum.<fmt>``
    (crane_stiffness.campaign.full_figures.gum_coverage_figure); the files written."""
    target.mkdir(parents=True, exist_ok=True)
    path = target / 'coverage.csv'
    with open(path, 'w', newline='') as f:
        writer = csv.writer(f)
        writer.writerow(['quantity', 'covered', 'sessions', 'fraction', 'ci95_low', 'ci95_high', 'consistent_with_95'])
        for c in coverage:
            low, high = c.interval
            writer.writerow([c.quantity, c.covered, c.total, f'{c.fraction:.4f}', f'{low:.4f}', f'{high:.4f}',
                             c.consistent])
    files = [str(path)]
    if coverage:
        files += _figure(coverage, target, formats)
    if any(c.quantity.startswith('U K[') for c in coverage):  # a six-axis study's GUM intervals
        from crane_stiffness.campaign.full_figures import gum_coverage_figure
        pooled = pooled_gum_coverage(full)
        path = target / 'coverage_gum_pooled.csv'
        with open(path, 'w', newline='') as f:
            writer = csv.writer(f)
            writer.writerow(['quantity', 'covered', 'entries', 'fraction', 'ci95_low', 'ci95_high'])
            for c in pooled:
                writer.writerow([c.quantity, c.covered, c.total, f'{c.fraction:.4f}', *(f'{v:.4f}' for v in
                                                                                        c.interval)])
        files.append(str(path))
        files += gum_coverage_figure([(c.quantity, c.covered, c.total, *c.interval) for c in [*coverage, *pooled]],
                                     target, formats)
    return files


def _figure(coverage: Sequence[Coverage], target: Path, formats: Sequence[str]) -> list[str]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    n = len(coverage)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.16 * n + 2.5), 4.2), layout='constrained')
    x = list(range(n))
    fractions = [c.fraction for c in coverage]
    lows = [c.fraction - c.interval[0] for c in coverage]
    highs = [c.interval[1] - c.fraction for c in coverage]
    colours = ['tab:blue' if c.consistent else 'tab:red' for c in coverage]
    ax.errorbar(x, fractions, yerr=[lows, highs], fmt='none', ecolor='0.5', capsize=2)
    ax.scatter(x, fractions, c=colours, s=14, zorder=3)
    ax.axhline(NOMINAL, color='k', lw=0.8, ls='--', label='nominal 0.95')
    ax.set_xticks(x, [c.quantity for c in coverage], rotation=90, fontsize=6 if n > 20 else 8)
    ax.set_ylabel('fraction covering the truth')
    ax.set_ylim(max(0.0, min(c.interval[0] for c in coverage) - 0.05), 1.01)
    sessions = sorted({c.total for c in coverage})
    ax.set_title(f'coverage over {sessions[0]}' + (f'–{sessions[-1]}' if len(sessions) > 1 else '')
                 + ' sessions (Clopper–Pearson 95 % interval; red: 0.95 outside it)', fontsize=9)
    ax.legend(loc='best', fontsize=8)
    files = []
    for fmt in formats:
        path = target / f'coverage.{fmt}'
        fig.savefig(path, dpi=130)
        files.append(str(path))
    plt.close(fig)
    return files
