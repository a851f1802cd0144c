"""What can only be a typo stops the rig before anything starts, naming the closest declared name: a launch argument
the rig does not declare (launch takes any ``name:=value`` and would run without it) and a parameter-file section
that applies to no node of the rig (read by none). A node that ends on its own with a non-zero status ends the
launch, naming it (rig_description.exit_problem; test_genuine_cli drives the genuine ``ros2 launch``)."""
from __future__ import annotations

import pytest

from crane_stiffness.launcher.rig_description import (ARGUMENTS, LAUNCH_OWN, RigError, check_argument_names,
                                                     exit_problem, rig_nodes)

from helpers import REPO

CONFIG = REPO / 'config'


@pytest.mark.parametrize('given, closest', [({'transprot': 'drivers'}, 'transport'),
                                            ({'sim_sensor': 'false'}, 'sim_sensors'),
                                            ({'programm': 'moment_z'}, 'program'),
                                            ({'use_simtime': 'true'}, 'use_sim_time')])
def test_an_undeclared_argument_is_refused_with_the_closest_one(given, closest):
    name = next(iter(given))
    with pytest.raises(RigError, match=rf"{name}:=\.\.\.: the rig has no argument '{name}' \(did you mean "
                                       rf"'{closest}'\?\)"):
        rig_nodes(CONFIG, given)


def test_an_argument_like_none_lists_them_all():
    with pytest.raises(RigError) as info:
        check_argument_names(['zzzz'])
    assert "no argument 'zzzz'; the rig's arguments: program, crane," in str(info.value)
    assert all(a.name in str(info.value) for a in ARGUMENTS)


def test_launch_configurations_of_launch_itself_and_the_declared_ones_pass():
    """What ``ros2 launch`` puts in the launch context besides the arguments (--launch-prefix, launch_ros's
    namespace, remaps, global parameters) is not a typo; the process launcher takes the rig's arguments only."""
    check_argument_names([*(a.name for a in ARGUMENTS), *LAUNCH_OWN])
    with pytest.raises(RigError, match="no argument 'launch-prefix'"):
        rig_nodes(CONFIG, {'launch-prefix': 'gdb'})


def test_a_section_no_node_of_the_rig_reads_is_refused_with_the_closest_node(tmp_path):
    sensors = tmp_path / 'sensors.yaml'
    sensors.write_text((CONFIG / 'sensors.yaml').read_text().replace('stiffness_estimator:', 'stiffness_estimater:'))
    with pytest.raises(RigError, match=rf"{sensors}: section 'stiffness_estimater' applies to no node of the rig "
                                       r"\(did you mean 'stiffness_estimator'\?\)"):
        rig_nodes(CONFIG, {'sensors': str(sensors)})
    drivers = tmp_path / 'drivers.yaml'
    drivers.write_text((CONFIG / 'drivers_emulated.yaml').read_text().replace('modbus_lvdt:', 'modbus_lvtd:'))
    # Read by the drivers' nodes only: refused with transport:=drivers, not read (nor checked) without.
    with pytest.raises(RigError, match=r"section 'modbus_lvtd' applies to no node of the rig \(did you mean "
                                       r"'modbus_lvdt'\?\)"):
        rig_nodes(CONFIG, {'transport': 'drivers', 'drivers': str(drivers)})
    assert 'modbus_lvdt' not in [n.name for n in rig_nodes(CONFIG, {'drivers': str(drivers)})]
    # A section like no node at all lists the rig's nodes.
    crane = tmp_path / 'crane.yaml'
    crane.write_text((CONFIG / 'crane_lab.yaml').read_text() + '\nzz:\n  ros__parameters:\n    q: 1\n')
    with pytest.raises(RigError, match=r"section 'zz' applies to no node of the rig; its nodes: crane_model, "):
        rig_nodes(CONFIG, {'crane': str(crane)})


def test_every_shipped_file_has_only_sections_of_the_rigs_nodes():
    for program in ('side_force', 'moment_z', 'force_z', 'side_force_slack', 'full6'):
        for transport in ('sim', 'drivers'):
            assert rig_nodes(CONFIG, {'program': program, 'transport': transport})
    for drivers in sorted(CONFIG.glob('drivers_*.yaml')):
        assert rig_nodes(CONFIG, {'transport': 'drivers', 'sim_sensors': 'false', 'drivers': str(drivers)})


@pytest.mark.parametrize('process, code, shutting_down, expected', [
    ('crane_model-1', 2, False, 'crane_model exited with status 2: the rig cannot measure without it, so the launch '
                                "stops (see crane_model's output above)"),
    ('netft', -11, False, 'netft was killed by signal 11: the rig cannot measure'),
    ('load_program-7', 1, False, 'load_program exited with status 1: it gave up waiting for the rig (its last lines '
                                 'say what never came)'),
    ('load_program-7', 0, False, ''),   # its program done
    ('crane_model-1', 0, False, ''),
    ('lvdt-3', 1, True, ''),            # after Ctrl-C: the launch is ending anyway
    # the recorder's cut recording (a ~/stop from outside) ends the launch non-zero even at Ctrl-C
    ('session_recorder-5', 3, True, "session_recorder exited with status 3: its recording was stopped from outside"),
    ('session_recorder-5', 3, False, "session_recorder exited with status 3: its recording was stopped from outside"),
    ('session_recorder-5', 0, True, ''),
    ('crane_model-1', 3, True, ''),
])
def test_a_node_ending_with_a_failure_stops_the_launch_naming_it(process, code, shutting_down, expected):
    problem = exit_problem(process, code, shutting_down)
    assert problem.startswith(expected) and (problem == '') == (expected == '')


def test_launchs_own_timeouts_are_not_typos():
    check_argument_names(['sigterm_timeout', 'sigkill_timeout', 'program'])
