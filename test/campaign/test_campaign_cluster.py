"""`crane-stiffness campaign run --scheduler` on a real Dask cluster: a scheduler and two workers as separate
processes, each worker on a machine of its own (a network namespace: its own loopback, so its rigs' DDS stays on
it), the campaign's client beside the scheduler. One worker's machine is lost in the middle of a session (every
process in it killed at once): the campaign still completes, each session exactly once, with the same numbers and
the same recorded streams as the same campaign run on one machine. Needs root (network namespaces)."""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from crane_stiffness.bag import BagReader
from crane_stiffness.launcher.ports import free_port
from crane_stiffness.testing.cluster_network import StarNetwork

pytestmark = pytest.mark.ros  # every test here starts the rig's nodes

BIN = Path(sys.prefix) / 'bin'
SESSIONS = ['fy_W25_l0.5_r1', 'fy_W25_l1.5_r1', 'fy_W50_l0.5_r1', 'fy_W50_l1.5_r1', 'fy_W100_l0.5_r1',
            'fy_W100_l1.5_r1']
#: The recorded streams compared message by message: the sensors and the commands.
STREAMS = ('/load_cell/wrench', '/lvdt/displacement', '/crane/wrench_command')
#: The numbers of each branch's final estimate that simulated time fixes (the run's last status and the window's
#: nonlinearity depend on how long after the program's end the rig ran, as test_sim_time says).
FIT = ('stiffness', 'intercept', 'stderr', 'ci95_low', 'ci95_high', 'r2', 'n', 'rls_stiffness', 'prediction')
MS = 1_000_000


def campaign_file(tmp_path: Path) -> Path:
    path = tmp_path / 'six.yaml'
    path.write_text('campaign:\n  ros__parameters:\n    name: six\n    series: [fy]\n'
                    '    programs: [campaign_side_force]\n    weights: [25.0, 50.0, 100.0]\n'
                    '    lengths: [0.5, 1.5]\n    seed: 7\n')
    return path


def streams(bag: Path) -> dict[str, list[tuple[int, bytes]]]:
    """Each stream's (header stamp [ns], serialized message), in the order recorded."""
    reader = BagReader(bag)
    try:
        out: dict[str, list[tuple[int, bytes]]] = {}
        for topic in STREAMS:
            fields = reader.decode(topic)
            stamps = fields['stamp_sec'].astype(np.int64) * 1_000_000_000 + fields['stamp_nanosec']
            out[topic] = list(zip(stamps.tolist(), (m.data for m in reader.messages([topic]))))
        return out
    finally:
        reader.close()


