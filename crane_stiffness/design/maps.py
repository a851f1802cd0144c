"""Design maps: any two of (x, y, h, W, a, b, com_x, com_y) on a grid, the others fixed.

At each grid point the crane is set up by the inverse problem to hold the platform level at (x, y, z) (z: the
sag of the centred symmetric crane under W unless given), then: the smallest force stiffness [N/m] and its
direction, the smallest moment stiffness [N·m/rad] and its axis (the split of :mod:`.pose`), the smallest tension
[N] and its wire, and the smallest slack margin [N] over a set of force directions (:mod:`.margins`) with its
direction and wire. Points the wires cannot hold get status ``unreachable`` and empty values.

The CSV is written one row of the first variable at a time, with the map's definition in ``map.json`` beside it:
a run that stops is resumed from the last complete row by running the same command again.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from crane_stiffness.design.errors import DesignInputError
from crane_stiffness.design.margins import CAP, RTOL, XTOL, sphere_directions
from crane_stiffness.design.pose import centre_height, split_stiffness_batch
from crane_stiffness.model.geometry import CraneGeometry
from crane_stiffness.model.inverse import (REACHABLE, SINGULAR, UNREACHABLE, map_points, rotation_of,
                                          wire_material)

#: The variables a map can run over: name -> (unit, meaning).
VARIABLES = {
    'x': ('m', 'platform centre x, fixed frame'), 'y': ('m', 'platform centre y, fixed frame'),
    'h': ('m', 'height between the triangles (sets l0)'), 'W': ('N', 'suspended weight'),
    'a': ('m', 'half side of the platform triangle'), 'b': ('m', 'half side of the overhead triangle'),
    'com_x': ('m', 'payload centre of mass x, body frame'), 'com_y': ('m', 'payload centre of mass y, body frame'),
}
#: Largest grid (points): beyond it a map takes hours and its CSV gigabytes.
MAX_POINTS = 1_000_000
STATUS_NAMES = {REACHABLE: 'ok', UNREACHABLE: 'unreachable', SINGULAR: 'singular'}
COLUMNS = ['status', 'force_stiffness_min_N_per_m', 'force_dir_x', 'force_dir_y', 'force_dir_z',
           'moment_stiffness_min_Nm_per_rad', 'moment_axis_x', 'moment_axis_y', 'moment_axis_z', 'tension_min_N',
           'tension_min_wire', 'margin_min_N', 'margin_dir_x', 'margin_dir_y', 'margin_dir_z', 'margin_wire'] + \
          [f'offset_{i}_m' for i in range(1, 7)]


@dataclass(frozen=True)
class GridAxis:
    """One map variable: ``n`` values from ``lo`` to ``hi`` (inclusive) in the variable's unit."""

    name: str
    lo: float
    hi: float
    n: int

    def __post_init__(self) -> None:
        if self.name not in VARIABLES:
            raise DesignInputError('grid variable', self.name, f'must be one of {sorted(VARIABLES)}')
        for which, v in (('lo', self.lo), ('hi', self.hi)):
            if not math.isfinite(v):
                raise DesignInputError(f'{self.name} {which}', v, 'must be finite')
        if not (isinstance(self.n, int) and self.n >= 2):
            raise DesignInputError(f'{self.name} points', self.n, 'must be an integer >= 2')
        if not self.lo < self.hi:
            raise DesignInputError(f'{self.name} range', [self.lo, self.hi], 'must have lo < hi')
        if self.name in ('h', 'W', 'a', 'b') and self.lo <= 0.0:
            raise DesignInputError(f'{self.name} lo', self.lo, f'must be > 0 ({VARIABLES[self.name][1]})')

    @property
    def values(self) -> np.ndarray:
        return np.linspace(self.lo, self.hi, self.n)


