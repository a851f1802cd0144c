"""A campaign's sessions on the workers of a Dask cluster (``campaign run FILE --scheduler ADDRESS``).

Each session is one Dask task (:func:`remote_session`): the worker runs the simulated rig in a scratch directory of
its own, in a ROS domain of its own (:class:`_WorkerDomains`: ROS_DOMAIN_ID of the worker's environment and the
next ones, one per worker thread), and returns the session's ``result.json`` and its files (``bags/<id>/`` and
``sessions/<id>/``) as one tar archive. Only the client writes into the campaign directory
(:func:`store_session`): it unpacks a returned archive beside the campaign, then moves the bag and the session
folder (``result.json`` last) into place. So a worker needs no shared file system, and a worker lost in the middle
of a session leaves nothing behind: Dask runs the task again on another worker, and the campaign directory gets
each session exactly once, from the one run that finished.

The numbers do not depend on where a session runs: on simulated time a session's streams and estimate are the
same on any machine at any load (docs/simulated_time.md); its seeds and program come from the plan, made by the
client (the program text is sent along, so a worker's install needs no campaign file).

A worker must have this package installed (with the extra ``dask``) and ROS 2 as for ``ros2 run``; its
environment gives ROS_DOMAIN_ID (the first domain of its rigs) and ROS_AUTOMATIC_DISCOVERY_RANGE (LOCALHOST when
unset: the rig's nodes run on the worker's machine). Imports no ROS itself.
"""
from __future__ import annotations

import io
import json
import os
import shutil
import tarfile
import tempfile
import threading
import uuid
from pathlib import Path
from typing import Any, Callable, Mapping

from crane_stiffness.campaign.errors import CampaignError
from crane_stiffness.campaign.spec import Campaign, SessionPlan

#: Where the client unpacks a returned session before moving it into the campaign directory.
INCOMING = '.incoming'