def wait_until(predicate, timeout_s: float, what: str, procs: dict[str, subprocess.Popen], logs: Path) -> None:
    """Until ``predicate()``; fails with the logs' tails when one of ``procs`` (by log name) exits first."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        for log, proc in procs.items():
            assert proc.poll() is None, (f'{log} exited ({proc.returncode}) before {what}:\n'
                                         + (logs / log).read_text()[-3000:])
        assert time.monotonic() < deadline, f'no {what} after {timeout_s} s'
        time.sleep(0.2)


def test_a_campaign_on_a_dask_cluster_survives_a_lost_worker(tmp_path, ros_domains):
    ros_domains(2)
    spec = campaign_file(tmp_path)
    # One machine: the same campaign, two sessions side by side.
    local = subprocess.run([str(BIN / 'crane-stiffness'), 'campaign', 'run', str(spec), '--out',
                            str(tmp_path / 'local'), '--jobs', '2', '--quiet'],
                           capture_output=True, text=True, timeout=1800)
    assert local.returncode == 0, local.stderr[-3000:]

    out, logs = tmp_path / 'cluster', tmp_path / 'logs'
    logs.mkdir()
    with StarNetwork(['w1', 'w2']) as net:
        port = free_port()  # any port: the hub's loopback and links are its own
        procs: dict[str, subprocess.Popen] = {}

        def start(machine: str, argv: list[str], log: str) -> subprocess.Popen:
            with open(logs / log, 'w') as f:
                procs[log] = subprocess.Popen(net.run(machine, argv), stdout=f, stderr=subprocess.STDOUT,
                                              stdin=subprocess.DEVNULL)
            return procs[log]

        try:
            scheduler = start('hub', [sys.executable, '-m', 'distributed.cli.dask_scheduler', '--host', '0.0.0.0',
                                      '--port', str(port), '--no-dashboard'], 'scheduler.log')
            workers = {}
            for name in ('w1', 'w2'):
                (tmp_path / name).mkdir()
                workers[name] = start(name, [sys.executable, '-m', 'distributed.cli.dask_worker',
                                             f'tcp://{net.hub_address[name]}:{port}', '--host', net.address[name],
                                             '--nthreads', '1', '--no-nanny', '--no-dashboard',
                                             '--local-directory', str(tmp_path / name)],
                                      f'{name}.log')
            ready = subprocess.run(net.run('hub', [sys.executable, '-c',
                                                   'from dask.distributed import Client; '
                                                   f'c = Client("tcp://127.0.0.1:{port}", timeout="300s"); '
                                                   'c.wait_for_workers(2, timeout=300); c.close()']),
                                   capture_output=True, text=True, timeout=600)
            assert ready.returncode == 0, ready.stderr[-2000:] + (logs / 'w1.log').read_text()[-2000:]
            client = start('hub', [str(BIN / 'crane-stiffness'), 'campaign', 'run', str(spec), '--out', str(out),
                                   '--scheduler', f'tcp://127.0.0.1:{port}', '--quiet'], 'client.log')
            # w1's machine is lost once its session records: a bag file in its scratch directory.
            wait_until(lambda: any((tmp_path / 'w1').rglob('*.mcap')), 900, 'a session recording on w1', procs,
                       logs)
            assert len(net.kill('w1')) >= 1  # the worker, with the rig host its session's nodes ran in
            code = client.wait(timeout=1800)
            assert code == 0, (logs / 'client.log').read_text()[-3000:]
            assert scheduler.poll() is None and workers['w2'].poll() is None
        finally:
            for proc in procs.values():
                if proc.poll() is None:
                    proc.kill()
                proc.wait()

    lost = [p.name.split('-')[1] for p in (tmp_path / 'w1').rglob('session-*') if p.is_dir()]
    assert len(lost) == 1, f'w1 was lost during one session: {lost}'
    assert sorted(p.name for p in (out / 'bags').iterdir()) == sorted(SESSIONS)
    assert sorted(p.parent.name for p in (out / 'sessions').glob('*/result.json')) == sorted(SESSIONS)
    assert not (out / '.incoming').exists() and not (out / 'interrupted').exists()
    for session in SESSIONS:
        mine = json.loads((out / 'sessions' / session / 'result.json').read_text())
        theirs = json.loads((tmp_path / 'local' / 'sessions' / session / 'result.json').read_text())
        assert mine['bag'] == str(out / 'bags' / session)
        if session == lost[0]:  # run again, on the worker left
            assert mine['worker'].startswith(f'tcp://{net.address["w2"]}:'), mine['worker']
        for branch in ('loading', 'unloading'):
            assert ({f: mine['estimate'][branch][f] for f in FIT}
                    == {f: theirs['estimate'][branch][f] for f in FIT}), (session, branch)
        assert mine['status']['loading'] == theirs['status']['loading'], session
        recorded, alone = streams(out / 'bags' / session), streams(tmp_path / 'local' / 'bags' / session)
        for topic in STREAMS:
            end = min(recorded[topic][-1][0], alone[topic][-1][0])  # each rig stops a little after the program
            common = [m for m in recorded[topic] if m[0] <= end]
            assert len(common) > 100 and common == [m for m in alone[topic] if m[0] <= end], (session, topic)
        # nothing lost or recorded twice: every wrench of the program on its 1 ms grid, once
        stamps = [t for t, _ in recorded['/load_cell/wrench']]
        assert len(stamps) >= 5800 and all(t2 - t1 == MS for t1, t2 in zip(stamps, stamps[1:])), session


@pytest.mark.parametrize('name,kind', [('bags/s1/../../x', 'file'), ('/etc/x', 'file'), ('bags/other/x', 'file'),
                                       ('sessions/s1/link', 'symlink'), ('plan.json', 'file')])
def test_a_returned_session_holding_anything_but_its_own_files_is_refused(tmp_path, name, kind):
    """What a worker returns goes into the campaign directory only as the session's own files."""
    import io
    import tarfile
    from types import SimpleNamespace

    from crane_stiffness.campaign.distributed import store_session
    from crane_stiffness.campaign.errors import CampaignError

    def archive(entries: list[tuple[str, str]]) -> bytes:
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode='w') as tar:
            for path, what in entries:
                info = tarfile.TarInfo(path)
                if what == 'symlink':
                    info.type, info.linkname = tarfile.SYMTYPE, '/etc/passwd'
                    tar.addfile(info)
                else:
                    info.size = 2
                    tar.addfile(info, io.BytesIO(b'{}'))
        return buffer.getvalue()

    plan = SimpleNamespace(id='s1')
    good = [('bags/s1/s1_0.mcap', 'file'), ('sessions/s1/result.json', 'file')]
    out = tmp_path / 'ok'
    result = store_session(out, plan, {'archive': archive(good), 'result': {'session': 's1'}, 'worker': 'tcp://w'})
    assert result['bag'] == str(out / 'bags' / 's1') and (out / 'bags' / 's1' / 's1_0.mcap').is_file()
    assert sorted(p.name for p in out.iterdir()) == ['bags', 'sessions']
    bad = tmp_path / 'bad'
    with pytest.raises(CampaignError, match='refused'):
        store_session(bad, plan, {'archive': archive([*good, (name, kind)]), 'result': {}, 'worker': 'tcp://w'})
    assert not (bad / 'bags').exists() and not (bad / 'sessions').exists() and not (tmp_path / 'x').exists()
