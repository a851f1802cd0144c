"""The live 6×6 fit's expanded uncertainty: U of every entry of K, and of K2, from the step means the live estimator
holds and the sensors' declared calibrations, by the GUM's law of propagation alone (no Monte Carlo live:
:func:`crane_stiffness.uncertainty.matrix.matrix_uncertainty` with ``trials=0``, ~7 ms with every component
declared). The same function, inputs and numbers as the offline analysis' law of propagation
(crane_stiffness.analysis.full6_uncertainty): what differs offline is the Monte Carlo beside it. No ROS.

The calibrations are the sensor nodes' parameters as read over ROS (``calibration.*``; the load cell's
``full_scale``): the load cell's, the pose sensor's and, when the deflection comes from one, an LVDT array's
(:func:`~crane_stiffness.uncertainty.calibration6.six_axis_inputs`). A sensor not read (yet) has every component left
out, and the statement says "statistical only" for it; a declaration the budget refuses leaves no U at all (NaN),
named, rather than a U that silently drops it.

The interval published is the live fit's K ∓ U (K of the pairs, as /stiffness6/stiffness; the step means' fit that U
comes from agrees with it within a fraction of its standard error, crane_stiffness.uncertainty.matrix).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np
from numpy.typing import NDArray

from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.full6.statistics import PairStatistics
from crane_stiffness.uncertainty.calibration6 import CalibrationInputs, six_axis_inputs
from crane_stiffness.uncertainty.matrix import matrix_uncertainty

#: The sensors whose declared calibrations count, in six_axis_inputs' order.
SENSORS = ('load_cell', 'pose_sensor', 'lvdt_array')


@dataclass(frozen=True)
class LiveMatrixU:
    """U of the live fit.

    Attributes:
        U: each entry's expanded uncertainty (6, 6) [N/m, N/rad, N·m/m, N·m/rad] (NaN: none, ``problem`` says why).
        k: each entry's coverage factor (6, 6) [-] (t_95 of its ν_eff).
        k2_U, k2_k: K2's expanded uncertainty [N/rad] and coverage factor.
        steps: step means the Type A is fitted from.
        statistical_only: no calibration component counted.
        statement: what U holds ('calibration counted: …; statistical only for …', or 'statistical only: …').
        problem: why there is no U ('' when there is one).
    """

    U: NDArray[np.float64]
    k: NDArray[np.float64]
    k2_U: float
    k2_k: float
    steps: int
    statistical_only: bool
    statement: str
    problem: str = field(default='')

    @property
    def stated(self) -> bool:
        return not self.problem


def _none(steps: int, statistical_only: bool, statement: str, problem: str) -> LiveMatrixU:
    nan = np.full((6, 6), math.nan)
    return LiveMatrixU(nan, nan.copy(), math.nan, math.nan, steps, statistical_only, statement, problem)


class LiveMatrixUncertainty:
    """The calibrations read so far (:meth:`set_calibration`) and U of the current step means (:meth:`of`),
    computed again only when the step means or the calibrations changed."""

    def __init__(self) -> None:
        self.calibrations: dict[str, Mapping[str, Any] | None] = dict.fromkeys(SENSORS)
        self._inputs: CalibrationInputs | str | None = None  # six_axis_inputs of them, or why it refused them
        self._last: tuple[bytes, LiveMatrixU] | None = None

    def set_calibration(self, sensor: str, values: Mapping[str, Any] | None) -> None:
        """The declared calibration of ``sensor`` (one of :data:`SENSORS`): its node's parameters, None: not read."""
        if sensor not in SENSORS:
            raise ValueError(f'sensor {sensor!r}: one of {", ".join(SENSORS)}')
        self.calibrations[sensor] = None if values is None else dict(values)
        self._inputs = None
        self._last = None

    def inputs(self) -> CalibrationInputs | str:
        """The Type B inputs of the calibrations read, or the reason they were refused."""
        if self._inputs is not None:
            return self._inputs
        inputs: CalibrationInputs | str
        try:
            inputs = six_axis_inputs(self.calibrations['load_cell'], self.calibrations['pose_sensor'],
                                     self.calibrations['lvdt_array'])
        except (CraneStiffnessError, ValueError) as exc:
            inputs = f'the declared calibration was refused ({exc})'
        self._inputs = inputs
        return inputs

    def of(self, stats: PairStatistics) -> LiveMatrixU:
        """U of K and K2 from the step means of ``stats`` (the live estimator's pairs)."""
        means = stats.step_means
        key = means.tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        inputs = self.inputs()
        steps = int(means.shape[0])
        if isinstance(inputs, str):
            out = _none(steps, True, f'no U: {inputs}', inputs)
        else:
            try:
                result = matrix_uncertainty(means[:, :6], means[:, 6:], inputs, trials=0)
            except (CraneStiffnessError, ValueError, np.linalg.LinAlgError) as exc:
                out = _none(steps, inputs.statistical_only, f'no U yet: {exc}', str(exc))
            else:
                out = LiveMatrixU(result.stiffness.U, result.stiffness.k, float(result.k2.U), float(result.k2.k),
                                  steps, inputs.statistical_only, inputs.statement)
        self._last = (key, out)
        return out


__all__ = ['LiveMatrixU', 'LiveMatrixUncertainty', 'SENSORS']
