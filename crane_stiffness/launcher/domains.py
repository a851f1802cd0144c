"""A ROS domain claimed by one rig, host-wide, before the rig uses it: two rigs never share a domain and mix their data.

DDS keeps rigs apart only by their domain id: two rigs of one machine in one domain (two Dask workers started with the
same ``ROS_DOMAIN_ID``, a campaign beside another ROS program, two campaigns at once) read each other's commands and
samples, and nothing else stops it. So every rig this package starts (the demo, ``campaign run`` and its rig hosts, a
Dask worker's rig host, the tests) first *claims* its domain:

1. **A lock file per domain** (:func:`try_claim`): an exclusive ``flock`` on ``<claim dir>/domain-<id>.lock``, taken
   without waiting and held while the rig runs. The kernel releases it when the process ends however it ends (a
   SIGKILL too), so a claim never outlives its rig. The file says who holds it (pid, program, since when), for the
   message of the rig that finds it taken.
2. **A look at the ROS graph** (:func:`foreign_nodes`): nodes already in the domain that are not the rig's own (a
   ROS program that knows nothing of the lock files). A domain with any is not taken either.

A domain in use is skipped for the next free one (:func:`claim_domain`, ``search=True``) or the run is refused naming
the domain and who holds it (:class:`DomainInUseError`). A claim passes to the processes the rig starts
(:data:`INHERITED_ENV`): a node process, a rig host's process or a test's rig in a claimed domain is the claimer's
own and takes it without a second lock.

The claim directory is ``CRANE_STIFFNESS_DOMAIN_CLAIMS_DIR`` if set, else ``$XDG_RUNTIME_DIR/crane_stiffness/domains``,
else ``/tmp/crane_stiffness-<uid>/domains``: one machine, one user's rigs.
"""
from __future__ import annotations

import fcntl
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator, Mapping

from crane_stiffness.launcher.rosrun import RosRunError

#: The highest DDS domain id Fast DDS maps to ports with its default port base.
MAX_DOMAIN_ID = 232
#: The environment variable that hands a claim down to the processes a rig starts: the domains claimed by an
#: ancestor, comma-separated.
INHERITED_ENV = 'CRANE_STIFFNESS_DOMAIN_CLAIMED'
#: How long a rig looks at the graph for nodes not its own before it takes a domain [s of wall time], unless
#: CRANE_STIFFNESS_DOMAIN_LOOK_S says otherwise; the look ends as soon as it finds one. A Fast DDS participant
#: announces itself 5 times 0.1 s apart when it starts, then every 3 s: a node started a while ago is seen at its next
#: announcement. A node missed on a very busy machine still cannot mix with this package's rigs: they all take the
#: lock.
GRAPH_LOOK_S = 4.0


def graph_look_s() -> float:
    """The graph look's length [s]: CRANE_STIFFNESS_DOMAIN_LOOK_S if set (0: no look), else :data:`GRAPH_LOOK_S`."""
    text = os.environ.get('CRANE_STIFFNESS_DOMAIN_LOOK_S', '')
    try:
        return max(0.0, float(text)) if text else GRAPH_LOOK_S
    except ValueError:
        raise DomainInUseError(f'CRANE_STIFFNESS_DOMAIN_LOOK_S={text!r}: must be a number of seconds') from None


class DomainInUseError(RosRunError):
    """The ROS domain a rig would take is in use (its lock held, or nodes of others in its graph)."""


def claim_dir() -> Path:
    """The directory of the lock files (see the module docstring); created if missing."""
    given = os.environ.get('CRANE_STIFFNESS_DOMAIN_CLAIMS_DIR')
    if given:
        path = Path(given)
    elif os.environ.get('XDG_RUNTIME_DIR'):
        path = Path(os.environ['XDG_RUNTIME_DIR']) / 'crane_stiffness' / 'domains'
    else:
        path = Path('/tmp') / f'crane_stiffness-{os.getuid()}' / 'domains'
    path.mkdir(parents=True, exist_ok=True)
    return path


def inherited(env: Mapping[str, str] | None = None) -> set[int]:
    """The domains an ancestor process claimed for this one (:data:`INHERITED_ENV`)."""
    text = (os.environ if env is None else env).get(INHERITED_ENV, '')
    return {int(part) for part in text.split(',') if part.strip().isdigit()}


def with_claim(env: Mapping[str, str], domain: int) -> dict[str, str]:
    """``env`` for a process started in the claimed ``domain``: ROS_DOMAIN_ID set and the claim handed down."""
    claimed = sorted(inherited(env) | {domain})
    return {**env, 'ROS_DOMAIN_ID': str(domain), INHERITED_ENV: ','.join(map(str, claimed))}