class _WorkerDomains:
    """The ROS domains of one worker process: ROS_DOMAIN_ID and the next ones, one per thread, handed out and
    back (a rig never shares its domain with another rig of the same worker: simulated time keeps one /clock per
    domain)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._free: list[int] | None = None

    def take(self, threads: int) -> int:
        with self._lock:
            if self._free is None:
                base = int(os.environ.get('ROS_DOMAIN_ID', '0') or 0)
                self._free = [base + k for k in range(max(1, threads))]
                if self._free[-1] > 232:
                    raise CampaignError(f'worker with ROS_DOMAIN_ID={base} and {threads} threads needs domains up '
                                        f'to {self._free[-1]}; DDS has 0..232')
            if not self._free:
                raise CampaignError('worker: more sessions at once than threads (no ROS domain free)')
            return self._free.pop(0)

    def give_back(self, domain: int) -> None:
        with self._lock:
            assert self._free is not None
            self._free.append(domain)


_DOMAINS = _WorkerDomains()
#: The rig hosts of this worker process by ROS domain, kept between its tasks (a rig that stays up).
_HOSTS: dict[int, Any] = {}


def _host(domain: int) -> Any:
    """This worker's rig host in ``domain`` (made at its first session; only the thread holding the domain uses
    it)."""
    from crane_stiffness.launcher.rig_host import RigHost
    host = _HOSTS.get(domain)
    if host is None:
        host = _HOSTS[domain] = RigHost(domain)
    return host


def remote_session(campaign: Campaign, plan: SessionPlan, program_text: str, arguments: Mapping[str, str],
                   ready_timeout_s: float, rig: str = 'host') -> dict[str, Any]:
    """Run one session on this Dask worker, on its rig host (``rig`` 'host', kept up between sessions) or with its
    nodes as processes ('processes'): ``{'result': <result.json>, 'archive': <tar bytes of bags/<id> and
    sessions/<id>>, 'worker': <address>}``. The scratch directory goes when the session ends, however it ends."""
    from crane_stiffness.campaign.parallel import distributed
    from crane_stiffness.campaign.session import SessionRunner
    from crane_stiffness.launcher import rosrun
    from crane_stiffness.params.files import share_dir
    from crane_stiffness.rosnode.discovery import use_quick_discovery

    use_quick_discovery()
    worker = distributed('this worker').get_worker()
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    domain = _DOMAINS.take(worker.state.nthreads)
    scratch = Path(tempfile.mkdtemp(prefix=f'session-{plan.id}-', dir=worker.local_directory))
    try:
        if rig == 'host':
            runner = SessionRunner(campaign, scratch, False, arguments, env, share_dir() / 'config', None,
                                   ready_timeout_s, {plan.id: program_text}, rig='host-here', here=_host(domain))
        else:
            runner = SessionRunner(campaign, scratch, False, arguments, env, share_dir() / 'config',
                                   rosrun.node_executables(), ready_timeout_s, {plan.id: program_text})
        result = runner.run(plan, None, domain, lambda fraction: None)
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode='w') as tar:
            for part in ('bags', 'sessions'):
                if (scratch / part / plan.id).exists():
                    tar.add(scratch / part / plan.id, arcname=f'{part}/{plan.id}')
        return {'result': result, 'archive': buffer.getvalue(), 'worker': worker.address}
    finally:
        _DOMAINS.give_back(domain)
        shutil.rmtree(scratch, ignore_errors=True)


def store_session(out: Path, plan: SessionPlan, returned: Mapping[str, Any]) -> dict[str, Any]:
    """Put a session a worker returned into the campaign directory ``out``: its bag and its folder, ``result.json``
    (naming the bag where it now is and the worker it ran on) written last. Whatever an earlier attempt left of the
    same session is set aside first (``interrupted/``), as a local run does."""
    from crane_stiffness.campaign.session import RESULT_FILE, set_aside

    staging = out / INCOMING / f'{plan.id}-{uuid.uuid4().hex[:8]}'
    staging.mkdir(parents=True)
    try:
        with tarfile.open(fileobj=io.BytesIO(returned['archive']), mode='r') as tar:
            tar.extractall(staging, members=_session_members(tar, plan))
        folder = staging / 'sessions' / plan.id
        result = dict(returned['result'])
        result['bag'] = str(out / 'bags' / plan.id)
        result['worker'] = returned['worker']
        (folder / RESULT_FILE).unlink(missing_ok=True)  # written again below, after the bag is in place
        set_aside(out, plan)
        (out / 'bags').mkdir(exist_ok=True)
        (out / 'sessions').mkdir(exist_ok=True)
        os.replace(staging / 'bags' / plan.id, out / 'bags' / plan.id)
        os.replace(folder, out / 'sessions' / plan.id)
        tmp = out / 'sessions' / plan.id / (RESULT_FILE + '.tmp')
        tmp.write_text(json.dumps(result, indent=1, allow_nan=True))
        os.replace(tmp, out / 'sessions' / plan.id / RESULT_FILE)
        return result
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        try:
            (out / INCOMING).rmdir()
        except OSError:  # another session is being unpacked, or it is gone already
            pass


def _session_members(tar: tarfile.TarFile, plan: SessionPlan) -> list[tarfile.TarInfo]:
    """The archive's members, each a plain file or folder under ``bags/<id>/`` or ``sessions/<id>/``; anything else
    (a link, a device, an absolute path, ``..``) is refused naming it: the campaign directory only ever gets the
    session's own files. (Python's extraction filters are not in every 3.11.)"""
    members = tar.getmembers()
    for m in members:
        parts = Path(m.name).parts
        if (not (m.isfile() or m.isdir()) or Path(m.name).is_absolute() or '..' in parts or len(parts) < 2
                or parts[0] not in ('bags', 'sessions') or parts[1] != plan.id):
            raise CampaignError(f'session {plan.id}: the archive its worker returned holds {m.name!r} '
                                f'(not a file of bags/{plan.id}/ or sessions/{plan.id}/): refused')
    return members


def run_on_cluster(campaign: Campaign, out: Path, todo: list[SessionPlan], program_texts: Mapping[str, str],
                   arguments: Mapping[str, str], scheduler: str, ready_timeout_s: float,
                   on_session: Callable[[SessionPlan], None] | None,
                   finished: Callable[[SessionPlan, dict[str, Any]], None], rig: str = 'host') -> None:
    """Every session of ``todo`` as a task on the cluster at ``scheduler``; each stored as it comes back
    (:func:`store_session`) and passed to ``finished``. A worker lost mid-session: Dask runs its task again on
    another worker (up to the scheduler's ``allowed-failures``); a session that fails on its worker raises here
    and the tasks not yet finished are cancelled (the finished ones are kept: run again to resume)."""
    from crane_stiffness.campaign.parallel import connect, distributed
    client = connect(scheduler)
    as_completed = distributed(scheduler).as_completed
    futures = []
    try:
        plans = {}
        for plan in todo:
            if on_session is not None:
                on_session(plan)
            future = client.submit(remote_session, campaign, plan, program_texts[plan.id], dict(arguments),
                                   ready_timeout_s, rig, pure=False, key=f'session-{plan.id}-{uuid.uuid4().hex[:8]}')
            plans[future.key] = plan
            futures.append(future)
        for future in as_completed(futures):
            plan = plans[future.key]
            try:
                returned = future.result()
            except Exception as exc:  # the session's own error on its worker, or KilledWorker after retries
                raise CampaignError(f'session {plan.id} failed on the cluster {scheduler}: {type(exc).__name__}: '
                                    f'{exc}') from exc
            future.release()  # the archive is stored: the cluster need not keep it
            finished(plan, store_session(out, plan, returned))
    finally:
        for future in futures:
            if not future.done():
                future.cancel()
        client.close()
