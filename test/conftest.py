"""Test set-up shared by every test: DDS stays on loopback, each session gets its own domain id.

These variables are set before anything imports rclpy, so every in-process node and every subprocess the tests
start inherits them. This file holds what pytest itself uses (the environment, fixtures, hooks); what the tests
import is in helpers/.
"""
from __future__ import annotations

import os
import random
import signal
import sys
import time
from typing import Any

import pytest

from helpers import REPO

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'  # never multicast off this machine
os.environ.setdefault('ROS_DOMAIN_ID', str(random.Random(os.getpid() ^ time.time_ns()).randint(1, 100)))
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)  # the venv is the ament prefix with rclpy and the msgs
os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
os.environ.setdefault('MPLBACKEND', 'Agg')
# A test run started in the background (`make test &`, a CI step without job control) inherits SIGINT ignored,
# and so would every node it starts: Ctrl-C (the SIGINT the tests send) would do nothing before a node installs its
# own handler. The processes the tests start get SIGINT as a terminal gives it (exec resets a handled signal).
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


#: The highest DDS domain id Fast DDS maps to ports with its default port base.
MAX_DOMAIN_ID = 232
#: Domains above each band's top that a test may still use: a campaign's sessions side by side take ROS_DOMAIN_ID and
#: the next ones (one per job), so a band stops short of the domain above it.
SIDE_BY_SIDE = 4


def _domain_band() -> tuple[list[int], int]:
    """The DDS domain ids this run's tests cycle through, starting at ROS_DOMAIN_ID, and the one domain above them
    (SIDE_BY_SIDE apart) of the tests' rig host (:func:`rig_host`): from the band 1..100, or the band
    CRANE_STIFFNESS_TEST_DOMAINS="LO-HI" names (two test runs on one machine, each in its own band, never meet).
    Under pytest-xdist (`make test` runs the tests in one process more than the cores) each worker takes its own
    share of the band."""
    band = os.environ.get('CRANE_STIFFNESS_TEST_DOMAINS', '1-100')
    lo, hi = (int(v) for v in band.split('-'))
    if not 0 <= lo <= hi <= MAX_DOMAIN_ID:
        raise pytest.UsageError(f'CRANE_STIFFNESS_TEST_DOMAINS={band}: DDS domain ids go from 0 to {MAX_DOMAIN_ID} '
                                '(Fast DDS finds no port for a higher one: every node of such a test exits with 1)')
    workers = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1'))
    share = (hi - lo + 1) // workers
    if share <= 2 * SIDE_BY_SIDE + 1:
        raise pytest.UsageError(f'CRANE_STIFFNESS_TEST_DOMAINS={lo}-{hi}: too few domains for {workers} test '
                                f'process(es) (more than {2 * SIDE_BY_SIDE + 1} each)')
    k = int(os.environ.get('PYTEST_XDIST_WORKER', 'gw0').removeprefix('gw'))
    lo, host = lo + k * share, lo + (k + 1) * share - 1
    hi = host - 1 - SIDE_BY_SIDE
    start = int(os.environ['ROS_DOMAIN_ID'])
    start = start if lo <= start <= hi else lo
    return list(range(start, hi + 1)) + list(range(lo, start)), host


_BAND, HOST_DOMAIN = _domain_band()
_DOMAINS = __import__('itertools').cycle(_BAND)


def _claim_next() -> Any:
    """The next domain of the band whose host-wide claim is free (crane_stiffness.launcher.domains: a lock file per
    domain; another test run or rig of this machine in the same band holds its own), claimed."""
    from crane_stiffness.launcher.domains import try_claim
    for _ in range(len(_BAND)):
        claim = try_claim(next(_DOMAINS), f'pytest worker {os.getpid()}')
        if claim is not None:
            return claim
    raise RuntimeError(f'every DDS domain of the band {_BAND[0]}-{_BAND[-1]} is claimed by other processes')


@pytest.fixture(autouse=True)
def ros_domain(monkeypatch):
    """Every test in a DDS domain of its own, claimed host-wide while it runs (nodes it creates, and processes it
    starts, inherit it and the claim), so nothing a previous test left alive (a latched publisher, a slow process),
    nor another test run or rig on this machine, can reach it."""
    from crane_stiffness.launcher.domains import INHERITED_ENV
    _CLAIMS[:] = [_claim_next()]
    monkeypatch.setenv('ROS_DOMAIN_ID', str(_CLAIMS[0].domain))
    monkeypatch.setenv(INHERITED_ENV, str(_CLAIMS[0].domain))
    yield str(_CLAIMS[0].domain)
    for claim in _CLAIMS:
        claim.release()
    _CLAIMS.clear()


_CLAIMS: list[Any] = []  # the claims of the test running (ros_domain's, and ros_domains' more)


