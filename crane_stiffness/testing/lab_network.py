"""The rig through the drivers (``transport:=drivers``) as processes, and the lab network of two machines as two
Linux network namespaces joined by a veth pair. Used by test_rig_drivers, test_lab_network and bench_rig.

:func:`start_rig_with` starts the nodes :func:`crane_stiffness.launcher.rig_description.rig_nodes` gives for any rig
arguments (the demo's :func:`crane_stiffness.launcher.rig.start_rig` takes only program/record/session), each the
way ``ros2 run`` starts it. :func:`emulated_ports` picks free loopback ports for the emulators and points the
drivers at them, so runs side by side on one machine do not meet on the fixed ports of config/drivers_emulated.yaml.

:class:`LabNetwork` makes two network namespaces ("daq" and "analysis", unique names) and a veth pair between
them with addresses from a private /30 that exists only inside them, and removes all of it again;
:class:`NamespacedProcesses` starts each node inside the namespace of its machine (``ip netns exec``; it execs the
node, so the signals of ``stop()`` reach the node itself). Needs root (CAP_SYS_ADMIN, CAP_NET_ADMIN).
"""
from __future__ import annotations

import os
import socket
import subprocess
import uuid
from pathlib import Path
from typing import Any, Mapping, Sequence

from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.launcher.rig_description import PACKAGE, NodeStart, rig_nodes
from crane_stiffness.sim.program import LoadProgram, load_program_file
from crane_stiffness.launcher.ports import free_port
from crane_stiffness.launcher.rig import start_nodes
from crane_stiffness.launcher.rosrun import Processes, command


class LabNetworkError(CraneStiffnessError):
    """The namespaces or the veth pair cannot be made here (with the command and its error)."""


def emulated_ports(host: str = '127.0.0.1') -> dict[str, dict[str, Any]]:
    """Per-node parameter overrides: free ports for rdt_emulator (UDP RDT, TCP /netftapi2.xml) and
    modbus_emulator (TCP), the drivers pointed at them; every device on ``host``."""
    rdt, http, modbus = free_port(host=host, kind=socket.SOCK_DGRAM), free_port(host=host), free_port(host=host)
    return {'rdt_emulator': {'host': host, 'port': rdt, 'http_port': http},
            'netft': {'host': host, 'port': rdt, 'http_port': http},
            'modbus_emulator': {'host': host, 'port': modbus},
            'modbus_lvdt': {'host': host, 'port': modbus}}


def start_rig_with(procs: Processes, share: Path, given: Mapping[str, Any], bags: Path | None = None,
                   ready_timeout_s: float = 60.0, overrides: Mapping[str, Mapping[str, Any]] | None = None,
                   start_program: bool = True) -> tuple[LoadProgram, list[NodeStart]]:
    """Start every node of the rig for the rig arguments ``given`` at the same instant, as ``ros2 launch
    crane_stiffness rig.launch.py <given>`` does (load_program waits until the rig is ready, at most
    ``ready_timeout_s``, and exits when the program is done). ``bags``: the recorder's output directory.
    ``overrides``: extra parameters by node name. ``start_program`` False leaves load_program out (the caller
    starts it later). Returns the program and the nodes (of rig_nodes) started."""
    nodes = rig_nodes(share, given)
    program = next(n for n in nodes if n.runs_program)
    prog = load_program_file(program.parameter_files[0])
    start_nodes(procs, nodes, bags, ready_timeout_s, overrides, start_program)
    return prog, nodes


def _ip(*args: str) -> str:
    """``ip args...``; LabNetworkError with the command and its error when it fails."""
    try:
        out = subprocess.run(['ip', *args], capture_output=True, text=True, timeout=20)
    except FileNotFoundError:
        raise LabNetworkError('the `ip` command (iproute2) is not installed: cannot make network namespaces') from None
    if out.returncode != 0:
        raise LabNetworkError(f'`ip {" ".join(args)}` failed (exit {out.returncode}): {out.stderr.strip()}'
                              + (' - network namespaces need root (CAP_SYS_ADMIN and CAP_NET_ADMIN)'
                                 if os.geteuid() != 0 else ''))
    return out.stdout


class NetworkNamespaces:
    """Network namespaces made by a test (``made``: their names, in order) and removed again: a context manager whose
    ``__exit__`` removes them even when making them failed half-way. Subclasses make them in :meth:`create`."""

    def __init__(self) -> None:
        self.made: list[str] = []

    def create(self) -> 'NetworkNamespaces':
        raise NotImplementedError

    def remove(self) -> list[str]:
        """Remove the namespaces made (their veth pairs go with them); returns the errors, if any."""
        errors = []
        for name in reversed(self.made):
            try:
                _ip('netns', 'del', name)
            except LabNetworkError as exc:
                errors.append(str(exc))
        self.made = []
        return errors

    def __enter__(self) -> Any:
        try:
            return self.create()
        except BaseException:
            self.remove()
            raise

    def __exit__(self, *exc: object) -> None:
        self.remove()


