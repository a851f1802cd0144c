"""The figures of a campaign's series ``full`` (matplotlib, Agg): the whole 6×6 stiffness of every set-up against
the model (crane_stiffness.full6.reference).

- ``full_stiffness_diagonal``: K's six diagonal entries against W, one panel each, for every wire length the
  nominal model's exact tangent (solid) and eq. (18) (dashed) over W, and each session's measured entry with its
  95 % interval (hollow: session not OK); the calibrated model beside them when given.
- ``full_coupling_k2``: the side–tilt coupling K2 [N/rad] against W likewise: the term the paper's eq. (18) has and
  one-axis tests never measure, with its sign.
- ``coverage_gum``: a six-axis coverage study's GUM intervals (crane_stiffness.campaign.coverage): how often each
  entry's expanded interval of K held the tangent (a 6×6 map), and the pooled fractions of the expanded, Monte
  Carlo and statistical-only intervals of K, C and K2 with their Clopper–Pearson intervals against 0.95.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

import matplotlib

matplotlib.use('Agg')  # headless
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from crane_stiffness.campaign.rows import Full6Row  # noqa: E402
from crane_stiffness.full6.reference import entry_name, k2_of  # noqa: E402

#: A model of the crane for a set-up: geometry.* parameters -> the geometry.* parameters to draw (calibrated).
Adjust = Callable[[dict[str, Any]], dict[str, Any]]
UNITS = ('N/m', 'N/m', 'N/m', 'N·m/rad', 'N·m/rad', 'N·m/rad')
COLORS = ('tab:blue', 'tab:red', 'tab:green', 'tab:purple', 'tab:brown')
#: K's columns as the coverage rows spell them (crane_stiffness.campaign.coverage.DEFLECTIONS; not imported from
#: there: coverage imports this module for its figure).
_COLUMNS = ('ux', 'uy', 'uz', 'thx', 'thy', 'thz')


def model_matrices(nominal: dict[str, Any], weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(tangent, eq. (18)) K at rest for each W of ``weights`` [N] on the set-up ``nominal`` (its length): two
    (n, 6, 6) arrays, eq. (18) NaN where it does not describe the geometry."""
    from crane_stiffness.full6.reference import reference_at_rest
    from crane_stiffness.params.geometry import geometry_from_params
    g = geometry_from_params(nominal)
    tangent, paper = [], []
    for w in weights:
        ref = reference_at_rest(g.replace(weight=float(w)))
        tangent.append(ref.tangent)
        paper.append(np.full((6, 6), np.nan) if ref.paper is None else ref.paper)
    return np.array(tangent), np.array(paper)


def _lengths(rows: Sequence[Full6Row]) -> list[float]:
    return sorted({round(r.l0, 9) for r in rows})


def _weights(rows: Sequence[Full6Row]) -> np.ndarray:
    w_max = max(r.weight for r in rows) * 1.15
    return np.linspace(max(w_max / 60, 0.5), w_max, 30)


def _measured(ax: Any, rows: Sequence[Full6Row], value: Callable[[Full6Row], tuple[float, float, float]],
              color: str, label: str) -> None:
    for ok in (True, False):
        sel = [r for r in rows if r.ok == ok]
        if not sel:
            continue
        v = np.array([value(r) for r in sel], dtype=float)
        err = np.abs(v[:, 1:].T - v[:, 0])
        ax.errorbar([r.weight for r in sel], v[:, 0], yerr=err, fmt='o', ms=6, color=color, capsize=3,
                    mfc=color if ok else 'none', label=label + ('' if ok else ' (not OK)'))


#: Per wire length: (W grid, tangent K, eq. (18) K, calibrated K or None), each (n, 6, 6) (:func:`_models`).
Models = dict[float, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]]


def _models(rows: Sequence[Full6Row], calibrated: Adjust | None) -> Models:
    """The model matrices of every wire length over a W grid, computed once for a figure's panels."""
    weights = _weights(rows)
    out: Models = {}
    for l0 in _lengths(rows):
        nominal = next(r for r in rows if round(r.l0, 9) == l0).nominal
        tangent, paper = model_matrices(nominal, weights)
        cal = None if calibrated is None else model_matrices(calibrated(nominal), weights)[0]
        out[l0] = (weights, tangent, paper, cal)
    return out


def _curves(ax: Any, models: Models, pick: Callable[[np.ndarray], np.ndarray], labelled: bool) -> None:
    for c, (l0, (weights, tangent, paper, cal)) in zip(COLORS * 4, models.items()):
        ax.plot(weights, pick(tangent), '-', color=c, lw=1.5,
                label=f'l0 = {l0:g} m: exact tangent' if labelled else None)
        ax.plot(weights, pick(paper), '--', color=c, lw=1.0, label='eq. (18)' if labelled and c == COLORS[0] else None)
        if cal is not None:
            ax.plot(weights, pick(cal), '-', color='tab:orange', lw=1.2,
                    label='calibrated model' if labelled and c == COLORS[0] else None)


