"""The session record (session_record): built from plain values, read back from a bag's metadata records."""
from __future__ import annotations

import json
from types import SimpleNamespace

from crane_stiffness.bag.session_metadata import (NODE_PARAMETERS_METADATA, SESSION_METADATA, read_node_parameters,
                                            read_session, session_record)
from crane_stiffness.sim.program import LoadProgram

PROGRAM_KEYS = ('name', 'rate_hz', 'repeats', 'segments.kind', 'segments.axis', 'segments.target',
                'segments.duration')
OWN = ('session_recorder', '/**')
STEPS = {'name': 'steps', 'segments.kind': ['ramp', 'hold'], 'segments.axis': ['fz', 'fz'],
         'segments.target': [100.0, 100.0], 'segments.duration': [1.0, 2.0]}


def _record(program=None, sections=None):
    return session_record(
        session='s1', start_ns=1_700_000_000_000_000_000,
        parameters={'geometry.a': 1.5, 'geometry.h': 2.0, 'notes': 'operator A', 'topics': ['/x']},
        geometry=SimpleNamespace(l0=[1.0, 2.0], k=[3.0, 4.0]), program=program, param_sections=sections or {},
        param_files=[{'path': '/p.yaml', 'text': 'x: 1'}], program_keys=PROGRAM_KEYS, own_sections=OWN,
        recorder={'compression': 'zstd', 'node': '/session_recorder'}, ros_distro='jazzy', host='rig-pc')


def test_record_of_the_recorders_own_program_and_sensor_sections():
    program = LoadProgram.from_params(STEPS)
    record, warnings = _record(program, {'/**': {'notes': 'x'}, 'load_cell': {'sample_rate_hz': 1000.0},
                                         'load_program': dict(STEPS, name='other')})
    assert warnings == []
    assert list(record) == ['software_version', 'notes', 'rig', 'program', 'start_time_ns', 'session', 'sensors',
                            'config_files', 'recorder', 'ros_distro', 'host']
    assert all(isinstance(v, str) for v in record.values())
    session = read_session({SESSION_METADATA: record})
    assert session['rig'] == {'geometry': {'geometry.a': 1.5, 'geometry.h': 2.0}, 'l0': [1.0, 2.0], 'k': [3.0, 4.0]}
    assert session['program']['name'] == 'steps' and session['program']['source'] == 'parameters'
    assert session['program']['duration_s'] == 3.0
    assert session['sensors'] == {'load_cell': {'sample_rate_hz': 1000.0}}
    assert session['notes'] == 'operator A' and session['start_time_ns'] == '1700000000000000000'
    assert session['recorder'] == {'compression': 'zstd', 'node': '/session_recorder'}


def test_program_from_a_parameter_file_section_or_a_warning():
    record, warnings = _record(None, {'load_program': dict(STEPS, use_sim_time=False)})
    assert warnings == [] and read_session({SESSION_METADATA: record})['program']['source'] == \
        'parameter file section load_program'
    bad = dict(STEPS, **{'segments.duration': [1.0]})
    record, warnings = _record(None, {'load_program': bad})
    assert len(warnings) == 1 and 'load_program is invalid' in warnings[0]
    assert 'program' not in read_session({SESSION_METADATA: record})


def test_node_parameters_and_missing_records():
    records = {NODE_PARAMETERS_METADATA: {'/lvdt': json.dumps({'scale': 2.0}), 'broken': '{', 'list': '[1]'}}
    assert read_node_parameters(records) == {'lvdt': {'scale': 2.0}}
    assert read_session(records) == {} and read_node_parameters({}) == {}
