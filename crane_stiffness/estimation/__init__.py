"""Stiffness estimation from synchronised load and displacement samples: pure Python/numpy, no ROS.

- :mod:`.fit` — batch line fit with confidence interval and nonlinearity indicator, sliding-window and recursive
  least squares, and the composed :class:`StiffnessEstimator`.
- :mod:`.branch` — loading/unloading branch tracking, live and vectorized.
- :mod:`.sync` — approximate pairing of the force and displacement streams by header stamp.
- :mod:`.errors` — the package's exceptions.
"""
from crane_stiffness.estimation.branch import BRANCHES, LOADING, UNLOADING, Branch, BranchTracker, branch_labels
from crane_stiffness.estimation.errors import DataError, EstimationError, ParameterError, SyncError
from crane_stiffness.estimation.fit import (Estimate, LineFit, RecursiveLeastSquares, RlsResult, StiffnessEstimator,
                                            WindowedLeastSquares, fit_line, split_half_nonlinearity, t_quantile)
from crane_stiffness.estimation.sync import (DISPLACEMENT, FORCE, STREAMS, ApproximateTimeSync, Pair,
                                             StreamCounters, SyncCounters)

__all__ = [
    'BRANCHES', 'DISPLACEMENT', 'FORCE', 'LOADING', 'STREAMS', 'UNLOADING', 'ApproximateTimeSync', 'Branch',
    'BranchTracker', 'DataError', 'Estimate', 'EstimationError', 'LineFit', 'Pair', 'ParameterError',
    'RecursiveLeastSquares', 'RlsResult', 'StiffnessEstimator', 'StreamCounters', 'SyncCounters', 'SyncError',
    'WindowedLeastSquares', 'branch_labels', 'fit_line', 'split_half_nonlinearity', 't_quantile',
]
