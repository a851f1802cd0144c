"""Figures in the style of the paper (matplotlib, headless Agg backend): PNG or SVG by the file's extension; and the
figures of an analysed session and of a comparison of sessions (:func:`write_session_figures`,
:func:`write_comparison_figures`)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import matplotlib

matplotlib.use('Agg')  # no display on a lab PC running headless or in CI
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from crane_stiffness.analysis.sweep import ForceDisplacement, StiffnessRow  # noqa: E402
from crane_stiffness.contract.axes import FORCE_AXES  # noqa: E402
from crane_stiffness.estimation.branch import BRANCHES, LOADING, UNLOADING  # noqa: E402

if TYPE_CHECKING:
    from crane_stiffness.analysis.load import SessionData
    from crane_stiffness.analysis.results import SessionAnalysis
    from crane_stiffness.estimation.inputs import CommandSeries
    from crane_stiffness.estimation.live_pairs import LivePairs

#: Largest number of points drawn per series in a figure.
PLOT_POINTS = 20_000


def save_figure(fig, path: str | Path) -> Path:
    """Save ``fig`` to ``path`` (PNG or SVG by its extension) and free it. PNG at zlib's fastest level: encoding took
    a quarter of a figure's time at the default level, and the files stay small (line plots compress well)."""
    path = Path(path)
    if path.suffix == '.png':
        fig.savefig(path, pil_kwargs={'compress_level': 1})
    else:
        fig.savefig(path)
    plt.close(fig)
    return path


def _finish(fig, ax, xlabel: str, ylabel: str, title: str, path: str | Path, *, title_size: float = 10,
            legend_size: float = 8, legend_loc: str = 'best') -> Path:
    """Labels, grid, legend, then save to ``path`` (PNG or SVG by its extension) and free the figure."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=title_size)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=legend_size, loc=legend_loc)
    fig.tight_layout()
    return save_figure(fig, path)


def _labels(axis: str) -> tuple[str, str, float]:
    """(load label, displacement label, displacement scale to plotted unit)."""
    if axis in FORCE_AXES:
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
    return _finish(fig, ax, xlab, ylab, title, path, title_size=10,
                   legend_size=8, legend_loc='lower right')


def plot_stiffness_vs_weight(rows: Sequence[StiffnessRow], axis: str, path: str | Path, title: str = '') -> Path:
    """Stiffness to a small load against W, one line per wire length (Figs. 10 and 13); eq. (18) as markers."""
    unit = 'N/m' if axis in FORCE_AXES else 'N·m/rad'
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=110)
    heights = sorted({r.height for r in rows})
    for h in heights:
        sel = [r for r in rows if r.height == h]
        w = np.array([r.weight for r in sel])
        ax.plot(w, [r.tangent for r in sel], '-', lw=1.6, label=f'l0 = {sel[0].l0:.3f} m (model)')
        ax.plot(w, [r.paper for r in sel], 'x', ms=5, color=ax.lines[-1].get_color())
    return _finish(fig, ax, 'suspended weight W [N]', f'stiffness to {axis} [{unit}]',
                   title or f'stiffness to {axis} against weight (x: eq. 18)', path, title_size=10,
                   legend_size=8, legend_loc='best')


# --- recorded sessions (crane_stiffness.analysis.analyze, .compare) --------------------------------------------

_BRANCH_STYLE = {'loading': ('tab:blue', '^'), 'unloading': ('tab:red', 'v')}


def _reading_label(axis: str, lvdt_scale: float) -> tuple[str, str, float]:
    """Labels of a measured plot: the axis' own displacement label when the LVDT reads along it, else the reading."""
    ylab, xlab, s = _labels(axis)
    if lvdt_scale != 1.0:
        xlab = 'LVDT reading [mm]'
    return ylab, xlab, s


