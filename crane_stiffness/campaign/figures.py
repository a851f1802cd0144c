"""The campaign's figures (matplotlib, Agg): stiffness against W for each wire length with the measured sessions on
the model curves (Fig. 10: side force fy; Fig. 13: moment mz; and the vertical force fz), and the force–displacement
overlays of each series and length (Figs. 5–9 style: every weight's hold means on its model curve). Sessions not OK
are drawn hollow. A calibrated model (crane_stiffness.campaign.calibrate) is drawn beside the nominal one when given.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Callable, Sequence

import matplotlib

matplotlib.use('Agg')  # headless
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from crane_stiffness.campaign.rows import SessionRow  # noqa: E402

#: Figure names of the series, as the paper numbers them.
FIGURE = {'fy': 'fig10_side_force_stiffness', 'mz': 'fig13_moment_stiffness', 'fz': 'vertical_force_stiffness'}
TITLE = {'fy': 'Fig. 10: side stiffness (fy) against W', 'mz': 'Fig. 13: stiffness to a moment about z against W',
         'fz': 'vertical stiffness (fz) against W'}
#: A model of the crane for a set-up: geometry.* parameters -> the geometry.* parameters to draw (calibrated).
Adjust = Callable[[dict[str, Any]], dict[str, Any]]


def model_curves(nominal: dict[str, Any], axis: str, weights: np.ndarray) -> dict[str, np.ndarray]:
    """The model's stiffness along ``axis`` against W for the set-up ``nominal`` (its length): exact tangent, eq.
    (18)/(19), W = 0 elastic, single wire carrying W/6 (fy only)."""
    from crane_stiffness.analysis.sweep import stiffness_vs_weight
    from crane_stiffness.model import single_wire_pendulum_stiffness
    from crane_stiffness.params.geometry import geometry_from_params
    g = geometry_from_params(nominal)
    rows = stiffness_vs_weight(g, axis, [g.height], weights)
    single = np.array([single_wire_pendulum_stiffness(g.replace(weight=float(w))) if axis in ('fx', 'fy') and w > 0
                       else math.nan for w in weights])
    return {'tangent': np.array([r.tangent for r in rows]), 'eq18': np.array([r.paper for r in rows]),
            'elastic': np.array([r.elastic for r in rows]), 'single_wire': single}


def _points(ax: Any, rows: Sequence[SessionRow], x: Callable[[SessionRow], float],
            y: Callable[[SessionRow], Sequence[float]], color: str, label: str) -> None:
    for ok in (True, False):
        sel = [r for r in rows if r.ok == ok]
        if not sel:
            continue
        values = np.array([y(r) for r in sel])
        err = np.abs(values[:, 1:].T - values[:, 0])
        ax.errorbar([x(r) for r in sel], values[:, 0], yerr=err, fmt='o', ms=6, color=color, capsize=3,
                    mfc=color if ok else 'none', label=label + ('' if ok else ' (not OK)'))


def plot_stiffness_against_weight(rows: Sequence[SessionRow], axis: str, path: Path,
                                  calibrated: Adjust | None = None) -> Path:
    """Top: stiffness against W per wire length, the model curves and each session's measured value with its 95 %
    interval (log scale: the lengths differ by orders); bottom: measured over model tangent − 1 [%]."""
    sel = [r for r in rows if r.series == axis]
    lengths = sorted({round(r.l0, 9) for r in sel})
    unit = sel[0].unit or ('N/m' if axis.startswith('f') else 'N·m/rad')
    fig, axes = plt.subplots(2, len(lengths), figsize=(5.2 * len(lengths), 7.2), dpi=100, squeeze=False,
                             gridspec_kw={'height_ratios': [2.2, 1]})
    for j, l0 in enumerate(lengths):
        here = sorted((r for r in sel if round(r.l0, 9) == l0), key=lambda r: r.weight)
        top, bottom = axes[0, j], axes[1, j]
        w_max = max(r.weight for r in here) * 1.15
        weights = np.linspace(max(w_max / 60, 0.5), w_max, 30)
        scale = here[0].model_tangent / _tangent_at(here[0].nominal, axis)  # the LVDT's reading per unit motion
        curves = model_curves(here[0].nominal, axis, weights)
        top.plot(weights, curves['tangent'] * scale, '-', color='k', lw=1.6, label='nonlinear model (exact tangent)')
        top.plot(weights, curves['eq18'] * scale, '--', color='tab:blue', lw=1.2, label='linearized, eq. (18)/(19)')
        top.plot(weights, curves['elastic'] * scale, ':', color='tab:green', lw=1.4, label='W = 0, elastic only')
        if np.isfinite(curves['single_wire']).any():
            top.plot(weights, curves['single_wire'] * scale, '-.', color='tab:red', lw=1.2,
                     label='single wire, W/6')
        reference = None
        if calibrated is not None:
            cal = model_curves(calibrated(here[0].nominal), axis, weights)
            top.plot(weights, cal['tangent'] * scale, '-', color='tab:orange', lw=1.6, label='calibrated model')
            reference = cal['tangent'] * scale
        _points(top, here, lambda r: r.weight, lambda r: (r.k, r.ci95_low, r.ci95_high), 'tab:purple', 'measured')
        top.set_yscale('log')
        top.set_title(f'l0 = {l0:g} m (h = {here[0].height:.4g} m)', fontsize=10)
        top.set_ylabel(f'stiffness to {axis} [{unit}]')
        top.grid(True, which='both', alpha=0.3)
        top.legend(fontsize=7, loc='best')
        bottom.axhline(0.0, color='k', lw=1.0)
        _points(bottom, here, lambda r: r.weight,
                lambda r: tuple(100 * (v / r.model_tangent - 1) for v in (r.k, r.ci95_low, r.ci95_high)),
                'tab:purple', 'measured − nominal model')
        if reference is not None:
            bottom.plot(weights, 100 * (reference / (curves['tangent'] * scale) - 1), '-', color='tab:orange',
                        lw=1.4, label='calibrated − nominal')
        bottom.set_xlabel('suspended weight W [N]')
        bottom.set_ylabel('vs nominal tangent [%]')
        bottom.grid(True, alpha=0.3)
        bottom.legend(fontsize=7, loc='best')
    fig.suptitle(TITLE.get(axis, axis), fontsize=11)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def _tangent_at(nominal: dict[str, Any], axis: str) -> float:
    from crane_stiffness.model import axis_stiffness, rest_pose, tangent_stiffness
    from crane_stiffness.params.geometry import geometry_from_params
    g = geometry_from_params(nominal)
    return axis_stiffness(tangent_stiffness(g, rest_pose(g)), axis)


def plot_force_displacement_overlay(rows: Sequence[SessionRow], axis: str, l0: float, path: Path) -> Path:
    """Figs. 5–9 style for one series and length: each weight's model curve (nonlinear, in the LVDT's reading) and
    its session's hold means (loading ▲, unloading ▼; hollow when the session is not OK)."""
    here = sorted((r for r in rows if r.series == axis and round(r.l0, 9) == round(l0, 9)), key=lambda r: r.weight)
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=100)
    colors = plt.get_cmap('viridis')(np.linspace(0.0, 0.85, max(len(here), 1)))
    s = 1e6 if axis.startswith('f') else 1e3
    for r, color in zip(here, colors):
        analysis = json.loads((Path(r.analysis) / 'analysis.json').read_text())
        model = analysis.get('model') or {}
        curves = model.get('curves') or {}
        scale = float(model.get('lvdt_scale') or 1.0)
        if curves:
            ax.plot(np.asarray(curves['nonlinear'], dtype=float) * scale * s, curves['load'], '-', color=color,
                    lw=1.3, label=f'W = {r.weight:g} N model')
        for approach, marker in (('loading', '^'), ('unloading', 'v')):
            steps = [st for st in analysis.get('steps', []) if st['approach'] == approach
                     and st['displacement_mean'] is not None]
            ax.plot([st['displacement_mean'] * s for st in steps], [st['force_mean'] for st in steps], marker,
                    color=color, ms=5, mfc=color if r.ok else 'none', ls='none')
    ax.plot([], [], '^', color='gray', label='measured hold means, loading')
    ax.plot([], [], 'v', color='gray', label='unloading')
    ax.set_xlabel(f'LVDT reading along {axis} [{"µm" if axis.startswith("f") else "mrad"}]')
    ax.set_ylabel(f'{"force" if axis.startswith("f") else "moment"} {axis} [{"N" if axis.startswith("f") else "N·m"}]')
    ax.set_title(f'{axis}, l0 = {l0:g} m: measured and model, each weight', fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc='best')
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def write_campaign_figures(rows: Sequence[SessionRow], out: Path, formats: Sequence[str],
                           calibrated: Adjust | None = None, suffix: str = '') -> list[str]:
    """Every figure of the campaign in ``out``: stiffness against W per series, force–displacement per series and
    length."""
    written = []
    for axis in sorted({r.series for r in rows}, key=['fy', 'mz', 'fz'].index):
        for fmt in formats:
            written.append(str(plot_stiffness_against_weight(rows, axis, out / f'{FIGURE[axis]}{suffix}.{fmt}',
                                                              calibrated)))
            if calibrated is None:
                for l0 in sorted({round(r.l0, 9) for r in rows if r.series == axis}):
                    written.append(str(plot_force_displacement_overlay(
                        rows, axis, l0, out / f'force_displacement_{axis}_l{l0:g}.{fmt}')))
    return written
