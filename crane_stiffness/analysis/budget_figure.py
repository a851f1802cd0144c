"""The uncertainty budget of an analysed session as a figure (``budget.png``/``.svg``): per estimate (the loading
and unloading branches' measured k, the model's prediction) the contributions |c_i|·u(x_i) of its inputs as
horizontal bars, largest first, with the combined standard uncertainty u_c and the expanded U marked. Pure: no ROS
import (matplotlib's headless Agg backend).

Units: the stiffness unit of the LVDT's reading (N/m or N·m/rad), the prediction's contributions converted by the
LVDT's reading per unit displacement as its value is (:class:`~crane_stiffness.analysis.results.ModelSummary`).
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import matplotlib

matplotlib.use('Agg')  # no display on a lab PC running headless or in CI
import matplotlib.pyplot as plt  # noqa: E402

from crane_stiffness.analysis.figures import save_figure  # noqa: E402

if TYPE_CHECKING:
    from crane_stiffness.analysis.results import SessionAnalysis

#: The file's stem (``budget.png``).
STEM = 'budget'
#: Inputs drawn per estimate; the rest are summed into one bar ("n others").
MAX_BARS = 8


def budget_bars(result: dict[str, Any], scale: float = 1.0) -> list[tuple[str, float]]:
    """(input name, |c_i|·u(x_i) × |scale|) of a result's dict (``UncertaintyResult.to_dict()``), largest first; past
    :data:`MAX_BARS` the rest summed in quadrature as one bar 'n others' (their share of u_c²)."""
    rows = sorted(((row['name'], abs(float(row['contribution'])) * abs(scale)) for row in result['budget']),
                  key=lambda item: item[1], reverse=True)
    if len(rows) <= MAX_BARS:
        return rows
    rest = rows[MAX_BARS - 1:]
    return rows[:MAX_BARS - 1] + [(f'{len(rest)} others (in quadrature)', sum(v * v for _, v in rest) ** 0.5)]


def estimates(analysis: SessionAnalysis) -> list[tuple[str, dict[str, Any], float]]:
    """(title, result dict, scale) of each estimate with a budget: loading, unloading, prediction."""
    out = []
    u = analysis.uncertainty
    for branch in ('loading', 'unloading'):
        entry = u.get(branch)
        if entry is not None:
            out.append((f"{branch} ({entry['fit']})", entry['uncertainty'], 1.0))
    prediction = u.get('prediction')
    if prediction is not None:
        out.append((f"model prediction (exact tangent at rest, {prediction['axis']})", prediction['uncertainty'],
                    float(prediction['lvdt_scale'])))
    return out


def plot_budget(path: str | Path, panels: Sequence[tuple[str, dict[str, Any], float]], unit: str,
                title: str = '') -> Path:
    """One panel per estimate: bars of |c_i|·u(x_i) [unit], largest on top, u_c (dotted) and U (dashed) marked."""
    bars_of = [budget_bars(result, scale) for _, result, scale in panels]
    heights = [max(len(bars), 1) for bars in bars_of]
    height_in = 1.1 + 0.32 * sum(heights) + 0.55 * len(panels)
    fig, axes = plt.subplots(len(panels), 1, figsize=(7.4, height_in), dpi=100,
                             gridspec_kw={'height_ratios': [h + 1.5 for h in heights]}, squeeze=False)
    # A fixed layout (tight_layout measures every text by drawing it: a third of the figure's cost)
    longest = max((len(name) for bars in bars_of for name, _ in bars), default=10)
    bottom, top = 0.5 / height_in, 1.0 - (0.65 if title else 0.35) / height_in
    gap_in, n = 0.7, len(panels)  # between panels: the x labels of one and the title of the next
    fig.subplots_adjust(left=min(max(0.04 + 0.0085 * longest, 0.15), 0.45), right=0.97, bottom=bottom, top=top,
                        hspace=gap_in * n / max(height_in * (top - bottom) - gap_in * (n - 1), 0.1))
    for ax, (name, result, scale), bars in zip(axes[:, 0], panels, bars_of):
        labels = [b[0] for b in bars][::-1]
        values = [b[1] for b in bars][::-1]
        ax.barh(range(len(values)), values, color='tab:blue', height=0.6)
        ax.set_yticks(range(len(values)), labels, fontsize=8)
        u_c, big_u = float(result['u_c']) * abs(scale), float(result['U']) * abs(scale)
        ax.axvline(u_c, color='k', ls=':', lw=1.2, label=f'u_c = {u_c:.4g}')
        ax.axvline(big_u, color='tab:red', ls='--', lw=1.4,
                   label=f"U = {big_u:.4g} (k = {float(result['k']):.2f}, {100 * float(result['coverage']):.0f} %)")
        for y, v in enumerate(values):
            ax.text(v, y, f' {v:.4g}', va='center', fontsize=7)
        ax.set_xlim(0.0, 1.15 * max([big_u, *values]))
        ax.set_title(f"{name}: k = {float(result['value']) * scale:.6g} {unit}", fontsize=9)
        ax.legend(fontsize=7, loc='lower right')
        ax.grid(True, axis='x', alpha=0.3)
        ax.tick_params(axis='x', labelsize=8)
    axes[-1, 0].set_xlabel(f'contribution |c_i|·u(x_i) [{unit}]')
    if title:
        fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)


def write_budget_figure(analysis: SessionAnalysis, out: Path, formats: Sequence[str]) -> list[str]:
    """``budget.<fmt>`` in ``out`` for each format when the analysis has a budget; returns the paths written."""
    panels = estimates(analysis)
    if not panels:
        return []
    title = f'{analysis.session}: uncertainty budget along {analysis.axis}'
    return [str(plot_budget(Path(out) / f'{STEM}.{fmt}', panels, analysis.unit, title)) for fmt in formats]


__all__ = ['MAX_BARS', 'STEM', 'budget_bars', 'estimates', 'plot_budget', 'write_budget_figure']