def plot_diagonal(rows: Sequence[Full6Row], path: Path, calibrated: Adjust | None = None) -> Path:
    """K's diagonal against W (module docstring)."""
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.4), dpi=100)
    models = _models(rows, calibrated)
    for i, ax in enumerate(axes.flat):
        def entry(k: np.ndarray, i: int = i) -> np.ndarray:
            return k[:, i, i]

        def measured(r: Full6Row, i: int = i) -> tuple[float, float, float]:
            return r.diagonal[i]['measured'], r.diagonal[i]['low'], r.diagonal[i]['high']
        _curves(ax, models, entry, labelled=i == 0)
        for c, l0 in zip(COLORS * 4, _lengths(rows)):
            here = [r for r in rows if round(r.l0, 9) == l0]
            _measured(ax, here, measured, c, f'measured, l0 = {l0:g} m')
        ax.set_title(f'{entry_name(i, i)} [{UNITS[i]}]')
        ax.set_xlabel('suspended weight W [N]')
        ax.grid(True, alpha=0.3)
        if len(_lengths(rows)) > 1:
            ax.set_yscale('log')
    axes.flat[0].legend(fontsize=7, loc='best')
    fig.suptitle('The whole stiffness, one designed test per set-up: K\'s diagonal against W (95 % intervals)')
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_k2(rows: Sequence[Full6Row], path: Path, calibrated: Adjust | None = None) -> Path:
    """K2 against W (module docstring)."""
    fig, ax = plt.subplots(figsize=(7.5, 5.2), dpi=100)
    _curves(ax, _models(rows, calibrated), lambda k: np.array([k2_of(m) for m in k]), labelled=True)
    for c, l0 in zip(COLORS * 4, _lengths(rows)):
        here = [r for r in rows if round(r.l0, 9) == l0]
        _measured(ax, here, lambda r: (r.k2, r.k2_low, r.k2_high), c, f'measured, l0 = {l0:g} m')
    if len(_lengths(rows)) > 1 and all(r.k2 > 0 for r in rows):
        ax.set_yscale('log')  # the lengths differ by an order
    else:
        ax.axhline(0.0, color='0.6', lw=0.8)
    ax.set_xlabel('suspended weight W [N]')
    ax.set_ylabel('K2 [N/rad] (side force per tilt)')
    ax.set_title('The side–tilt coupling K2 against W (95 % intervals)')
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def write_full_figures(rows: Sequence[Full6Row], out: Path, formats: Sequence[str] = ('png',),
                       calibrated: Adjust | None = None, suffix: str = '') -> list[str]:
    """Both figures in every format into ``out``; the paths written."""
    files = []
    for fmt in formats:
        files.append(str(plot_diagonal(rows, out / f'full_stiffness_diagonal{suffix}.{fmt}', calibrated)))
        files.append(str(plot_k2(rows, out / f'full_coupling_k2{suffix}.{fmt}', calibrated)))
    return files


__all__ = ['model_matrices', 'plot_diagonal', 'plot_k2', 'write_full_figures']


def gum_coverage_figure(rows: Sequence[tuple[str, int, int, float, float]], target: Path,
                        formats: Sequence[str] = ('png',)) -> list[str]:
    """``coverage_gum.<fmt>`` in ``target`` from the coverage rows (quantity, covered, sessions, CI low, CI high) of
    crane_stiffness.campaign.coverage (module docstring); nothing without 'U K[..]' rows. The files written."""
    from crane_stiffness.contract.axes import AXES
    by_name = {r[0]: r for r in rows}
    if not any(name.startswith('U K[') for name in by_name):
        return []
    grid = np.full((6, 6), np.nan)
    for i in range(6):
        for j in range(6):
            r = by_name.get(f'U K[{AXES[i]},{_COLUMNS[j]}]')
            if r is not None and r[2]:
                grid[i, j] = r[1] / r[2]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11.5, 4.6), layout='constrained',
                                      gridspec_kw={'width_ratios': [1.0, 1.25]})
    image = left.imshow(grid, cmap='RdYlGn', vmin=0.85, vmax=1.0)
    for i in range(6):
        for j in range(6):
            if np.isfinite(grid[i, j]):
                left.text(j, i, f'{grid[i, j]:.2f}', ha='center', va='center', fontsize=8)
    left.set_xticks(range(6), ['u_x', 'u_y', 'u_z', 'θ_x', 'θ_y', 'θ_z'])
    left.set_yticks(range(6), list(AXES))
    sessions = sorted({r[2] for r in rows if r[0].startswith('U K[')})
    left.set_title(f'K: sessions whose value ± U holds the true tangent ({sessions[-1]} sessions)', fontsize=9)
    fig.colorbar(image, ax=left, shrink=0.8)
    pooled = [name for name in ('U K (36 pooled)', 'MC K (36 pooled)', 'stat K (36 pooled)', 'U C (36 pooled)',
                                'MC C (36 pooled)', 'stat C (36 pooled)', 'U K2', 'stat K2',
                                'prediction U K (36 pooled)', 'prediction MC K (36 pooled)',
                                'prediction U C (36 pooled)', 'prediction U K2') if name in by_name]
    x = np.arange(len(pooled))
    frac = np.array([by_name[n][1] / by_name[n][2] for n in pooled])
    low = np.array([by_name[n][3] for n in pooled])
    high = np.array([by_name[n][4] for n in pooled])
    colours = ['tab:green' if n.startswith('prediction') else 'tab:blue' if n.startswith('U') else
               'tab:orange' if n.startswith('MC') else 'tab:gray' for n in pooled]
    right.bar(x, frac, color=colours, alpha=0.8)
    right.errorbar(x, frac, yerr=[frac - low, high - frac], fmt='none', ecolor='k', capsize=3)
    right.axhline(0.95, color='k', ls='--', lw=0.8, label='nominal 0.95')
    right.set_xticks(x, pooled, rotation=30, ha='right', fontsize=8)
    right.set_ylim(max(0.0, float(np.nanmin(low)) - 0.05), 1.01)
    right.set_ylabel('fraction of intervals holding the tangent')
    right.set_title('pooled: expanded (U), Monte Carlo (MC), statistical only (stat),\nthe model\'s prediction '
                    '(green); Clopper–Pearson 95 %', fontsize=9)
    right.legend(loc='lower right', fontsize=8)
    files = []
    for fmt in formats:
        path = Path(target) / f'coverage_gum.{fmt}'
        fig.savefig(path, dpi=130)
        files.append(str(path))
    plt.close(fig)
    return files
