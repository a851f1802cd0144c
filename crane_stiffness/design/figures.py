"""Figures of the design questions (matplotlib, headless Agg): map heatmaps with contours and the usable-workspace
outline, the slack margins per direction as polar and sphere plots. PNG or SVG by the file's extension."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use('Agg')  # no display on a lab PC running headless or in CI
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
import numpy as np  # noqa: E402

from crane_stiffness.design.maps import VARIABLES  # noqa: E402
from crane_stiffness.design.margins import Margins  # noqa: E402

#: The mapped quantities drawn: column -> (title, unit, file stem).
MAP_QUANTITIES = {
    'force_stiffness_min_N_per_m': ('smallest force stiffness', 'N/m', 'map_force_stiffness'),
    'margin_min_N': ('smallest slack margin over the force directions', 'N', 'map_slack_margin'),
    'tension_min_N': ('smallest wire tension', 'N', 'map_tension'),
    'moment_stiffness_min_Nm_per_rad': ('smallest moment stiffness', 'N·m/rad', 'map_moment_stiffness'),
}


def _label(name: str) -> str:
    unit, meaning = VARIABLES[name]
    return f'{name} [{unit}] ({meaning})'


def plot_map(meta: dict[str, Any], grids: dict[str, np.ndarray], column: str, path: str | Path,
             usable_load: float | None = None) -> Path:
    """Heatmap of one column over the two grid variables, with labelled contours, the unreachable points blank
    and, given usable_load [N], the outline of the usable workspace (slack margin > usable_load in every
    force direction)."""
    title, unit, _ = MAP_QUANTITIES[column]
    n1, n2 = meta['axis1']['name'], meta['axis2']['name']
    x, y = grids[n1], grids[n2]
    z = np.ma.masked_invalid(grids[column])
    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    mesh = ax.pcolormesh(x, y, z, shading='auto', cmap='viridis')
    fig.colorbar(mesh, ax=ax, label=f'{title} [{unit}]')
    if z.count() > 4 and float(z.max()) > float(z.min()):
        cs = ax.contour(x, y, z, levels=8, colors='white', linewidths=0.7)
        ax.clabel(cs, fontsize=7, fmt='%.4g')
    margin = np.ma.masked_invalid(grids['margin_min_N'])
    if usable_load is not None and margin.count() > 4 and float(margin.max()) > usable_load > float(margin.min()):
        ax.contour(x, y, margin, levels=[usable_load], colors='red', linewidths=2.0)
        ax.plot([], [], color='red', linewidth=2.0, label=f'usable: margin > {usable_load:g} N every way')
        ax.legend(fontsize=8, loc='upper right')
    ax.set_xlabel(_label(n1))
    ax.set_ylabel(_label(n2))
    base = meta['base']
    ax.set_title(f'{title}\na = {base["a"]:.4g} m, b = {base["b"]:.4g} m, h = {base["height"]:.4g} m, '
                 f'W = {base["weight"]:.4g} N (where not mapped); {meta["directions"]} directions', fontsize=9)
    if n1 in ('x', 'y') and n2 in ('x', 'y'):
        ax.set_aspect('equal')
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_maps(meta: dict[str, Any], grids: dict[str, np.ndarray], out_dir: Path,
              usable_load: float | None = None) -> list[Path]:
    """Every quantity of MAP_QUANTITIES as ``<stem>.png`` in out_dir."""
    return [plot_map(meta, grids, col, out_dir / f'{stem}.png', usable_load)
            for col, (_, _, stem) in MAP_QUANTITIES.items()]


def plot_margin_polar(horizontal: Margins, couples: Margins | None, path: str | Path, title: str) -> Path:
    """Polar plots of the slack margin: horizontal forces by their direction in the x–y plane (N), and couples by
    their axis in the x–y plane (N·m). Radius = load that slackens the first wire; labels name that wire."""
    panels = [horizontal] + ([couples] if couples is not None else [])
    fig, axes = plt.subplots(1, len(panels), subplot_kw={'projection': 'polar'}, figsize=(5.2 * len(panels), 5.2))
    axes = np.atleast_1d(axes)
    for ax, m in zip(axes, panels):
        ang = np.arctan2(m.directions[:, 1], m.directions[:, 0])
        order = np.argsort(ang)
        r = np.where(np.isfinite(m.margin), m.margin, np.nan)
        ang_c = np.append(ang[order], ang[order][0] + 2 * math.pi)
        r_c = np.append(r[order], r[order][0])
        ax.plot(ang_c, r_c, color='C0', linewidth=1.5)
        i_min = int(np.nanargmin(r))
        unit = 'N' if m.kind == 'force' else 'N·m'
        ax.plot([ang[i_min]], [r[i_min]], 'o', color='C3')
        ax.set_title(f'{"horizontal force" if m.kind == "force" else "couple about a horizontal axis"}: '
                     f'smallest {r[i_min]:.4g} {unit}\n(wire_{int(m.wire[i_min]) + 1} slack first), '
                     f'x to the right, y up', fontsize=9)
        ax.set_rlabel_position(100)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_margin_sphere(m: Margins, path: str | Path, title: str) -> Path:
    """The slack margin over the sphere of directions as a map of azimuth (from x towards y) against elevation
    (up positive: z points down), one dot per direction coloured by the margin (∞ drawn grey)."""
    d = m.directions
    az = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    el = np.degrees(np.arcsin(np.clip(-d[:, 2], -1.0, 1.0)))
    finite = np.isfinite(m.margin)
    unit = 'N' if m.kind == 'force' else 'N·m'
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    ax.scatter(az[~finite], el[~finite], c='0.75', s=18, label='no wire slack (within the cap)')
    values = m.margin[finite]
    # Margins span decades (a side push against a near-downward pull): a logarithmic colour scale shows both.
    norm = LogNorm() if values.size and values.min() > 0 and values.max() > 3 * values.min() else None
    sc = ax.scatter(az[finite], el[finite], c=values, s=18, cmap='viridis', norm=norm)
    fig.colorbar(sc, ax=ax, label=f'slack margin [{unit}]')
    ax.set_xlabel('azimuth [deg] (0 = +x, 90 = +y)')
    ax.set_ylabel('elevation [deg] (+90 = up)')
    ax.set_xlim(-180, 180)
    ax.set_ylim(-90, 90)
    ax.set_title(title, fontsize=9)
    if (~finite).any():
        ax.legend(fontsize=8, loc='lower right')
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
