"""Geometry and wire model of the six-wire robot crane (paper eqs. 1–3).

Frame (the paper's Fig. 3): origin at the centre of the platform at its unloaded rest pose, x and y horizontal,
**z pointing down**; the overhead triangle lies at z = −h. Units are SI throughout (m, N, N/m, Pa).

Wires 1..6 run AD, BD, BE, CE, CF, AF: overhead vertex A, B or C to platform vertex D, E or F.
This module is the one place to change the wire model (stiffness per wire, unstretched lengths).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any, Mapping

import numpy as np

from crane_stiffness.model.errors import GeometryError

SQRT3 = math.sqrt(3.0)
#: Overhead vertex and platform vertex of each wire, by letter (AD, BD, BE, CE, CF, AF).
WIRE_ENDS = (('A', 'D'), ('B', 'D'), ('B', 'E'), ('C', 'E'), ('C', 'F'), ('A', 'F'))
WIRE_NAMES = tuple(f'wire_{i}' for i in range(1, 7))

#: The paper's laboratory model: a = b = 114.3 mm, wire diameter 1.08 mm, E = 206,831 MPa.
LAB_A = 0.1143
LAB_B = 0.1143
LAB_WIRE_DIAMETER = 1.08e-3
LAB_YOUNGS_MODULUS = 206_831e6


def overhead_vertices(b: float, h: float) -> np.ndarray:
    """Overhead vertices A, B, C (eq. 1), shape (3, 3), rows in the fixed frame [m]."""
    return np.array([[-b, -b * SQRT3 / 3, -h],
                     [b, -b * SQRT3 / 3, -h],
                     [0.0, 2 * b * SQRT3 / 3, -h]])


def platform_vertices(a: float) -> np.ndarray:
    """Platform vertices D, E, F (eq. 2) in the body frame, shape (3, 3) [m]."""
    return np.array([[0.0, -2 * a * SQRT3 / 3, 0.0],
                     [a, a * SQRT3 / 3, 0.0],
                     [-a, a * SQRT3 / 3, 0.0]])


def rest_wire_length(a: float, b: float, h: float) -> float:
    """Wire length l0 = sqrt(h² + 4(a² + b² − ab)/3) between the triangles at height h (eq. 3) [m]."""
    return math.sqrt(h * h + 4.0 * (a * a + b * b - a * b) / 3.0)


def height_from_length(a: float, b: float, l0: float) -> float:
    """Inverse of :func:`rest_wire_length`: the height h at which wires of length l0 hang vertical-plane taut [m]."""
    horizontal2 = 4.0 * (a * a + b * b - a * b) / 3.0
    if l0 * l0 <= horizontal2:
        raise GeometryError('l0', l0, f'must exceed the horizontal span {math.sqrt(horizontal2):.6g} m')
    return math.sqrt(l0 * l0 - horizontal2)


def _check_finite(name: str, value: float, *, positive: bool = False, nonnegative: bool = False) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise GeometryError(name, value, 'must be a number') from None
    if not math.isfinite(value):
        raise GeometryError(name, value, 'must be finite')
    if positive and value <= 0.0:
        raise GeometryError(name, value, 'must be > 0')
    if nonnegative and value < 0.0:
        raise GeometryError(name, value, 'must be >= 0')
    return value


def _check_vector(name: str, value: Any, n: int) -> tuple[float, ...]:
    arr = np.asarray(value, dtype=float).reshape(-1) if value is not None else np.zeros(n)
    if arr.shape != (n,):
        raise GeometryError(name, value, f'must have {n} components')
    if not np.all(np.isfinite(arr)):
        raise GeometryError(name, value, 'must be finite')
    return tuple(float(x) for x in arr)


@dataclass(frozen=True)
class CraneGeometry:
    """Geometry, wires and suspended weight of the crane. Immutable and validated on construction.

    Attributes:
        a: half side of the platform (lower) triangle [m].
        b: half side of the overhead triangle [m].
        height: vertical distance h between the triangles at the unloaded rest pose [m]; the wires' unstretched
            length l0 follows from it (eq. 3).
        weight: total suspended weight W = W' (platform, substructure, payload) [N], acting along +z.
        wire_stiffness: k of every wire [N/m]. Give either this, or both ``wire_diameter`` and ``youngs_modulus``
            (then k = A·E/l0 per wire, A = π d²/4).
        wire_diameter: wire diameter d [m].
        youngs_modulus: Young's modulus E of the wire [Pa].
        com_offset: centre of mass of the suspended load, body frame, from the platform centre [m].
        load_point: point where the external force is applied, body frame, from the platform centre [m].
        length_offsets: per-wire change of unstretched length (the paper's length actuators), wires 1..6 [m].
    """

    a: float
    b: float
    height: float
    weight: float
    wire_stiffness: float | None = None
    wire_diameter: float | None = None
    youngs_modulus: float | None = None
    com_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    load_point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    length_offsets: tuple[float, float, float, float, float, float] = (0.0,) * 6
    _derived: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, 'a', _check_finite('a', self.a, positive=True))
        set_(self, 'b', _check_finite('b', self.b, positive=True))
        set_(self, 'height', _check_finite('height', self.height, positive=True))
        set_(self, 'weight', _check_finite('weight', self.weight, nonnegative=True))
        has_k = self.wire_stiffness is not None
        has_material = self.wire_diameter is not None or self.youngs_modulus is not None
        if has_k and has_material:
            raise GeometryError('wire_stiffness', self.wire_stiffness,
                                'give either wire_stiffness or wire_diameter with youngs_modulus, not both')
        if self.wire_stiffness is not None:  # has_k
            set_(self, 'wire_stiffness', _check_finite('wire_stiffness', self.wire_stiffness, positive=True))
        else:
            if self.wire_diameter is None or self.youngs_modulus is None:
                raise GeometryError('wire_stiffness', None,
                                    'give wire_stiffness, or both wire_diameter and youngs_modulus')
            set_(self, 'wire_diameter', _check_finite('wire_diameter', self.wire_diameter, positive=True))
            set_(self, 'youngs_modulus', _check_finite('youngs_modulus', self.youngs_modulus, positive=True))
        set_(self, 'com_offset', _check_vector('com_offset', self.com_offset, 3))
        set_(self, 'load_point', _check_vector('load_point', self.load_point, 3))
        set_(self, 'length_offsets', _check_vector('length_offsets', self.length_offsets, 6))
        l0 = self.l0
        for i, off in enumerate(self.length_offsets):
            if l0 + off <= 0.5 * l0:
                raise GeometryError('length_offsets', self.length_offsets,
                                    f'wire_{i + 1} offset {off:.6g} m leaves less than half of l0 = {l0:.6g} m')

    # Derived quantities -------------------------------------------------------------------------------------
    @property
    def l0(self) -> float:
        """Nominal unstretched wire length at height h (eq. 3) [m]."""
        return rest_wire_length(self.a, self.b, self.height)

    @property
    def wire_area(self) -> float | None:
        """Wire cross-section A = π d²/4 [m²], or None when k was given directly."""
        return None if self.wire_diameter is None else math.pi * self.wire_diameter ** 2 / 4.0

    @property
    def unstretched_lengths(self) -> np.ndarray:
        """Unstretched length of wires 1..6, l0 plus the per-wire offsets, shape (6,) [m]."""
        return self.l0 + np.asarray(self.length_offsets)

    @property
    def wire_stiffnesses(self) -> np.ndarray:
        """Axial stiffness of wires 1..6, shape (6,) [N/m]: k as given, or A·E/l0_i per wire."""
        if self.wire_stiffness is not None:
            return np.full(6, self.wire_stiffness)
        area, modulus = self.wire_area, self.youngs_modulus
        assert area is not None and modulus is not None  # __post_init__: without k both d and E are given
        return area * modulus / self.unstretched_lengths

    @property
    def k(self) -> float:
        """Nominal wire stiffness k [N/m] (A·E/l0 at the nominal length), as used by the paper's closed forms."""
        if self.wire_stiffness is not None:
            return self.wire_stiffness
        area, modulus = self.wire_area, self.youngs_modulus
        assert area is not None and modulus is not None  # __post_init__: without k both d and E are given
        return area * modulus / self.l0

    @property
    def top_points(self) -> np.ndarray:
        """Overhead attachment point of wires 1..6, fixed frame, shape (6, 3) [m]."""
        abc = overhead_vertices(self.b, self.height)
        idx = {'A': 0, 'B': 1, 'C': 2}
        return np.array([abc[idx[t]] for t, _ in WIRE_ENDS])

    @property
    def platform_points(self) -> np.ndarray:
        """Platform attachment point of wires 1..6, body frame, shape (6, 3) [m]."""
        dfe = platform_vertices(self.a)
        idx = {'D': 0, 'E': 1, 'F': 2}
        return np.array([dfe[idx[p]] for _, p in WIRE_ENDS])

    @property
    def is_paper_symmetric(self) -> bool:
        """True when the paper's closed forms apply: equal wires, load at the centre, no offsets."""
        return (not any(self.length_offsets) and not any(self.com_offset) and not any(self.load_point))

    def replace(self, **changes: Any) -> 'CraneGeometry':
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of the constructor fields (for JSON, YAML and bag metadata)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            if not f.init:
                continue
            v = getattr(self, f.name)
            out[f.name] = list(v) if isinstance(v, tuple) else v
        return out

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> 'CraneGeometry':
        """Build from a mapping of field names (unknown keys are an error naming them).

        ``l0`` may be given instead of ``height``; ``lab_model: true`` fills a, b and the lab wire.
        """
        values = dict(values)
        if values.pop('lab_model', False):
            values = {**lab_model_fields(), **{k: v for k, v in values.items() if v is not None}}
        names = {f.name for f in fields(cls) if f.init}
        if 'l0' in values:
            l0 = values.pop('l0')
            if values.get('height') is not None:
                raise GeometryError('l0', l0, 'give either height or l0, not both')
            values['height'] = height_from_length(float(values['a']), float(values['b']), float(l0))
        unknown = sorted(set(values) - names)
        if unknown:
            raise GeometryError(unknown[0], values[unknown[0]], f'is not a geometry field (known: {sorted(names)})')
        missing = [n for n in ('a', 'b', 'height', 'weight') if values.get(n) is None]
        if missing:
            raise GeometryError(missing[0], None, 'is required')
        return cls(**values)


def lab_model_fields() -> dict[str, float]:
    """Dimensions and wire of the paper's laboratory model (height and weight are test-specific)."""
    return {'a': LAB_A, 'b': LAB_B, 'wire_diameter': LAB_WIRE_DIAMETER, 'youngs_modulus': LAB_YOUNGS_MODULUS}


def lab_model(height: float, weight: float, **overrides: Any) -> CraneGeometry:
    """The paper's lab model (a = b = 114.3 mm, d = 1.08 mm, E = 206,831 MPa) at a given height [m] and weight [N]."""
    return CraneGeometry(**{**lab_model_fields(), 'height': height, 'weight': weight, **overrides})
