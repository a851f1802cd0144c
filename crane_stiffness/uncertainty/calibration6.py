"""The declared calibrations of a six-axis measurement as input quantities, and how each acts on its readings: the
Type B part of the 6×6 stiffness's uncertainty (crane_stiffness.uncertainty.matrix). No ROS.

The instrument model, each effect a small error of a reading with estimate 0 (nothing is corrected; its uncertainty
is counted), in the order the simulated load cell applies them (crane_stiffness.sim.sensors, .sim.truth):

- **load cell** (w the true wrench at the platform centre, r its reading, both [fx fy fz mx my mz], N and N·m)::

      v = (I + E) · diag(1 + s) · blkdiag(R(θ)ᵀ, R(θ)ᵀ) · w,      r_i = v_i + L_i·FS_i·T3(v_i / FS_i)

  ``s`` (6,) the sensitivity errors [fraction of reading] (``calibration.sensitivity``, % of reading); ``θ`` (3,) the
  mounting misalignment, a rotation vector of the sensor's axes about crane_base x y z [rad]
  (``calibration.misalignment``); ``E`` the cross-talk left after the sensor's calibration matrix, E_ij = ε_ij ·
  FS_i / FS_j for i ≠ j with ε_ij bounded by ``calibration.crosstalk`` of the receiving axis i [% FS]: a full-scale
  load on axis j puts at most that share of axis i's full scale into it (30 inputs); ``L`` (6,) the nonlinearity
  [fraction of FS] (``calibration.nonlinearity``, % FS) as the smooth worst-case curve T3(x) = 4x³ − 3x of
  crane_stiffness.uncertainty.measurement (its slope near rest is −3L: the bound min(e/R, 3L) of the one-axis budget
  for a test near rest). FS = the load cell's ``full_scale`` per axis.
- **pose sensor** (d the true deflection [u_x u_y u_z θ_x θ_y θ_z], m and rad; p its reading): the tracker's frame
  is aligned with crane_base to within its declared angle accuracy φ (3,) [rad] (``calibration.angle``), which
  turns translations and rotations alike: ``p = blkdiag(R(φ), R(φ)) · d``. Its position accuracy
  (``calibration.position``, m) is a bias of the readings: it moves the fit's offset, not C; it is listed as counted
  with no effect on C, never left out silently.

Not counted, and why: the load cell's hysteresis (a loop about the step's path; the fold-over steps ±w average it
out of C to first order) and zero drift (it moves the step means in time and shows in the Type A of the step means,
crane_stiffness.uncertainty.matrix); the tracker's scale, which no declared component states (a motion-capture
calibration fixes the scale with its wand; state it as a certificate if it matters). A component declared
``not_stated`` (or not declared at all: a bag without the sensors' parameters) is left out and named.

:func:`six_axis_inputs` reads the declarations into :class:`CalibrationInputs` (the scalar input quantities, what was
counted and left out); :meth:`CalibrationInputs.correct` applies the inverse of the model for many draws at once to
the step means (the measured wrench and deflection of each held step), so a refit of the corrected means gives C
under those calibration errors (JCGM 102's vector Monte Carlo, and the law of propagation by finite differences).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np
from numpy.typing import NDArray

from crane_stiffness.sim.calibration import Stated
from crane_stiffness.uncertainty.errors import InputError
from crane_stiffness.uncertainty.inputs import InputQuantity
from crane_stiffness.uncertainty.measurement import stated_component

_DISTRIBUTION = {'normal': 'normal', 'rectangular': 'rectangular', 'triangular': 'triangular', 'u_shaped': 'arcsine'}
_AXES = ('fx', 'fy', 'fz', 'mx', 'my', 'mz')
_XYZ = ('x', 'y', 'z')
#: Fixed-point iterations inverting the nonlinearity (its slope 3L is ~1e-2 at most: four leave ~1e-10 of it).
_NONLINEAR_ITERATIONS = 4


def _quantity(name: str, stated: Stated, index: int, scale: float) -> InputQuantity:
    """An error with estimate 0 from a stated component's entry ``index`` times ``scale`` (its unit to the
    model's: % to a fraction, or 1)."""
    value = float(stated.value[index]) * scale
    if stated.distribution == 'normal':
        return InputQuantity.expanded(name, 0.0, value, stated.k, unit='1' if scale != 1.0 else stated.unit)
    return InputQuantity.bounded(name, 0.0, value, _DISTRIBUTION[stated.distribution],
                                 unit='1' if scale != 1.0 else stated.unit)