@pytest.fixture
def ros_domains(monkeypatch, ros_domain):
    """``take(n)``: ROS_DOMAIN_ID set to the first of ``n`` consecutive domains of the band, all claimed, the others
    taken from the cycle too (for a campaign running sessions side by side in ROS_DOMAIN_ID, ROS_DOMAIN_ID + 1, ...)."""
    from crane_stiffness.launcher.domains import INHERITED_ENV

    def take(n: int) -> list[int]:
        claims = [_CLAIMS[0]]
        while len(claims) < n:
            following = _claim_next()
            _CLAIMS.append(following)
            claims = claims + [following] if following.domain == claims[-1].domain + 1 else [following]
        domains = [c.domain for c in claims]
        monkeypatch.setenv('ROS_DOMAIN_ID', str(domains[0]))
        monkeypatch.setenv(INHERITED_ENV, ','.join(map(str, domains)))
        return domains
    return take


@pytest.fixture
def rclpy_context(ros_domain):
    """A fresh rclpy context for one test; create nodes with ``context=rclpy_context``."""
    import rclpy
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.shutdown(context=ctx)


@pytest.fixture
def install_tree(colcon_install, ros_domain):
    """(install_base, env) of the session's colcon build; env is what sourcing the install's local_setup gives, in
    this test's DDS domain."""
    from crane_stiffness.launcher.rosrun import install_environment
    return colcon_install, install_environment(colcon_install)


