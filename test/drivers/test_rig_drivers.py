"""The rig through the drivers: ``rig.launch.py transport:=drivers`` runs load_cell's physics
as an RDT F/T device (rdt_emulator) read by netft, and the LVDT's as a Modbus TCP analog input (modbus_emulator)
read by modbus_lvdt, instead of the simulated sensors' direct topics. The side-force program, every node started
the way ``ros2 run`` starts it from the colcon install tree, all at the same instant, gives the estimate within 2 %
of the model's prediction; the rig description's choices for the arguments are pinned here too."""
from __future__ import annotations

import time

import pytest

from crane_stiffness.launcher.rig_description import NODES, RigError, config_files, rig_nodes
from crane_stiffness.launcher import rosrun
from crane_stiffness.testing.lab_network import emulated_ports, start_rig_with
from crane_stiffness.launcher.rig import Observer, summarize, wait_for_program_start

from helpers import PATIENCE_S, REPO
from helpers.processes import final_counters

CONFIG = REPO / 'config'


def test_transport_argument_chooses_the_nodes():
    sim = [n.name for n in rig_nodes(CONFIG)]
    assert sim == ['crane_model', 'load_cell', 'lvdt', 'stiffness_estimator', 'session_recorder', 'load_program']
    drivers = {n.name: n for n in rig_nodes(CONFIG, {'transport': 'drivers'})}
    assert list(drivers) == ['crane_model', 'rdt_emulator', 'modbus_emulator', 'netft', 'modbus_lvdt',
                             'stiffness_estimator', 'session_recorder', 'load_program']
    for name in ('rdt_emulator', 'netft', 'modbus_lvdt'):
        assert drivers[name].parameter_files == (str(CONFIG / 'drivers_emulated.yaml'),)
    # The LVDT's emulator takes its series' arrangement (axis, contact point) from the program file.
    assert drivers['modbus_emulator'].parameter_files == tuple(
        str(CONFIG / f) for f in ('drivers_emulated.yaml', 'program_side_force.yaml'))
    # The estimator reads the drivers file last (its pairing suits the drivers' rates), and only through drivers.
    assert drivers['stiffness_estimator'].parameter_files == tuple(
        str(CONFIG / f) for f in ('crane_lab.yaml', 'sensors.yaml', 'program_side_force.yaml', 'drivers_emulated.yaml'))
    assert {n.name: n for n in rig_nodes(CONFIG)}['stiffness_estimator'].parameter_files == tuple(
        str(CONFIG / f) for f in ('crane_lab.yaml', 'sensors.yaml', 'program_side_force.yaml'))
    # The program waits for the emulators to hold the applied load and the pose (nothing of them may be lost), and
    # for both streams from the drivers.
    waits = drivers['load_program'].parameters
    assert '/crane/wrench_command: crane_model stiffness_estimator session_recorder' in waits['wait_for_subscribers']
    assert '/crane/applied_wrench: rdt_emulator session_recorder' in waits['wait_for_subscribers']
    assert '/crane/platform_pose: modbus_emulator session_recorder' in waits['wait_for_subscribers']
    assert {'/load_cell/wrench', '/lvdt/displacement'} <= set(waits['wait_for_messages'])
    # Real hardware: the drivers alone, with a drivers file naming the devices.
    hw = [n.name for n in rig_nodes(CONFIG, {'transport': 'drivers', 'sim_sensors': 'false',
                                             'drivers': str(CONFIG / 'drivers_ati_labjack.yaml')})]
    assert hw == ['crane_model', 'netft', 'modbus_lvdt', 'stiffness_estimator', 'session_recorder', 'load_program']
    # Where each node belongs in the lab (the network test splits the rig by it), and one launch per PC.
    assert {n.name for n in NODES if n.machine == 'analysis'} == {'stiffness_estimator', 'stiffness6_estimator',
                                                                 'session_recorder', 'live_view'}
    daq = {n.name: n for n in rig_nodes(CONFIG, {'transport': 'drivers', 'machine': 'daq'})}
    analysis = [n.name for n in rig_nodes(CONFIG, {'transport': 'drivers', 'machine': 'analysis'})]
    assert analysis == ['stiffness_estimator', 'session_recorder']
    assert sorted([*daq, *analysis]) == sorted(drivers)
    # The program on the DAQ PC still waits for the estimator and the recorder on the analysis PC.
    assert daq['load_program'].parameters == waits


def test_transport_refusals_name_the_value_or_file(tmp_path):
    with pytest.raises(RigError, match="transport 'hardware': expected one of sim, drivers"):
        rig_nodes(CONFIG, {'transport': 'hardware'})
    with pytest.raises(RigError, match="machine 'lab': expected one of all, daq, analysis"):
        rig_nodes(CONFIG, {'machine': 'lab'})
    missing = tmp_path / 'nope.yaml'
    with pytest.raises(RigError, match=f'drivers file {missing} not found'):
        rig_nodes(CONFIG, {'transport': 'drivers', 'drivers': str(missing)})
    # The drivers file is read only by the drivers' nodes: with the simulated sensors it is not needed.
    assert 'netft' not in [n.name for n in rig_nodes(CONFIG, {'drivers': str(missing)})]
    assert config_files(CONFIG, {'drivers': str(missing)})['sensors'] == str(CONFIG / 'sensors.yaml')


