"""The live stiffness estimator of one loaded axis: every pair labelled loading or unloading and fitted on its branch
(windowed least squares and recursive least squares with forgetting), and the estimate of each branch.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from crane_stiffness.estimation.branch import BRANCHES, Branch, BranchTracker
from crane_stiffness.estimation.errors import ParameterError
from crane_stiffness.estimation.fit import LineFit, WindowedLeastSquares
from crane_stiffness.estimation.rls import RecursiveLeastSquares
from crane_stiffness.estimation.quality import scatter_ratio

_LINE_FIT_FIELDS = tuple(f.name for f in fields(LineFit))


@dataclass(frozen=True, slots=True)
class Estimate(LineFit):
    """Stiffness estimate of one load branch: the :class:`~crane_stiffness.estimation.fit.LineFit` of the branch's
    window (floats; its ``nonlinearity`` is over the window, > 0 means softening), and:

    Attributes:
        stamp_s: Stamp of the newest sample on this branch, s.
        branch: 'loading' or 'unloading'.
        rls_stiffness: Recursive least-squares slope over all samples of the branch (with forgetting); NaN if not
            available yet.
        rls_stderr: Its approximate standard error.
    """

    stamp_s: float
    branch: Branch
    rls_stiffness: float
    rls_stderr: float


class StiffnessEstimator:
    """Live stiffness of one loaded axis, fitted separately on the loading and the unloading branch.

    Each sample ``(stamp_s, force, displacement)`` is labelled by a :class:`BranchTracker` (from ``load`` if given,
    e.g. the commanded load, else from ``force``) and goes into that branch's :class:`WindowedLeastSquares` and
    :class:`RecursiveLeastSquares`. ``force`` is the load along the axis (N, or N·m for a moment test) and
    ``displacement`` the motion along it (m, or rad).

    :meth:`add` is O(1); :meth:`estimate` costs a sort of the window (the nonlinearity indicator), so call it at
    the publishing rate, not per sample. Choose ``window`` to span several hold levels: a window inside one hold
    has no spread in displacement and yields no estimate.
    """

    PARAM_NAMES = ('hysteresis', 'window', 'forgetting', 'initial_covariance')

    def __init__(self, hysteresis: float, window: int = 500, forgetting: float = 0.999, *,
                 initial_covariance: float = 1e12, nonlinearity: bool = True, x_noise: float = 0.0) -> None:
        """Args: hysteresis: branch dead band in load units (see BranchTracker). window: pairs per windowed fit.
        forgetting: RLS λ. initial_covariance: RLS prior variance. nonlinearity: compute the indicator. x_noise:
        the displacement noise counted in the windowed fits until :meth:`set_displacement_noise` (m or rad; 0:
        ordinary least squares), and again after :meth:`reset`."""
        self._tracker = BranchTracker(hysteresis)
        self._windows = {b: WindowedLeastSquares(window, nonlinearity=nonlinearity) for b in BRANCHES}
        self._rls = {b: RecursiveLeastSquares(forgetting, initial_covariance=initial_covariance) for b in BRANCHES}
        self._stamps: dict[Branch, float] = {b: math.nan for b in BRANCHES}
        # σx counted in each branch's windowed fit (fit.py: errors in both variables); 0 = ordinary least squares
        self._x_noise_default = 0.0
        self._x_noise: dict[Branch, float] = {}
        for b in BRANCHES:
            self.set_displacement_noise(b, x_noise)
        self._x_noise_default = x_noise
        self._rejected = 0

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> StiffnessEstimator:
        """Build from a parameter dict with keys from :attr:`PARAM_NAMES` (``hysteresis`` required)."""
        unknown = sorted(set(params) - set(cls.PARAM_NAMES))
        if unknown:
            raise ParameterError(unknown[0], params[unknown[0]],
                                 f'unknown parameter; known: {", ".join(cls.PARAM_NAMES)}')
        if 'hysteresis' not in params:
            raise ParameterError('hysteresis', None, 'is required (branch dead band in load units)')
        return cls(**{key: params[key] for key in cls.PARAM_NAMES if key in params})

    @property
    def branch(self) -> Branch:
        """Branch of the last accepted sample."""
        return self._tracker.branch

    @property
    def rejected(self) -> int:
        """Samples skipped because a value was NaN or Inf."""
        return self._rejected

    def reset(self) -> None:
        """Forget everything (e.g. at the start of a new program)."""
        self._tracker.reset()
        for branch in BRANCHES:
            self._windows[branch].reset()
            self._rls[branch].reset()
            self._stamps[branch] = math.nan
            self._x_noise[branch] = self._x_noise_default
        self._rejected = 0

    def add(self, stamp_s: float, force: float, displacement: float, load: float | None = None) -> Branch | None:
        """Feed one synchronised pair; returns its branch, or None if it was skipped for a NaN/Inf value."""
        force = float(force)
        displacement = float(displacement)
        branch_load = force if load is None else float(load)
        if not (math.isfinite(force) and math.isfinite(displacement) and math.isfinite(branch_load)):
            self._rejected += 1
            return None
        branch = self._tracker.update(branch_load)
        self._windows[branch].add(displacement, force)
        self._rls[branch].add(displacement, force)
        self._stamps[branch] = float(stamp_s)
        return branch

    def set_displacement_noise(self, branch: Branch, x_noise: float) -> None:
        """Count a displacement noise of standard deviation ``x_noise`` (m or rad, ≥ 0; 0: ordinary least squares)
        in ``branch``'s windowed fit from now on (:mod:`~crane_stiffness.estimation.fit`)."""
        x_noise = float(x_noise)
        if not (x_noise >= 0.0 and math.isfinite(x_noise)):
            raise ParameterError('x_noise', x_noise, 'must be finite and >= 0 (m or rad)')
        self._x_noise[branch] = x_noise

    def nonlinearity(self, branch: Branch) -> float:
        """The nonlinearity indicator of ``branch``'s window (partitions the window, whatever the constructor's
        ``nonlinearity``); NaN while the window cannot be fitted."""
        fit = self._windows[branch].result(nonlinearity=True, x_noise=self._x_noise[branch])
        return math.nan if fit is None else float(fit.nonlinearity)

    def scatter_ratio(self, branch: Branch) -> float:
        """``branch``'s residual rms over what the noise of both series explains (:func:`~crane_stiffness.
        estimation.quality.scatter_ratio`, pairs in arrival order); NaN while the window cannot be fitted."""
        window = self._windows[branch]
        fit = window.result(nonlinearity=False, x_noise=self._x_noise[branch])
        if fit is None:
            return math.nan
        x, y = window.data()
        return scatter_ratio(x, y, float(fit.stiffness), float(fit.residual_rms))

    def estimate(self, branch: Branch | None = None) -> Estimate | None:
        """Estimate of ``branch`` (default: the current one), or None while its window cannot be fitted."""
        branch = self._tracker.branch if branch is None else branch
        if branch not in BRANCHES:
            raise ParameterError('branch', branch, f'must be one of {", ".join(BRANCHES)}')
        fit = self._windows[branch].result(x_noise=self._x_noise[branch])
        if fit is None:
            return None
        rls = self._rls[branch].result()
        return Estimate(**{name: getattr(fit, name) for name in _LINE_FIT_FIELDS},
                        stamp_s=self._stamps[branch], branch=branch,
                        rls_stiffness=math.nan if rls is None else rls.stiffness,
                        rls_stderr=math.nan if rls is None else rls.stderr)

    def x_noise(self, branch: Branch) -> float:
        """The displacement noise ``branch``'s windowed fit counts now, m or rad (0: ordinary least squares)."""
        return self._x_noise[branch]

    def window_len(self, branch: Branch) -> int:
        """Pairs held in ``branch``'s window."""
        return len(self._windows[branch])

    def window_data(self, branch: Branch) -> tuple[Any, Any]:
        """Copies of ``branch``'s window: (displacements, forces), oldest first, shape (n,) each."""
        return self._windows[branch].data()

    def estimates(self) -> dict[Branch, Estimate | None]:
        """Estimates of both branches."""
        return {branch: self.estimate(branch) for branch in BRANCHES}
