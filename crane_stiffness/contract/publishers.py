"""Which node publishes each rig topic, for people: a wait that times out names the node that should have published
(``never came: a message on /load_cell/wrench from netft (the F/T driver): is it running?``) rather than a topic
alone. Plain Python, no ROS.

A topic may have several possible publishers, the simulated one first and the one for real hardware last (the load
cell's wrench: ``load_cell`` or the F/T driver ``netft``); which one a rig runs follows from the nodes it names
(:func:`awaited_from`).
"""
from __future__ import annotations

from typing import Iterable

from crane_stiffness.contract import topics

#: topic -> ((node, what it is for people), ...): simulated first, hardware (a driver) last.
PUBLISHERS: dict[str, tuple[tuple[str, str], ...]] = {
    topics.WRENCH_COMMAND: (('load_program', 'the load program'),),
    topics.APPLIED_WRENCH: (('crane_model', 'the crane model'),),
    topics.PLATFORM_POSE: (('crane_model', 'the crane model'),),
    topics.PREDICTED_STIFFNESS: (('crane_model', "the model's prediction"),),
    topics.PREDICTED_AXIS_STIFFNESS: (('crane_model', "the model's prediction"),),
    topics.LOAD_CELL_WRENCH: (('load_cell', 'the simulated load cell'), ('netft', 'the F/T driver')),
    topics.LVDT_DISPLACEMENT: (('lvdt', 'the simulated LVDT'), ('modbus_lvdt', 'the DAQ driver of the LVDT')),
    topics.POSE_SENSOR_POSE: (('pose_sensor', 'the simulated pose sensor'),
                              ('lvdt_array', 'the pose from an LVDT array; a tracker remapped onto the topic')),
    topics.STIFFNESS_VALUES: (('stiffness_estimator', 'the estimator, pairing both streams'),),
    topics.STIFFNESS_ESTIMATE: (('stiffness_estimator', 'the estimator'),),
    topics.STIFFNESS6_STATUS: (('stiffness6_estimator', 'the 6x6 fit'),),
}


def awaited_from(topic: str, rig: Iterable[str] = ()) -> str:
    """`` from NODE (what it is): is it running?`` for the node that should publish ``topic`` ('' for a topic
    outside :data:`PUBLISHERS`). ``rig``: the names of nodes known to run (e.g. the readers a load program waits
    for): a possible publisher among them is named; with none among them, the hardware one (the last); with no
    names known at all, every possible one."""
    candidates = PUBLISHERS.get(topic)
    if not candidates:
        return ''
    known = {name for name in rig if name}
    chosen = [c for c in candidates if c[0] in known] or (list(candidates[-1:]) if known else list(candidates))
    return ' from ' + ' or '.join(f'{node} ({what})' for node, what in chosen) + ': is it running?'


__all__ = ['PUBLISHERS', 'awaited_from']