def test_every_drivers_file_has_only_parameters_the_nodes_declare():
    """A key a node does not declare would stop it at start (exit 2): every drivers file is checked against the
    nodes' ParamSpecs here, without a process."""
    import yaml

    from crane_stiffness.nodes import modbus_emulator, modbus_lvdt, netft, rdt_emulator, stiffness_estimator
    declared = {'rdt_emulator': rdt_emulator.PARAMS, 'netft': netft.PARAMS, 'modbus_emulator': modbus_emulator.PARAMS,
                'modbus_lvdt': modbus_lvdt.PARAMS, 'stiffness_estimator': stiffness_estimator.PARAMS}
    files = sorted(CONFIG.glob('drivers_*.yaml'))
    assert {f.name for f in files} >= {'drivers_emulated.yaml', 'drivers_ati_labjack.yaml',
                                       'drivers_onrobot_labjack.yaml'}
    for path in files:
        data = yaml.safe_load(path.read_text())
        for node, section in data.items():
            names = {s.name: s for s in declared[node]}
            for key, value in section['ros__parameters'].items():
                assert key in names, f'{path.name}: {node}.{key} is not a parameter of {node}'
                default = names[key].default
                # ROS keeps a parameter's type: a float written without a point would be refused.
                assert type(value) is type(default) or (isinstance(default, list) and isinstance(value, list)), \
                    f'{path.name}: {node}.{key} = {value!r} ({type(value).__name__}), declared ' \
                    f'{type(default).__name__}'


def test_side_force_through_the_drivers_gives_the_prediction(install_tree, tmp_path):
    """`ros2 launch crane_stiffness rig.launch.py transport:=drivers`, every process at once from the install tree
    (the emulators on free loopback ports), the side-force program: the estimate within 2 % of the prediction,
    and the readings really came through the drivers."""
    import rclpy
    install, env = install_tree
    share = rosrun.installed_config(install)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    observer = Observer(context=ctx)
    given = {'program': 'side_force', 'transport': 'drivers', 'session': 'drivers'}
    try:
        with rosrun.Processes(env, tmp_path / 'logs') as procs:
            prog, nodes = start_rig_with(procs, share, given, tmp_path / 'bags', ready_timeout_s=120,
                                         overrides=emulated_ports())
            wait_for_program_start(observer, procs, 150)
            deadline = time.monotonic() + prog.duration_s + PATIENCE_S
            while procs.procs['load_program'].poll() is None and time.monotonic() < deadline:
                procs.check_alive(allow_exit=('load_program',))
                observer.spin_once(0.1)
            assert procs.procs['load_program'].poll() == 0, procs.log('load_program')[-3000:]
            # Until the estimator has fitted 1.5 s of samples after the program's end (the sensors run on; stamps on
            # this host's clock): the same data however late a loaded machine delivers it.
            from crane_stiffness.nodes.stiffness_estimator import VALUE_FIELDS
            newest = VALUE_FIELDS.index('sample_stamp')
            fitted_through = time.time() + 1.5
            deadline = time.monotonic() + PATIENCE_S
            while (observer.values is None or observer.values.data[newest] < fitted_through) \
                    and time.monotonic() < deadline:
                procs.check_alive(allow_exit=('load_program',))
                observer.spin_once(0.05)
            codes = procs.stop()
            logs = {name: procs.log(name) for name in procs.procs}
        summary = summarize(share, 'side_force', 'drivers', tmp_path / 'bags', observer, codes)
    finally:
        observer.destroy_node()
        rclpy.shutdown(context=ctx)
    assert 'load_cell' not in codes and 'lvdt' not in codes
    assert all(code == 0 for code in codes.values()), {n: logs[n][-1500:] for n, c in codes.items() if c}
    ft, daq = final_counters(logs['netft']), final_counters(logs['modbus_lvdt'])
    rdt, modbus = final_counters(logs['rdt_emulator']), final_counters(logs['modbus_emulator'])
    duration = prog.duration_s
    # 7 kHz records in, their 1 ms means out; a poll every 10 ms (a starved timer skips some: generous margins).
    assert ft['received'] > 7000 * duration * 0.9 and ft['published'] > 1000 * duration * 0.9, ft
    assert rdt['published'] >= ft['received'] and ft['records_lost'] <= 0.001 * ft['received'], (rdt, ft)
    assert daq['published'] > 50 * duration and daq['failures'] <= 3, daq
    assert modbus['published'] >= daq['published'], (modbus, daq)
    assert 'http_port' in logs['netft'] or 'counts/N' in logs['netft']  # calibration read from /netftapi2.xml
    # Interpolated pairing (drivers_emulated.yaml): one pair per LVDT reading, the force interpolated at its stamp,
    # not one per force sample. (LVDT readings before netft's first sample pair with nothing: modbus_lvdt may start
    # publishing seconds earlier, so the share paired is bounded loosely.)
    est_counters = final_counters(logs['stiffness_estimator'])
    assert 'pairing interpolate_force' in logs['stiffness_estimator'], logs['stiffness_estimator'][-2000:]
    # At most one pair per LVDT reading (nearest-stamp pairing of every force sample would give ~10 times as many);
    # how many readings find a force around their stamp depends on the machine's load.
    assert 100 < est_counters['pairs'] <= est_counters['displacement_passed_checks'], est_counters
    assert est_counters['pairs'] < 0.2 * est_counters['force_passed_checks'], est_counters
    est = summary['estimate']['loading']
    print('through the drivers:', summary['relative_error'], est, est_counters)
    assert abs(summary['relative_error']) < 0.02, (summary['relative_error'], est, summary['prediction'])
    assert est['n'] > 500, est
    assert summary['bag'] is not None
    # analyze pairs the recorded streams the same way (the recorded estimator parameters): over the time the
    # estimator reported on, as many pairs as it made, and the live window fitted offline gives the live estimate.
    # Not to the bit: the recorder and the estimator match the sensors' writers at different instants of the start
    # (best effort), so the first samples of the loading window differ (measured: 1,173 live, 1,178 offline,
    # stiffness 0.002 % apart; the unloading window, later, the same to 1e-11).
    from crane_stiffness.analysis.analyze import analyze_session
    analysis = analyze_session(summary['bag'], write_files=False)
    assert analysis.settings['pairing'] == 'interpolate_force' and analysis.live is not None
    live = analysis.live
    print('offline:', analysis.pairing, live.inputs, live.max_rel_diff)
    assert 0 < analysis.pairing['pairs'] < 0.2 * analysis.pairing['force_messages'], analysis.pairing
    # (Pair counts agree only roughly: a force sample the estimator found stale by its arrival time cannot be judged
    # so from the recorder's log time; on a loaded machine 233 were, and the pairs differed by 1.1 %.)
    # Every pair one of them made and the other did not is a sample the estimator judged stale or could not pair
    # (counted, over the whole run), or one only one of them received: the recorder's best-effort subscription
    # missed it, or DDS matched the estimator to a sensor's writer later than the recorder (up to ~2.5 s at start).
    accounted = (est_counters['force_stale'] + est_counters['displacement_stale']
                 + est_counters['displacement_unmatched']
                 + abs(live.inputs['bag_force_messages'] - live.inputs['live_force_received'])
                 + abs(live.inputs['bag_displacement_messages'] - live.inputs['live_displacement_received']))
    assert abs(live.inputs['offline_pairs'] - live.inputs['live_pairs']) <= \
        max(0.1 * live.inputs['live_pairs'], accounted), (live.inputs, est_counters)
    for branch in ('loading', 'unloading'):
        assert live.offline[branch]['stiffness'] == pytest.approx(live.live[branch]['stiffness'], rel=0.002), branch


