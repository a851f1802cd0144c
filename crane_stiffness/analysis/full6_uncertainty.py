"""The offline 6×6 analysis' measurement uncertainty (crane_stiffness.analysis.full6): K, C and K2 with their GUM
uncertainty from the step means and the sensors' declared calibrations (crane_stiffness.uncertainty.matrix,
.calibration6), and E_n entry by entry against the model's tangent with its own uncertainty
(crane_stiffness.uncertainty.prediction6). Pure: no ROS import.

What goes into ``full6.json`` under ``uncertainty`` (:func:`session_matrix_uncertainty`): the measured matrices with,
per entry (6×6 lists, K rows loads and columns displacements, C the transpose layout), ``value``, ``u_c``, ``u_a``,
``u_b``, ``nu_eff``, ``k``, ``U``, ``coverage``, ``interval`` [low, high] (value ∓ U), ``statistical_interval``
(value ∓ t·u_a, the repeatability) and the Monte Carlo's (JCGM 102) ``monte_carlo`` {mean, u, interval}; K2 the same
as numbers; the 36×36 covariances of row-major vec K and vec C (law of propagation, the Monte Carlo's and the Type A
alone) under ``covariance``; what was counted and left out (``statistical_only``, ``calibration``, ``notes``); the
model's ``prediction`` (nominal tangent, u and U per entry) and ``En`` per entry of K and for K2.
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np

from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.full6.statistics import PairStatistics
from crane_stiffness.model.geometry import CraneGeometry
from crane_stiffness.uncertainty.budget import json_ready
from crane_stiffness.uncertainty.calibration6 import six_axis_inputs
from crane_stiffness.uncertainty.matrix import MatrixUncertainty, matrix_uncertainty
from crane_stiffness.uncertainty.prediction6 import MatrixPrediction, en_matrix, predict_matrix

#: The crane inputs' uncertainties unless the caller names a file (in the package's config/).
DEFAULT_UNCERTAINTY_FILE = 'uncertainty_lab.yaml'
LOAD_CELL_NODES = ('load_cell', '/load_cell', 'netft', '/netft')
POSE_SENSOR_NODES = ('pose_sensor', '/pose_sensor')
LVDT_ARRAY_NODES = ('lvdt_array', '/lvdt_array')


def _node(sensors: dict[str, dict[str, Any]], names: tuple[str, ...]) -> dict[str, Any] | None:
    for name in names:
        if isinstance(sensors.get(name), dict):
            return sensors[name]
    return None


def _prediction(geometry: CraneGeometry, uncertainty_file: str | os.PathLike | None, seed: int
                ) -> tuple[MatrixPrediction, str]:
    from crane_stiffness.params.files import config_path
    from crane_stiffness.uncertainty.crane_inputs import input_names, load_uncertainty_file
    path = config_path(str(uncertainty_file) if uncertainty_file is not None else DEFAULT_UNCERTAINTY_FILE)
    entries = load_uncertainty_file(path)
    if uncertainty_file is None:  # the lab file, for whatever crane: keep its entries this crane has
        known = set(input_names(geometry))
        entries = {name: entry for name, entry in entries.items() if name in known}
    return predict_matrix(geometry, uncertainty=entries, seed=seed), str(path)


def session_matrix_uncertainty(stats: PairStatistics, sensors: dict[str, dict[str, Any]],
                               geometry: CraneGeometry | None, problems: list[str], *,
                               uncertainty_file: str | os.PathLike | None = None, seed: int = 0
                               ) -> tuple[dict[str, Any] | None, MatrixUncertainty | None]:
    """The ``uncertainty`` section of ``full6.json`` (module docstring) and the result itself, from the pairs'
    statistics (their step means), the recorded node parameters and the geometry (None: no prediction, no E_n);
    (None, None) with a problem appended when the step means cannot give it."""
    means = stats.step_means
    calibration = six_axis_inputs(_node(sensors, LOAD_CELL_NODES), _node(sensors, POSE_SENSOR_NODES),
                                  _node(sensors, LVDT_ARRAY_NODES))
    try:
        result = matrix_uncertainty(means[:, :6], means[:, 6:], calibration, seed=seed)
    except (CraneStiffnessError, np.linalg.LinAlgError) as exc:
        problems.append(f'no measurement uncertainty: {exc}')
        return None, None
    out = json_ready(result.to_dict())  # (what is left out is said there and in the report, not as a problem:
    # a component a lab declares not_stated is its statement, not a fault of the session)
    if geometry is None:
        return out, result
    try:
        prediction, path = _prediction(geometry, uncertainty_file, seed)
    except (CraneStiffnessError, ValueError, OSError) as exc:
        problems.append(f"the model's 6×6 prediction with its uncertainty failed: {exc}")
        return out, result
    out['prediction'] = {**json_ready(prediction.to_dict()), 'uncertainty_file': path}
    en = en_matrix(result.stiffness.value, result.stiffness.U, prediction.stiffness, prediction.stiffness_U)
    en_k2 = float(en_matrix(result.k2.value, result.k2.U, prediction.k2, prediction.k2_U))
    out['En'] = {'stiffness': json_ready([[None if not np.isfinite(v) else float(v) for v in row] for row in en]),
                 'k2': en_k2, 'agree': int(np.sum(np.abs(en) <= 1.0)), 'of': int(np.sum(np.isfinite(en))),
                 'rule': '|E_n| <= 1 agrees (measured U against the model\'s U = 1.96 u of its Monte Carlo)'}
    return out, result


__all__ = ['DEFAULT_UNCERTAINTY_FILE', 'session_matrix_uncertainty']
