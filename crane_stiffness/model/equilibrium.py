"""Nonlinear quasi-static equilibrium of the platform (paper eqs. 4–16, corrected as in docs/physics.md).

Given the geometry (with the suspended weight W along +z) and an external wrench held fixed in space, find the
pose (u, Q) at which the six unilateral wire forces, the weight and the load balance. The equilibrium wanted is the
one reached by loading continuously from the rest pose: the solver tries the full load with damped Newton and, when
that fails or jumps too far, falls back to load continuation with adaptive steps.

Frames and units: the paper's fixed frame (origin at the platform centre at the *unloaded* rest pose, z down);
u in metres, angles in radians, forces in N, moments in N·m about the platform centre.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from crane_stiffness.model import _kernels as kern
from crane_stiffness.model.errors import ConvergenceError, NoEquilibriumError
from crane_stiffness.model.geometry import CraneGeometry
from crane_stiffness.model.rotation import matrix_to_euler_zxy

#: Default convergence tolerance: every point of the platform within this distance of the solution [m].
DEFAULT_XTOL = 1e-12
DEFAULT_MAX_ITER = 60
#: A single continuation step may turn the platform by at most this angle [rad] ...
MAX_STEP_ROTATION = 0.35
#: ... and move it by at most this fraction of the wire length.
MAX_STEP_TRANSLATION = 0.25
MIN_LOAD_FRACTION = 1e-7


@dataclass(frozen=True)
class Equilibrium:
    """A static equilibrium of the platform.

    Attributes:
        displacement: u, platform centre from its unloaded rest position, fixed frame, shape (3,) [m].
        rotation: Q, body→fixed, shape (3, 3).
        wire_lengths: current length of wires 1..6, shape (6,) [m].
        wire_tensions: tension of wires 1..6, shape (6,) [N] (0 when slack).
        slack: True for wires shorter than their unstretched length, shape (6,).
        load: the external wrench [fx, fy, fz, mx, my, mz] (fixed frame) [N, N·m].
        iterations: Newton iterations used in total (all continuation steps).
        residual: net force [N] and moment [N·m] left at the solution, shape (6,).
        continuation_steps: 1 when the full load was solved directly.
    """

    displacement: np.ndarray
    rotation: np.ndarray
    wire_lengths: np.ndarray
    wire_tensions: np.ndarray
    slack: np.ndarray
    load: np.ndarray
    iterations: int
    residual: np.ndarray
    continuation_steps: int = 1
    converged: bool = True

    @property
    def euler_zxy(self) -> np.ndarray:
        """The paper's angles [φ, θ, ψ] (Q = R_z(φ)·R_x(θ)·R_y(ψ)) [rad]."""
        return matrix_to_euler_zxy(self.rotation)

    @property
    def rotation_vector(self) -> np.ndarray:
        """Rotation of the platform as a rotation vector [θx, θy, θz] in the fixed frame [rad]."""
        q = self.rotation
        angle = math.acos(max(-1.0, min(1.0, (np.trace(q) - 1.0) / 2.0)))
        axis = np.array([q[2, 1] - q[1, 2], q[0, 2] - q[2, 0], q[1, 0] - q[0, 1]])
        if angle < 1e-9:
            return axis / 2.0
        return axis * angle / (2.0 * math.sin(angle))

    def to_dict(self) -> dict:
        """JSON-ready dict (the CLI's ``solve --json`` output)."""
        return {
            'converged': bool(self.converged),
            'displacement': self.displacement.tolist(),
            'rotation': self.rotation.tolist(),
            'euler_zxy': self.euler_zxy.tolist(),
            'wire_lengths': self.wire_lengths.tolist(),
            'wire_tensions': self.wire_tensions.tolist(),
            'slack': [bool(s) for s in self.slack],
            'load': self.load.tolist(),
            'iterations': int(self.iterations),
            'continuation_steps': int(self.continuation_steps),
            'residual_force': float(np.linalg.norm(self.residual[:3])),
            'residual_moment': float(np.linalg.norm(self.residual[3:])),
        }


