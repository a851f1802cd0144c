"""Figures in the style of the paper (matplotlib, headless Agg backend): PNG or SVG by the file's extension."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use('Agg')  # no display on a lab PC running headless or in CI
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from crane_stiffness.analysis.sweep import ForceDisplacement, StiffnessRow  # noqa: E402

_FORCE_AXES = ('fx', 'fy', 'fz')


def _labels(axis: str) -> tuple[str, str, float]:
    """(load label, displacement label, displacement scale to plotted unit)."""
    if axis in _FORCE_AXES:
        return f'external force {axis} [N]', f'displacement δu_{axis[1]} [mm]', 1e3
    return f'external moment {axis} [N·m]', f'rotation δθ_{axis[1]} [mrad]', 1e3


def plot_force_displacement(curves: ForceDisplacement, path: str | Path, title: str = '',
                            measured: tuple[np.ndarray, np.ndarray] | None = None,
                            measured_label: str = 'measured') -> Path:
    """Load against displacement like Figs. 5–9: nonlinear model (solid), linearized eq. (18) (dashed),
    W = 0 elastic-only (dotted), single wire with W/6 (dash-dot), and measured points if given.

    ``measured`` is (displacement [m or rad], load [N or N·m]).
    """
    ylab, xlab, s = _labels(curves.axis)
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=110)
    ax.plot(curves.nonlinear * s, curves.load, '-', color='k', lw=1.8, label='nonlinear model')
    ax.plot(curves.linear * s, curves.load, '--', color='tab:blue', lw=1.2, label='linearized, eq. (18)')
    ax.plot(curves.elastic * s, curves.load, ':', color='tab:green', lw=1.4, label='W = 0, elastic only')
    if np.any(np.isfinite(curves.pendulum)):
        ax.plot(curves.pendulum * s, curves.load, '-.', color='tab:red', lw=1.2, label='single wire, W/6')
    slack = curves.slack_wires > 0
    if np.any(slack):
        ax.plot(curves.nonlinear[slack] * s, curves.load[slack], 'o', ms=3, mfc='none', color='tab:orange',
                label='nonlinear, wire(s) slack')
    if measured is not None:
        ax.plot(np.asarray(measured[0]) * s, np.asarray(measured[1]), '.', ms=3, color='tab:purple', alpha=0.6,
                label=measured_label)
    xmax = max(np.nanmax(np.abs(curves.nonlinear)), np.nanmax(np.abs(curves.linear))) * s * 1.4
    ax.set_xlim(min(0.0, -0.05 * xmax), xmax)
    ax.set_xlabel(xlab)
    ax.set_ylabel(ylab)
    ax.set_title(title, fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc='lower right')
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_stiffness_vs_weight(rows: Sequence[StiffnessRow], axis: str, path: str | Path, title: str = '') -> Path:
    """Stiffness to a small load against W, one line per wire length (Figs. 10 and 13); eq. (18) as markers."""
    unit = 'N/m' if axis in _FORCE_AXES else 'N·m/rad'
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=110)
    heights = sorted({r.height for r in rows})
    for h in heights:
        sel = [r for r in rows if r.height == h]
        w = np.array([r.weight for r in sel])
        ax.plot(w, [r.tangent for r in sel], '-', lw=1.6, label=f'l0 = {sel[0].l0:.3f} m (model)')
        ax.plot(w, [r.paper for r in sel], 'x', ms=5, color=ax.lines[-1].get_color())
    ax.set_xlabel('suspended weight W [N]')
    ax.set_ylabel(f'stiffness to {axis} [{unit}]')
    ax.set_title(title or f'stiffness to {axis} against weight (x: eq. 18)', fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path
