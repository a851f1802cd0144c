"""Compile the model's numba kernels into their on-disk cache, once, where the package is installed.

The kernels of :mod:`crane_stiffness.model._kernels` are ``@njit(cache=True)``: numba keeps the machine code in
``__pycache__`` beside ``_kernels.py`` (or, where that directory is read-only, in its user-wide cache), keyed by the
source file's modification time and size. Compiled on first use they cost crane_model ~15 s of CPU at start; compiled
here, after installation, every node and CLI call starting from that install loads them in well under a second.

``setup.py install`` (what ``colcon build`` runs) calls this on the installed package; ``make install`` calls it
after ``pip install``. By hand::

    python -m crane_stiffness.model.kernel_cache     # compile (or load) and report what came from where

:func:`exercise` runs every kernel with the argument types the package uses (the solver's single, warm-started,
continuation, path and batch solves, the Jacobian and the tangent stiffness), so nothing is left to compile at run
time; :func:`cache_report` says, per kernel, how many signatures came from the cache and how many were compiled
(a kernel only called from other kernels is compiled into them and loaded with them). The kernels of
``_batch_kernels`` and ``_pose_kernels`` call those of ``_kernels``; numba keys each cache by its own file only, so
this runs after every install, which rewrites all three files.
"""
from __future__ import annotations

import sys
import time

__all__ = ['cache_report', 'exercise', 'main']


def exercise() -> None:
    """Call every compiled kernel through the public model API with the types the nodes and the CLI use."""
    import numpy as np

    from crane_stiffness.model import (axis_stiffness, lab_model, net_wrench, rest_pose, solve_batch,
                                       solve_equilibrium, solve_path, tangent_stiffness, wrench_jacobian)
    g = lab_model(0.5, 50.0)
    rest = rest_pose(g)
    eq = solve_equilibrium(g, load=np.array([0.0, 2.0, 0.0, 0.0, 0.0, 0.0]))          # cold: continuation
    eq = solve_equilibrium(g, load=np.array([0.0, 2.5, 0.0, 0.0, 0.0, 0.01]), initial=eq)  # warm start
    axis_stiffness(tangent_stiffness(g, eq), 'fy')
    tangent_stiffness(g, rest)
    net_wrench(g, eq.displacement, eq.rotation, np.zeros(6))
    wrench_jacobian(g, eq.displacement, eq.rotation, np.zeros(6))
    solve_batch(g, np.array([[0.0, 1.0, 0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]]))
    solve_path(g, np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0, 0.0, 0.0]]))
    # The parallel batch and the design kernels (crane-stiffness workspace, bench_solver).
    from crane_stiffness.design.maps import GridAxis, MapSpec, compute_rows
    from crane_stiffness.design.margins import slack_margins, sphere_directions
    from crane_stiffness.design.pose import at_pose
    from crane_stiffness.model.batch import solve_batch_parallel
    solve_batch_parallel(g, np.array([[0.0, 1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 20.0, 0.0, 0.0, 0.0, 0.0]]))
    report = at_pose(g, (0.001, 0.0, 0.0))
    slack_margins(report.solution.geometry, report.equilibrium, sphere_directions(4), 'force')
    compute_rows(MapSpec(GridAxis('x', -0.01, 0.01, 2), GridAxis('y', -0.01, 0.01, 2), g, directions=2), range(2))


def kernels() -> dict:
    """The compiled dispatchers of _kernels by name (empty without numba)."""
    from crane_stiffness.model import _batch_kernels, _kernels, _pose_kernels
    if not _kernels.HAVE_NUMBA:
        return {}
    from numba.core.registry import CPUDispatcher
    found: dict = {}
    for module in (_kernels, _batch_kernels, _pose_kernels):
        for name, obj in vars(module).items():
            # a kernel imported from another module is listed once, under its own module
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == module.__name__:
                found[f'{module.__name__.rsplit(".", 1)[-1]}.{name}'] = obj
    return found


def cache_report() -> dict[str, dict[str, int]]:
    """{kernel: {'hits': signatures loaded from the cache, 'misses': signatures compiled}} so far in this process."""
    report = {}
    for name, dispatcher in kernels().items():
        stats = dispatcher.stats
        report[name] = {'hits': sum(stats.cache_hits.values()), 'misses': sum(stats.cache_misses.values())}
    return report


def main(argv: list[str] | None = None) -> int:
    from crane_stiffness.model import _kernels
    if not _kernels.HAVE_NUMBA:
        print('kernel cache: numba is not installed; the model runs as plain Python', flush=True)
        return 0
    t0 = time.perf_counter()
    exercise()
    report = cache_report()
    compiled = sum(r['misses'] for r in report.values())
    loaded = sum(r['hits'] for r in report.values())
    where = next(iter(kernels().values())).stats.cache_path
    print(f'kernel cache: {compiled} signature(s) compiled, {loaded} loaded from {where} '
          f'in {time.perf_counter() - t0:.1f} s', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
