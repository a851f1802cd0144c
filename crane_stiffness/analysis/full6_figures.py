"""Figures of a 6×6 analysis (crane_stiffness.analysis.full6), to read at a glance (matplotlib, headless Agg; PNG or
SVG):

- ``full6_stiffness``: left, K measured / tangent − 1 per entry (diverging colours, symmetric about 0; each entry
  annotated with the measured value and the error in %; entries the tangent has as zero shown grey with their value;
  a thick black frame where the 95 % interval misses the tangent's entry). Middle and right, the tangent's and the
  measured K normalised to unit diagonal, K_ij / sqrt(|K_ii·K_jj|) (unit-free, the same colours from −1 to 1), where
  the side–tilt coupling K2 (±0.5 on the lab model, dashed frames) stands out beside the zeros.
- ``full6_ellipsoids``: the compliance ellipsoids, measured (solid) against the tangent's (dashed): top, the
  displacements under every unit force, {C_tt·f : |f| = 1 N} [µm] (C_tt the translational 3×3 block of C); bottom,
  the rotations under every unit moment, {C_rr·m : |m| = 1 N·m} [mrad]; each as its three orthogonal projections
  (the outline of the ellipsoid seen along z, y and x), with the principal compliances (the ellipsoid's semi-axes)
  measured and modelled in the title.

Rows of K are the loads fx … mz, columns the displacements u_x … θ_z, fixed frame ``crane_base``, z down.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import matplotlib

matplotlib.use('Agg')  # no display on a lab PC running headless or in CI
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from crane_stiffness.contract.axes import AXES  # noqa: E402
from crane_stiffness.full6.reference import DISPLACEMENTS, K2_ENTRIES  # noqa: E402

if TYPE_CHECKING:
    from crane_stiffness.analysis.full6_result import Full6Analysis

#: Smallest half-range of the error colour scale [%]: errors well inside it look pale, as they should.
MIN_ERROR_SCALE_PCT = 1.0
_CMAP = 'RdBu_r'


def normalised(k: NDArray[np.float64]) -> NDArray[np.float64]:
    """K_ij / sqrt(|K_ii·K_jj|) (6, 6): unit-free, 1 on the diagonal."""
    d = np.sqrt(np.abs(np.diag(k)))
    return k / np.outer(d, d)


def _short(value: float) -> str:
    """A matrix entry in four digits: 71.69k, −17.9k, 2.055M, 0.0123."""
    a = abs(value)
    for scale, suffix in ((1e6, 'M'), (1e3, 'k')):
        if a >= scale:
            return f'{value / scale:.4g}{suffix}'
    return f'{value:.3g}'


def _matrix_axes(ax, title: str) -> None:
    ax.set_xticks(range(6), DISPLACEMENTS)
    ax.set_yticks(range(6), AXES)
    ax.set_xlabel('displacement')
    ax.set_ylabel('load')
    ax.set_title(title, fontsize=10)


def _error_panel(fig, ax, a: Full6Analysis) -> None:
    assert a.comparison is not None and a.fit is not None
    measured = a.fit.stiffness
    err = np.array(a.comparison['stiffness_relative_error'], dtype=float) * 100.0
    zero = np.array(a.comparison['tangent_zero'], dtype=bool)
    covers = np.array(a.comparison['stiffness_covers'], dtype=bool)
    limit = max(MIN_ERROR_SCALE_PCT, float(np.nanmax(np.abs(err))) if np.isfinite(err).any() else 0.0)
    shown = np.ma.masked_invalid(np.where(zero, np.nan, err))
    ax.imshow(np.where(zero, 1.0, np.nan), cmap='Greys', vmin=0.0, vmax=6.0)
    image = ax.imshow(shown, cmap=_CMAP, vmin=-limit, vmax=limit)
    for i in range(6):
        for j in range(6):
            text = f'{_short(measured[i, j])}\n' + ('model 0' if zero[i, j] else f'{err[i, j]:+.2f} %')
            ax.text(j, i, text, ha='center', va='center', fontsize=7.5,
                    color='white' if not zero[i, j] and abs(err[i, j]) > 0.6 * limit else 'black')
            if not covers[i, j]:
                ax.add_patch(Rectangle((j - 0.47, i - 0.47), 0.94, 0.94, fill=False, ec='black', lw=2.8))
    fig.colorbar(image, ax=ax, fraction=0.046, pad=0.03, label='measured / tangent − 1 [%]')
    missed = int((~covers).sum())
    _matrix_axes(ax, f'K measured against the exact tangent\n{missed} of 36 intervals miss the tangent (framed)')


def _normalised_panel(fig, ax, k: NDArray[np.float64], title: str):
    n = normalised(k)
    image = ax.imshow(n, cmap=_CMAP, vmin=-1.0, vmax=1.0)
    for i in range(6):
        for j in range(6):
            ax.text(j, i, f'{n[i, j]:+.2f}', ha='center', va='center', fontsize=8,
                    color='white' if abs(n[i, j]) > 0.6 else 'black')
    for i, j, _ in K2_ENTRIES:
        ax.add_patch(Rectangle((j - 0.47, i - 0.47), 0.94, 0.94, fill=False, ec='black', lw=1.4, ls='--'))
    _matrix_axes(ax, title)
    return image


def plot_stiffness_heatmap(a: Full6Analysis, path: str | Path) -> Path:
    """The ``full6_stiffness`` figure (module docstring) of an analysis with a model comparison."""
    assert a.model is not None and a.fit is not None
    fig, axes = plt.subplots(1, 3, figsize=(19.0, 6.4), dpi=100)
    _error_panel(fig, axes[0], a)
    image = _normalised_panel(fig, axes[1], a.model.tangent, 'tangent K, normalised: K_ij / √|K_ii·K_jj|\n'
                      'dashed: the K2 entries (+K2 at fy·θ_x, mx·u_y; −K2 at fx·θ_y, my·u_x)')
    fig.colorbar(image, ax=axes[1], fraction=0.046, pad=0.03, label='K_ij / √|K_ii·K_jj|')
    image = _normalised_panel(fig, axes[2], a.fit.stiffness, f'measured K, normalised\nK2 = {a.fit.k2:.5g} N/rad '
                              f'(95 % CI {a.fit.k2_low:.5g} … {a.fit.k2_high:.5g}), tangent {a.model.k2:.5g}')
    fig.colorbar(image, ax=axes[2], fraction=0.046, pad=0.03, label='K_ij / √|K_ii·K_jj|')
    fig.suptitle(f'Session {a.session}: the 6×6 stiffness, {a.pairs["n"]} pairs in {a.pairs["steps"]} steps, '
                 f'status {a.status["level"]}', fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def ellipse(block: NDArray[np.float64], plane: tuple[int, int], points: int = 181) -> NDArray[np.float64]:
    """Outline (points, 2) of the projection onto the coordinates ``plane`` of the ellipsoid {A·u : |u| = 1},
    A = ``block`` (3, 3): the ellipse x·S⁻¹·x = 1 with S = P·A·Aᵀ·Pᵀ."""
    p = np.asarray(block, dtype=float)[list(plane), :]
    values, vectors = np.linalg.eigh(p @ p.T)
    t = np.linspace(0.0, 2.0 * np.pi, points)
    return (vectors @ (np.sqrt(np.maximum(values, 0.0))[:, None] * np.vstack([np.cos(t), np.sin(t)]))).T


def plot_ellipsoids(a: Full6Analysis, path: str | Path) -> Path:
    """The ``full6_ellipsoids`` figure (module docstring) of an analysis with a model comparison."""
    assert a.model is not None and a.fit is not None
    c, model = a.fit.compliance, a.model.compliance
    rows = ((slice(0, 3), 1e6, 'µm', ('u_x', 'u_y', 'u_z'), 'translations under a unit force [µm/N]'),
            (slice(3, 6), 1e3, 'mrad', ('θ_x', 'θ_y', 'θ_z'), 'rotations under a unit moment [mrad/(N·m)]'))
    planes = ((0, 1), (0, 2), (1, 2))
    fig, axes = plt.subplots(2, 3, figsize=(14.0, 9.0), dpi=100)
    for r, (block, scale, unit, names, what) in enumerate(rows):
        measured, modelled = c[block, block] * scale, model[block, block] * scale
        for k, (i, j) in enumerate(planes):
            ax = axes[r, k]
            for m, style, color, lw, label in ((measured, '-', 'tab:red', 2.8, 'measured'),
                                               (modelled, '--', 'k', 1.2, 'tangent')):
                xy = ellipse(m, (i, j))
                ax.plot(xy[:, 0], xy[:, 1], style, color=color, lw=lw, label=label)
            ax.set_aspect('equal', adjustable='datalim')
            ax.axhline(0.0, color='0.8', lw=0.6)
            ax.axvline(0.0, color='0.8', lw=0.6)
            ax.set_xlabel(f'{names[i]} [{unit}]')
            ax.set_ylabel(f'{names[j]} [{unit}]')
            ax.grid(True, alpha=0.3)
            if k == 0:
                ax.legend(fontsize=8, loc='upper right')
        s_meas = np.linalg.svd(measured, compute_uv=False)
        s_model = np.linalg.svd(modelled, compute_uv=False)
        axes[r, 1].set_title(f'{what}\nprincipal compliances (semi-axes): measured '
                             + ', '.join(f'{v:.4g}' for v in s_meas) + '; tangent '
                             + ', '.join(f'{v:.4g}' for v in s_model) + '; measured / tangent − 1: '
                             + ', '.join(f'{100 * (m / t - 1):+.2f} %' for m, t in zip(s_meas, s_model)), fontsize=9.5)
    fig.suptitle(f'Session {a.session}: compliance ellipsoids, three orthogonal projections each', fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    plt.close(fig)
    return path


def write_full6_figures(a: Full6Analysis, out: Path, formats: Sequence[str]) -> list[str]:
    """Both figures in each of ``formats`` ('png', 'svg') into ``out``; none without a model to compare with.
    Returns the paths written."""
    if a.model is None or a.fit is None:
        return []
    written = []
    for fmt in formats:
        written.append(str(plot_stiffness_heatmap(a, out / f'full6_stiffness.{fmt}')))
        written.append(str(plot_ellipsoids(a, out / f'full6_ellipsoids.{fmt}')))
    return written


__all__ = ['MIN_ERROR_SCALE_PCT', 'ellipse', 'normalised', 'plot_ellipsoids', 'plot_stiffness_heatmap',
           'write_full6_figures']
