"""Stiffness estimation from synchronised load and displacement samples: pure Python/numpy, no ROS.

- :mod:`.fit` — batch line fit with confidence interval and nonlinearity indicator (:class:`LineFit`, the one fit
  record), sliding-window and recursive least squares.
- :mod:`.branch` — loading/unloading branch tracking, live and vectorized.
- :mod:`.estimator` — :class:`StiffnessEstimator`: tracker and fits per branch composed, its :class:`Estimate`.
- :mod:`.sync` — approximate pairing of the force and displacement streams by header stamp, live and vectorized.
- :mod:`.inputs` — the input checks and the commanded load in effect, live and vectorized.
- :mod:`.live` — :class:`~.live.LiveStiffness`, everything the stiffness_estimator node computes, and the same
  pairs and branches for whole recorded streams.
- :mod:`.errors` — the package's exceptions.
"""
from crane_stiffness.estimation.branch import BRANCHES, LOADING, UNLOADING, Branch, BranchTracker, branch_labels
from crane_stiffness.estimation.errors import DataError, EstimationError, ParameterError, SyncError
from crane_stiffness.estimation.estimator import Estimate, StiffnessEstimator
from crane_stiffness.estimation.fit import (LineFit, RecursiveLeastSquares, RlsResult, WindowedLeastSquares, fit_line,
                                            split_half_nonlinearity, t_quantile)
from crane_stiffness.estimation.sync import (DISPLACEMENT, FORCE, STREAMS, ApproximateTimeSync, Pair,
                                             StreamCounters, SyncCounters)

__all__ = [
    'BRANCHES', 'DISPLACEMENT', 'FORCE', 'LOADING', 'STREAMS', 'UNLOADING', 'ApproximateTimeSync', 'Branch',
    'BranchTracker', 'DataError', 'Estimate', 'EstimationError', 'LineFit', 'Pair', 'ParameterError',
    'RecursiveLeastSquares', 'RlsResult', 'StiffnessEstimator', 'StreamCounters', 'SyncCounters', 'SyncError',
    'WindowedLeastSquares', 'branch_labels', 'fit_line', 'split_half_nonlinearity', 't_quantile',
]