@pytest.fixture(scope='session')
def colcon_install(tmp_path_factory):
    """A colcon build of this package (copied out of the work tree), as a real ROS workspace would have it: one per
    test run, the first test process to need it builds it while the others wait (pytest-xdist's workers share the
    parent of their base temporary directories)."""
    import fcntl
    import shutil

    from crane_stiffness.launcher.rosrun import colcon_build
    root = tmp_path_factory.getbasetemp()
    if 'PYTEST_XDIST_WORKER' in os.environ:
        root = root.parent
    ws = root / 'colcon_ws'
    with open(root / 'colcon_ws.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (ws / 'built').exists():
            shutil.rmtree(ws, ignore_errors=True)  # what a failed build in another process left
            src = ws / 'src' / 'crane_stiffness'
            shutil.copytree(REPO, src, ignore=shutil.ignore_patterns('.venv', '.git', 'build', 'install', 'log',
                                                                     'out', '__pycache__', 'bags', '*.egg-info'))
            colcon_build(src, ws / 'build', ws / 'install', ws / 'log')
            (ws / 'built').touch()
    return ws / 'install'


@pytest.fixture(scope='session')
def rig_host(colcon_install):
    """The simulated rig that stays up between sessions (crane_stiffness.launcher.host_process.HostProcess: every
    node of the rig in one process of its own, as ``campaign run`` runs sessions) in a domain of its own
    (HOST_DOMAIN), for the tests about a session's numbers; ``rig_host.run(share=..., out=..., program=..., ...)``
    gives a session's outcome. The rig of processes, as ``ros2 launch`` starts it, has tests of its own (launcher/),
    and test_rig_host pins the two to the same numbers and streams."""
    from crane_stiffness.launcher.host_process import HostProcess
    from crane_stiffness.launcher.rosrun import install_environment
    env = {**install_environment(colcon_install), 'ROS_DOMAIN_ID': str(HOST_DOMAIN)}
    with HostProcess(HOST_DOMAIN, env) as host:
        yield host


# --- Markers ---------------------------------------------------------------------------------------------------
# ``ros``: the test starts ROS (an rclpy context and nodes in this process, node processes, the genuine ros2 command
# line): DDS traffic, seconds to minutes each. `pytest -m "not ros" test` runs the pure tests alone. Every test using
# one of ROS_FIXTURES is marked here; modules of ROS tests only say so themselves (``pytestmark``), and the few
# others that start ROS without these fixtures (a node's main() in-process) carry the mark on the test.
ROS_FIXTURES = {'rclpy_context', 'install_tree', 'colcon_install', 'rig_host'}

# Tests that need an outside tool the project does not install drive it the way a user has it; without it they
# cannot run: they are left out and the run says so in one line per tool.
# ``genuine_cli``: the real `ros2` (ros2cli, launch, launch_ros), on PATH from a sourced setup file.
GENUINE_CLI = __import__('shutil').which('ros2')
# ``lichtblick``: a web build of Lichtblick (the open-source Foxglove app; not in any registry as a built app), the
# directory holding its index.html named by LICHTBLICK_WEB.
LICHTBLICK_WEB = os.environ.get('LICHTBLICK_WEB', '')
OUTSIDE_TOOLS = {
    'genuine_cli': (GENUINE_CLI, 'genuine ros2 CLI', 'not on PATH (source its setup file to run them)'),
    'lichtblick': (LICHTBLICK_WEB if os.path.isfile(os.path.join(LICHTBLICK_WEB, 'index.html')) else None,
                   'Lichtblick web build',
                   f'not found: LICHTBLICK_WEB={LICHTBLICK_WEB!r} holds no index.html' if LICHTBLICK_WEB
                   else 'not found (set LICHTBLICK_WEB to the directory of its index.html)'),
}
_NOT_RUN: dict[str, list[str]] = {marker: [] for marker in OUTSIDE_TOOLS}


def pytest_configure(config):
    config.addinivalue_line('markers', 'ros: starts ROS (rclpy nodes, node processes, DDS); deselect with -m "not ros"')
    config.addinivalue_line('markers', 'genuine_cli: drives the genuine ros2 CLI (needs `ros2` on PATH)')
    config.addinivalue_line('markers', 'lichtblick: opens the layouts in Lichtblick (needs LICHTBLICK_WEB)')


def pytest_itemcollected(item):
    if ROS_FIXTURES & set(item.fixturenames) or any(item.get_closest_marker(m) for m in OUTSIDE_TOOLS):
        item.add_marker(pytest.mark.ros)


@pytest.hookimpl(trylast=True)  # after -m and -k: what they left out is not reported as not run for want of a tool
def pytest_collection_modifyitems(config, items):
    left_out = []
    for marker, (found, _, _) in OUTSIDE_TOOLS.items():
        if not found:
            missing = [item for item in items if item.get_closest_marker(marker) is not None]
            _NOT_RUN[marker].extend(item.nodeid for item in missing)
            left_out += missing
    if left_out:
        config.hook.pytest_deselected(items=left_out)
        items[:] = [item for item in items if item not in left_out]
    items[:] = _long_ones_first(items, int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1')))


#: Tests that run a rig, a campaign or a cluster: tens of seconds each, where most take a fraction of one.
LONG_FIXTURES = {'rig_host', 'install_tree', 'colcon_install', 'ros_domains'}


def _long(item: pytest.Item) -> bool:
    return bool(LONG_FIXTURES & set(getattr(item, 'fixturenames', ()))) or 'campaign' in item.path.parts


def _long_ones_first(items: list[pytest.Item], workers: int) -> list[pytest.Item]:
    """``items`` with the long ones first in each of the ``workers`` runs of the order: pytest-xdist's worksteal gives
    each test process one contiguous share of the order (the first len // workers, ...) and idle processes take tests
    from the end of the others' shares, so the long tests start early, evenly shared, instead of ending the run one
    after another. The others keep their order (their module fixtures are made once per share)."""
    long_ones = [item for item in items if _long(item)]
    others = [item for item in items if not _long(item)]
    ordered: list[pytest.Item] = []
    remaining = len(items)
    for k in range(workers):
        size = remaining // (workers - k)  # as worksteal shares them out
        mine = long_ones[k::workers]
        take = max(0, size - len(mine))
        ordered += mine + others[:take]
        others = others[take:]
        remaining -= size
    return ordered + others


def pytest_sessionfinish(session):
    """A pytest-xdist worker sends what it left out for want of a tool to the controller, which reports it."""
    workeroutput = getattr(session.config, 'workeroutput', None)
    if workeroutput is not None:
        workeroutput['crane_stiffness_not_run'] = _NOT_RUN


@pytest.hookimpl(optionalhook=True)  # a pytest-xdist hook: absent when the tests run in one process
def pytest_testnodedown(node, error):
    """(pytest-xdist, in the controller) a worker's tests left out for want of a tool, for the summary."""
    for marker, ids in getattr(node, 'workeroutput', {}).get('crane_stiffness_not_run', {}).items():
        _NOT_RUN[marker].extend(i for i in ids if i not in _NOT_RUN[marker])


def pytest_terminal_summary(terminalreporter):
    for marker, (found, name, absent) in OUTSIDE_TOOLS.items():
        if _NOT_RUN[marker]:
            terminalreporter.write_line(f'{name} {absent}: {len(_NOT_RUN[marker])} check(s) not run: '
                                        + ', '.join(n.split('::')[-1] for n in _NOT_RUN[marker]))
        elif found:
            terminalreporter.write_line(f'{name}: {found}')


# --- the bag of the bag I/O tests (test_bag_io, test_bag_damage): one per module ---
@pytest.fixture(scope='module')
def messages():
    """Rig messages serialized by rclpy (helpers.bags.make_messages)."""
    from helpers.bags import make_messages
    return make_messages()


@pytest.fixture(scope='module')
def bag(tmp_path_factory, messages):
    """A bag of ``messages`` written by our writer, small chunks."""
    from helpers.bags import write_bag
    return write_bag(tmp_path_factory.mktemp('bags') / 'session', messages, chunk_size=16 * 1024)


@pytest.fixture(scope='session')
def chromium_path() -> str:
    """Debian's ``chromium`` for the page tests (helpers.browser); its absence fails them, never skips them."""
    from helpers.browser import chromium
    try:
        return chromium()
    except RuntimeError as exc:  # the check cannot be made without it: a failure, never a skip
        pytest.fail(f'headless Chromium is needed for the page test: {exc}')
