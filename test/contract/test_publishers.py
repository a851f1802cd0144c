"""A wait that times out names the node that should have published: the simulated one when the rig runs it, the
driver otherwise (contract.publishers.awaited_from, load_program's "never came")."""
from __future__ import annotations

from crane_stiffness.contract import topics
from crane_stiffness.contract.publishers import PUBLISHERS, awaited_from
from crane_stiffness.launcher.rig_description import rig_nodes
from crane_stiffness.nodes import NODES

from helpers import REPO


def readers(given: dict[str, str]) -> list[str]:
    """The readers load_program waits for, as the launch file tells it."""
    program = next(n for n in rig_nodes(REPO / 'config', given) if n.runs_program)
    return [entry.split(':', 1)[1] for entry in program.parameters['wait_for_subscribers']]


def names(entries: list[str]) -> list[str]:
    return [name for entry in entries for name in entry.split()]


def test_the_driver_is_named_when_the_rig_runs_through_the_drivers():
    drivers = names(readers({'transport': 'drivers'}))
    assert awaited_from(topics.LOAD_CELL_WRENCH, drivers) == ' from netft (the F/T driver): is it running?'
    assert awaited_from(topics.LVDT_DISPLACEMENT, drivers) == \
        ' from modbus_lvdt (the DAQ driver of the LVDT): is it running?'
    hardware = names(readers({'transport': 'drivers', 'sim_sensors': 'false'}))
    assert awaited_from(topics.LOAD_CELL_WRENCH, hardware) == ' from netft (the F/T driver): is it running?'


def test_the_simulated_sensor_is_named_on_the_simulated_rig():
    sim = names(readers({}))
    assert awaited_from(topics.LOAD_CELL_WRENCH, sim) == ' from load_cell (the simulated load cell): is it running?'
    assert awaited_from(topics.PREDICTED_AXIS_STIFFNESS, sim) == \
        " from crane_model (the model's prediction): is it running?"
    six = names(readers({'program': 'full6'}))
    assert awaited_from(topics.POSE_SENSOR_POSE, six).startswith(' from pose_sensor (the simulated pose sensor)')


def test_with_no_node_known_every_possible_publisher_is_named_and_an_unknown_topic_gets_nothing():
    assert awaited_from(topics.LOAD_CELL_WRENCH) == \
        ' from load_cell (the simulated load cell) or netft (the F/T driver): is it running?'
    assert awaited_from('/somewhere/else', ['crane_model']) == ''


def test_every_publisher_named_is_a_node_of_the_package_and_every_topic_is_in_the_contract():
    assert {node for entries in PUBLISHERS.values() for node, _ in entries} <= set(NODES)
    assert set(PUBLISHERS) <= set(topics.RIG_TOPICS) | {topics.STIFFNESS_ESTIMATE, topics.STIFFNESS6_STATUS}
