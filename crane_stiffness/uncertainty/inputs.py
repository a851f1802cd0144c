"""An input quantity as a calibration certificate or a data sheet states it, and its standard uncertainty.

The GUM's rules (JCGM 100:2008, 4.3): a certificate's expanded uncertainty U with coverage factor k gives
u = U/k (4.3.3, a normal distribution); a half-width a of the interval the value lies in gives u = a/√3 for a
rectangular distribution (4.3.7), a/√6 for a triangular one (4.3.9) and a/√2 for a U-shaped (arcsine) one (the
quantity spends most time near the ends, e.g. a cyclic temperature; JCGM 101 6.4.6); a normal distribution is
given by its standard uncertainty u itself. Degrees of freedom ν (G.4.2) default to ∞ (the uncertainty is known
exactly); a Type A evaluation from n readings has ν = n − 1.

The flat form (:func:`input_from_mapping`) is what a parameter file holds, one mapping per input, e.g.
``{value: 1.08e-3, U: 2.0e-5, k: 2, unit: m}`` or ``{value: 0.5, half_width: 5.0e-4, distribution: rectangular}``
or ``{value: 50.0, u: 0.05, dof: 12}``; values are in the input's own unit (SI in this package).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from crane_stiffness.uncertainty.errors import InputError

#: Divisor of the half-width a for each distribution given by its bounds: u = a / divisor (GUM 4.3.7–4.3.9).
HALF_WIDTH_DIVISORS = {'rectangular': math.sqrt(3.0), 'triangular': math.sqrt(6.0), 'arcsine': math.sqrt(2.0)}
#: Every distribution an input may have ('normal' is given by u, or by U and k).
DISTRIBUTIONS = ('normal', *HALF_WIDTH_DIVISORS)
#: Other spellings accepted in files.
_ALIASES = {'gaussian': 'normal', 'uniform': 'rectangular', 'u-shaped': 'arcsine', 'u_shaped': 'arcsine'}
#: The keys of the flat form.
MAPPING_KEYS = ('value', 'unit', 'u', 'U', 'k', 'half_width', 'distribution', 'dof')


def _finite(field: str, value: Any) -> float:
    if isinstance(value, bool):
        raise InputError(field, value, 'must be a number')
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(field, value, 'must be a number') from None
    if not math.isfinite(number):
        raise InputError(field, value, 'must be finite')
    return number


def _uncertainty(field: str, value: Any) -> float:
    number = _finite(field, value)
    if number < 0.0:
        raise InputError(field, value, 'an uncertainty must be >= 0')
    return number


def _dof(field: str, value: Any) -> float:
    if isinstance(value, str) and value.strip().lower() in ('inf', 'infinity', '.inf'):
        return math.inf
    if isinstance(value, bool):
        raise InputError(field, value, 'must be a number > 0 or inf')
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(field, value, 'must be a number > 0 or inf') from None
    if math.isnan(number) or number <= 0.0:
        raise InputError(field, value, 'degrees of freedom must be > 0 (inf: the uncertainty is known exactly)')
    return number


def distribution_name(field: str, value: Any) -> str:
    """The canonical name of a distribution ('normal', 'rectangular', 'triangular', 'arcsine'), aliases allowed."""
    name = str(value).strip().lower()
    name = _ALIASES.get(name, name)
    if name not in DISTRIBUTIONS:
        raise InputError(field, value, f'unknown distribution (one of {", ".join(DISTRIBUTIONS)}; '
                                       f'also {", ".join(_ALIASES)})')
    return name


def check_correlation(field: str, value: Any) -> float:
    """A correlation coefficient r, checked: finite and within [-1, 1] (GUM 5.2.2)."""
    r = _finite(field, value)
    if not -1.0 <= r <= 1.0:
        raise InputError(field, value, 'a correlation coefficient must lie in [-1, 1]')
    return r


@dataclass(frozen=True)
class InputQuantity:
    """One input quantity X_i: its estimate x_i, standard uncertainty u(x_i), distribution and degrees of freedom.

    Build it with :meth:`normal`, :meth:`expanded` (a certificate's U and k) or :meth:`bounded` (a half-width and
    a distribution); the constructor checks every field. ``value`` and ``u`` are in ``unit``.
    """

    name: str
    value: float
    u: float
    distribution: str = 'normal'
    dof: float = math.inf
    unit: str = ''

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise InputError('name', self.name, 'must be a non-empty string')
        set_ = object.__setattr__
        set_(self, 'value', _finite(f'{self.name}.value', self.value))
        set_(self, 'u', _uncertainty(f'{self.name}.u', self.u))
        set_(self, 'distribution', distribution_name(f'{self.name}.distribution', self.distribution))
        set_(self, 'dof', _dof(f'{self.name}.dof', self.dof))

    @classmethod
    def normal(cls, name: str, value: float, u: float, *, dof: float = math.inf, unit: str = '') -> InputQuantity:
        """A normal input given by its standard uncertainty u (e.g. a Type A evaluation with dof = n − 1)."""
        return cls(name, value, u, 'normal', dof, unit)

    @classmethod
    def expanded(cls, name: str, value: float, U: float, k: float, *, dof: float = math.inf,
                 unit: str = '') -> InputQuantity:
        """A certificate's expanded uncertainty U with coverage factor k: u = U/k, normal (GUM 4.3.3)."""
        big_u = _uncertainty(f'{name}.U', U)
        k = _finite(f'{name}.k', k)
        if k <= 0.0:
            raise InputError(f'{name}.k', k, 'a coverage factor must be > 0')
        return cls(name, value, big_u / k, 'normal', dof, unit)

    @classmethod
    def bounded(cls, name: str, value: float, half_width: float, distribution: str = 'rectangular', *,
                dof: float = math.inf, unit: str = '') -> InputQuantity:
        """A value known to lie within value ± half_width: u = a/√3 (rectangular), a/√6 (triangular), a/√2
        (arcsine) (GUM 4.3.7, 4.3.9); 'normal' takes the half-width as u."""
        a = _uncertainty(f'{name}.half_width', half_width)
        dist = distribution_name(f'{name}.distribution', distribution)
        return cls(name, value, a / HALF_WIDTH_DIVISORS.get(dist, 1.0), dist, dof, unit)

    @property
    def half_width(self) -> float:
        """Half-width a of a bounded distribution (u times its divisor); for a normal input, u itself."""
        return self.u * HALF_WIDTH_DIVISORS.get(self.distribution, 1.0)

    def with_value(self, value: float) -> InputQuantity:
        """The same uncertainty about another estimate."""
        return InputQuantity(self.name, value, self.u, self.distribution, self.dof, self.unit)

    def scaled(self, factor: float) -> InputQuantity:
        """The same input with its uncertainty multiplied by ``factor`` (>= 0)."""
        return InputQuantity(self.name, self.value, self.u * factor, self.distribution, self.dof, self.unit)

    def draws(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n draws from the input's distribution (JCGM 101 6.4), shape (n,), in ``unit``.

        Normal with finite ν: the scaled and shifted t distribution t_ν(x, u²) of JCGM 101 6.4.9 (its standard
        deviation is u·√(ν/(ν−2)), larger than u, for ν > 2). Rectangular, triangular and arcsine: over
        value ± a; their degrees of freedom (the reliability of a Type B bound) do not enter the draws.
        """
        x, u = self.value, self.u
        if self.distribution == 'normal':
            if math.isinf(self.dof):
                return x + u * rng.standard_normal(n)
            return x + u * rng.standard_t(self.dof, n)
        a = self.half_width
        if self.distribution == 'rectangular':
            return rng.uniform(x - a, x + a, n)
        if self.distribution == 'triangular':
            return rng.triangular(x - a, x, x + a, n)
        # arcsine on [x − a, x + a]: x + a·sin(φ) with φ uniform (JCGM 101 6.4.6).
        return x + a * np.sin(rng.uniform(-0.5 * math.pi, 0.5 * math.pi, n))

    def to_dict(self) -> dict[str, Any]:
        """The input in the flat form, as :func:`input_from_mapping` reads it (u, distribution, dof, unit)."""
        out: dict[str, Any] = {'value': self.value, 'unit': self.unit, 'distribution': self.distribution}
        if self.distribution == 'normal':
            out['u'] = self.u
        else:
            out['half_width'] = self.half_width
        out['dof'] = 'inf' if math.isinf(self.dof) else self.dof
        return out


def input_from_mapping(name: str, entry: Mapping[str, Any], *, value: float | None = None,
                       unit: str = '') -> InputQuantity:
    """An input from its flat form (a parameter file's mapping), e.g. ``{value: 1.08e-3, U: 2e-5, k: 2}``.

    Exactly one way of giving the uncertainty: ``U`` with ``k`` (normal); ``u`` (with ``distribution`` normal, the
    default); or ``half_width`` with ``distribution`` (rectangular by default). ``dof`` is optional (a number or
    'inf'). ``value`` may be left out of the mapping when the caller knows it (e.g. from the crane's geometry):
    then the argument ``value`` is used. Unknown keys are refused.
    """
    if not isinstance(entry, Mapping):
        raise InputError(name, entry, 'must be a mapping such as {value: .., U: .., k: 2} or '
                                      '{value: .., half_width: .., distribution: rectangular}')
    unknown = sorted(set(entry) - set(MAPPING_KEYS))
    if unknown:
        raise InputError(f'{name}.{unknown[0]}', entry[unknown[0]], f'unknown key (known: {", ".join(MAPPING_KEYS)})')
    if 'value' in entry:
        value = entry['value']
    if value is None:
        raise InputError(f'{name}.value', None, 'is required')
    unit = str(entry.get('unit', unit))
    dof = entry.get('dof', math.inf)
    given = [key for key in ('U', 'u', 'half_width') if key in entry]
    if len(given) != 1:
        raise InputError(name, dict(entry), 'give exactly one of U (with k), u, half_width (with distribution)')
    if 'k' in entry and given != ['U']:
        raise InputError(f'{name}.k', entry['k'], 'a coverage factor goes with U only')
    if given == ['U']:
        if 'k' not in entry:
            raise InputError(f'{name}.k', None, 'U needs its coverage factor k (as the certificate states it)')
        if distribution_name(f'{name}.distribution', entry.get('distribution', 'normal')) != 'normal':
            raise InputError(f'{name}.distribution', entry['distribution'], 'U with k states a normal distribution')
        return InputQuantity.expanded(name, value, entry['U'], entry['k'], dof=dof, unit=unit)
    if given == ['u']:
        return InputQuantity(name, value, entry['u'], entry.get('distribution', 'normal'), dof, unit)
    return InputQuantity.bounded(name, value, entry['half_width'], entry.get('distribution', 'rectangular'),
                                 dof=dof, unit=unit)


def entries_from_params(params: Mapping[str, Any], prefix: str) -> dict[str, dict[str, Any]]:
    """{input: flat form} from flat ROS parameters ``<prefix><input>.<key>`` (as rclpy and
    :func:`crane_stiffness.params.files.load_params` flatten ``uncertainty: {weight: {U: 0.1, k: 2}}`` to
    ``uncertainty.weight.U`` and ``uncertainty.weight.k``); other parameters are left out. ``prefix`` ends with a
    dot, e.g. 'uncertainty.'."""
    out: dict[str, dict[str, Any]] = {}
    for key, value in params.items():
        if not key.startswith(prefix):
            continue
        name, dot, field = key[len(prefix):].partition('.')
        if not dot or not field or '.' in field:
            raise InputError(key, value, f'must be {prefix}<input>.<key>, e.g. {prefix}weight.U')
        out.setdefault(name, {})[field] = value
    return out


def inputs_from_mapping(entries: Mapping[str, Mapping[str, Any]]) -> list[InputQuantity]:
    """Several inputs from a mapping of name → flat form, in the mapping's order."""
    return [input_from_mapping(name, entry) for name, entry in entries.items()]
