"""Start nodes the way ``ros2 run`` does, with or without the ros2 CLI installed.

``ros2 run PKG EXE`` finds PKG's prefix through the ament index (the first prefix in AMENT_PREFIX_PATH holding
``share/ament_index/resource_index/packages/PKG``) and executes ``<prefix>/lib/PKG/EXE``. :func:`command` performs
exactly that look-up and runs the executable itself, as ``ros2 launch`` does (launch starts a node's executable, not
``ros2 run``), so the demo and the tests start every node from the colcon install tree the same way with or without
a ROS install, and the signals they send reach the node, not a wrapper (the genuine ``ros2 run`` dies at once on
SIGTERM, leaving its node to end on its own). ``use_ros2_cli=True`` runs the genuine ``ros2 run`` instead.
``python -m crane_stiffness.launcher.rosrun PKG EXE [args]`` is the command-line form. :class:`Processes` runs a set
of such nodes and stops them cleanly.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

from crane_stiffness import PACKAGE
from crane_stiffness.errors import CraneStiffnessError


class RosRunError(CraneStiffnessError):
    """A package or executable that ``ros2 run`` would not find either."""


class RigStartError(RosRunError):
    """The rig did not start its program within the start-up timeout (a node DDS never matched, say): nothing was
    measured, so the session may simply be run again."""


class RigInterrupted(RosRunError):
    """The run was asked to stop (Ctrl-C in a campaign running sessions side by side) before its end."""


def package_prefix(package: str, ament_prefix_path: str | None = None) -> Path:
    """The first prefix of AMENT_PREFIX_PATH that registers ``package`` in its ament index."""
    paths = ament_prefix_path if ament_prefix_path is not None else os.environ.get('AMENT_PREFIX_PATH', '')
    for prefix in filter(None, paths.split(os.pathsep)):
        if (Path(prefix) / 'share' / 'ament_index' / 'resource_index' / 'packages' / package).is_file():
            return Path(prefix)
    raise RosRunError(f'Package {package!r} not found in AMENT_PREFIX_PATH={paths!r}')


def executable_path(package: str, executable: str, ament_prefix_path: str | None = None) -> Path:
    """``<prefix>/lib/<package>/<executable>`` as ``ros2 run`` resolves it."""
    prefix = package_prefix(package, ament_prefix_path)
    exe = prefix / 'lib' / package / executable
    if not (exe.is_file() and os.access(exe, os.X_OK)):
        raise RosRunError(f'No executable {executable!r} found in {prefix / "lib" / package}')
    return exe


def command(package: str, executable: str, args: Sequence[str] = (), env: Mapping[str, str] | None = None,
            use_ros2_cli: bool = False) -> list[str]:
    """argv that runs a node like ``ros2 run package executable args...``: the executable itself, or with
    ``use_ros2_cli`` the genuine ``ros2 run`` (which must be on PATH)."""
    if use_ros2_cli:
        return ['ros2', 'run', package, executable, *args]
    apath = (env or os.environ).get('AMENT_PREFIX_PATH', '')
    return [str(executable_path(package, executable, apath)), *args]


def install_environment(install_base: str | os.PathLike, package: str = PACKAGE,
                        base: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment ``source install/local_setup.sh`` would give for an isolated colcon install of package:
    its prefix first in AMENT_PREFIX_PATH and its site-packages first on PYTHONPATH."""
    env = dict(os.environ if base is None else base)
    prefix = Path(install_base).resolve() / package
    site = prefix / 'lib' / f'python{sys.version_info.major}.{sys.version_info.minor}' / 'site-packages'
    env['AMENT_PREFIX_PATH'] = os.pathsep.join(filter(None, [str(prefix), env.get('AMENT_PREFIX_PATH', '')]))
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(site), env.get('PYTHONPATH', '')]))
    return env


def colcon_build(source: str | os.PathLike, build_base: str | os.PathLike, install_base: str | os.PathLike,
                 log: str | os.PathLike) -> None:
    """``colcon build`` of the package at ``source`` (raises CalledProcessError with colcon's output)."""
    colcon = Path(sys.executable).parent / 'colcon'
    env = dict(os.environ, COLCON_LOG_PATH=str(log))
    subprocess.run([str(colcon if colcon.exists() else 'colcon'), 'build', '--paths', str(source),
                    '--build-base', str(build_base), '--install-base', str(install_base)],
                   cwd=str(source), env=env, check=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                   text=True)


def installed_config(install_base: str | os.PathLike, package: str = PACKAGE) -> Path:
    """The package's installed ``config/`` in an isolated colcon install (``share/<package>/config``)."""
    return Path(install_base) / package / 'share' / package / 'config'


def build_workspace(source: str | os.PathLike, ws: str | os.PathLike) -> tuple[dict[str, str], Path]:
    """``colcon build`` of ``source`` into ``ws/{build,install,log}``: (the install's environment, its config
    directory)."""
    ws = Path(ws)
    colcon_build(source, ws / 'build', ws / 'install', ws / 'log')
    return install_environment(ws / 'install'), installed_config(ws / 'install')