def plot_session_force_displacement(path: str | Path, axis: str, *, curves: dict | None = None,
                                    lvdt_scale: float = 1.0,
                                    cloud: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
                                    holds: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
                                    fits: dict[str, tuple[float, float]] | None = None, title: str = '') -> Path:
    """A recorded session against the paper's models (Figs. 5–9 styles).

    ``cloud``: paired samples per branch (LVDT reading [m], load), drawn light; ``holds``: the settled mean of each
    hold per approach, drawn as markers; ``fits``: (stiffness, intercept) of each branch, drawn as lines over the
    measured range; ``curves``: ForceDisplacement.columns() of the model (displacement along the axis), scaled by
    ``lvdt_scale`` to the LVDT reading.
    """
    ylab, xlab, s = _reading_label(axis, lvdt_scale)
    fig, ax = plt.subplots(figsize=(6.8, 5.0), dpi=110)
    extent: list[float] = []  # x range: model (nonlinear, linear) and measured, not the far softer pendulum
    if curves:
        load = np.asarray(curves['load'])
        for key in ('nonlinear', 'linear'):
            extent += [float(np.nanmin(curves[key])) * lvdt_scale * s, float(np.nanmax(curves[key])) * lvdt_scale * s]
        styles = (('nonlinear', '-', 'k', 1.8, 'nonlinear model'), ('linear', '--', 'tab:blue', 1.2,
                  'linearized, eq. (18)'), ('elastic', ':', 'tab:green', 1.4, 'W = 0, elastic only'),
                  ('pendulum', '-.', 'tab:red', 1.2, 'single wire, W/6'))
        for key, ls, color, lw, label in styles:
            x = np.asarray(curves[key], dtype=float) * lvdt_scale
            if np.any(np.isfinite(x)):
                ax.plot(x * s, load, ls, color=color, lw=lw, label=label, alpha=0.8)
    xs: list[np.ndarray] = []
    for branch, (x, y) in (cloud or {}).items():
        color, _ = _BRANCH_STYLE.get(branch, ('tab:gray', '.'))
        if len(x):
            ax.plot(np.asarray(x) * s, y, '.', ms=1.5, color=color, alpha=0.15, rasterized=True)
            xs.append(np.asarray(x))
    for branch, (x, y) in (holds or {}).items():
        color, marker = _BRANCH_STYLE.get(branch, ('tab:gray', 'o'))
        if len(x):
            ax.plot(np.asarray(x) * s, y, marker, ms=6, color=color, mfc='none', mew=1.4,
                    label=f'hold means, {branch}')
            xs.append(np.asarray(x))
    for x in xs:
        if np.isfinite(x).any():
            extent += [float(np.nanmin(x)) * s, float(np.nanmax(x)) * s]
    if fits and xs:
        allx = np.concatenate(xs)
        grid = np.linspace(np.nanmin(allx), np.nanmax(allx), 2)
        for branch, (k, c) in fits.items():
            color, _ = _BRANCH_STYLE.get(branch, ('tab:gray', 'o'))
            ax.plot(grid * s, k * grid + c, '-', color=color, lw=1.0, alpha=0.9, label=f'fit {branch}: {k:.5g}')
    if extent:
        lo, hi = min(extent + [0.0]), max(extent + [0.0])
        pad = 0.08 * (hi - lo) if hi > lo else 1.0
        ax.set_xlim(lo - pad, hi + pad)
    return _finish(fig, ax, xlab, ylab, title, path, title_size=9,
                   legend_size=7, legend_loc='best')


