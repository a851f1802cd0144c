"""The session recorder's parameters (its recording settings, and the rig's geometry and test program it records
with a session when they are given to it) and their validation."""
from __future__ import annotations

import json
import os
import socket
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping, Sequence

from crane_stiffness.contract import topics
from crane_stiffness.bag.writer import COMPRESSIONS
from crane_stiffness.rosnode.parameter_reader import plain
from crane_stiffness.rosnode.parameters import check, valid_topic_name
from crane_stiffness.bag.session_metadata import session_record
from crane_stiffness.params.files import NodeSections, read_params_files
from crane_stiffness.params.geometry import GEOMETRY_PARAMS, geometry_from_params
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.sim.program import PROGRAM_KEYS, PROGRAM_PARAMS, LoadProgram

PROGRAM_DEFAULTS = {p.name: p.default for p in PROGRAM_PARAMS}
#: Sections of a parameter file that hold this node's own parameters (not recorded as another node's): ROS's rule.
OWN_SECTIONS = NodeSections('session_recorder')

#: Longest flush interval, split duration and stop delay [s]: finite (a timer period and a duration in ns must be
#: integers) and longer than any session.
MAX_INTERVAL_S = 86400.0

PARAMS = GEOMETRY_PARAMS + PROGRAM_PARAMS + (
    ParamSpec('topics', list(topics.RIG_TOPICS), 'topics to record; rig topics use their contract type and QoS, '
              'others are subscribed once a publisher appears [-]'),
    ParamSpec('session', '', "bag name: the bag is <output_dir>/<session>/; '' = session_<UTC time> [-]"),
    ParamSpec('output_dir', 'bags', 'directory the session bags are written to [-]'),
    ParamSpec('compression', 'zstd', 'MCAP chunk compression: zstd, lz4 or none [-]',
              choices=tuple(sorted(COMPRESSIONS))),
    ParamSpec('chunk_size', 262144, 'uncompressed MCAP chunk size; a chunk is on disk once full [bytes]', low=1),
    ParamSpec('flush_interval_s', 0.5, 'also write the current chunk once it is this old, so a crash (SIGKILL) loses '
              'at most this much; 0 = by size only [s]', low=0.0, high=MAX_INTERVAL_S),
    ParamSpec('split_max_bytes', 0, 'start a new .mcap file at this size, 0 = never [bytes]', low=0,
              rule='0 (never) or >= 1024'),
    ParamSpec('split_max_duration_s', 0.0, 'start a new .mcap file after this much time, 0 = never [s]', low=0.0,
              high=MAX_INTERVAL_S),
    ParamSpec('fsync', False, 'fsync every write (survives power loss too; slower) [-]'),
    ParamSpec('autostart', True, 'start recording when the node starts (else call ~/start) [-]'),
    ParamSpec('stop_on_program_done', True, "stop and close the bag when /load_program/state reports 'done' after "
              'the program ran [-]'),
    ParamSpec('stop_delay_s', 1.0, "keep recording this long after 'done' so the last samples and estimates "
              'arrive [s]', low=0.0, high=MAX_INTERVAL_S),
    ParamSpec('exit_on_program_done', False, 'shut the node down once the bag closed at the program end is '
              'written [-]'),
    ParamSpec('executor', 'events', "executor of the recorder process: 'events' (rclpy's EventsExecutor, in C++: "
              "about a quarter of the CPU per message) or 'single' (SingleThreadedExecutor); read at start [-]",
              choices=('events', 'single')),
    ParamSpec('notes', '', 'free text stored with the session (operator, specimen, remarks) [-]'),
    ParamSpec('campaign_entry', '', "the session's place in a test campaign, a JSON object stored with the session "
              "under 'campaign' (series, W, l0, the true crane of a simulated rig, what the operator confirmed; "
              "crane_stiffness.campaign); '' = not part of a campaign [-]", rule="'' or a JSON object"),
    ParamSpec('record_node_parameters', ['/crane_model', '/load_program', '/load_cell', '/lvdt',
                                         '/stiffness_estimator', '/pose_sensor', '/stiffness6_estimator', '/netft',
                                         '/modbus_lvdt', '/lvdt_array'],
              'nodes whose parameters (the sensors\' declared calibration.* among them) are read over ROS '
              "(get_parameters) once they appear and stored with the session; [''] = none [-]"),
)