@dataclass(frozen=True)
class BatchEquilibrium:
    """Equilibria of N load cases: arrays with a leading axis of N (see :class:`Equilibrium` for units)."""

    displacement: np.ndarray   # (N, 3)
    rotation: np.ndarray       # (N, 3, 3)
    wire_lengths: np.ndarray   # (N, 6)
    wire_tensions: np.ndarray  # (N, 6)
    slack: np.ndarray          # (N, 6)
    loads: np.ndarray          # (N, 6)
    iterations: np.ndarray     # (N,)
    residual: np.ndarray       # (N, 6)

    def __len__(self) -> int:
        return self.loads.shape[0]

    def __getitem__(self, i: int) -> Equilibrium:
        return Equilibrium(self.displacement[i], self.rotation[i], self.wire_lengths[i], self.wire_tensions[i],
                           self.slack[i], self.loads[i], int(self.iterations[i]), self.residual[i])


#: The geometry's leading kernel arguments: top, plat, l0, kw, weight, com, ploc (a fixed-length tuple, so that
#: mypy can check the compiled kernels' calls that unpack it).
_KernelGeometry = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]


class _Arrays:
    """The geometry as the contiguous float arrays the kernels take."""

    def __init__(self, g: CraneGeometry) -> None:
        self.top = np.ascontiguousarray(g.top_points)
        self.plat = np.ascontiguousarray(g.platform_points)
        self.l0 = np.ascontiguousarray(g.unstretched_lengths)
        self.kw = np.ascontiguousarray(g.wire_stiffnesses)
        self.weight = float(g.weight)
        self.com = np.array(g.com_offset, dtype=float)
        self.ploc = np.array(g.load_point, dtype=float)
        # Characteristic length: scales moments to forces and rotations to displacements.
        self.lc = max(g.a, g.b)
        self.l0_nominal = g.l0
        # One Newton iteration moves the centre by at most 5 % of the wire length.
        self.max_move = 0.05 * g.l0
        # One continuation step may turn the platform by MAX_STEP_ROTATION and shift it by a share of l0.
        self.min_cos_turn = math.cos(MAX_STEP_ROTATION)
        self.max_shift = MAX_STEP_TRANSLATION * g.l0

    def args(self) -> _KernelGeometry:
        return self.top, self.plat, self.l0, self.kw, self.weight, self.com, self.ploc

    def homotopy(self, lam: float) -> _KernelGeometry:
        """Kernel arguments with the offsets (centre of mass, wire lengths) scaled by lam: lam = 0 is the symmetric
        crane, whose rest pose is a plain vertical sag, lam = 1 the real one."""
        nominal = np.full(6, self.l0_nominal)
        return (self.top, self.plat, nominal + lam * (self.l0 - nominal), self.kw, self.weight, lam * self.com,
                self.ploc)


def geometry_arrays(g: CraneGeometry) -> _Arrays:
    # Cached on the (immutable) geometry itself: hashing a dataclass on every solve costs more than the solve.
    arr = g._derived.get('arrays')
    if arr is None:
        arr = g._derived['arrays'] = _Arrays(g)
    return arr


def as_load(force=None, moment=None, load=None) -> np.ndarray:
    """A load vector [fx, fy, fz, mx, my, mz] from force [N] and moment [N·m] (fixed frame), validated."""
    if type(load) is np.ndarray and load.shape == (6,) and load.dtype == np.float64:
        vec = load  # fast path for the solver's hot callers
    elif load is not None:
        vec = np.asarray(load, dtype=float).reshape(-1)
        if vec.shape != (6,):
            raise ValueError(f'load = {load!r}: must have 6 components [fx, fy, fz, mx, my, mz]')
    else:
        f = np.zeros(3) if force is None else np.asarray(force, dtype=float).reshape(-1)
        m = np.zeros(3) if moment is None else np.asarray(moment, dtype=float).reshape(-1)
        if f.shape != (3,):
            raise ValueError(f'force = {force!r}: must have 3 components [fx, fy, fz] in N')
        if m.shape != (3,):
            raise ValueError(f'moment = {moment!r}: must have 3 components [mx, my, mz] in N·m')
        vec = np.concatenate([f, m])
    if not math.isfinite(vec.sum()):  # a sum is NaN/Inf iff a component is (or it overflows: also invalid)
        raise ValueError(f'load = {vec.tolist()}: every component must be finite')
    return vec


