"""docs/hardware.md "Your first day on the rig", run as written: every ```sh block of the section in order, in one
shell, with the genuine ros2 command line over the session's colcon workspace, and the device emulators standing in
for the sensors (rdt_emulator for the F/T box, modbus_emulator for the DAQ: each its own process on a free loopback
port, fed by the rig's crane_model as the real crane feeds real sensors). Only step 1's addresses are replaced, by
the emulators'; the operator's `y` comes on the shell's input.

Then what the section promises is checked in what the day left: every step's exit status 0 but the session's, 0 when
its verdict is OK and 5 when NOT OK for lost samples and nothing else (on this machine the emulators and the rig
share the cores with other tests and may lose samples, which the verdict names; the numbers are checked either
way), the session record naming who confirmed the set-up, the load applied by the operator mode (each level
confirmed by the measured load settling), crane_model's outputs named as predictions, the tare and zero at the
unloaded state with their offsets, and the checksums of the session."""
from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

from crane_stiffness.bag import BagReader
from crane_stiffness.bag.session_metadata import read_session, read_session_end
from crane_stiffness.launcher.ports import free_port
from crane_stiffness.launcher.rosrun import installed_config
from helpers.verdicts import check_exit_and_verdict

pytestmark = [pytest.mark.genuine_cli, pytest.mark.ros]

REPO = Path(__file__).resolve().parents[2]
SECTION = '## Your first day on the rig'
SESSION = 'fy_W50_l0.5_r1'


def section_blocks(text: str, title: str) -> list[str]:
    """The ```sh code blocks of the section ``title`` (up to the next ``## `` heading), in order."""
    start = text.index(title + '\n')
    end = text.find('\n## ', start + len(title))
    body = text[start:] if end < 0 else text[start:end]
    return re.findall(r'^```sh\n(.*?)^```$', body, flags=re.S | re.M)


