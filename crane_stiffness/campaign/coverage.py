"""How often a campaign's 95 % intervals cover the model's value, quantity by quantity, with a binomial interval on
that fraction: the check that the intervals the rig publishes mean what they say (a coverage study is a campaign
of many seeded sessions of one set-up: ``config/campaign_coverage.yaml``, ``config/campaign_coverage_full.yaml``).

The quantities: for the one-axis series, the loading and the unloading stiffness of each series against the model's
exact tangent at rest (in the LVDT's reading units, as the campaign's rows); for the series full, each of the 36
entries of K against the tangent and of C = K⁻¹ against the tangent's inverse, and the coupling K2 against the
tangent's. Each session counts once per quantity: a session without that interval (no fit) is left out of its total.
The fraction's interval is Clopper–Pearson's (exact, two-sided 95 %): a fraction whose interval leaves out 0.95 is
a departure to explain. Reads the analyses ``campaign analyze`` wrote; no ROS.
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


def campaign_coverage(rows: Sequence[SessionRow], full: Sequence[Full6Row]) -> list[Coverage]:
    """Every quantity's coverage over the analysed sessions (the rows ``campaign analyze`` made; each row's
    analysis file is read for its intervals)."""
    counts: dict[str, list[int]] = {}
    for row in rows:
        analysis = json.loads((Path(row.analysis) / 'analysis.json').read_text())
        model = analysis.get('model') or {}
        tangent = _float(model.get('tangent_at_rest')) * _float(model.get('lvdt_scale', 1.0))
        for branch in ('loading', 'unloading'):
            fit = (analysis.get('branch_fits') or {}).get(branch) or {}
            low, high = _float(fit.get('ci95_low')), _float(fit.get('ci95_high'))
            covers = None if not (math.isfinite(low) and math.isfinite(high) and math.isfinite(tangent)) else \
                low <= tangent <= high
            _count(counts, f'k {row.series} {branch}', covers)
    for frow in full:
        analysis = json.loads((Path(frow.analysis) / 'full6.json').read_text())
        comparison = analysis.get('comparison') or {}
        for name, key in (('K', 'stiffness_covers'), ('C', 'compliance_covers')):
            covers = comparison.get(key)
            if covers is None:
                continue
            for i in range(6):
                for j in range(6):
                    label = f'{name}[{AXES[i]},{DEFLECTIONS[j]}]' if name == 'K' else \
                        f'{name}[{DEFLECTIONS[i]},{AXES[j]}]'
                    _count(counts, label, covers[i][j])
        _count(counts, 'K2', (analysis.get('k2') or {}).get('covers_tangent'))
        _count_gum(counts, analysis)
    return [Coverage(q, c, n) for q, (c, n) in counts.items()]


def _inside(interval: Any, truth: Any) -> list[list[bool]] | None:
    """Entry by entry, whether [low, high] (two 6×6 lists, or two numbers) holds ``truth``; None when missing."""
    import numpy as np
    if not interval or truth is None:
        return None
    low, high, t = (np.asarray(x, dtype=float) for x in (interval[0], interval[1], truth))
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        return None
    return ((low <= t) & (t <= high)).tolist()


def _count_gum(counts: dict[str, list[int]], analysis: dict[str, Any], kinds: tuple[str, ...] = ('U',),
               per_entry: bool = True) -> None:
    """The six-axis session's GUM intervals (full6.json's ``uncertainty``, crane_stiffness.analysis.full6_uncertainty)
    against the tangent. Per entry (``per_entry``): 'U K[..]' of K (the expanded interval value ± U), 'U C[..]',
    and 'U K2', 'stat K2' (the statistical-only interval). Pooled over the 36 entries (not ``per_entry``):
    '<kind> K (36 pooled)', '<kind> C (36 pooled)' for each of ``kinds``: 'U', 'stat' (value ± t·u_a), 'MC' (the
    JCGM 102 Monte Carlo's interval)."""
    u = analysis.get('uncertainty') or {}
    reference = analysis.get('reference') or {}
    if not u or not reference:
        return
    for name, key, truth in (('K', 'stiffness', reference.get('tangent')), ('C', 'compliance',
                                                                           reference.get('compliance'))):
        entries = u.get(key) or {}
        intervals = {'U': entries.get('interval'), 'stat': entries.get('statistical_interval'),
                     'MC': (entries.get('monte_carlo') or {}).get('interval')}
        for kind in kinds:
            covers = _inside(intervals[kind], truth)
            if covers is None:
                continue
            for i in range(6):
                for j in range(6):
                    if per_entry:
                        label = f'{kind} {name}[{AXES[i]},{DEFLECTIONS[j]}]' if name == 'K' else \
                            f'{kind} {name}[{DEFLECTIONS[i]},{AXES[j]}]'
                        _count(counts, label, covers[i][j])
                    else:
                        _count(counts, f'{kind} {name} (36 pooled)', covers[i][j])
    if per_entry:
        k2 = u.get('k2') or {}
        for kind, interval in (('U', k2.get('interval')), ('stat', k2.get('statistical_interval'))):
            covers = _inside(interval, (analysis.get('k2') or {}).get('tangent'))
            if covers is not None:
                _count(counts, f'{kind} K2', covers)


def pooled_gum_coverage(full: Sequence[Full6Row]) -> list[Coverage]:
    """Pooled over the 36 entries of K and of C, the sessions' expanded ('U'), statistical-only ('stat') and
    Monte Carlo ('MC') intervals that hold the tangent (see :func:`_count_gum`). A pooled count's 36 entries of one
    session share its calibration errors, so its binomial interval is narrower than it should be; the per-entry
    counts of :func:`campaign_coverage` are the exact ones."""
    counts: dict[str, list[int]] = {}
    for frow in full:
        analysis = json.loads((Path(frow.analysis) / 'full6.json').read_text())
        _count_gum(counts, analysis, ('U', 'MC', 'stat'), per_entry=False)
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
    ax.set_ylabel('fraction of 95 % intervals covering the model')
    ax.set_ylim(max(0.0, min(c.interval[0] for c in coverage) - 0.05), 1.01)
    sessions = sorted({c.total for c in coverage})
    ax.set_title(f'coverage over {sessions[0]}' + (f'–{sessions[-1]}' if len(sessions) > 1 else '')
                 + ' sessions (Clopper–Pearson 95 % interval; red: 0.95 outside it)', fontsize=9)
    ax.legend(loc='lower left', fontsize=8)
    files = []
    for fmt in formats:
        path = target / f'coverage.{fmt}'
        fig.savefig(path, dpi=130)
        files.append(str(path))
    plt.close(fig)
    return files
