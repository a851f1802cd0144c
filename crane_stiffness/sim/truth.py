"""The true calibration errors of a simulated sensor: what its certificate's uncertainty is about. No ROS.

``truth.mode`` says which errors a simulated sensor has:

- ``perfect`` (the default): none; the sensor reads as it did before calibration errors existed, number for number.
- ``given``: the errors of the ``truth.*`` parameters (a study sets them: "a load cell 1 % high on fy").
- ``drawn``: drawn once per session from the sensor's declared calibration (``calibration.*``, see
  :mod:`crane_stiffness.sim.calibration`) with the generator seeded by ``truth.seed``: the same seed and declaration
  give the same errors, so a run on simulated time is repeated exactly, and the errors of a recorded session follow
  from its recorded node parameters (:func:`load_cell_truth`, :func:`lvdt_truth` of them). A component declared
  ``not_stated`` draws zero.

Load cell: per-axis sensitivity errors s (a reading ``(1 + s_i)`` times the load on axis i) and the mounting
misalignment θ (a rotation vector, crane_base, of the sensor's axes: it reads the wrench in its own axes, ``R(θ)ᵀ·f``
and ``R(θ)ᵀ·m``). LVDT: a sensitivity error s and a linearity error L (fraction of the half stroke FS), the reading
of a displacement d being ``(1 + s)·d + L·FS·T3(d/FS)``, with T3(x) = 4x³ − 3x: the cubic that stays within ±1 on
the stroke and has no straight-line part in the minimax sense, so L is the deviation from the best straight line a
data sheet's linearity states.

The truth is the simulation's secret: it is recorded (as the node's parameters; the drawn errors follow from them)
for tests and studies, and no analysis reads it.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.sim.calibration import LOAD_CELL_COMPONENTS, LVDT_COMPONENTS, calibration_of
from crane_stiffness.sim.errors import ParameterError

MODES = ('perfect', 'given', 'drawn')
#: A kind of sensor's own stream of a seed: a load cell and an LVDT drawn with one truth.seed get independent errors.
_LOAD_CELL_STREAM, _LVDT_STREAM = 1, 2
_MODE = ParamSpec('truth.mode', 'perfect', 'true calibration errors of the simulated sensor: perfect (none), '
                  'given (the truth.* values) or drawn (from the calibration.* declaration with truth.seed) [-]',
                  choices=MODES)
_SEED = ParamSpec('truth.seed', 0, 'seed of the draw of the true calibration errors (truth.mode drawn) [-]', low=0)
#: The simulated load cell's true calibration errors (the load_cell node).
LOAD_CELL_TRUTH_PARAMS: tuple[ParamSpec, ...] = (
    _MODE, _SEED,
    ParamSpec('truth.sensitivity', [0.0] * 6, 'truth.mode given: sensitivity error per axis fx fy fz mx my mz, '
              '+1 = reads 1 % high (6 values, one = all) [% of reading]', rule='finite'),
    ParamSpec('truth.misalignment', [0.0] * 3, "truth.mode given: rotation vector of the sensor's axes from "
              'crane_base [rad]', rule='3 finite numbers'),
)
#: The simulated LVDT's true calibration errors (the lvdt node).
LVDT_TRUTH_PARAMS: tuple[ParamSpec, ...] = (
    _MODE, _SEED,
    ParamSpec('truth.sensitivity', 0.0, 'truth.mode given: sensitivity error of the channel, +1 = reads 1 % high '
              '[% of reading]', rule='finite'),
    ParamSpec('truth.linearity', 0.0, 'truth.mode given: linearity error, deviation from the straight line at '
              'its largest, share of the half stroke max(|range_m|) [% FS]', rule='finite'),
)


@dataclass(frozen=True)
class LoadCellTruth:
    """A load cell's true errors: ``sensitivity`` (6,) as fractions (0.01 = 1 % high), ``misalignment`` (3,) rad."""

    sensitivity: NDArray[np.float64]
    misalignment: NDArray[np.float64]

    @property
    def perfect(self) -> bool:
        """No error at all."""
        return not (self.sensitivity.any() or self.misalignment.any())

    def as_dict(self) -> dict[str, list[float]]:
        """For a log or a study: ``sensitivity`` in % of reading, ``misalignment`` in rad."""
        return {'sensitivity': (100.0 * self.sensitivity).tolist(), 'misalignment': self.misalignment.tolist()}


