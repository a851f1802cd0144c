"""Independent per-session jobs run in parallel: on local processes (all cores by default), or on a Dask cluster
given its scheduler's address (``tcp://host:8786``; the optional extra ``dask[distributed]``). A Dask cluster's
workers must see the campaign directory at the same path (a shared file system) and have this package installed.
No ROS."""
from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from multiprocessing.context import BaseContext
from typing import Any, Callable, Sequence

from crane_stiffness.campaign.errors import CampaignError

Job = Sequence[Any]


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def map_sessions(func: Callable[..., str], jobs: Sequence[Job], *, workers: int | None = None,
                 scheduler: str | None = None, progress: Callable[[str], None] | None = None) -> list[str]:
    """``func(*job)`` for every job, in parallel; the results in the order of ``jobs``. ``progress`` is called
    with the first argument of each job as it finishes."""
    if not jobs:
        return []
    if scheduler:
        return _on_dask(func, jobs, scheduler, progress)
    workers = default_workers() if workers is None else workers
    if workers < 1:
        raise CampaignError(f'workers = {workers}: must be >= 1')
    results: list[str] = [''] * len(jobs)
    if workers == 1 or len(jobs) == 1:
        for i, job in enumerate(jobs):
            results[i] = func(*job)
            if progress is not None:
                progress(str(job[0]))
        return results
    with ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=_context(func)) as pool:
        futures = {pool.submit(func, *job): i for i, job in enumerate(jobs)}
        for future in as_completed(futures):
            i = futures[future]
            results[i] = future.result()
            if progress is not None:
                progress(str(jobs[i][0]))
    return results


def _context(func: Callable[..., str]) -> BaseContext:
    """Worker processes forked from a server that imported ``func``'s module and the analysis once and warmed the
    model's kernels and matplotlib (crane_stiffness.campaign.worker_preload: seconds per process when each worker
    does it itself), never from this process (which may hold threads); a clean interpreter ('spawn') where there is
    no fork server."""
    try:
        context = get_context('forkserver')
    except ValueError:  # no fork server on this platform
        return get_context('spawn')
    context.set_forkserver_preload([func.__module__, 'crane_stiffness.analysis.analyze',
                                    'crane_stiffness.analysis.figures', 'crane_stiffness.campaign.worker_preload'])
    return context


def distributed(scheduler: str) -> Any:
    """The ``dask.distributed`` module (the optional extra ``dask``); CampaignError saying so when it is missing."""
    try:
        import dask.distributed
    except ImportError:
        raise CampaignError(f'--scheduler {scheduler}: dask.distributed is not installed (pip install '
                            "'crane_stiffness[dask]')") from None
    return dask.distributed


def connect(scheduler: str) -> Any:
    """A dask.distributed Client of the scheduler at ``scheduler`` (``tcp://host:8786``); CampaignError saying why
    when dask.distributed is not installed or the scheduler cannot be reached within Dask's connect timeout (its
    setting ``distributed.comm.timeouts.connect``, 30 s unless changed, e.g. by the environment variable
    DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT=5s)."""
    dask_distributed = distributed(scheduler)
    timeout = dask_distributed.config['distributed']['comm']['timeouts']['connect']  # dask's global settings
    try:
        return dask_distributed.Client(scheduler, timeout=timeout)
    except (OSError, TimeoutError) as exc:
        raise CampaignError(f'--scheduler {scheduler}: cannot connect within {timeout} (Dask\'s '
                            f'distributed.comm.timeouts.connect): {exc}') from None


def _on_dask(func: Callable[..., str], jobs: Sequence[Job], scheduler: str,
             progress: Callable[[str], None] | None) -> list[str]:
    client = connect(scheduler)
    dask_completed = distributed(scheduler).as_completed
    try:
        futures = [client.submit(func, *job, pure=False) for job in jobs]
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[str] = [''] * len(jobs)
        for future in dask_completed(futures):
            i = index[future.key]
            results[i] = future.result()
            if progress is not None:
                progress(str(jobs[i][0]))
        return results
    finally:
        client.close()