def test_a_driver_waits_for_a_device_that_starts_after_it():
    """Every node of a launch starts at once: the driver's first contact is retried for wait_for_device_s (here a
    Modbus device that starts listening 1 s after the first attempt), a device that never comes is an error naming
    the time waited, and a device that answers wrongly is an error at once."""
    import threading

    from crane_stiffness.devices.modbus_device import ModbusDevice
    from crane_stiffness.drivers.errors import DeviceAddressError, DeviceResponseError
    from crane_stiffness.drivers.modbus import Channel, ModbusPoller
    from crane_stiffness.rosnode.device_params import wait_for_device
    from crane_stiffness.launcher.ports import free_port

    port = free_port()
    device = ModbusDevice(lambda: 1.5e-3, channel=Channel(gain=0.001), port=port)
    timer = threading.Timer(1.0, device.start)
    poller = ModbusPoller('127.0.0.1', port, 1, Channel(gain=0.001), timeout_s=PATIENCE_S)  # refused until it starts
    logged: list[str] = []
    t0 = time.monotonic()
    timer.start()
    try:
        reading = wait_for_device(poller.read, 20.0, logged.append)
    finally:
        timer.join()
        poller.close()
        device.stop()
    assert reading.metres == pytest.approx(1.5e-3, rel=1e-6)
    assert 0.9 < time.monotonic() - t0 < 15
    assert len(logged) == 1 and 'trying again for up to 20 s (wait_for_device_s)' in logged[0], logged
    gone = ModbusPoller('127.0.0.1', free_port(), 1, Channel(), timeout_s=PATIENCE_S)  # refused at once
    with pytest.raises(DeviceAddressError, match=r'tried for 0.6 s: wait_for_device_s'):
        wait_for_device(gone.read, 0.6)
    calls = []

    def wrong():
        calls.append(1)
        raise DeviceResponseError('answered Modbus exception 2')
    with pytest.raises(DeviceResponseError):
        wait_for_device(wrong, 10.0)
    assert len(calls) == 1