def net_wrench(geometry: CraneGeometry, displacement, rotation, load=None) -> np.ndarray:
    """Net wrench [F; M] on the platform at a pose: wires + weight + external load, shape (6,) [N, N·m].

    Zero at an equilibrium. This is the residual of eqs. (15)–(16) with the weight included.
    """
    arr = geometry_arrays(geometry)
    w = np.empty(6)
    kern.assemble(*arr.args(), as_load(load=np.zeros(6) if load is None else load),
                  np.asarray(displacement, dtype=float), np.ascontiguousarray(rotation, dtype=float), w,
                  np.empty((6, 6)), np.empty(6), np.empty(6), False)
    return w


def wrench_jacobian(geometry: CraneGeometry, displacement, rotation, load=None) -> tuple[np.ndarray, np.ndarray]:
    """(w, K): net wrench (6,) and K = −∂w/∂[δu, δω] (6, 6), rotations perturbed in the fixed frame."""
    arr = geometry_arrays(geometry)
    w = np.empty(6)
    kmat = np.empty((6, 6))
    kern.assemble(*arr.args(), as_load(load=np.zeros(6) if load is None else load),
                  np.asarray(displacement, dtype=float), np.ascontiguousarray(rotation, dtype=float), w, kmat,
                  np.empty(6), np.empty(6), True)
    return w, kmat


def check_load_admissible(geometry: CraneGeometry, load: np.ndarray) -> None:
    """Raise NoEquilibriumError for loads no wire system hanging from above can hold.

    Every wire pulls the platform upwards (towards −z), so the downward force W + fz must be positive, or the load
    and the weight must both vanish (the unloaded rest pose with slack-free, tension-free wires).
    """
    down = geometry.weight + load[2]
    if down > 0.0:
        return
    if down == 0.0 and not np.any(load) and geometry.weight == 0.0:
        return
    raise NoEquilibriumError(
        f'no equilibrium: the net downward force W + fz = {geometry.weight:.6g} + {load[2]:.6g} = {down:.6g} N is '
        f'not positive, so the wires (which can only pull up) would all go slack')


def _step(arr: _Arrays, args: _KernelGeometry, load: np.ndarray, u: np.ndarray, q: np.ndarray, xtol: float,
          max_iter: int):
    """One continuation step in place on (u, q): Newton, accepted only near the start (else status JUMPED)."""
    lengths = np.empty(6)
    tensions = np.empty(6)
    w = np.empty(6)
    status, iters = kern.solve_step(*args, load, u, q, xtol, max_iter, arr.lc, arr.max_move, arr.min_cos_turn,
                                    arr.max_shift, lengths, tensions, w)
    return status, iters, lengths, tensions, w


@dataclass
class _PathEnd:
    u: np.ndarray
    q: np.ndarray
    lengths: np.ndarray
    tensions: np.ndarray
    residual: np.ndarray
    iterations: int
    steps: int


def _continuation(arr: _Arrays, args_at, load_at, u: np.ndarray, q: np.ndarray, xtol: float, max_iter: int,
                  max_steps: int, what) -> _PathEnd:
    """Follow equilibria from lam = 0 (pose u, q) to lam = 1 with adaptive steps.

    args_at(lam) gives the kernel's geometry arguments, load_at(lam) the load and what() the goal, for errors.
    A step is taken when Newton
    converges without jumping far (kernel ``solve_step``); otherwise it is halved, down to MIN_LOAD_FRACTION.
    """
    lam, step = 0.0, 1.0
    total_iters = steps = 0
    while True:
        target = min(1.0, lam + step)
        status, iters, lengths, tensions, w = _step(arr, args_at(target), load_at(target), u, q, xtol, max_iter)
        total_iters += iters
        steps += 1
        if status == kern.CONVERGED:
            lam = target
            if lam >= 1.0:
                return _PathEnd(u, q, lengths, tensions, w, total_iters, steps)
            step = min(2.0 * step, 1.0 - lam)
        else:
            step *= 0.5
            if step < MIN_LOAD_FRACTION:
                raise NoEquilibriumError(
                    f'no equilibrium found along the path to {what()} beyond {lam:.6g} of the way (the platform '
                    f'cannot hold it continuously: a limit point, where it would swing or flip away; solver '
                    f'status {status})')
        if steps >= max_steps:
            raise ConvergenceError(f'gave up after {steps} continuation steps at {lam:.6g} of the way to {what()}')