def plot_session_timeseries(path: str | Path, axis: str, series: dict[str, tuple[np.ndarray, np.ndarray]],
                            holds: Sequence[tuple[float, float, str]] = (), title: str = '') -> Path:
    """Command and measured load, displacement and (if recorded) the live stiffness against time.

    ``series``: name → (t [s from the program start], values) for 'command', 'force', 'displacement' [m] and
    optionally 'live_stiffness'; ``holds``: (start, end, approach) spans shaded on every panel.
    """
    ylab, _, _ = _labels(axis)
    panels = 3 if 'live_stiffness' in series else 2
    fig, axes = plt.subplots(panels, 1, figsize=(8.0, 2.3 * panels + 0.6), dpi=110, sharex=True)
    spans: dict[str, list[tuple[float, float]]] = {}
    for start, end, approach in holds:
        spans.setdefault(approach, []).append((start, end - start))
    for a in axes:
        for approach, ranges in spans.items():  # one collection per approach: fast with thousands of holds
            a.broken_barh(ranges, (0, 1), transform=a.get_xaxis_transform(), lw=0, alpha=0.08,
                          color=_BRANCH_STYLE.get(approach, ('tab:gray', ''))[0])
        a.grid(True, alpha=0.3)
    if 'force' in series:
        axes[0].plot(*series['force'], '-', color='tab:purple', lw=0.6, label='load cell')
    if 'command' in series:
        axes[0].plot(*series['command'], '-', color='k', lw=1.0, label='command')
    axes[0].set_ylabel(ylab, fontsize=8)
    axes[0].legend(fontsize=7, loc='upper right')
    if 'displacement' in series:
        t, x = series['displacement']
        axes[1].plot(t, np.asarray(x) * 1e6, '-', color='tab:orange', lw=0.6)
    axes[1].set_ylabel('LVDT [µm]', fontsize=8)
    if panels == 3:
        t, k = series['live_stiffness']
        axes[2].plot(t, k, '-', color='tab:green', lw=0.8)
        axes[2].set_ylabel('live k (loading)', fontsize=8)
    axes[-1].set_xlabel('time from the program start [s]')
    axes[0].set_title(title, fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_sessions_overlay(path: str | Path, axis: str,
                          sessions: Sequence[tuple[str, tuple[Sequence[float], Sequence[float], Sequence[str]],
                                                   tuple[np.ndarray, np.ndarray] | None]],
                          title: str = '') -> Path:
    """Several sessions on one force–displacement plot: each session's hold means (▲ loading, ▼ unloading) and,
    thin, its nonlinear model curve (already in LVDT reading units)."""
    ylab, xlab, s = _labels(axis)
    fig, ax = plt.subplots(figsize=(6.8, 5.0), dpi=110)
    colors = plt.rcParams['axes.prop_cycle'].by_key()['color']
    for i, (name, means, curve) in enumerate(sessions):
        color = colors[i % len(colors)]
        x, y, approach = np.asarray(means[0], float), np.asarray(means[1], float), np.asarray(means[2])
        for branch, marker in (('loading', '^'), ('unloading', 'v')):
            sel = approach == branch
            if sel.any():
                ax.plot(x[sel] * s, y[sel], marker, color=color, mfc='none', ms=6,
                        label=name if branch == 'loading' or not (approach == 'loading').any() else None)
        if curve is not None:
            ax.plot(np.asarray(curve[0]) * s, curve[1], '-', color=color, lw=1.0, alpha=0.6)
    return _finish(fig, ax, xlab, ylab, title or 'sessions compared (lines: nonlinear model of each)', path,
                   title_size=9,
                   legend_size=7, legend_loc='best')


# ---------------------------------------------------------------------------------------- analysed sessions --
def _decimate(n: int, limit: int = PLOT_POINTS) -> slice:
    return slice(None, None, max(1, math.ceil(n / limit)))


def write_session_figures(result: SessionAnalysis, data: SessionData, pairs: LivePairs,
                          commands: CommandSeries | None, t0: float, out: Path, formats: Sequence[str]) -> list[str]:
    """The figures of one analysed session in ``out`` (force_displacement and timeseries, one file per format);
    returns the paths written. Times are drawn from ``t0`` (s)."""
    written: list[str] = []
    scale = result.model.lvdt_scale if result.model is not None and abs(result.model.lvdt_scale) > 1e-9 else None
    step = _decimate(pairs.stamp.size)
    cloud: dict[str, tuple[np.ndarray, np.ndarray]]  # (displacement, force) by branch, as the plot takes them
    holds: dict[str, tuple[np.ndarray, np.ndarray]]
    cloud = {LOADING: (pairs.displacement[step][pairs.loading[step]], pairs.force[step][pairs.loading[step]]),
             UNLOADING: (pairs.displacement[step][~pairs.loading[step]], pairs.force[step][~pairs.loading[step]])}
    holds = {a: (np.array([s.displacement_mean for s in result.steps if s.approach == a]),
                 np.array([s.force_mean for s in result.steps if s.approach == a])) for a in BRANCHES}
    title = f'{result.session}: {result.axis}' + (f', program {result.program["name"]}' if result.program else '')
    if result.geometry:
        title += f', W = {result.geometry["weight"]:g} N, l0 = {result.geometry["l0"]:.3f} m'
    assert data.force is not None  # a required topic: load_session decoded it
    for fmt in formats:
        path = out / f'force_displacement.{fmt}'
        plot_session_force_displacement(
            path, result.axis, curves=result.model.curves if result.model is not None and scale else None,
            lvdt_scale=scale or 1.0, cloud=cloud, holds=holds,
            fits={b: (float(f.stiffness), float(f.intercept))  # one fit each: floats already
                  for b, f in result.branch_fits.items() if f is not None},
            title=title)
        written.append(str(path))
        path = out / f'timeseries.{fmt}'
        f_step = _decimate(data.force.size)
        series = {'force': (data.force['stamp_s'][f_step] - t0, data.force[result.axis][f_step]),
                  'displacement': (pairs.stamp[step] - t0, pairs.displacement[step])}
        if commands is not None:
            series['command'] = (commands.stamp - t0, commands.value)
        if data.live_series is not None and data.live_series.size:
            l_step = _decimate(data.live_series.size)
            series['live_stiffness'] = (data.live_series['log_time_ns'][l_step] * 1e-9 - t0,
                                        data.live_series['data'][l_step])
        plot_session_timeseries(path, result.axis, series,
                                holds=[(s.start_s, s.end_s, s.approach) for s in result.steps],
                                title=f'{result.session}: command, load and displacement')
        written.append(str(path))
    return written


def write_comparison_figures(analyses: Sequence[SessionAnalysis], out: Path, formats: Sequence[str]) -> list[str]:
    """The overlay of the sessions' quasi-static points and model curves in ``out`` (one file per format); returns
    the paths written."""
    written: list[str] = []
    for fmt in formats:
        path = out / f'compare_force_displacement.{fmt}'
        series = []
        for a in analyses:
            holds = ([s.displacement_mean for s in a.steps], [s.force_mean for s in a.steps],
                     [s.approach for s in a.steps])
            curve = None
            if a.model is not None and a.model.curves and abs(a.model.lvdt_scale) > 1e-9:
                curve = (np.asarray(a.model.curves['nonlinear']) * a.model.lvdt_scale,
                         np.asarray(a.model.curves['load']))
            series.append((a.session, holds, curve))
        plot_sessions_overlay(path, analyses[0].axis, series, title=f'{len(analyses)} session(s) compared')
        written.append(str(path))
    return written