def start(argv: list[str], env: dict[str, str], log: Path) -> subprocess.Popen:
    with open(log, 'w') as out:
        return subprocess.Popen(argv, env=env, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                process_group=0)


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def end_leftovers(mark: str) -> list[str]:
    """End the processes this test's script left running (a step that hung: its background rig and nodes, which
    name the test's folder ``mark`` on their command lines); their command lines."""
    left = {}
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit() and int(entry.name) != os.getpid():
            try:
                argv = (entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode(errors='replace')
            except OSError:
                continue
            if mark in argv:
                left[int(entry.name)] = argv
    for sig in (signal.SIGINT, signal.SIGKILL):
        for pid in left:
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass
        if sig == signal.SIGINT:
            time.sleep(10.0)
    return list(left.values())


def test_the_first_day_runs_as_written_with_the_emulators_for_the_sensors(install_tree, tmp_path):
    install, env = install_tree
    blocks = section_blocks((REPO / 'docs' / 'hardware.md').read_text(), SECTION)
    assert len(blocks) == 6 and blocks[0].startswith('export FT_HOST='), blocks
    config = installed_config(install)
    rdt, http, modbus = free_port(kind=socket.SOCK_DGRAM), free_port(), free_port()
    env = {**env, 'HOME': str(tmp_path), 'USER': 'alice', 'LOGNAME': 'alice'}
    drivers = str(config / 'drivers_emulated.yaml')
    devices = [
        start(['ros2', 'run', 'crane_stiffness', 'rdt_emulator', '--ros-args', '--params-file', drivers,
               '-p', f'port:={rdt}', '-p', f'http_port:={http}'], env, tmp_path / 'rdt_emulator.log'),
        start(['ros2', 'run', 'crane_stiffness', 'modbus_emulator', '--ros-args', '--params-file', drivers,
               '--params-file', str(config / 'program_campaign_side_force.yaml'), '-p', f'port:={modbus}'], env,
              tmp_path / 'modbus_emulator.log')]
    stand_in = (f'export FT_HOST=127.0.0.1 FT_PORT={rdt} FT_HTTP={http} DAQ_HOST=127.0.0.1 DAQ_PORT={modbus}'
                '  # the emulators stand in for the sensors\n')
    # Each step's exit status (its last command's) noted after it: the run goes on after a NOT OK session, as the
    # section says to (the verdict is kept and signed with the rest).
    statuses = tmp_path / 'statuses'
    script = ''.join(block + ('' if i else stand_in) + f'echo $? >> {statuses}\n' for i, block in enumerate(blocks))
    try:
        day = subprocess.run(['bash', '-c', script], input='y\n', env=env, cwd=tmp_path, capture_output=True,
                             text=True, timeout=1800)
    finally:
        for device in devices:
            stop(device)
        leftovers = end_leftovers(str(tmp_path))
    rig = tmp_path / 'rig'
    logs = '\n'.join(f'--- {p.name}:\n{p.read_text(errors="replace")[-3000:]}' for p in
                     [*tmp_path.glob('*.log'), *rig.glob('*.log')])
    codes = [int(line) for line in statuses.read_text().split()]
    verdict_file = rig / 'day1' / 'sessions' / SESSION / 'verdict.json'
    verdict = json.loads(verdict_file.read_text()) if verdict_file.is_file() else {}
    # Every step ended 0, but the session's (step 5): 0 when its verdict is OK, 5 when NOT OK. (The emulators, the rig
    # and the drivers share this machine's cores with the tests: on a loaded machine the wall-clock streams lose
    # samples, which the verdict names; real devices do not wait for a core.)
    assert len(codes) == 6 and codes[:4] == [0, 0, 0, 0] and codes[5] == 0 and verdict, \
        f'{codes}\n{day.stdout[-4000:]}\n{day.stderr[-6000:]}\n{logs}'
    check_exit_and_verdict(codes[4], verdict, day.stderr[-3000:])  # NOT OK for lost samples only
    print(f'verdict {verdict["status"]}: {verdict["reasons"]}')
    assert not leftovers, leftovers  # every command of the day ended what it started
    # Step 3: a reading from each device through its driver; the program stopped, the tare and the zero answered.
    assert 'wrench:' in day.stdout and 'point:' in day.stdout, day.stdout[-3000:]
    assert day.stdout.count('success=True') == 3, day.stdout[-3000:]
    # Step 5: the set-up asked for, the verdict shown before the run's end, with its numbers; NOT OK named on stderr.
    assert 'hang W = 50 N, set the wires to l0 = 0.5 m' in day.stderr
    assert 'leave the platform unloaded and still' in day.stderr
    assert f'{SESSION}: level 1/6: set fy = ' in day.stderr, day.stderr[-4000:]  # each level at the terminal too
    assert f'session {SESSION}: {verdict["status"]}' in day.stderr, day.stderr[-4000:]
    assert verdict['cut_short'] == '' and abs(verdict['relative_error']) < 0.1 and verdict['U'] > 0, verdict
    assert verdict['decision'] == ('continued' if verdict['status'] == 'OK' else
                                   'continued (not asked: non-interactive run), marked NOT OK')
    if verdict['status'] != 'OK':
        assert f'  {SESSION}: ' + '; '.join(verdict['reasons']) in day.stderr
    with BagReader(rig / 'day1' / 'bags' / SESSION) as reader:
        record = read_session(reader)
        entry = record['campaign']
        end = read_session_end(reader)
    assert entry['rig'] == 'hardware' and entry['confirmed']['user'] == 'alice'
    assert entry['load_application'] == 'operator' and entry['model_outputs'].startswith('predictions')
    # (the notes, which analyze's report shows, say it too)
    assert record['notes'].startswith(f'campaign first_day, session {SESSION}; crane_model outputs: predictions')
    program = end['program_state']
    assert [t['service'] for t in program['tare']] == ['/netft/tare', '/modbus_lvdt/zero']
    assert all(t['success'] and t['by'] == 'alice' for t in program['tare']), program['tare']
    assert 'tare' in program['tare'][0]['message'].lower() and program['tare'][1]['message']
    levels = program['confirmed']
    assert len(levels) == 6 and all(c['how'].startswith('measured fy settled') and c['by'] == 'alice'
                                     for c in levels), levels
    assert [c['level'] for c in levels] == [1, 2, 3, 4, 5, 6] and levels[-1]['value'] == 0.0
    # Step 6: the report and the checksums of the session.
    assert (rig / 'day1' / 'campaign' / 'report.md').is_file()
    sums = (rig / 'day1' / 'SHA256SUMS').read_text()
    assert 'verdict.json' in sums and 'report.md' in sums and '.mcap' in sums