class Processes:
    """Nodes started as separate processes; ``stop()`` (or leaving the ``with``) sends SIGINT like Ctrl-C, then
    SIGTERM, then SIGKILL to what is still running. stdout and stderr go to ``<log_dir>/<name>.log``.

    By default every node runs in a session of its own. With ``process_group=True`` all of them join one process
    group, as the nodes of ``ros2 launch`` in a terminal do: its leader is a stand-in for the launch process (a
    ``sleep``), and :meth:`signal_group` sends a signal to the whole group like Ctrl-C in that terminal.
    """

    def __init__(self, env: Mapping[str, str], log_dir: str | os.PathLike, process_group: bool = False,
                 executables: str | os.PathLike | None = None) -> None:
        self.env = dict(env)
        #: Where the node executables are when they are not in an ament prefix's lib/<package> (the venv's bin/ of a
        #: pip install: :func:`node_executables`); None = as ``ros2 run`` finds them.
        self.executables = None if executables is None else Path(executables)
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.procs: dict[str, subprocess.Popen] = {}
        self.leader: subprocess.Popen | None = None
        if process_group:
            self.leader = subprocess.Popen(['sleep', 'infinity'], stdin=subprocess.DEVNULL,
                                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                           process_group=0)  # a new group in this session: others may join it

    @property
    def pgid(self) -> int | None:
        """The shared process group (``process_group=True``), else None."""
        return None if self.leader is None else self.leader.pid

    def signal_group(self, sig: int) -> None:
        """``sig`` to every process of the shared group at once (the launch stand-in included), like Ctrl-C."""
        if self.pgid is None:
            raise RosRunError('signal_group needs Processes(..., process_group=True)')
        os.killpg(self.pgid, sig)

    def _signal(self, proc: subprocess.Popen, sig: int) -> None:
        try:
            if self.leader is None:
                os.killpg(proc.pid, sig)  # the node's own session: the node and anything it started
            else:
                proc.send_signal(sig)
        except ProcessLookupError:
            pass

    def start(self, name: str, package: str, executable: str, args: Sequence[str] = ()) -> subprocess.Popen:
        if self.executables is not None:
            return self._popen(name, [str(self.executables / executable), *args], self.env)
        return self._popen(name, command(package, executable, args, self.env), self.env)

    def _popen(self, name: str, argv: Sequence[str], env: Mapping[str, str]) -> subprocess.Popen:
        """Start ``argv`` as node ``name`` (log ``<log_dir>/<name>.log``, own session or the shared group)."""
        log = open(self.log_dir / f'{name}.log', 'w')
        group: dict[str, Any] = ({'start_new_session': True} if self.leader is None  # Popen keywords
                                 else {'process_group': self.leader.pid})
        proc = subprocess.Popen(argv, env=env, stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, **group)
        log.close()
        self.procs[name] = proc
        return proc

    def log(self, name: str) -> str:
        return (self.log_dir / f'{name}.log').read_text(errors='replace')

    def check_alive(self, allow_exit: Sequence[str] = ()) -> None:
        """Raise with the log tail if a node has exited on its own (nodes in allow_exit may exit with status 0)."""
        for name, p in self.procs.items():
            if p.poll() is not None and not (name in allow_exit and p.returncode == 0):
                raise RosRunError(f'node {name} exited with status {p.returncode}:\n{self.log(name)[-2000:]}')

    def stop(self, timeout_s: float = 10.0, names: Sequence[str] | None = None) -> dict[str, int]:
        """Stop the named nodes (default all); returns every node's exit status so far (None if running)."""
        chosen = [p for n, p in self.procs.items() if names is None or n in names]
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            running = [p for p in chosen if p.poll() is None]
            for p in running:
                self._signal(p, sig)
            deadline = time.monotonic() + timeout_s
            while any(p.poll() is None for p in running) and time.monotonic() < deadline:
                time.sleep(0.05)
        if self.leader is not None and names is None and self.leader.poll() is None:
            self.leader.kill()
            self.leader.wait()
        return {name: p.returncode for name, p in self.procs.items()}

    def __enter__(self) -> 'Processes':
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def node_executables(package: str = PACKAGE, probe: str = 'crane_model') -> Path | None:
    """Where this installation's node executables are: None when ``ros2 run`` finds them (an ament prefix's
    lib/<package>, a colcon workspace), else the directory beside this interpreter (``.venv/bin`` of a pip install,
    which registers the package in the venv's ament index but puts its scripts on PATH). RosRunError if neither."""
    try:
        executable_path(package, probe)
        return None
    except RosRunError:
        pass
    here = Path(sys.prefix) / 'bin'
    if (here / probe).is_file():
        return here
    raise RosRunError(f'no {probe} executable in an ament prefix (AMENT_PREFIX_PATH) nor in {here}: run `make '
                      'install`, or source a workspace holding the package')


def start_installed(executable: str, args: Sequence[str], log: str | os.PathLike) -> subprocess.Popen:
    """The executable installed beside this interpreter (``.venv/bin``: a node, ``crane-stiffness``) in a session of
    its own, its output to ``log``."""
    exe = Path(sys.prefix) / 'bin' / executable
    if not exe.exists():
        raise RosRunError(f'{exe} missing: run `make install` first')
    with open(log, 'w') as out:
        return subprocess.Popen([str(exe), *args], stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                start_new_session=True)


def interrupt(proc: subprocess.Popen, timeout_s: float = 10.0) -> int:
    """Ctrl-C for a process started in a session of its own: SIGINT to its group, SIGKILL after ``timeout_s``; its
    exit status."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return proc.returncode


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) < 2:
        print('usage: python -m crane_stiffness.launcher.rosrun PACKAGE EXECUTABLE [args...]', file=sys.stderr)
        return 2
    try:
        exe = executable_path(argv[0], argv[1])
    except RosRunError as exc:
        print(exc, file=sys.stderr)
        return 1
    os.execv(str(exe), [str(exe), *argv[2:]])
    return 0  # not reached


if __name__ == '__main__':
    sys.exit(main())
