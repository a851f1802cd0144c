"""Start-up of the rig the way the tools start it: every process at the same instant from a fresh
install tree, cold (no compiled-kernel cache) or warm; the launch file's refusals; the compiled-kernel cache."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import PATIENCE_S, REPO as _REPO
from helpers.processes import final_counters

from crane_stiffness.contract import topics
from crane_stiffness.launcher.rig_description import RigError, rig_nodes
from crane_stiffness.launcher import rosrun
from crane_stiffness.launcher.rig import Observer, run_rig, start_node, wait_for_program_start

KERNEL_CACHE = ('*.nbi', '*.nbc')


def _site(install: Path) -> Path:
    return install / 'crane_stiffness' / 'lib' / f'python{sys.version_info.major}.{sys.version_info.minor}' / \
        'site-packages'


def _share(install: Path) -> Path:
    return rosrun.installed_config(install)


def _cache_files(install: Path) -> list[Path]:
    model = _site(install) / 'crane_stiffness' / 'model' / '__pycache__'
    return [p for pattern in KERNEL_CACHE for p in model.glob(pattern)]


@pytest.fixture
def cold_install(colcon_install, tmp_path, ros_domain):
    """A fresh copy of the colcon install tree with no compiled-kernel cache: what a build without the cache step
    (an install tree without the kernel cache) gives, so crane_model compiles its kernels for ~15 s at start."""
    install = tmp_path / 'install'
    shutil.copytree(colcon_install, install, ignore=shutil.ignore_patterns(*KERNEL_CACHE), symlinks=True)
    assert not _cache_files(install)
    return install, rosrun.install_environment(install)


def test_colcon_build_installs_the_compiled_kernels_and_a_node_loads_them(install_tree):
    """The cache is made at build time beside the installed modules, and is valid there: a fresh process
    running crane_model's start-up work compiles nothing."""
    install, env = install_tree
    assert _cache_files(install), 'colcon build left no compiled kernels in the install tree'
    code = ('import json, numpy as np\n'
            'from crane_stiffness.model import lab_model, rest_pose, solve_equilibrium, tangent_stiffness, '
            'axis_stiffness\n'
            'from crane_stiffness.model.kernel_cache import cache_report\n'
            'g = lab_model(0.5, 50.0); eq = solve_equilibrium(g, load=np.array([0, 1.6, 0, 0, 0, 0.]), '
            'initial=rest_pose(g))\n'
            'axis_stiffness(tangent_stiffness(g, eq), "fy")\n'
            'print(json.dumps(cache_report()))\n')
    out = subprocess.run([sys.executable, '-c', code], env=env, cwd=str(install), capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert sum(r['misses'] for r in report.values()) == 0, report
    assert sum(r['hits'] for r in report.values()) >= 2, report


def _run_rig(install: Path, env: dict, tmp_path: Path, program: str = 'side_force', record: bool = True,
             ready_timeout_s: float = 120.0) -> tuple[dict, Observer, float, dict]:
    """Every node of rig.launch.py started at once (crane_stiffness.launcher.rig.run_rig)."""
    return run_rig(_share(install), env, tmp_path, program, session='startup', record=record,
                   ready_timeout_s=ready_timeout_s)


def _check_run(summary: dict, observer: Observer, logs: dict) -> None:
    # The program started only after the model's prediction was there (load_program's own account: an observer's
    # arrival times of two topics from two publishers say nothing of the order load_program saw them in) ...
    assert observer.predicted_at is not None and observer.running_at is not None
    assert 'rig ready after' in logs['load_program'], logs['load_program'][-3000:]
    # ... crane_model received every command ...
    sent = final_counters(logs['load_program'])['published']
    received = final_counters(logs['crane_model'])['received']
    # (The program's 100 Hz timer skips ticks when the machine is starved of CPU: ~1,650-2,100 commands in 21 s.)
    assert sent > 1000 and received == sent, (sent, received)
    # ... and the estimate is the model's.
    assert abs(summary['relative_error']) < 0.02, summary['estimate']['loading']
    assert all(code == 0 for code in summary['node_exit_codes'].values()), summary['node_exit_codes']


def test_cold_launch_all_nodes_at_once_waits_for_the_model(cold_install, tmp_path):
    """Every process started at the same instant from a fresh install tree with no compiled
    kernels; crane_model compiles for many seconds while the sensors, the estimator and the recorder are up."""
    install, env = cold_install
    summary, observer, started_after, logs = _run_rig(install, env, tmp_path)
    _check_run(summary, observer, logs)
    assert _cache_files(install), 'crane_model did not compile its kernels (was the start really cold?)'
    assert summary['bag'] is not None


def test_ros2_run_in_any_order_model_last(install_tree, tmp_path):
    """`ros2 run` by hand: load_program first, the model last and late; nothing starts before it, nothing is lost."""
    import rclpy
    install, env = install_tree
    share = _share(install)
    program = tmp_path / 'short.yaml'
    program.write_text('load_program:\n  ros__parameters:\n    name: short\n    rate_hz: 100.0\n'
                       '    segments.kind: [hold, ramp, hold, ramp]\n    segments.axis: [fy, fy, fy, fy]\n'
                       '    segments.target: [0.0, 2.0, 2.0, 0.0]\n    segments.duration: [0.5, 1.0, 0.5, 1.0]\n')
    nodes = {n.name: n for n in rig_nodes(share, {'program': str(program), 'record': False})}
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    observer = Observer(context=ctx)
    try:
        with rosrun.Processes(env, tmp_path / 'logs') as procs:
            order = ['load_program', 'stiffness_estimator', 'lvdt', 'load_cell', 'crane_model']
            for name in order:
                start_node(procs, nodes[name], {'exit_on_done': True, 'ready_log_period_s': 1.0}
                           if name == 'load_program' else None)
                if name == 'load_cell':
                    end = time.monotonic() + 4.0  # the model comes late: nothing may start meanwhile
                    while time.monotonic() < end:
                        observer.spin_once(0.05)
                    assert observer.running_at is None and not observer.state
            wait_for_program_start(observer, procs, PATIENCE_S)
            deadline = time.monotonic() + PATIENCE_S
            while procs.procs['load_program'].poll() is None and time.monotonic() < deadline:
                observer.spin_once(0.1)
            codes = procs.stop()
            logs = {name: procs.log(name) for name in order}
    finally:
        observer.destroy_node()
        rclpy.shutdown(context=ctx)
    assert codes['load_program'] == 0, logs['load_program'][-3000:]
    assert 'waiting (' in logs['load_program'] and 'crane_model subscribed to /crane/wrench_command' in \
        logs['load_program']
    sent = final_counters(logs['load_program'])['published']
    received = final_counters(logs['crane_model'])['received']
    # The program ran to its end (how many of its 300 ticks a starved timer sent is a speed question, benchmarks/'s);
    # the model got every command sent.
    assert "' finished" in logs['load_program'] and sent > 0 and received == sent, (sent, received)
    # Nothing started while the model was missing (checked above); load_program says when it found the rig ready.
    assert 'rig ready after' in logs['load_program'] and observer.predicted_at is not None


def test_load_program_gives_up_naming_what_never_came(install_tree, tmp_path):
    """The rig without crane_model: load_program exits non-zero after ready_timeout_s, naming the model."""
    install, env = install_tree
    nodes = [n for n in rig_nodes(_share(install), {'record': False}) if n.name != 'crane_model']
    with rosrun.Processes(env, tmp_path / 'logs') as procs:
        for node in nodes:
            if not node.runs_program:
                start_node(procs, node)
        # The estimator up first (on a loaded machine it can take longer than the timeout to start), so that the
        # program's give-up line must leave it out.
        deadline = time.monotonic() + PATIENCE_S
        while 'fitting' not in procs.log('stiffness_estimator'):
            assert time.monotonic() < deadline, procs.log('stiffness_estimator')
            procs.check_alive()
            time.sleep(0.1)
        t0 = time.monotonic()
        for node in nodes:
            if node.runs_program:
                start_node(procs, node, {'ready_timeout_s': 6.0, 'ready_log_period_s': 2.0})
        program = procs.procs['load_program']
        while program.poll() is None and time.monotonic() < t0 + PATIENCE_S:
            time.sleep(0.1)
        waited = time.monotonic() - t0
        procs.stop()
        log = procs.log('load_program')
    assert program.returncode == 1, log
    gave_up = next(line for line in log.splitlines() if 'gave up' in line)
    # Not before ready_timeout_s; and by its own clock (its start-up, slow on a loaded machine, not counted) soon after.
    assert waited >= 6.0, waited
    assert 6 <= int(re.search(r'gave up after (\d+) s', gave_up).group(1)) < 40, gave_up
    assert 'crane_model subscribed to /crane/wrench_command' in gave_up
    assert f"{topics.PREDICTED_AXIS_STIFFNESS} from crane_model (the model's prediction): is it running?" in gave_up
    assert 'stiffness_estimator subscribed' not in gave_up  # it was there (its values, from no sensor, never came)
    # While it waited it said what it waited for, one line each.
    assert any('waiting (' in line and 'crane_model subscribed' in line for line in log.splitlines())
    assert 'program did not start' in gave_up and '"state": "running"' not in log


def test_load_program_rejects_a_malformed_wait_entry(install_tree, tmp_path):
    _, env = install_tree
    argv = rosrun.command('crane_stiffness', 'load_program',
                          ['--ros-args', '-p', 'wait_for_subscribers:=["/crane/wrench_command crane_model"]'],
                          env, use_ros2_cli=False)
    out = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=PATIENCE_S)
    assert out.returncode == 2 and 'wait_for_subscribers' in out.stderr and 'TOPIC: NODE' in out.stderr


