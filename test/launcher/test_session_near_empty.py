"""A session whose bag is near empty (a sensor stream the recorder subscribed to holds almost nothing: a driver that
never delivered) is marked failed in its end record, and cut_short, which the rig's summary, the demo and the
campaign read, says so; a bag with the streams full is not. Pure: the record is what the recorder writes."""
from __future__ import annotations

import importlib.util

from crane_stiffness.bag.session_metadata import (MIN_STREAM_MESSAGES, cut_short, near_empty,
                                                  session_end_record)
from crane_stiffness.contract import topics

from helpers import REPO

DONE = {'state': 'done'}


def test_a_sensor_stream_with_almost_nothing_fails_the_session_naming_it():
    recorded = {topics.WRENCH_COMMAND: 21, topics.LOAD_CELL_WRENCH: 21000, topics.LVDT_DISPLACEMENT: 3}
    end = session_end_record('program done', 10, 21024, recorded, DONE)
    assert end['failed'] == (f'the bag is near empty: {topics.LVDT_DISPLACEMENT} 3 message(s) (fewer than '
                             f'{MIN_STREAM_MESSAGES}): the sensor never delivered; nothing was measured')
    assert cut_short(end) == end['failed']
    # A stream subscribed to with nothing at all counts too (the record's per-topic counts leave out zeros).
    end = session_end_record('shutdown', 10, 21, {**recorded, topics.LVDT_DISPLACEMENT: 0}, DONE)
    assert f'{topics.LVDT_DISPLACEMENT} 0 message(s)' in cut_short(end)


def test_full_streams_and_streams_not_recorded_pass():
    full = {topics.LOAD_CELL_WRENCH: MIN_STREAM_MESSAGES, topics.LVDT_DISPLACEMENT: 5000}
    assert near_empty(full) == ''
    end = session_end_record('program done', 10, 5100, full, DONE)
    assert 'failed' not in end and cut_short(end) == ''
    # The recorder subscribes to the pose sensor in every session; a one-axis session has none: not near empty
    # (the demo's session, which records no pose, once failed on it).
    assert near_empty({**full, topics.WRENCH_COMMAND: 0, topics.POSE_SENSOR_POSE: 0}) == ''


def test_the_demo_refuses_a_near_empty_session():
    spec = importlib.util.spec_from_file_location('crane_stiffness_demo', REPO / 'scripts' / 'demo.py')
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    end = session_end_record('program done', 10, 30, {topics.LOAD_CELL_WRENCH: 7, topics.LVDT_DISPLACEMENT: 7}, DONE)
    ok = {'level': 'OK', 'message': ''}
    summary = {'status': {'loading': ok, 'unloading': ok, 'input': ok}, 'relative_error': 0.0,
               'recording': {'problem': cut_short(end)}}
    assert module.verdict(summary, 0.02).startswith("the session's bag: the bag is near empty"), summary
