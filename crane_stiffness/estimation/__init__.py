"""Stiffness estimation from synchronised load and displacement samples: pure Python/numpy, no ROS.

- :mod:`.fit` — the line fit of load on displacement with errors in both variables, its confidence interval and
  nonlinearity indicator (:class:`LineFit`, the one fit record): batch and sliding window side by side.
- :mod:`.rls` — recursive least squares with forgetting.
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
from crane_stiffness.estimation.fit import (LineFit, WindowedLeastSquares, fit_line, split_half_nonlinearity,
                                            t_quantile)
from crane_stiffness.estimation.rls import RecursiveLeastSquares, RlsResult
from crane_stiffness.estimation.sync import (DISPLACEMENT, FORCE, STREAMS, ApproximateTimeSync, Pair,
                                             StreamCounters, SyncCounters)

__all__ = [
    'BRANCHES', 'DISPLACEMENT', 'FORCE', 'LOADING', 'STREAMS', 'UNLOADING', 'ApproximateTimeSync', 'Branch',
    'BranchTracker', 'DataError', 'Estimate', 'EstimationError', 'LineFit', 'Pair', 'ParameterError',
    'RecursiveLeastSquares', 'RlsResult', 'StiffnessEstimator', 'StreamCounters', 'SyncCounters', 'SyncError',
    'WindowedLeastSquares', 'branch_labels', 'fit_line', 'split_half_nonlinearity', 't_quantile',
]