@dataclass(frozen=True)
class MapSpec:
    """A map: two grid axes, the base geometry for everything not on them, the fixed pose and the directions.

    ``position`` is (x, y) [m], ``z`` [m] or None (the centred crane's sag under W at each point), ``rotation``
    the paper's angles [φ, θ, ψ] [rad]; ``directions`` force directions for the margin, ``cap`` its limit (×W).
    """

    axis1: GridAxis
    axis2: GridAxis
    base: CraneGeometry
    position: tuple[float, float] = (0.0, 0.0)
    z: float | None = None
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    directions: int = 64
    cap: float = CAP
    _z_cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.axis1.name == self.axis2.name:
            raise DesignInputError('grid variables', [self.axis1.name, self.axis2.name], 'must be two different ones')
        points = self.axis1.n * self.axis2.n
        if points > MAX_POINTS:
            raise DesignInputError('grid points', points, f'must be <= {MAX_POINTS:,} ({self.axis1.n} x '
                                   f'{self.axis2.n} asked)')
        if self.base.weight <= 0.0 and 'W' not in (self.axis1.name, self.axis2.name):
            raise DesignInputError('weight', self.base.weight, 'must be > 0 (slack-free wires need a weight)')
        if not (isinstance(self.directions, int) and 1 <= self.directions <= 10_000):
            raise DesignInputError('directions', self.directions, 'must be an integer from 1 to 10000')
        rotation_of(self.rotation)

    def to_dict(self) -> dict[str, Any]:
        return {'axis1': asdict(self.axis1), 'axis2': asdict(self.axis2), 'base': self.base.to_dict(),
                'position': list(self.position), 'z': self.z, 'rotation': list(self.rotation),
                'directions': self.directions, 'cap': self.cap}

    def fixed(self, name: str) -> float:
        """The value of a variable not on the grid."""
        g = self.base
        return {'x': self.position[0], 'y': self.position[1], 'h': g.height, 'W': g.weight, 'a': g.a, 'b': g.b,
                'com_x': g.com_offset[0], 'com_y': g.com_offset[1]}[name]

    def point_values(self, rows: Iterable[int]) -> dict[str, np.ndarray]:
        """Every variable's value at the points of the given rows of axis1 (all of axis2), flat (P,)."""
        rows = list(rows)
        v1 = np.repeat(self.axis1.values[rows], self.axis2.n)
        v2 = np.tile(self.axis2.values, len(rows))
        out = {name: np.full(v1.shape, self.fixed(name)) for name in VARIABLES}
        out[self.axis1.name], out[self.axis2.name] = v1, v2
        return out

    def heights_z(self, vals: dict[str, np.ndarray]) -> np.ndarray:
        """z of each point [m]: the given z, or the sag of the centred symmetric crane with that a, b, h, W."""
        if self.z is not None:
            return np.full(vals['x'].shape, float(self.z))
        out = np.empty(vals['x'].shape)
        for i, key in enumerate(zip(vals['a'], vals['b'], vals['h'], vals['W'])):
            if key not in self._z_cache:
                a, b, h, w = (float(v) for v in key)
                self._z_cache[key] = centre_height(self.base.replace(a=a, b=b, height=h, weight=w))
            out[i] = self._z_cache[key]
        return out


def compute_rows(spec: MapSpec, rows: Iterable[int]) -> dict[str, np.ndarray]:
    """The map's columns (see COLUMNS) for the points of the given rows of axis1, flat (P,)."""
    vals = spec.point_values(rows)
    out = compute_points(spec, vals)
    out[spec.axis1.name] = vals[spec.axis1.name]
    out[spec.axis2.name] = vals[spec.axis2.name]
    return out