def test_launch_file_fails_at_once_for_an_unknown_program_or_a_missing_file(tmp_path):
    """What rig.launch.py evaluates (rig_description.rig_nodes): a bad argument fails before any node starts."""
    config = _REPO / 'config'
    # every program_<name>.yaml of config/, listed by name (the series' programs and the campaigns' short ones)
    names = sorted(p.name[len('program_'):-len('.yaml')] for p in config.glob('program_*.yaml'))
    assert {'force_z', 'moment_z', 'side_force', 'side_force_slack', 'campaign_side_force'} <= set(names)
    with pytest.raises(RigError, match=r"unknown program 'bogus': no file .*program_bogus\.yaml; known programs: "
                                       + re.escape(', '.join(names))):
        rig_nodes(config, {'program': 'bogus'})
    missing = tmp_path / 'my_crane.yaml'
    with pytest.raises(RigError, match=f'crane file {missing} not found'):
        rig_nodes(config, {'crane': str(missing)})
    with pytest.raises(RigError, match='program file .*nope.yaml not found'):
        rig_nodes(config, {'program': str(tmp_path / 'nope.yaml')})
    # The launch file passes load_program what to wait for, for the nodes it starts.
    program = next(n for n in rig_nodes(config, {'record': 'false'}) if n.name == 'load_program')
    waits = program.parameters
    assert waits['wait_for_messages'] == [topics.PREDICTED_AXIS_STIFFNESS, topics.LOAD_CELL_WRENCH,
                                          topics.LVDT_DISPLACEMENT, topics.STIFFNESS_VALUES]  # the estimator pairing
    assert not any('session_recorder' in entry for entry in waits['wait_for_subscribers'])
    assert f'{topics.WRENCH_COMMAND}: crane_model stiffness_estimator' in waits['wait_for_subscribers']
    # The load cell applies the load crane_model has in force, never the raw command.
    assert f'{topics.APPLIED_WRENCH}: load_cell' in waits['wait_for_subscribers']


