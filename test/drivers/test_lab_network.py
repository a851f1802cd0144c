"""The lab network: the DAQ PC runs the model, the program, the device emulators and the drivers;
the analysis PC runs the estimator and the recorder. Here the two PCs are two Linux network namespaces joined by a
veth pair whose addresses exist only inside them (made and removed by the test, unique names). DDS is opened by
the one documented switch, set only inside the namespaces; the analysis namespace's veth counters show that the
streams crossed the pair. The side-force program gives the estimate within 2 % of the
prediction, and the bag, read back with the ``mcap`` package, is complete.

Where namespaces cannot be made (not root, no iproute2), the test FAILS with the reason: it is not skipped.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from crane_stiffness.launcher import rosrun
from crane_stiffness.testing.lab_network import LabNetwork, LabNetworkError, NamespacedProcesses, start_rig_with
from crane_stiffness.launcher.rig import decode_values
from crane_stiffness.params.geometry import geometry_from_params
from crane_stiffness.params.files import load_params
from crane_stiffness.model import axis_stiffness, rest_pose, tangent_stiffness
from crane_stiffness.launcher.rig_description import rig_nodes
from helpers import PATIENCE_S
from helpers.processes import final_counters

pytestmark = pytest.mark.ros  # every test here starts ROS (conftest)


def _read_bag(bag: Path) -> dict[str, list[tuple[int, bytes]]]:
    """Every message of the session's MCAP files by topic, (log time ns, CDR bytes), with the ``mcap`` package."""
    from mcap.reader import make_reader
    out: dict[str, list[tuple[int, bytes]]] = {}
    files = sorted(bag.glob('*.mcap'))
    assert files, f'no MCAP file in {bag}'
    for f in files:
        with open(f, 'rb') as fh:
            for _schema, channel, message in make_reader(fh).iter_messages():
                out.setdefault(channel.topic, []).append((message.log_time, message.data))
    return out


SWITCHES = {
    # The one switch: automatic discovery on the subnet (multicast), instead of the default LOCALHOST.
    'subnet': lambda peer: {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'},
    # A routed lab network without multicast: the other PC's address as a static peer.
    'static_peers': lambda peer: {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_STATIC_PEERS': peer},
}


@pytest.mark.parametrize('switch', sorted(SWITCHES))
def test_drivers_on_one_pc_estimator_and_recorder_on_another(install_tree, tmp_path, switch):
    from rclpy.serialization import deserialize_message
    from geometry_msgs.msg import WrenchStamped
    from std_msgs.msg import Float64MultiArray

    install, env = install_tree
    share = rosrun.installed_config(install)
    net = LabNetwork()
    try:
        net.create()
    except LabNetworkError as exc:
        net.remove()
        pytest.fail(f'cannot make the lab network (two network namespaces joined by a veth pair): {exc}')
    try:
        ns = net.namespaces
        peers = {'daq': net.analysis_address, 'analysis': net.daq_address}
        # Set only inside the namespaces. (Fast DDS's default transports: shared memory within a namespace, UDP
        # between them - the bytes counted on the veth pair below show the streams crossed it.)
        env_of = {ns[m]: SWITCHES[switch](peers[m]) for m in ns}
        given = {'program': 'side_force', 'transport': 'drivers', 'session': 'lab'}
        # What `ros2 launch crane_stiffness rig.launch.py transport:=drivers machine:=daq` (resp. analysis) starts on
        # each PC.
        machine = {n.name: ns[m] for m in ns for n in rig_nodes(share, {**given, 'machine': m})}
        before = net.link_bytes('analysis')
        with NamespacedProcesses(env, tmp_path / 'logs', machine, env_of) as procs:
            # The emulators serve on the DAQ namespace's own loopback at the ports of drivers_emulated.yaml.
            # Every command must reach the bag, and a reliable sample lost at the recorder's socket (its buffer
            # overflows when it is starved of CPU) is repaired only after the writer's next heartbeat (Fast DDS:
            # every 3 s). So load_program is kept up (not exit_on_done: it would leave 1 s after its last command,
            # taking the repair with it) until the recorder, closing 8 s after 'done', has closed the bag.
            prog, nodes = start_rig_with(procs, share, given, tmp_path / 'bags', ready_timeout_s=120,
                                         overrides={'load_program': {'exit_on_done': False},
                                                    'session_recorder': {'stop_delay_s': 8.0}})
            deadline = time.monotonic() + 150 + prog.duration_s
            finished = f'program {prog.name!r} finished'
            while finished not in procs.log('load_program') and time.monotonic() < deadline:
                procs.check_alive()
                time.sleep(0.2)
            assert finished in procs.log('load_program'), procs.log('load_program')[-3000:]
            recorder = procs.procs['session_recorder']
            end = time.monotonic() + PATIENCE_S  # the recorder closes the bag by itself when the program is done
            while recorder.poll() is None and 'closed ' not in procs.log('session_recorder') and \
                    time.monotonic() < end:
                time.sleep(0.2)
            codes = procs.stop()
            logs = {name: procs.log(name) for name in procs.procs}
        after = net.link_bytes('analysis')
    finally:
        errors = net.remove()
    assert not errors, errors
    assert all(code == 0 for code in codes.values()), {n: logs[n][-1500:] for n, c in codes.items() if c}
    assert 'rig ready after' in logs['load_program']

    # The streams crossed the veth pair (1 kHz of wrenches and the LVDT's polls: megabytes).
    crossed = after['rx_bytes'] - before['rx_bytes']
    assert crossed > 2_000_000, (before, after)

    # The bag, read back with the mcap package: every command, the sensor streams without gaps, the estimates.
    bag = tmp_path / 'bags' / 'lab'
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    messages = _read_bag(bag)
    assert sum(len(v) for v in messages.values()) == meta['message_count']
    sent = final_counters(logs['load_program'])['published']
    assert len(messages['/crane/wrench_command']) == sent > 1000
    ft = final_counters(logs['netft'])
    stamps = []
    for _, data in messages['/load_cell/wrench']:
        h = deserialize_message(data, WrenchStamped).header.stamp
        stamps.append(h.sec * 1_000_000_000 + h.nanosec)
    stamps = np.unique(np.array(stamps))
    steps = np.round(np.diff(stamps) / 1e6).astype(int)  # netft publishes 1 ms means
    missing = int(np.sum(steps[steps > 1] - 1))
    assert len(stamps) > 1000 * prog.duration_s, (len(stamps), ft)
    # Sensor data is best effort (as on a real network): on this shared 2-core machine the recorder, starved of
    # CPU, sometimes falls ~1 s behind and its socket buffer overflows (a few % lost; 0 on a quiet machine). More
    # would mean the stream did not really get through.
    assert missing <= 0.05 * len(stamps), (missing, len(stamps))
    assert len(messages['/lvdt/displacement']) > 50 * prog.duration_s   # 100 Hz polls, a starved timer skips some
    values = messages['/stiffness/estimate_values']
    est = decode_values(deserialize_message(values[-1][1], Float64MultiArray))
    g = geometry_from_params(load_params(share / 'crane_lab.yaml'))
    predicted = axis_stiffness(tangent_stiffness(g, rest_pose(g)), 'fy')
    rel = (est['loading']['stiffness'] - predicted) / predicted
    assert abs(rel) < 0.02, (rel, est['loading'])
    assert est['loading']['n'] > 500
    print(f'\n{switch}: {crossed / 1e6:.1f} MB crossed the veth pair; /load_cell/wrench in the bag: {len(stamps)} '
          f'samples, {missing} missing from the 1 ms grid; estimate {rel:+.4%} from the prediction')