@dataclass
class DomainClaim:
    """A claimed ROS domain; :meth:`release` (or leaving the ``with``) gives it back. ``own``: this process took the
    lock (False: an ancestor holds it, see :data:`INHERITED_ENV`)."""

    domain: int
    path: Path | None = None
    skipped: list[tuple[int, str]] = field(default_factory=list)  #: domains passed over, with who holds each
    _fd: int | None = None

    @property
    def own(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)  # (closing the file releases the flock)

    def __enter__(self) -> 'DomainClaim':
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _check_domain(domain: int) -> None:
    if not 0 <= domain <= MAX_DOMAIN_ID:
        raise DomainInUseError(f'ROS domain {domain}: DDS domain ids go from 0 to {MAX_DOMAIN_ID}')


def holder(domain: int) -> str:
    """Who holds ``domain``'s lock, as its file says (or 'unknown')."""
    try:
        info = json.loads((claim_dir() / f'domain-{domain}.lock').read_text() or '{}')
    except (OSError, ValueError):
        return 'unknown'
    if not info:
        return 'unknown'
    since = time.strftime('%H:%M:%S', time.localtime(info.get('since', 0)))
    return f"pid {info.get('pid')} ({info.get('owner', '?')}, since {since})"


def try_claim(domain: int, owner: str) -> DomainClaim | None:
    """The lock of ``domain`` taken without waiting, the file saying who holds it; None if another process holds it."""
    _check_domain(domain)
    path = claim_dir() / f'domain-{domain}.lock'
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    os.ftruncate(fd, 0)
    os.write(fd, json.dumps({'pid': os.getpid(), 'owner': owner, 'since': time.time()}).encode())
    return DomainClaim(domain, path, _fd=fd)


def foreign_nodes(domain: int, look_s: float | None = None) -> list[str]:
    """The nodes in ``domain``'s ROS graph, looked at from a participant of this process (the look's own node left
    out) until one is seen or ``look_s`` seconds (default :func:`graph_look_s`) have passed: before a rig starts,
    every one is foreign."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    rclpy.init(args=[], context=context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    try:
        name = f'crane_stiffness_domain_look_{os.getpid()}'
        node = rclpy.create_node(name, context=context, start_parameter_services=False,
                                 enable_rosout=False)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        found: set[str] = set()
        end = time.monotonic() + (graph_look_s() if look_s is None else look_s)
        while time.monotonic() < end and not found:
            executor.spin_once(timeout_sec=0.05)
            found |= {f'{ns.rstrip("/")}/{n}' for n, ns in node.get_node_names_and_namespaces() if n != name}
        executor.shutdown()
        node.destroy_node()
        return sorted(found)
    finally:
        rclpy.try_shutdown(context=context)


def _candidates(first: int, search: bool) -> Iterator[int]:
    yield first
    if search:
        yield from range(first + 1, MAX_DOMAIN_ID + 1)
        yield from range(1, first)


def claim_domain(first: int, owner: str = '', *, search: bool = True, look_s: float | None = None,
                 env: Mapping[str, str] | None = None, avoid: Iterable[int] = ()) -> DomainClaim:
    """Claim ``first``, or with ``search`` the next free domain after it (wrapping to 1): its lock taken and no
    foreign node in its graph (looked at for ``look_s`` seconds at most, default :func:`graph_look_s`; 0: no look).
    A domain an ancestor claimed (``env``'s :data:`INHERITED_ENV`) is this process's own: taken as it is.
    ``avoid``: domains not to take (others of the same run).

    Raises:
        DomainInUseError: ``first`` is in use and ``search`` is off (naming who holds it), or no domain is free.
    """
    _check_domain(first)
    if first in inherited(env):
        return DomainClaim(first)
    owner = owner or ' '.join(os.path.basename(a) for a in sys.argv[:2])
    skipped: list[tuple[int, str]] = []
    avoided = set(avoid) | (inherited(env) - {first})
    for domain in _candidates(first, search):
        if domain in avoided:
            continue
        claim = try_claim(domain, owner)
        if claim is None:
            skipped.append((domain, f'claimed by {holder(domain)}'))
        else:
            wait = graph_look_s() if look_s is None else look_s
            nodes = foreign_nodes(domain, wait) if wait > 0 else []
            if not nodes:
                claim.skipped = skipped
                return claim
            claim.release()
            shown = ', '.join(nodes[:5]) + (f' and {len(nodes) - 5} more' if len(nodes) > 5 else '')
            skipped.append((domain, f'nodes of others in its graph: {shown}'))
        if not search:
            raise DomainInUseError(f'ROS domain {domain} is in use ({skipped[-1][1]}): a rig there would mix its '
                                   'data with theirs; choose another ROS_DOMAIN_ID')
    raise DomainInUseError('no free ROS domain on this machine (' +
                           '; '.join(f'{d}: {why}' for d, why in skipped[:5]) + ')')


def describe_skipped(claim: DomainClaim) -> str:
    """One line for people: which domains were passed over and why ('' if none)."""
    if not claim.skipped:
        return ''
    return 'ROS domain(s) in use, passed over: ' + '; '.join(f'{d} ({why})' for d, why in claim.skipped)