def compute_points(spec: MapSpec, vals: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The map's columns (see COLUMNS) at arbitrary points: vals holds every variable of VARIABLES as (P,) arrays
    (the spec gives the rotation, z rule, directions, cap and the wire)."""
    if np.any(vals['W'] <= 0.0):
        raise DesignInputError('weight', float(vals['W'].min()), 'must be > 0 (slack-free wires need a weight)')
    npts = vals['x'].size
    pos = np.ascontiguousarray(np.column_stack([vals['x'], vals['y'], spec.heights_z(vals)]))
    com = np.ascontiguousarray(np.column_stack([vals['com_x'], vals['com_y'],
                                                np.full(npts, spec.base.com_offset[2])]))
    q = np.ascontiguousarray(rotation_of(spec.rotation))
    ae, k = wire_material(spec.base)
    dirs6 = np.zeros((spec.directions, 6))
    dirs = sphere_directions(spec.directions)
    dirs6[:, :3] = dirs
    status = np.empty(npts, dtype=np.int64)
    tensions, l0, kmats = np.empty((npts, 6)), np.empty((npts, 6)), np.empty((npts, 6, 6))
    margins = np.empty((npts, spec.directions))
    mwire = np.empty((npts, spec.directions), dtype=np.int64)
    mstat = np.empty((npts, spec.directions), dtype=np.int64)
    f = np.ascontiguousarray
    map_points(f(vals['a']), f(vals['b']), f(vals['h']), f(vals['W']), com, pos, q, ae, k,
                  np.array(spec.base.load_point, dtype=float), dirs6, float(spec.cap), RTOL, XTOL, status, tensions,
                  l0, kmats, margins, mwire, mstat)
    split = split_stiffness_batch(kmats)
    ok = status == REACHABLE
    nominal = np.sqrt(vals['h'] ** 2 + 4.0 * (vals['a'] ** 2 + vals['b'] ** 2 - vals['a'] * vals['b']) / 3.0)
    best = np.argmin(np.where(np.isnan(margins), np.inf, margins), axis=1)
    take = np.arange(npts)
    out: dict[str, np.ndarray] = {
        'status': status, 'force_stiffness_min_N_per_m': split['force_min'],
        'moment_stiffness_min_Nm_per_rad': split['moment_min'],
        'tension_min_N': np.where(ok, np.nanmin(np.where(ok[:, None], tensions, np.inf), axis=1), np.nan),
        'tension_min_wire': np.where(ok, np.argmin(np.where(ok[:, None], tensions, np.inf), axis=1) + 1, 0),
        'margin_min_N': np.where(ok, margins[take, best], np.nan),
        'margin_wire': np.where(ok, mwire[take, best] + 1, 0),
    }
    for i, c in enumerate('xyz'):
        out[f'force_dir_{c}'] = split['force_dir'][:, i]
        out[f'moment_axis_{c}'] = split['moment_dir'][:, i]
        out[f'margin_dir_{c}'] = np.where(ok, dirs[best, i], np.nan)
    for i in range(6):
        out[f'offset_{i + 1}_m'] = l0[:, i] - nominal
    return out


def _header(spec: MapSpec) -> list[str]:
    return [spec.axis1.name, spec.axis2.name] + COLUMNS


def _complete_rows(csv_path: Path, spec: MapSpec) -> int:
    """Rows of axis1 already complete in csv_path (a partial last row is cut off)."""
    with csv_path.open(newline='') as fh:
        lines = fh.read().splitlines()
    if not lines or lines[0].split(',') != _header(spec):
        return 0
    rows = (len(lines) - 1) // spec.axis2.n
    keep = 1 + rows * spec.axis2.n
    if keep != len(lines):
        csv_path.write_text('\n'.join(lines[:keep]) + '\n')
    return rows


def run_map(spec: MapSpec, out_dir: Path, *, fresh: bool = False, rows_per_chunk: int = 4,
            progress: Callable[[int, int], Any] | None = None) -> Path:
    """Compute the map into ``out_dir/map.csv`` (with ``map.json``), resuming a run of the same spec.

    progress(done_rows, total_rows) is called after each chunk. Raises DesignInputError when out_dir holds a map of
    another spec (unless fresh)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    csv_path, meta_path = out_dir / 'map.csv', out_dir / 'map.json'
    definition = spec.to_dict()
    done = 0
    if not fresh and meta_path.exists() and csv_path.exists():
        if json.loads(meta_path.read_text()) != json.loads(json.dumps(definition)):
            raise DesignInputError('out', str(out_dir), 'holds a map of another definition (use --fresh or '
                                   'another directory)')
        done = _complete_rows(csv_path, spec)
    if done == 0:
        meta_path.write_text(json.dumps(definition, indent=1) + '\n')
        with csv_path.open('w', newline='') as fh:
            csv.writer(fh).writerow(_header(spec))
    total = spec.axis1.n
    if progress is not None:
        progress(done, total)
    header = _header(spec)
    while done < total:
        rows = range(done, min(total, done + rows_per_chunk))
        cols = compute_rows(spec, rows)
        with csv_path.open('a', newline='') as fh:
            wr = csv.writer(fh)
            for r in zip(*(cols[h].tolist() for h in header)):
                wr.writerow([repr(v) if isinstance(v, float) else v for v in r])
        done = rows.stop
        if progress is not None:
            progress(done, total)
    return csv_path


def read_map(csv_path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(definition from map.json, columns as grids (n1, n2)) of a finished map."""
    meta = json.loads((csv_path.parent / 'map.json').read_text())
    n1, n2 = meta['axis1']['n'], meta['axis2']['n']
    with csv_path.open(newline='') as fh:
        reader = csv.reader(fh)
        header = next(reader)
        data = np.array([[float(v) for v in row] for row in reader])
    if data.shape[0] != n1 * n2:
        raise DesignInputError('map', str(csv_path), f'has {data.shape[0]} of {n1 * n2} points: not finished')
    return meta, {h: data[:, i].reshape(n1, n2) for i, h in enumerate(header)}
