"""Compile the model's numba kernels into their on-disk cache, once, where the package is installed.

The kernels of :mod:`crane_stiffness.model._kernels` are ``@njit(cache=True)``: numba keeps the machine code in
``__pycache__`` beside ``_kernels.py`` (or, where that directory is read-only, in its user-wide cache), keyed by a
hash of the source file's bytes. Compiled on first use they cost crane_model ~15 s of CPU at start; compiled
here, after installation, every node and CLI call starting from that install loads them in well under a second.

``setup.py install`` (what ``colcon build`` runs) calls this on the installed package; ``make install`` calls it
after ``pip install``. By hand::

    python -m crane_stiffness.model.kernel_cache     # compile (or load) and report what came from where
    python -m crane_stiffness.model.kernel_cache --seed-from .venv/lib/python3.11/site-packages

numba's cache does not depend on where the package is: the index of each kernel holds a hash of its source file's
bytes (numba 0.68, as pinned: ``numba/core/caching.py``), and its entries are keyed by the signature, the CPU and
the function's bytecode. So a cache compiled for one installation of the package serves another with the same
files: ``--seed-from`` copies it over (:func:`seed`) before the kernels are exercised, and they are then loaded, not
compiled. ``colcon build`` seeds the install tree this way from the installation of the interpreter that runs it
(``make install``'s ``.venv``), so the kernels are compiled once for both; ``make install`` also copies them into
the source tree (``--copy-to``), whose modules the demo's own process and the tests import.

:func:`exercise` runs every kernel with the argument types the package uses (the solver's single, warm-started,
continuation, path and batch solves, the Jacobian and the tangent stiffness), so nothing is left to compile at run
time; :func:`cache_report` says, per kernel, how many signatures came from the cache and how many were compiled
(a kernel only called from other kernels is compiled into them and loaded with them). The kernels of
``_batch_kernels``, ``_pose_kernels`` and ``_draw_kernels`` call those of ``_kernels``; numba checks each cache
against its own file only, so this runs after every install, and :func:`seed` copies a cache only between
installations whose Python files are all the same.
"""
from __future__ import annotations

import argparse
import hashlib
import shutil
import sys
import time
from pathlib import Path

__all__ = ['cache_report', 'exercise', 'main', 'seed']

#: numba's cache files: the index (``<module>.<kernel>-<line>.py<ver>.nbi``) and the data it points to (``.nbc``).
CACHE_PATTERNS = ('*.nbi', '*.nbc')


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
    # Many cranes' rest tangents at once (the uncertainty room's Monte Carlo of the prediction).
    from crane_stiffness.model.draws import rest_stiffness_draws
    rest_stiffness_draws(g, weight=np.array([50.0, 50.1]))


def kernels() -> dict:
    """The compiled dispatchers of _kernels by name (empty without numba)."""
    from crane_stiffness.model import _batch_kernels, _draw_kernels, _kernels, _pose_kernels
    if not _kernels.HAVE_NUMBA:
        return {}
    from numba.core.registry import CPUDispatcher
    found: dict = {}
    for module in (_kernels, _batch_kernels, _pose_kernels, _draw_kernels):
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


def _sources(package: Path) -> dict[str, bytes]:
    """{path relative to ``package``: sha256 of the bytes} of every Python file of the package."""
    return {str(p.relative_to(package)): hashlib.sha256(p.read_bytes()).digest()
            for p in sorted(package.rglob('*.py')) if '__pycache__' not in p.parts}


def seed(source: str | Path, target: str | Path) -> int:
    """Copy the compiled kernels of the package installed under ``source`` (a site-packages directory, or the
    ``crane_stiffness`` directory itself) into the package at ``target`` when both hold the same Python files, byte
    for byte; the number of files copied (0 when they differ or ``source`` has none).

    Every file counts, not only the kernels' own: a kernel calling another module's kernel has it compiled in, and
    numba checks each cache against its own file only."""
    def package(path: str | Path) -> Path:
        path = Path(path)
        return path if (path / 'model' / '_kernels.py').is_file() else path / 'crane_stiffness'
    src, dst = package(source), package(target)
    if src.resolve() == dst.resolve() or not (src / 'model' / '_kernels.py').is_file():
        return 0
    if _sources(src) != _sources(dst):
        return 0
    copied = 0
    for cache in sorted(src.rglob('__pycache__')):
        files = [f for pattern in CACHE_PATTERNS for f in sorted(cache.glob(pattern))]
        if not files:
            continue
        into = dst / cache.relative_to(src)
        into.mkdir(parents=True, exist_ok=True)
        for f in files:
            shutil.copy2(f, into / f.name)
            copied += 1
    return copied


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog='python -m crane_stiffness.model.kernel_cache',
                                 description='Compile (or load) the model kernels into their cache beside this '
                                             'installation of the package.')
    ap.add_argument('--seed-from', metavar='DIR', action='append', default=[],
                    help='first copy the compiled kernels of the package installed in DIR (a site-packages '
                         'directory) when its files are the same as this one\'s (repeatable: the first that '
                         'matches)')
    ap.add_argument('--copy-to', metavar='DIR', action='append', default=[],
                    help='then copy the compiled kernels into the package in DIR (a source tree, a site-packages '
                         'directory) when its files are the same as this one\'s (repeatable)')
    args = ap.parse_args(argv)
    from crane_stiffness.model import _kernels
    if not _kernels.HAVE_NUMBA:
        print('kernel cache: numba is not installed; the model runs as plain Python', flush=True)
        return 0
    here = Path(_kernels.__file__).resolve().parent.parent
    for source in args.seed_from:
        copied = seed(source, here)
        if copied:
            print(f'kernel cache: {copied} file(s) copied from {source} (same sources)', flush=True)
            break
    t0 = time.perf_counter()
    exercise()
    report = cache_report()
    compiled = sum(r['misses'] for r in report.values())
    loaded = sum(r['hits'] for r in report.values())
    where = next(iter(kernels().values())).stats.cache_path
    print(f'kernel cache: {compiled} signature(s) compiled, {loaded} loaded from {where} '
          f'in {time.perf_counter() - t0:.1f} s', flush=True)
    for target in args.copy_to:
        copied = seed(here, target)
        print(f'kernel cache: {copied} file(s) copied to {target}' if copied else
              f'kernel cache: nothing copied to {target} (not the same package files)', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