def rotation_matrices(w: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrices exp([w]×) (M, 3, 3) of rotation vectors w (M, 3) [rad] (Rodrigues, vectorised)."""
    w = np.asarray(w, dtype=float).reshape(-1, 3)
    angle = np.linalg.norm(w, axis=1)
    k = np.zeros((w.shape[0], 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle ** 2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle ** 2 / 24.0, (1.0 - np.cos(safe)) / safe ** 2)
    return np.eye(3) + a[:, None, None] * k + b[:, None, None] * (k @ k)


def _blockdiag(r: NDArray[np.float64]) -> NDArray[np.float64]:
    out = np.zeros((r.shape[0], 6, 6))
    out[:, :3, :3] = r
    out[:, 3:, 3:] = r
    return out


@dataclass(frozen=True)
class CalibrationInputs:
    """The Type B inputs of a six-axis measurement (module docstring).

    Attributes:
        inputs: the scalar input quantities, estimate 0 each: names ``load_cell_sensitivity_<axis>``,
            ``load_cell_misalignment_<x|y|z>``, ``load_cell_crosstalk_<into>_<from>``,
            ``load_cell_nonlinearity_<axis>``, ``pose_sensor_angle_<x|y|z>`` (fractions, or rad).
        full_scale: the load cell's full scale per axis (6,) [N, N·m] (inf where not recorded).
        counted: the components counted (with their sensor), in order; left_out: those not stated or not declared.
        notes: what a reader should know (a component counted with no effect on C, why one is not counted).
    """

    inputs: tuple[InputQuantity, ...]
    full_scale: NDArray[np.float64]
    counted: tuple[str, ...]
    left_out: tuple[str, ...]
    notes: tuple[str, ...] = field(default=())

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(q.name for q in self.inputs)

    @property
    def statistical_only(self) -> bool:
        """No component counted: the uncertainty is the fit's alone."""
        return not self.counted

    @property
    def statement(self) -> str:
        """What the calibration part holds, for a report: 'statistical only' named wherever a component is missing."""
        if not self.counted:
            return 'statistical only: no calibration declared by the sensors (the uncertainty is the fit\'s alone)'
        text = f'calibration counted: {", ".join(self.counted)}'
        if self.left_out:
            text += f'; statistical only for {", ".join(self.left_out)} (not stated)'
        return text

    def standard_uncertainties(self) -> NDArray[np.float64]:
        """u of every input (N,), in the inputs' order."""
        return np.array([q.u for q in self.inputs])

    def _columns(self, x: NDArray[np.float64], prefix: str, suffixes: tuple[str, ...]) -> NDArray[np.float64]:
        """The draws (M, len(suffixes)) of the inputs ``prefix + suffix`` (0 where an input is absent)."""
        index = {name: i for i, name in enumerate(self.names)}
        out = np.zeros((x.shape[0], len(suffixes)))
        for j, suffix in enumerate(suffixes):
            i = index.get(prefix + suffix)
            if i is not None:
                out[:, j] = x[:, i]
        return out

    def correct(self, x: NDArray[np.float64], wrench: NDArray[np.float64], deflection: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The readings corrected for the errors ``x`` (M, N) (one draw per row, inputs in order): the wrench (k, 6)
        [N, N·m] and deflection (k, 6) [m, rad] of the k step means as they would be without those errors,
        (M, k, 6) each."""
        x = np.asarray(x, dtype=float).reshape(-1, len(self.inputs))
        m = x.shape[0]
        s = self._columns(x, 'load_cell_sensitivity_', _AXES)
        theta = self._columns(x, 'load_cell_misalignment_', _XYZ)
        nonlinearity = self._columns(x, 'load_cell_nonlinearity_', _AXES)
        cross = np.zeros((m, 6, 6))
        fs = self.full_scale
        for i in range(6):
            for j in range(6):
                if i != j and math.isfinite(fs[i]) and math.isfinite(fs[j]):
                    cross[:, i, j] = self._columns(x, f'load_cell_crosstalk_{_AXES[i]}_', (_AXES[j],))[:, 0] \
                        * fs[i] / fs[j]
        gain = (np.eye(6) + cross) * (1.0 + s)[:, None, :]
        gain = gain @ _blockdiag(np.transpose(rotation_matrices(theta), (0, 2, 1)))
        r = np.broadcast_to(np.asarray(wrench, dtype=float), (m, *np.shape(wrench)))
        v = r.copy()
        if np.any(nonlinearity):  # counted only with every full scale known (six_axis_inputs)
            amplitude = (nonlinearity * fs)[:, None, :]
            for _ in range(_NONLINEAR_ITERATIONS):  # v + L·FS·T3(v/FS) = r, solved by fixed point
                u = v / fs
                v = r - amplitude * u * (4.0 * u * u - 3.0)
        w = np.einsum('mij,mkj->mki', np.linalg.inv(gain), v)
        phi = self._columns(x, 'pose_sensor_angle_', _XYZ)
        turn = _blockdiag(rotation_matrices(phi))
        d = np.einsum('mab,kb->mka', np.transpose(turn, (0, 2, 1)), np.asarray(deflection, dtype=float))
        return w, d


def six_axis_inputs(load_cell: Mapping[str, Any] | None, pose_sensor: Mapping[str, Any] | None,
                    lvdt_array: Mapping[str, Any] | None = None) -> CalibrationInputs:
    """The Type B inputs from the sensor nodes' recorded parameters (``calibration.*``; the load cell's
    ``full_scale``), None where a node's parameters were not recorded. A component declared ``not_stated`` or not
    declared is left out and named. The deflection measured by an LVDT array (``lvdt_array``'s parameters recorded):
    its channels' calibrations are not propagated through the array's pose solution yet, so they are named as left
    out, never counted as zero."""
    inputs: list[InputQuantity] = []
    counted: list[str] = []
    left_out: list[str] = []
    if lvdt_array is not None:
        left_out.append('lvdt_array channel calibrations (not propagated through the array\'s pose)')
    notes: list[str] = []
    fs_value = (load_cell or {}).get('full_scale', [math.inf] * 6)
    try:
        full_scale = np.broadcast_to(np.atleast_1d(np.asarray(fs_value, dtype=float)), (6,)).copy()
    except ValueError:
        raise InputError('load_cell.full_scale', fs_value, 'must be 6 numbers (or one for every axis)') from None
    full_scale[~(full_scale > 0.0)] = math.inf
    sens = stated_component(load_cell, 'sensitivity', 6, '% of reading')
    if sens is None:
        left_out.append('load_cell sensitivity')
    else:
        inputs += [_quantity(f'load_cell_sensitivity_{a}', sens, i, 1e-2) for i, a in enumerate(_AXES)]
        counted.append('load_cell sensitivity')
    mis = stated_component(load_cell, 'misalignment', 3, 'rad')
    if mis is None:
        left_out.append('load_cell misalignment')
    else:
        inputs += [_quantity(f'load_cell_misalignment_{c}', mis, i, 1.0) for i, c in enumerate(_XYZ)]
        counted.append('load_cell misalignment')
    for name, what in (('crosstalk', 'cross-talk'), ('nonlinearity', 'nonlinearity')):
        stated = stated_component(load_cell, name, 6, '% FS')
        if stated is None:
            left_out.append(f'load_cell {what}')
            continue
        if not np.all(np.isfinite(full_scale)):
            left_out.append(f'load_cell {what}')
            notes.append(f'load_cell {what}: stated in % of full scale, but the load cell\'s full_scale was not '
                         'recorded for every axis: left out')
            continue
        if name == 'crosstalk':
            inputs += [_quantity(f'load_cell_crosstalk_{_AXES[i]}_{_AXES[j]}', stated, i, 1e-2)
                       for i in range(6) for j in range(6) if i != j]
        else:
            inputs += [_quantity(f'load_cell_nonlinearity_{a}', stated, i, 1e-2) for i, a in enumerate(_AXES)]
        counted.append(f'load_cell {what}')
    angle = stated_component(pose_sensor, 'angle', 3, 'rad')
    if angle is None:
        left_out.append('pose_sensor angle')
    else:
        inputs += [_quantity(f'pose_sensor_angle_{c}', angle, i, 1.0) for i, c in enumerate(_XYZ)]
        counted.append('pose_sensor angle')
    if stated_component(pose_sensor, 'position', 3, 'm') is None:
        left_out.append('pose_sensor position')
    else:
        counted.append('pose_sensor position')
        notes.append('pose_sensor position: a bias of the readings, it moves the fit\'s offset and not C '
                     '(counted, no effect on C)')
    notes.append('not counted: the load cell\'s hysteresis (the fold-over steps ±w average it out of C to first '
                 'order) and zero drift (it shows in the Type A of the step means); the tracker\'s scale (no '
                 'component declares it)')
    return CalibrationInputs(tuple(inputs), full_scale, tuple(counted), tuple(left_out), tuple(notes))


__all__ = ['CalibrationInputs', 'rotation_matrices', 'six_axis_inputs']
