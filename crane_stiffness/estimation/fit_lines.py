"""Each branch's fitted window as a line to draw, with its 95 % confidence band: what a live plot needs beside the
points (the estimate topics carry the slope and its interval, not where the window lies). Pure numpy, no ROS.

The band of the fitted line at displacement x (the window's fit, errors in both variables: fit.py) is
``y(x) ± t(0.975, n − 2) · sqrt(s²/n + (x − x̄)² · se_k²)`` with ``s² = SSE / (n − 2)`` and ``se_k`` the slope's
standard error (with no displacement noise counted, ``se_k² = s²/Sxx``: the classical band): each row carries what
that needs, so a viewer draws the band without the pairs.
"""
from __future__ import annotations

import math

import numpy as np

from crane_stiffness.estimation.branch import BRANCHES
from crane_stiffness.estimation.estimator import StiffnessEstimator
from crane_stiffness.estimation.fit import t_quantile

#: Columns of one row of :func:`fit_line_rows` (rows loading, unloading). Units: stiffness N/m (N·m/rad),
#: intercept N (N·m), x_mean, x_min, x_max m (rad), stderr (of the slope) N/m (N·m/rad), residual_std N (N·m), t95
#: and n without unit.
FIT_LINE_FIELDS = ('stiffness', 'intercept', 'x_mean', 'stderr', 'residual_std', 't95', 'n', 'x_min', 'x_max')


def fit_line_rows(estimator: StiffnessEstimator) -> list[float]:
    """Rows ``BRANCHES`` × :data:`FIT_LINE_FIELDS`, row-major; a branch that cannot be fitted yet is all NaN.
    O(window) per branch (reads the window): meant for a slow timer."""
    out: list[float] = []
    for branch in BRANCHES:
        est = estimator.estimate(branch)
        if est is None:
            out.extend([math.nan] * len(FIT_LINE_FIELDS))
            continue
        x, _ = estimator.window_data(branch)
        n = int(x.size)
        xm = float(x.mean())
        # residual_rms = sqrt(SSE / n): the band's s uses n − 2 degrees of freedom
        s = float(est.residual_rms) * math.sqrt(n / (n - 2))
        out.extend([float(est.stiffness), float(est.intercept), xm, float(est.stderr), s, t_quantile(n - 2), float(n),
                    float(x.min()), float(x.max())])
    return out


def band(row: dict[str, float], x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(line, lower, upper) at displacements ``x`` (shape (m,)) of one :func:`fit_line_rows` row as a dict."""
    line = row['stiffness'] * x + row['intercept']
    half = row['t95'] * np.sqrt(row['residual_std'] ** 2 / row['n'] + (x - row['x_mean']) ** 2 * row['stderr'] ** 2)
    return line, line - half, line + half