def test_colcon_build_copies_the_kernels_compiled_for_the_same_sources(colcon_install):
    """The install tree's cache is this interpreter's installation's (make install's .venv), copied when the
    package's Python files are the same: numba keys it by their contents, so it is loaded there as compiled (the
    test above)."""
    import sysconfig

    from crane_stiffness.model import kernel_cache
    venv = Path(sysconfig.get_paths()['purelib']) / 'crane_stiffness'
    built = _site(colcon_install) / 'crane_stiffness'
    venv_cache = venv / 'model' / '__pycache__'
    if not list(venv_cache.glob('*.nbi')) or kernel_cache._sources(venv) != kernel_cache._sources(built):
        pytest.fail(f'{venv} is not the package built here, or has no compiled kernels: run make install (make test '
                    'does it first)')
    installed = {p.name: p.read_bytes() for p in _cache_files(colcon_install)}
    assert installed and set(installed) == {p.name for pattern in KERNEL_CACHE for p in venv_cache.glob(pattern)}
    for name, data in installed.items():
        assert (venv_cache / name).read_bytes() == data, name


def test_kernel_cache_is_copied_only_between_identical_sources(tmp_path):
    """seed() copies nothing when any Python file of the package differs (a kernel compiled into another would be
    stale), and everything when all are the same."""
    from crane_stiffness.model import kernel_cache
    src, dst = tmp_path / 'a' / 'crane_stiffness', tmp_path / 'b' / 'crane_stiffness'
    for root in (src, dst):
        (root / 'model').mkdir(parents=True)
        (root / 'model' / '_kernels.py').write_text('K = 1\n')
        (root / 'other.py').write_text('X = 1\n')
    (src / 'model' / '__pycache__').mkdir()
    (src / 'model' / '__pycache__' / '_kernels.f-3.py311.nbi').write_bytes(b'index')
    (src / 'model' / '__pycache__' / '_kernels.f-3.py311.1.nbc').write_bytes(b'code')
    (dst / 'other.py').write_text('X = 2\n')
    assert kernel_cache.seed(tmp_path / 'a', tmp_path / 'b') == 0
    assert not (dst / 'model' / '__pycache__').exists()
    (dst / 'other.py').write_text('X = 1\n')
    assert kernel_cache.seed(tmp_path / 'a', tmp_path / 'b') == 2
    assert (dst / 'model' / '__pycache__' / '_kernels.f-3.py311.1.nbc').read_bytes() == b'code'
