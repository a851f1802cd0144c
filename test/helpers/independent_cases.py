"""The cases the CLI is checked on against the independent reference (``test/independent_crane.py``): random
geometries and loads with slack and rotated cases, the lab model, their reference equilibria, and the
tolerances of the comparison (the contract and its assumptions: test_independent_agreement.py)."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np


import independent_crane as ic  # noqa: E402 (test/ is on sys.path)

POSE_TOL_M = 1e-9
POSE_TOL_RAD = 1e-9
LENGTH_TOL_M = 3e-9
TENSION_RTOL = 1e-6
STIFFNESS_RTOL = 1e-6

SEED = 20240611
N_RANDOM = 20
MIN_MARGIN = 1e-5  # every wire at least this fraction of l0 away from its slack threshold
MAX_ROTATION_DEG = 25.0
ROTATED_DEG = 2.0

LAB_D = 1.08e-3
LAB_E = 206831e6

# Wire stiffness with --wire-diameter/--youngs-modulus AND --length-offsets: k_i = E A / (l0 + d_i), the wire
# model of crane_stiffness.model.geometry (only the "combined_wire" case is affected by this choice).
PER_WIRE_K_FROM_E = True


# ----------------------------------------------------------------------------------------------------------
# Cases
# ----------------------------------------------------------------------------------------------------------

@dataclass
class Case:
    name: str
    a: float
    b: float
    h: float
    weight: float
    k: float | None = None  # --wire-stiffness
    wire: bool = False  # --wire-diameter 1.08e-3 --youngs-modulus 206831e6
    lab_model: bool = False  # --lab-model
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    load_point: np.ndarray = field(default_factory=lambda: np.zeros(3))
    offsets: np.ndarray = field(default_factory=lambda: np.zeros(6))
    force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    moment: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def crane(self) -> ic.Crane:
        if self.lab_model or self.wire:
            return ic.make_crane(self.a, self.b, self.h, self.weight, wire_diameter=LAB_D, youngs_modulus=LAB_E,
                                 com=self.com, length_offsets=self.offsets, per_wire_stiffness=PER_WIRE_K_FROM_E)
        return ic.make_crane(self.a, self.b, self.h, self.weight, k=self.k, com=self.com,
                             length_offsets=self.offsets)

    def solve(self, max_steps=4000) -> ic.Equilibrium:
        return ic.solve(self.crane(), self.force, self.moment, self.load_point, max_steps=max_steps)

    def cli_args(self, command: str) -> list[str]:
        args = [command]
        if self.lab_model:
            args += ["--lab-model"]
        else:
            args += ["--a", num(self.a), "--b", num(self.b)]
        args += ["--height", num(self.h), "--weight", num(self.weight)]
        if not self.lab_model:
            if self.wire:
                args += ["--wire-diameter", num(LAB_D), "--youngs-modulus", num(LAB_E)]
            else:
                args += ["--wire-stiffness", num(self.k)]
        if np.any(self.com != 0):
            args += ["--com", *map(num, self.com)]
        if np.any(self.load_point != 0):
            args += ["--load-point", *map(num, self.load_point)]
        if np.any(self.offsets != 0):
            args += ["--length-offsets", *map(num, self.offsets)]
        args += ["--force", *map(num, self.force), "--moment", *map(num, self.moment), "--json"]
        return args


def num(x: float) -> str:
    return np.format_float_positional(float(x), unique=True, trim="0")


def exact(x):
    """Round values through their CLI text so that the reference sees exactly what the CLI parses."""
    return np.array([float(num(v)) for v in np.atleast_1d(x)]) if np.ndim(x) else float(num(x))


def wire_margin(crane: ic.Crane, eq: ic.Equilibrium) -> float:
    return float(np.min(np.abs(eq.wire_lengths - crane.l0)) / crane.l0_nominal)


def well_posed(case: Case) -> ic.Equilibrium | None:
    """The reference equilibrium, or None when the case is too close to a kink or a fold to compare."""
    crane = case.crane()
    try:
        eq = case.solve(max_steps=200)  # the accepted cases need well under 100 steps
    except ic.NoEquilibrium:
        return None
    if wire_margin(crane, eq) < MIN_MARGIN or math.degrees(eq.rotation_angle) > MAX_ROTATION_DEG:
        return None
    if eq.slack.sum() > 3:
        return None
    K = ic.tangent_stiffness(crane, eq.displacement, eq.rotation, case.force, case.load_point)
    d = np.r_[np.ones(3), np.full(3, 1.0 / max(case.a, case.b))]
    ev = np.linalg.eigvalsh(d[:, None] * (0.5 * (K + K.T)) * d[None, :])
    if ev[0] < 1e-5 * ev[-1]:
        return None
    return eq


def _load_direction(rng, a, b):
    d = rng.normal(size=6)
    d[2] *= 0.3  # mostly side forces
    d[3:] *= max(a, b)
    return d


def _draw_random_case(rng, index: int) -> Case | None:
    a, b = rng.uniform(0.05, 0.3, 2)
    h = rng.uniform(0.3, 2.0)
    W = rng.uniform(5.0, 200.0)
    if index % 2:
        wire = rng.random() < 0.4
        k = None if wire else 10 ** rng.uniform(3.0, 5.0)
    else:  # rotations of several degrees with every wire taut need soft wires
        wire = False
        k = 10 ** rng.uniform(3.0, 4.0)
    base = Case(f"random{index:02d}", exact(a), exact(b), exact(h), exact(W), k=None if wire else exact(k),
                wire=wire)
    crane = base.crane()
    eq0 = ic.solve(crane)
    K0 = ic.tangent_stiffness(crane, eq0.displacement, eq0.rotation)
    direction = _load_direction(rng, a, b)
    dx = np.linalg.solve(K0, direction)
    if index % 2:  # aim past the slack threshold of the most unloaded wire (linear prediction)
        ws = ic.wire_state(crane, eq0.displacement, eq0.rotation)
        n = ws.vectors / ws.lengths[:, None]
        dL = np.einsum("ij,ij->i", n, -dx[:3] + ic.cross(ws.arms, dx[3:]))
        scale = rng.uniform(1.2, 2.5) * ws.tensions.min() / max(-crane.k * dL.min(), 1e-300)
    else:  # aim at a rotation of a few degrees (linear prediction)
        scale = math.radians(rng.uniform(2.0, 8.0)) / np.linalg.norm(dx[3:])
    load = scale * direction
    # keep the loads moderate: side forces up to ~W/2, moments up to ~W a/2
    cap = max(np.linalg.norm(load[:3]) / (0.5 * W), np.linalg.norm(load[3:]) / (0.5 * W * max(a, b)), 1.0)
    load = load / cap
    for _ in range(4):
        case = Case(base.name, base.a, base.b, base.h, base.weight, k=base.k, wire=wire,
                    force=exact(load[:3]), moment=exact(load[3:]))
        eq = well_posed(case)
        if eq is not None:
            _REFERENCE[case.name] = eq
            return case
        load = 0.6 * load
    return None


def _special_cases(rng) -> list[Case]:
    cases = []
    # Weight alone: the tangent must equal eq. (18).
    cases.append(Case("weight_only", exact(0.17), exact(0.23), exact(1.1), exact(40.0), k=exact(8000.0)))
    # Centre of mass below and beside the platform centre, with side force and moment.
    cases.append(Case("com_offset", exact(0.2), exact(0.15), exact(0.9), exact(80.0), k=exact(6000.0),
                      com=exact([0.03, -0.02, 0.25]), force=exact([6.0, -4.0, 3.0]),
                      moment=exact([0.4, 0.3, -1.2])))
    # Force applied below the platform centre.
    cases.append(Case("load_point", exact(0.12), exact(0.18), exact(1.4), exact(60.0), k=exact(4000.0),
                      load_point=exact([0.02, 0.04, 0.2]), force=exact([-1.5, 2.1, 0.6]),
                      moment=exact([0.0, 0.0, 0.5])))
    # Length offsets of the order of the stretch under weight, all wires taut.
    crane = ic.make_crane(0.15, 0.15, 0.8, 50.0, k=20000.0)
    stretch = float(crane.weight / 6 / crane.k * crane.l0_nominal / 0.8)
    cases.append(Case("length_offsets_taut", exact(0.15), exact(0.15), exact(0.8), exact(50.0), k=exact(20000.0),
                      offsets=exact(stretch * np.array([0.3, -0.2, 0.25, -0.35, 0.1, 0.0])),
                      force=exact([2.0, 1.0, 0.0]), moment=exact([0.1, -0.2, 0.3])))
    # Uneven wires and a side load that slackens one of them.
    cases.append(Case("length_offsets_slack", exact(0.15), exact(0.15), exact(0.8), exact(50.0), k=exact(20000.0),
                      offsets=exact(stretch * np.array([0.5, -3.0, 0.0, 1.0, 0.0, 0.0])),
                      force=exact([-3.0, 6.0, 0.0]), moment=exact([0.0, 0.2, -0.1])))
    # Soft wires, heavy load: a twist of several degrees with every wire taut.
    cases.append(Case("soft_twist", exact(0.25), exact(0.25), exact(0.5), exact(150.0), k=exact(1500.0),
                      force=exact([1.0, -0.5, 0.0]), moment=exact([0.3, -0.2, 10.0])))
    # Everything at once, with the lab wire.
    cases.append(Case("combined_wire", exact(0.25), exact(0.2), exact(1.6), exact(120.0), wire=True,
                      com=exact([-0.01, 0.02, 0.1]), load_point=exact([0.05, 0.0, 0.12]),
                      offsets=exact([2e-5, -1e-5, 0.0, 1e-5, -2e-5, 0.0]),
                      force=exact([3.0, -2.0, 5.0]), moment=exact([0.3, 0.2, 0.6])))
    # --lab-model: side force along y, as in the paper's tests; low weight, long wires: wires go slack (Fig. 9).
    cases.append(Case("lab_model_side_force", ic.LAB_A, ic.LAB_B, exact(1.5), exact(20.0), lab_model=True,
                      force=exact([0.0, 3.0, 0.0]), moment=exact([0.0, 0.0, 0.0])))
    cases.append(Case("lab_model_twist", ic.LAB_A, ic.LAB_B, exact(0.6), exact(90.0), lab_model=True,
                      force=exact([0.0, 0.0, 0.0]), moment=exact([0.0, 0.0, 1.5])))
    return cases


#: The special cases' names, in the order _special_cases makes them.
SPECIAL_NAMES = ("weight_only", "com_offset", "load_point", "length_offsets_taut", "length_offsets_slack",
                 "soft_twist", "combined_wire", "lab_model_side_force", "lab_model_twist")
#: Every case's name, known without drawing the cases: the random ones are numbered in the order they are accepted.
#: (Drawing them solves the reference ~40 times, 5 s: done when a test first needs a case, not when pytest collects
#: the tests, which every test process does.)
CASE_NAMES = [f"random{n:02d}" for n in range(1, N_RANDOM + 1)] + list(SPECIAL_NAMES)


@lru_cache(maxsize=None)
def all_cases() -> tuple[Case, ...]:
    rng = np.random.default_rng(SEED)
    cases: list[Case] = []
    index = 0
    while len(cases) < N_RANDOM:
        index += 1
        if index > 4 * N_RANDOM:
            raise RuntimeError("could not draw enough well-posed random cases")
        case = _draw_random_case(rng, index)
        if case is not None:
            name = f"random{len(cases) + 1:02d}"
            _REFERENCE[name] = _REFERENCE.pop(case.name)
            case.name = name
            cases.append(case)
    out = tuple(cases) + tuple(_special_cases(rng))
    assert [c.name for c in out] == CASE_NAMES, [c.name for c in out]
    return out


_REFERENCE: dict[str, ic.Equilibrium] = {}


def reference(name: str) -> ic.Equilibrium:
    CASES[name]  # drawing the random cases stores their references
    if name not in _REFERENCE:
        _REFERENCE[name] = CASES[name].solve()
    return _REFERENCE[name]


class _Cases(Mapping[str, Case]):
    """The cases by name, drawn on first use."""

    def __getitem__(self, name: str) -> Case:
        return {c.name: c for c in all_cases()}[name]

    def __iter__(self) -> Iterator[str]:
        return iter(CASE_NAMES)

    def __len__(self) -> int:
        return len(CASE_NAMES)


CASES: Mapping[str, Case] = _Cases()
NO_EQUILIBRIUM = Case("upward_force", exact(0.15), exact(0.2), exact(1.0), exact(30.0), k=exact(5000.0),
                      force=exact([0.0, 0.0, -45.0]), moment=exact([0.0, 0.0, 0.0]))