def _rest(geometry: CraneGeometry, xtol: float) -> tuple[np.ndarray, np.ndarray]:
    """Rest pose under the weight (cached per geometry and tolerance)."""
    key = ('rest', xtol)
    if key not in geometry._derived:
        geometry._derived[key] = _solve_rest(geometry, xtol)
    return geometry._derived[key]


def _solve_rest(geometry: CraneGeometry, xtol: float) -> tuple[np.ndarray, np.ndarray]:
    """The symmetric crane's vertical sag, then a homotopy to the real offsets (centre of mass, wire lengths)."""
    arr = geometry_arrays(geometry)
    if geometry.weight == 0.0 and not any(geometry.length_offsets):
        return np.zeros(3), np.eye(3)
    zero = np.zeros(6)
    # Start below the sag, every wire stretched: at u = 0 all wires sit exactly on the slack threshold, where
    # rounding decides which ones count and K can be singular.
    g = geometry
    sag = g.weight * g.l0 ** 2 / (6.0 * float(arr.kw.min()) * g.height ** 2)
    u0 = np.array([0.0, 0.0, 2.0 * sag + 2.0 * float(np.abs(g.length_offsets).max()) * g.l0 / g.height])
    end = _continuation(arr, arr.homotopy, lambda lam: zero, u0, np.eye(3), xtol, DEFAULT_MAX_ITER,
                        2000, lambda: f'the rest pose under W = {geometry.weight} N')
    return end.u, end.q


def rest_pose(geometry: CraneGeometry, *, xtol: float = DEFAULT_XTOL) -> Equilibrium:
    """The equilibrium under the weight alone (no external load): the paper's loaded rest pose."""
    return solve_equilibrium(geometry, load=np.zeros(6), xtol=xtol)


def solve_equilibrium(geometry: CraneGeometry, force=None, moment=None, *, load=None,
                      initial: Equilibrium | None = None, xtol: float = DEFAULT_XTOL,
                      max_iter: int = DEFAULT_MAX_ITER, max_steps: int = 2000) -> Equilibrium:
    """Equilibrium of the platform under its weight and an external load.

    Args:
        geometry: the crane (includes the weight W).
        force: external force [fx, fy, fz] [N], fixed frame, applied at ``geometry.load_point``.
        moment: external moment [mx, my, mz] [N·m], fixed frame.
        load: alternatively the 6-vector [fx, fy, fz, mx, my, mz].
        initial: a previous equilibrium of the same geometry to warm-start from (the load path then runs from its
            load to this one).
        xtol: tolerance on the pose: every platform point within xtol of the solution [m].
        max_iter: Newton iterations per continuation step.
        max_steps: bound on continuation steps, so the solver never hangs.

    Returns:
        The :class:`Equilibrium`.

    Raises:
        NoEquilibriumError: the load cannot be held (upward force above W), or the load path loses equilibrium.
        ConvergenceError: the solver gave up; the message says at which load fraction.
    """
    load = as_load(force, moment, load)
    check_load_admissible(geometry, load)
    arr = geometry_arrays(geometry)
    if initial is not None:
        u = np.array(initial.displacement, dtype=float)
        q = np.array(initial.rotation, dtype=float)
        start_load = np.asarray(initial.load, dtype=float)
    else:
        u0, q0 = _rest(geometry, xtol)
        u, q = u0.copy(), q0.copy()
        start_load = np.zeros(6)
    args = arr.args()
    # Most loads are reached in one step; continuation only when that fails or lands far away.
    status, total_iters, lengths, tensions, w = _step(arr, args, load, u, q, xtol, max_iter)
    steps = 1
    if status != kern.CONVERGED:
        end = _continuation(arr, lambda lam: args, lambda lam: start_load + lam * (load - start_load), u, q,
                            xtol, max_iter, max_steps, lambda: f'the load {load.tolist()}')
        u, q, lengths, tensions, w = end.u, end.q, end.lengths, end.tensions, end.residual
        total_iters, steps = total_iters + end.iterations, 1 + end.steps
    slack = lengths < arr.l0
    if slack.all() and (geometry.weight > 0.0 or load.any()):
        raise NoEquilibriumError(f'all six wires are slack under the load {load.tolist()}')
    return Equilibrium(u, q, lengths, tensions, slack, load, total_iters, w, steps)


