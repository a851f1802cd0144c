"""A small cluster of machines as Linux network namespaces: a hub (the Dask scheduler and the campaign's client)
and one namespace per worker, each joined to the hub by a veth pair of its own. Used by the campaign cluster test.

Each link is a /30 of ``subnet`` (private, 10.x) that exists only inside the namespaces; workers reach the hub,
and the hub reaches every worker (the client fetches a session's result from the worker that ran it), but the
workers do not reach each other (their sessions need nothing from each other). Every namespace has its own
loopback, so the rigs of two workers never meet on DDS whatever their domains. :meth:`StarNetwork.kill` ends every
process of a namespace at once: a machine lost. Needs root (CAP_SYS_ADMIN, CAP_NET_ADMIN).
"""
from __future__ import annotations

import os
import signal
import subprocess
import uuid
from typing import Sequence

from crane_stiffness.testing.lab_network import LabNetworkError, NetworkNamespaces, _ip


class StarNetwork(NetworkNamespaces):
    """Namespaces ``hub`` and ``leaves`` (names given), leaf ``i`` linked to the hub over ``10.x.y.(4i+1)`` (hub
    end) and ``10.x.y.(4i+2)`` (leaf end). A context manager: ``__exit__`` ends every process left in them and
    removes them (the veth pairs go with them)."""

    def __init__(self, leaves: Sequence[str], subnet: str = '10.213.48.0') -> None:
        if not 1 <= len(leaves) <= 60:
            raise LabNetworkError(f'leaves = {list(leaves)!r}: 1 to 60 of them')
        tag = uuid.uuid4().hex[:6]
        base = subnet.rsplit('.', 1)[0]
        self.namespaces = {'hub': f'cs_hub_{tag}', **{leaf: f'cs_{leaf}_{tag}' for leaf in leaves}}
        self.leaves = list(leaves)
        self.hub_address = {leaf: f'{base}.{4 * i + 1}' for i, leaf in enumerate(leaves)}
        self.address = {leaf: f'{base}.{4 * i + 2}' for i, leaf in enumerate(leaves)}
        self._links = {leaf: (f'csh{i}{tag}', f'csl{i}{tag}') for i, leaf in enumerate(leaves)}
        super().__init__()

    def create(self) -> 'StarNetwork':
        for name in self.namespaces.values():
            _ip('netns', 'add', name)
            self.made.append(name)
            _ip('-n', name, 'link', 'set', 'lo', 'up')
        hub = self.namespaces['hub']
        for leaf in self.leaves:
            hub_end, leaf_end = self._links[leaf]
            _ip('link', 'add', hub_end, 'netns', hub, 'type', 'veth', 'peer', 'name', leaf_end, 'netns',
                self.namespaces[leaf])
            _ip('-n', hub, 'addr', 'add', f'{self.hub_address[leaf]}/30', 'dev', hub_end)
            _ip('-n', self.namespaces[leaf], 'addr', 'add', f'{self.address[leaf]}/30', 'dev', leaf_end)
            _ip('-n', hub, 'link', 'set', hub_end, 'up')
            _ip('-n', self.namespaces[leaf], 'link', 'set', leaf_end, 'up')
        return self

    def run(self, machine: str, argv: Sequence[str]) -> list[str]:
        """``argv`` as run inside ``machine``'s namespace (``ip netns exec``, which execs it: signals reach it)."""
        return ['ip', 'netns', 'exec', self.namespaces[machine], *argv]

    def pids(self, machine: str) -> list[int]:
        """The processes running in ``machine``'s namespace."""
        out = subprocess.run(['ip', 'netns', 'pids', self.namespaces[machine]], capture_output=True, text=True,
                             timeout=20)
        return [int(p) for p in out.stdout.split()]

    def kill(self, machine: str) -> list[int]:
        """SIGKILL to every process of ``machine`` at once (the machine lost); the pids killed."""
        pids = self.pids(machine)
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        return pids

    def remove(self) -> list[str]:
        """End what runs in the namespaces, then remove them; the errors, if any."""
        for machine, name in self.namespaces.items():
            if name in self.made:
                self.kill(machine)
        return super().remove()


__all__ = ['StarNetwork']