#: Settings read when a recording starts; their change applies to the next recording.
RECORDING_KEYS = ('topics', 'session', 'output_dir', 'compression', 'chunk_size', 'flush_interval_s',
                  'split_max_bytes', 'split_max_duration_s', 'fsync')


def validate(values: dict[str, Any]) -> dict[str, Any]:
    check(values['split_max_bytes'] == 0 or values['split_max_bytes'] >= 1024, 'split_max_bytes',
          values['split_max_bytes'], 'must be 0 (no split) or >= 1024 bytes')
    session = values['session']
    check(session == '' or (session not in ('.', '..') and '/' not in session), 'session', session,
          "must be '' or a directory name without '/'")
    check(values['output_dir'] != '', 'output_dir', values['output_dir'], 'must not be empty')
    names = list(values['topics'])
    check(bool(names) and all(isinstance(t, str) and t for t in names), 'topics', names,
          'must be a non-empty list of topic names')
    for t in names:
        check(valid_topic_name(t), 'topics', names, f'{t!r} is not a valid topic name')
    geometry = geometry_from_params(values)  # GeometryError (a ValueError) names the field
    campaign = None
    if values['campaign_entry']:
        try:
            campaign = json.loads(values['campaign_entry'])
        except ValueError:
            campaign = None
        check(isinstance(campaign, dict), 'campaign_entry', values['campaign_entry'], "must be '' or a JSON object")
    program_values = {k: plain(values[k]) for k in PROGRAM_KEYS}
    program = None
    if program_values != PROGRAM_DEFAULTS:
        program = LoadProgram.from_params(program_values)  # ParameterError (a ValueError) names the field
    return {'geometry': geometry, 'program': program, 'campaign': campaign}


def utc_session_name(now_ns: int) -> str:
    return 'session_' + datetime.fromtimestamp(now_ns / 1e9, tz=timezone.utc).strftime('%Y%m%dT%H%M%SZ')


def session_dir(output_dir: str, session: str, recordings: int, now_ns: int) -> Path:
    """The directory of a new recording: ``output_dir/session``, or named by ``now_ns`` [ns since the epoch]; a
    later recording (``recordings`` > 0) of the same fixed session name gets ``<session>_2``, ``_3``, ..."""
    path = Path(output_dir).expanduser() / (session or utc_session_name(now_ns))
    n = 2
    while recordings and session and path.exists():
        path, n = Path(output_dir).expanduser() / f'{session}_{n}', n + 1
    return path


__all__ = ['MAX_INTERVAL_S', 'OWN_SECTIONS', 'PARAMS', 'RECORDING_KEYS', 'session_dir', 'utc_session_name',
           'validate']


def recorder_session_record(session: str, start_ns: int, values: Mapping[str, Any], built: Mapping[str, Any],
                            params_files: Sequence[str], node: str, sim_time: bool) -> tuple[dict[str, str], list[str]]:
    """The session record of a recording (crane_stiffness.bag.session_metadata.session_record) from the recorder's
    parameter ``values`` (plain), what they built (geometry, program, campaign: :func:`validate`), its parameter
    files, its fully qualified ``node`` name and clock; with the warnings to log (a parameter file not recorded)."""
    files, sections, problems = read_params_files(params_files)
    record, warnings = session_record(
        session=session, start_ns=start_ns, parameters=dict(values), geometry=built['geometry'],
        program=built.get('program'), param_sections=sections, param_files=files, campaign=built.get('campaign'),
        program_keys=PROGRAM_KEYS, own_sections=OWN_SECTIONS,
        recorder={k: values[k] for k in RECORDING_KEYS} | {'node': node, 'time': 'simulated' if sim_time else 'wall'},
        ros_distro=os.environ.get('ROS_DISTRO', 'jazzy'), host=socket.gethostname())
    return record, [f'parameter file not recorded: {problem}' for problem in problems] + list(warnings)