class LabNetwork(NetworkNamespaces):
    """Two network namespaces, ``daq`` and ``analysis``, joined by a veth pair: ``daq_address`` on one end,
    ``analysis_address`` on the other, a /30 of ``subnet`` (private, 10.x) that exists only inside the namespaces;
    each namespace has its loopback up and a multicast route on its veth end (DDS discovery by multicast needs
    one). Names are unique (a random suffix). Use as a context manager: ``__exit__`` removes both namespaces (the
    veth pair goes with them) even when making them failed half-way."""

    def __init__(self, subnet: str = '10.213.47.0') -> None:
        tag = uuid.uuid4().hex[:6]
        self.namespaces = {'daq': f'cs_daq_{tag}', 'analysis': f'cs_ana_{tag}'}
        self.links = {'daq': f'csd{tag}', 'analysis': f'csa{tag}'}
        base = subnet.rsplit('.', 1)[0]
        self.addresses = {'daq': f'{base}.1', 'analysis': f'{base}.2'}
        super().__init__()

    @property
    def daq_address(self) -> str:
        return self.addresses['daq']

    @property
    def analysis_address(self) -> str:
        return self.addresses['analysis']

    def create(self) -> 'LabNetwork':
        for name in self.namespaces.values():
            _ip('netns', 'add', name)
            self.made.append(name)
        d, a = self.namespaces['daq'], self.namespaces['analysis']
        _ip('link', 'add', self.links['daq'], 'netns', d, 'type', 'veth', 'peer', 'name', self.links['analysis'],
            'netns', a)
        for machine, ns in self.namespaces.items():
            link = self.links[machine]
            _ip('-n', ns, 'addr', 'add', f'{self.addresses[machine]}/30', 'dev', link)
            _ip('-n', ns, 'link', 'set', 'lo', 'up')
            _ip('-n', ns, 'link', 'set', link, 'up')
            _ip('-n', ns, 'route', 'add', '224.0.0.0/4', 'dev', link)  # where DDS's multicast discovery goes
        return self

    def link_bytes(self, machine: str) -> dict[str, int]:
        """rx/tx byte counters of ``machine``'s veth end (what crossed the 'network')."""
        out = _ip('-n', self.namespaces[machine], '-s', '-o', 'link', 'show', self.links[machine])
        # -o: "... RX: bytes packets ... \    <rx bytes> <rx packets> ... \    TX: ... \    <tx bytes> ..."
        parts = [p.split() for p in out.split('\\')]
        rx = next(i for i, p in enumerate(parts) if p and p[0].startswith('RX'))
        tx = next(i for i, p in enumerate(parts) if p and p[0].startswith('TX'))
        return {'rx_bytes': int(parts[rx + 1][0]), 'tx_bytes': int(parts[tx + 1][0])}



class NamespacedProcesses(Processes):
    """:class:`Processes` whose nodes run inside network namespaces: ``namespace_of[name]`` (by node name) or
    ``default_namespace``; each node gets ``env`` updated with ``env_of[namespace]`` (e.g. the DDS discovery
    switch, which must be set only inside the namespaces)."""

    def __init__(self, env: Mapping[str, str], log_dir: str | os.PathLike, namespace_of: Mapping[str, str],
                 env_of: Mapping[str, Mapping[str, str]] | None = None, default_namespace: str | None = None) -> None:
        super().__init__(env, log_dir)
        self.namespace_of = dict(namespace_of)
        self.env_of = {k: dict(v) for k, v in (env_of or {}).items()}
        self.default_namespace = default_namespace

    def start(self, name: str, package: str, executable: str, args: Sequence[str] = ()) -> subprocess.Popen:
        ns = self.namespace_of.get(name, self.default_namespace)
        if ns is None:
            raise LabNetworkError(f'no network namespace for node {name}')
        env = {**self.env, **self.env_of.get(ns, {})}
        return self._popen(name, ['ip', 'netns', 'exec', ns, *command(package, executable, args, env)], env)


__all__ = ['LabNetwork', 'LabNetworkError', 'NetworkNamespaces', 'NamespacedProcesses', 'emulated_ports',
           'free_port', 'start_rig_with', 'PACKAGE']