@dataclass(frozen=True)
class LvdtTruth:
    """An LVDT channel's true errors as fractions: ``sensitivity`` (0.01 = 1 % high), ``linearity`` (of FS)."""

    sensitivity: float
    linearity: float

    @property
    def perfect(self) -> bool:
        """No error at all."""
        return self.sensitivity == 0.0 and self.linearity == 0.0

    def as_dict(self) -> dict[str, float]:
        """For a log or a study: both in %."""
        return {'sensitivity': 100.0 * self.sensitivity, 'linearity': 100.0 * self.linearity}


def _finite(field: str, value: Any, sizes: tuple[int, ...]) -> NDArray[np.float64]:
    try:
        array = np.atleast_1d(np.array(value, dtype=float))
    except (TypeError, ValueError):
        raise ParameterError(field, value, f'must be {" or ".join(map(str, sizes))} numbers') from None
    if isinstance(value, bool) or array.ndim != 1 or array.size not in sizes:
        raise ParameterError(field, value, f'must be {" or ".join(map(str, sizes))} numbers')
    if not np.isfinite(array).all():
        raise ParameterError(field, value, 'every entry must be finite')
    return np.broadcast_to(array, (max(sizes),)).copy()


def _mode(values: Mapping[str, Any]) -> str:
    mode = values['truth.mode']
    if mode not in MODES:
        raise ParameterError('truth.mode', mode, f'must be one of {", ".join(MODES)}')
    seed = values['truth.seed']
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError('truth.seed', seed, 'must be an integer >= 0')
    return mode


def load_cell_truth(values: Mapping[str, Any]) -> LoadCellTruth:
    """The load cell's true errors from its parameter values (:data:`LOAD_CELL_TRUTH_PARAMS` and, for ``drawn``,
    the ``calibration.*`` ones). Raises ParameterError naming a bad value."""
    mode = _mode(values)
    sensitivity = _finite('truth.sensitivity', values['truth.sensitivity'], (1, 6)) / 100.0
    misalignment = _finite('truth.misalignment', values['truth.misalignment'], (3,))
    stated = calibration_of(values, LOAD_CELL_COMPONENTS)  # checked in every mode: a bad declaration is refused
    if mode == 'perfect':
        return LoadCellTruth(np.zeros(6), np.zeros(3))
    if mode == 'given':
        return LoadCellTruth(sensitivity, misalignment)
    rng = np.random.default_rng((int(values['truth.seed']), _LOAD_CELL_STREAM))
    drawn = {c.name: stated[c.name].draw(rng) for c in LOAD_CELL_COMPONENTS}  # every component, in a fixed order
    return LoadCellTruth(drawn['sensitivity'] / 100.0, drawn['misalignment'])


def lvdt_truth(values: Mapping[str, Any]) -> LvdtTruth:
    """The LVDT's true errors from its parameter values (:data:`LVDT_TRUTH_PARAMS` and, for ``drawn``, the
    ``calibration.*`` ones: sensitivity and DAQ gain add up, linearity is the linearity). Raises ParameterError
    naming a bad value."""
    mode = _mode(values)
    sensitivity = float(_finite('truth.sensitivity', values['truth.sensitivity'], (1,))[0]) / 100.0
    linearity = float(_finite('truth.linearity', values['truth.linearity'], (1,))[0]) / 100.0
    stated = calibration_of(values, LVDT_COMPONENTS)
    if mode == 'perfect':
        return LvdtTruth(0.0, 0.0)
    if mode == 'given':
        return LvdtTruth(sensitivity, linearity)
    rng = np.random.default_rng((int(values['truth.seed']), _LVDT_STREAM))
    drawn = {c.name: float(stated[c.name].draw(rng)[0]) for c in LVDT_COMPONENTS}
    return LvdtTruth((drawn['sensitivity'] + drawn['daq_gain']) / 100.0, drawn['linearity'] / 100.0)


__all__ = ['LOAD_CELL_TRUTH_PARAMS', 'LVDT_TRUTH_PARAMS', 'MODES', 'LoadCellTruth', 'LvdtTruth', 'load_cell_truth',
           'lvdt_truth']
