"""A sensor's calibration as its certificate or data sheet states it: the instrument model declared once, as
parameters of each sensor node, for an uncertainty analysis to read later. No ROS.

Every component ``c`` of a sensor's calibration is three parameters, the same for every sensor::

    calibration.<c>               the stated value, per axis where the sensor has axes (a list; one entry = every
                                  axis): an expanded uncertainty U (distribution 'normal') or a half-width a (the
                                  others), in the component's unit (% of reading, % of full scale, m, rad, ...)
    calibration.<c>_distribution  normal | rectangular | triangular | u_shaped | not_stated
    calibration.<c>_k             the coverage factor k of U (normal only; a certificate's k = 2 for ~95 %)

The standard uncertainty u of a stated component (GUM 4.3): normal ``U / k``; rectangular ``a / sqrt(3)``;
triangular ``a / sqrt(6)``; U-shaped (arcsine) ``a / sqrt(2)``. ``not_stated`` says the certificate gives nothing
for it: :meth:`Stated.standard_uncertainty` is then None, never zero, so an analysis can say that its interval is
statistical only for that component.

The components (units in brackets; FS = the sensor's full scale: the load cell's ``full_scale`` per axis, an LVDT's
half stroke ``max(|range_m|)``):

- load cell (load_cell, netft): ``sensitivity`` [% of reading], ``crosstalk`` [% FS], ``nonlinearity`` [% FS],
  ``hysteresis`` [% FS], all six values fx fy fz mx my mz; ``zero_drift`` [% FS/h], six values; ``misalignment``
  [rad], three angles of the sensor's axes about crane_base's x y z.
- LVDT channel (lvdt, modbus_lvdt, lvdt_array): ``sensitivity`` [% of reading] (the LVDT and its conditioner as
  calibrated), ``linearity`` [% FS], ``daq_gain`` [% of reading], ``daq_offset`` [m] (the DAQ's offset error
  referred to the displacement).
- pose sensor (pose_sensor): ``position`` [m] per coordinate, ``angle`` [rad] per rotation-vector component.

The defaults are typical data-sheet figures (docs/hardware.md, "Entering a calibration certificate", names the
source of each); a lab enters its own certificate's numbers.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.sim.errors import ParameterError

PREFIX = 'calibration.'
#: The distributions a stated value may have; ``not_stated``: the certificate states nothing for the component.
DISTRIBUTIONS = ('normal', 'rectangular', 'triangular', 'u_shaped', 'not_stated')
#: Standard uncertainty per stated value (half-width a, or U for normal before dividing by k).
_DIVISORS = {'rectangular': math.sqrt(3.0), 'triangular': math.sqrt(6.0), 'u_shaped': math.sqrt(2.0)}


@dataclass(frozen=True)
class Stated:
    """One component of a calibration as stated: ``value`` (U or half-width a, per axis, in ``unit``), its
    ``distribution`` and, for 'normal', its coverage factor ``k``."""

    name: str
    value: NDArray[np.float64]
    distribution: str
    k: float
    unit: str

    @property
    def stated(self) -> bool:
        """Whether the certificate states this component (distribution other than 'not_stated')."""
        return self.distribution != 'not_stated'

    def standard_uncertainty(self) -> NDArray[np.float64] | None:
        """The standard uncertainty u per axis, in ``unit``; None when not stated (never zero for 'unknown')."""
        if not self.stated:
            return None
        if self.distribution == 'normal':
            return self.value / self.k
        return self.value / _DIVISORS[self.distribution]

    def draw(self, rng: np.random.Generator) -> NDArray[np.float64]:
        """One error per axis drawn from the stated distribution, in ``unit``: a true error a simulated sensor can
        have. Zero when not stated (nothing to draw from). Draws as many numbers whatever the distribution (one
        uniform and one normal per axis), so the draws of later components do not depend on this one's
        distribution."""
        n = self.value.size
        uniform = rng.random(n)
        normal = rng.standard_normal(n)
        a = self.value
        if self.distribution == 'normal':
            return a / self.k * normal
        if self.distribution == 'rectangular':
            return a * (2.0 * uniform - 1.0)
        if self.distribution == 'triangular':  # inverse CDF of the symmetric triangle on [-a, a]
            return a * np.where(uniform < 0.5, np.sqrt(2.0 * uniform) - 1.0, 1.0 - np.sqrt(2.0 * (1.0 - uniform)))
        if self.distribution == 'u_shaped':  # arcsine: a·sin of a uniform phase
            return a * np.sin(2.0 * math.pi * uniform)
        return np.zeros(n)


@dataclass(frozen=True)
class Component:
    """A calibration component of a kind of sensor: name, entries per axis, unit, what it is, default."""

    name: str
    size: int
    unit: str
    meaning: str
    default: tuple[float, ...]
    distribution: str
    k: float = 2.0

    def specs(self) -> tuple[ParamSpec, ...]:
        """Its three parameters (value, distribution, k)."""
        text = (f'{self.meaning}, as the certificate states it: expanded uncertainty U (normal) or half-width (other '
                'distributions)')
        if self.size > 1:
            value = ParamSpec(PREFIX + self.name, [float(v) for v in self.default],
                              f'{text}, {self.size} values (one = all) [{self.unit}]',
                              rule=f'{self.size} or 1 finite numbers >= 0')
        else:
            value = ParamSpec(PREFIX + self.name, float(self.default[0]), f'{text} [{self.unit}]', at_least=0.0)
        return (
            value,
            ParamSpec(PREFIX + self.name + '_distribution', self.distribution,
                      f'distribution of calibration.{self.name}; not_stated = the certificate states none (an '
                      'analysis then says its interval is statistical only) [-]', choices=DISTRIBUTIONS),
            ParamSpec(PREFIX + self.name + '_k', self.k,
                      f'coverage factor k of calibration.{self.name} when normal (U = k·u; 2 for ~95 %) [-]',
                      above=0.0),
        )


#: The six-axis load cell's components (load_cell, netft). Defaults: an ATI-class F/T sensor with its calibration
#: certificate, mounted by hand (docs/hardware.md).
LOAD_CELL_COMPONENTS = (
    Component('sensitivity', 6, '% of reading', 'sensitivity (calibration factor) uncertainty per axis fx fy fz '
              'mx my mz', (1.0,) * 6, 'normal'),
    Component('crosstalk', 6, '% FS', "cross-talk left after the sensor's calibration matrix, into each axis, as "
              'a share of its full_scale', (0.5,) * 6, 'rectangular'),
    Component('nonlinearity', 6, '% FS', 'nonlinearity per axis, share of its full_scale', (0.2,) * 6,
              'rectangular'),
    Component('hysteresis', 6, '% FS', 'hysteresis per axis, share of its full_scale', (0.1,) * 6, 'rectangular'),
    Component('zero_drift', 6, '% FS/h', 'zero drift per axis at constant temperature, share of its full_scale per '
              'hour', (0.05,) * 6, 'rectangular'),
    Component('misalignment', 3, 'rad', "mounting misalignment: angles of the sensor's axes about crane_base x y z "
              '(1 deg = 0.0175 rad couples 1.7 % of a cross load)', (0.0087,) * 3, 'rectangular'),
)
#: An LVDT channel's components (lvdt, modbus_lvdt, lvdt_array): the LVDT with its conditioner, and the DAQ.
LVDT_COMPONENTS = (
    Component('sensitivity', 1, '% of reading', 'sensitivity uncertainty of the LVDT and its conditioner as '
              'calibrated', (0.25,), 'normal'),
    Component('linearity', 1, '% FS', 'linearity error over the stroke, share of the half stroke', (0.25,),
              'rectangular'),
    Component('daq_gain', 1, '% of reading', "the DAQ channel's gain error", (0.05,), 'rectangular'),
    Component('daq_offset', 1, 'm', "the DAQ channel's offset error, referred to the displacement", (1.0e-6,),
              'rectangular'),
)
#: A pose sensor's components (pose_sensor): a motion-capture system's accuracy over its calibrated volume.
POSE_SENSOR_COMPONENTS = (
    Component('position', 3, 'm', 'position accuracy per coordinate x y z, crane_base', (2.0e-4,) * 3,
              'rectangular'),
    Component('angle', 3, 'rad', 'orientation accuracy per rotation-vector component, crane_base', (1.0e-3,) * 3,
              'rectangular'),
)


def _specs(components: tuple[Component, ...]) -> tuple[ParamSpec, ...]:
    return tuple(spec for c in components for spec in c.specs())


LOAD_CELL_CALIBRATION_PARAMS = _specs(LOAD_CELL_COMPONENTS)
LVDT_CALIBRATION_PARAMS = _specs(LVDT_COMPONENTS)
POSE_SENSOR_CALIBRATION_PARAMS = _specs(POSE_SENSOR_COMPONENTS)


def stated_values(field: str, value: Any, size: int) -> NDArray[np.float64]:
    """The stated value of ``field`` as ``size`` numbers (one number or a one-entry list: every axis), each finite
    and >= 0. Raises ParameterError naming the field."""
    if isinstance(value, bool):
        raise ParameterError(field, value, f'must be {size} or 1 numbers >= 0')
    try:
        array = np.atleast_1d(np.array(value, dtype=float))
    except (TypeError, ValueError):
        raise ParameterError(field, value, f'must be {size} or 1 numbers >= 0') from None
    if array.ndim != 1 or array.size not in (1, size):
        raise ParameterError(field, value, f'must be {size} or 1 numbers >= 0')
    if not np.isfinite(array).all():
        raise ParameterError(field, value, 'every entry must be finite (an uncertainty not stated: set '
                             f'{field}_distribution to not_stated)')
    if (array < 0.0).any():
        raise ParameterError(field, value, 'every entry must be >= 0 (a half-width or an expanded uncertainty)')
    return np.broadcast_to(array, (size,)).copy()


def calibration_of(values: Mapping[str, Any], components: tuple[Component, ...]) -> dict[str, Stated]:
    """The stated calibration of a sensor from its parameter values (``calibration.*`` keys; other keys ignored):
    {component name: :class:`Stated`}. Raises ParameterError naming the bad parameter (a negative or non-finite
    value, an unknown distribution, k <= 0)."""
    out = {}
    for c in components:
        name = PREFIX + c.name
        distribution = values[name + '_distribution']
        if distribution not in DISTRIBUTIONS:
            raise ParameterError(name + '_distribution', distribution, f'must be one of {", ".join(DISTRIBUTIONS)}')
        k = values[name + '_k']
        if isinstance(k, bool) or not isinstance(k, (int, float)) or not math.isfinite(k) or k <= 0:
            raise ParameterError(name + '_k', k, 'must be a finite number > 0')
        out[c.name] = Stated(c.name, stated_values(name, values[name], c.size), distribution, float(k), c.unit)
    return out


__all__ = ['DISTRIBUTIONS', 'LOAD_CELL_CALIBRATION_PARAMS', 'LOAD_CELL_COMPONENTS', 'LVDT_CALIBRATION_PARAMS',
           'LVDT_COMPONENTS', 'POSE_SENSOR_CALIBRATION_PARAMS', 'POSE_SENSOR_COMPONENTS', 'PREFIX', 'Component',
           'Stated', 'calibration_of', 'stated_values']