def checked_loads(geometry: CraneGeometry, loads) -> np.ndarray:
    """``loads`` as a contiguous (N, 6) float array [fx, fy, fz, mx, my, mz] [N, N·m], checked for the batch
    solvers: ValueError naming the first row with a non-finite component, NoEquilibriumError (with the reason) for
    the first load that pushes the platform up harder than its weight holds it down."""
    loads = np.ascontiguousarray(np.asarray(loads, dtype=float).reshape(-1, 6))
    if not np.all(np.isfinite(loads)):
        row = int(np.argwhere(~np.all(np.isfinite(loads), axis=1))[0, 0])
        raise ValueError(f'loads[{row}] = {loads[row].tolist()}: every component must be finite')
    down = geometry.weight + loads[:, 2]
    bad = np.flatnonzero((down < 0.0) | ((down == 0.0) & np.any(loads != 0.0, axis=1)))
    if bad.size:
        check_load_admissible(geometry, loads[bad[0]])  # raises with the reason
    return loads


def solve_batch(geometry: CraneGeometry, loads, *, xtol: float = DEFAULT_XTOL,
                max_iter: int = DEFAULT_MAX_ITER) -> BatchEquilibrium:
    """Equilibria for many load cases of one geometry, compiled loop over cases.

    Args:
        geometry: the crane.
        loads: (N, 6) array of [fx, fy, fz, mx, my, mz] [N, N·m].

    Each case is solved from the rest pose under the weight; cases that need load continuation (large loads) are
    finished by :func:`solve_equilibrium`. Raises NoEquilibriumError naming the first inadmissible case.
    """
    loads = checked_loads(geometry, loads)
    arr = geometry_arrays(geometry)
    u0, q0 = _rest(geometry, xtol)
    out = batch_outputs(loads.shape[0])
    kern.batch_solve(*arr.args(), loads, u0, q0, xtol, max_iter, arr.lc, arr.max_move, arr.min_cos_turn,
                     arr.max_shift, *out)
    return finish_batch(geometry, loads, out, xtol, max_iter)


def batch_outputs(n: int) -> tuple[np.ndarray, ...]:
    """What a batch kernel fills for ``n`` cases: u (n, 3), q (n, 3, 3), lengths, tensions, w (n, 6), status and
    iterations (n,) (int64)."""
    return (np.empty((n, 3)), np.empty((n, 3, 3)), np.empty((n, 6)), np.empty((n, 6)), np.empty((n, 6)),
            np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64))


def finish_batch(geometry: CraneGeometry, loads: np.ndarray, out: tuple[np.ndarray, ...], xtol: float,
                 max_iter: int) -> BatchEquilibrium:
    """The batch's result from a kernel's ``out`` (:func:`batch_outputs`): the cases it did not bring to
    CONVERGED (Newton could not reach them directly, or reached them far from the rest pose) solved again by
    :func:`solve_equilibrium`, which finishes them by load continuation or raises the error that says why."""
    u, q, lengths, tensions, w, status, iters = out
    for c in np.flatnonzero(status != kern.CONVERGED):
        eq = solve_equilibrium(geometry, load=loads[c], xtol=xtol, max_iter=max_iter)
        u[c], q[c], lengths[c], tensions[c], w[c] = (eq.displacement, eq.rotation, eq.wire_lengths,
                                                     eq.wire_tensions, eq.residual)
        iters[c] = eq.iterations
    return BatchEquilibrium(u, q, lengths, tensions, lengths < geometry_arrays(geometry).l0, loads, iters, w)


def solve_path(geometry: CraneGeometry, loads, *, xtol: float = DEFAULT_XTOL) -> list[Equilibrium]:
    """Equilibria along a load path (N, 6), each warm-started from the previous one: quasi-static loading."""
    out: list[Equilibrium] = []
    prev: Equilibrium | None = None
    for row in np.asarray(loads, dtype=float).reshape(-1, 6):
        prev = solve_equilibrium(geometry, load=row, initial=prev, xtol=xtol)
        out.append(prev)
    return out
