"""The session's metadata (the session record): how a recording of the rig describes itself, in MCAP Metadata
records of its bag.

Written by the session recorder (and by the synthetic sessions), read by the offline analysis. Three records:

- :data:`SESSION_METADATA`: software version, notes, rig geometry with the derived l0 and k, the test program, start
  time, and what the recorder knew (session name, the sensor sections and text of its parameter files, its own
  recording settings, ROS distro, host). Built by :func:`session_metadata` / :func:`session_record`, read by
  :func:`read_session`.
- :data:`NODE_PARAMETERS_METADATA`: the parameters the rig's nodes ran with, read from them over ROS,
  ``{node: JSON of {parameter: value}}``; read by :func:`read_node_parameters`.
- :data:`SESSION_END_METADATA`: added when the recording is closed (stop reason, end time, message counts; who
  stopped it, ``stopped_by``, when ~/stop was called).

MCAP metadata values are strings: everything that is not a string is stored as JSON
(:func:`crane_stiffness.bag.metadata.encode_metadata`). This module imports no ROS.
"""
from __future__ import annotations

import json
from collections.abc import Collection, Container, Mapping, Sequence
from typing import Any, Protocol, Union

from crane_stiffness import __version__
from crane_stiffness.bag.metadata import decode_metadata, encode_metadata
from crane_stiffness.contract import topics
from crane_stiffness.sim.program import LoadProgram

SESSION_METADATA = 'crane_stiffness/session'
"""Name of the MCAP Metadata record that describes a test session (rig, program, software, notes)."""
NODE_PARAMETERS_METADATA = 'crane_stiffness/node_parameters'
"""MCAP metadata record (written by session_recorder) of the parameters the rig's nodes ran with, read from the
nodes over ROS: {node name: JSON of {parameter: value}}. Preferred to the parameter files of the session record."""
SESSION_END_METADATA = 'crane_stiffness/session_end'
"""MCAP metadata record written when the recording is closed: stop reason, end time, message counts."""
CAMPAIGN_KEY = 'campaign'
"""Key of :data:`SESSION_METADATA` holding a campaign session's place (the recorder's ``campaign_entry``): campaign,
session id, series, weight, l0, height, repeat, program scale; for a simulated rig ``true_geometry`` (the
geometry.* parameters the crane_model node ran with) beside the record's ``rig.geometry`` (the nominal crane), and
``analysis_geometry``: 'nominal' (the analysis uses ``rig.geometry``, not the crane_model node's parameters); on
hardware ``confirmed`` (what the operator confirmed, how and when)."""


def analysis_geometry_params(session: Mapping[str, Any], node_parameters: Mapping[str, Mapping[str, Any]]
                             ) -> dict[str, Any] | None:
    """The geometry.* parameters the analysis models a session with: the nominal crane of the record's ``rig``
    when its campaign entry says ``analysis_geometry: nominal`` (a simulated crane that differs from the nominal
    one on purpose), else the crane_model node's parameters as it ran, else the record's ``rig.geometry``; None
    when neither was recorded."""
    rig = session.get('rig') if isinstance(session.get('rig'), dict) else None
    recorded = rig.get('geometry') if rig and isinstance(rig.get('geometry'), dict) else None
    campaign = session.get(CAMPAIGN_KEY)
    if isinstance(campaign, dict) and campaign.get('analysis_geometry') == 'nominal' and recorded:
        return dict(recorded)
    model = {k: v for k, v in node_parameters.get('crane_model', {}).items() if k.startswith('geometry.')}
    return model or (dict(recorded) if recorded else None)


class _HasMetadataRecords(Protocol):
    def metadata_records(self) -> dict[str, dict[str, str]]: ...


Records = Union[_HasMetadataRecords, Mapping[str, Mapping[str, str]]]
"""A :class:`~crane_stiffness.bag.BagReader` (anything with ``metadata_records()``), or its metadata records."""


class _Geometry(Protocol):
    l0: Any
    k: Any


# ------------------------------------------------------------------------------------------------------ writing --
def session_metadata(*, rig: Mapping[str, Any] | None = None, program: Any = None,
                     software_version: str = __version__, start_time_ns: int | None = None, notes: str = '',
                     **extra: Any) -> dict[str, str]:
    """Record for :data:`SESSION_METADATA`: rig geometry/parameters and program as JSON, version, start, notes."""
    data: dict[str, Any] = {'software_version': software_version, 'notes': notes}
    if rig is not None:
        data['rig'] = rig
    if program is not None:
        data['program'] = program
    if start_time_ns is not None:
        data['start_time_ns'] = str(int(start_time_ns))
    data.update(extra)
    return encode_metadata(data)


def session_record(*, session: str, start_ns: int, parameters: Mapping[str, Any], geometry: _Geometry,
                   program: LoadProgram | None, param_sections: Mapping[str, Mapping[str, Any]],
                   param_files: Sequence[Mapping[str, str]], program_keys: Collection[str],
                   own_sections: Container[str], recorder: Mapping[str, Any], ros_distro: str,
                   host: str, campaign: Mapping[str, Any] | None = None) -> tuple[dict[str, str], list[str]]:
    """The recorder's :data:`SESSION_METADATA` record, and warnings for the operator.

    Args:
        session: the bag's name.
        start_ns: start of the recording, ns since the epoch.
        parameters: the recorder's parameters (plain values): every ``geometry.*`` one, and ``notes``.
        geometry: the crane geometry built from them (its ``l0`` and ``k`` are recorded).
        program: the program set by the recorder's own parameters, or None; then the first section of
            ``param_sections`` that holds ``segments.kind`` (and is not one of ``own_sections``) is the program.
        param_sections: sections of the parameter files the recorder was started with, {node: flat parameters};
            those that are neither its own nor a program are recorded as the sensors' parameters.
        param_files: those files as ``{path, text}``.
        program_keys: the parameters that make up a program (those of the load_program node).
        own_sections: section names that hold the recorder's own parameters.
        recorder: the recorder's recording settings and node name.
        ros_distro, host: where the recording was made.
        campaign: the session's place in a test campaign (:data:`CAMPAIGN_KEY`), or None.
    """
    warnings: list[str] = []
    source = 'none'
    if program is not None:
        source = 'parameters'
    else:
        for name, section in param_sections.items():
            if name in own_sections or 'segments.kind' not in section:
                continue
            try:
                program = LoadProgram.from_params({k: v for k, v in section.items() if k in program_keys})
                source = f'parameter file section {name}'
            except ValueError as exc:
                warnings.append(f'program in parameter file section {name} is invalid: {exc}')
            break
    program_record = None
    if program is not None:
        program_record = {**program.to_params(), 'duration_s': program.duration_s, 'source': source}
    sensors = {name: section for name, section in param_sections.items()
               if name not in own_sections and 'segments.kind' not in section}
    rig = {'geometry': {k: parameters[k] for k in parameters if k.startswith('geometry.')},
           'l0': geometry.l0, 'k': geometry.k}
    extra: dict[str, Any] = {CAMPAIGN_KEY: dict(campaign)} if campaign else {}
    record = session_metadata(
        rig=rig, program=program_record, start_time_ns=start_ns, notes=parameters['notes'], session=session,
        sensors=sensors, config_files=list(param_files), recorder=dict(recorder), ros_distro=ros_distro, host=host,
        **extra)
    return record, warnings


# ------------------------------------------------------------------------------------------------------ reading --
def _records(source: Records) -> Mapping[str, Mapping[str, str]]:
    reader = getattr(source, 'metadata_records', None)
    return reader() if callable(reader) else source  # type: ignore[return-value]


#: The sensor streams every session measures with: one the recorder subscribed to that holds fewer messages than
#: :data:`MIN_STREAM_MESSAGES` makes the bag near empty (a driver that never delivered, a remapping to nowhere). Not
#: the pose sensor's: the recorder subscribes to it in every session, and only a six-axis program has one.
SENSOR_STREAMS = (topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT)
#: Fewer messages than this on a recorded sensor stream: the session measured nothing worth keeping (0.1 s at the
#: sensors' 1 kHz, 1 s of a DAQ polled at 100 Hz) [messages].
MIN_STREAM_MESSAGES = 100


def near_empty(recorded: Mapping[str, int]) -> str:
    """'' when every sensor stream the recorder subscribed to (a key of ``recorded``: topic -> messages in the bag)
    holds at least :data:`MIN_STREAM_MESSAGES`, else which do not, for people."""
    short = {t: int(recorded[t]) for t in SENSOR_STREAMS if t in recorded and int(recorded[t]) < MIN_STREAM_MESSAGES}
    if not short:
        return ''
    return ('the bag is near empty: ' + ', '.join(f'{t} {n} message(s)' for t, n in short.items())
            + f' (fewer than {MIN_STREAM_MESSAGES}): the sensor never delivered; nothing was measured')


def session_end_record(reason: str, end_ns: int, message_count: int, recorded: Mapping[str, int],
                       program_state: Mapping[str, Any], published: Mapping[str, int] | None = None,
                       published_through_ns: int | None = None, at_end: bool = False,
                       stopped_by: str | None = None) -> dict[str, Any]:
    """The :data:`SESSION_END_METADATA` record: why and when [ns of the recorder's clock] the recording ended, the
    messages in the bag (in all and per topic, ``recorded``) and the program's last state. On simulated time also
    ``published``: what the rig's nodes published per recorded topic through ``published_through_ns`` (their own
    counters, summed by the clock), ``missing``: what of it the bag lacks, and ``complete``: the session ended at the
    instant its program fixed (``at_end``) with nothing missing: the same bag at any load. ``stopped_by``: who
    called ~/stop, in words (the live view's client address and Origin, or a ROS service client:
    :mod:`crane_stiffness.contract.control_events`), for a recording stopped from outside. ``failed``, only when the
    bag is near empty (:func:`near_empty`): why the session failed."""
    record: dict[str, Any] = {'stop_reason': reason, 'end_time_ns': str(end_ns), 'message_count': message_count,
                              'topics': {t: n for t, n in recorded.items() if n}, 'program_state': dict(program_state)}
    if stopped_by is not None:
        record['stopped_by'] = stopped_by
    failed = near_empty(recorded)
    if failed:
        record['failed'] = failed
    if published:
        counted = {t: int(n) for t, n in sorted(published.items()) if t in recorded}
        missing = {t: n - recorded[t] for t, n in counted.items() if recorded[t] < n}
        record.update(published=counted, published_through_ns=str(published_through_ns), missing=missing,
                      complete=at_end and not missing)
    return record


def read_session_end(source: Records) -> dict[str, Any]:
    """The :data:`SESSION_END_METADATA` record with its JSON values decoded ({} when the bag has none: the recorder
    did not close it)."""
    return decode_metadata(_records(source).get(SESSION_END_METADATA, {}))


def cut_short(end: Mapping[str, Any]) -> str:
    """'' when a session's end record says its bag holds the whole run, else why not, for people: no end record
    (the recorder never closed the bag), a recording stopped from outside (~/stop) or by a write error, the node shut
    down before the program was done, a bag near empty (the record's ``failed``), or (simulated time) messages the
    rig published missing from the bag."""
    if not end:
        return 'the bag has no session end: the recorder did not close it (killed?)'
    reason = end.get('stop_reason', '?')
    program = end.get('program_state')
    state = program.get('state') if isinstance(program, dict) else None
    if reason == 'service':
        by = f' by {end["stopped_by"]}' if end.get('stopped_by') else ''
        return (f'the recording was stopped from outside (a ~/stop service call{by}) before the run\'s end, at '
                f'{int(end.get("end_time_ns", 0)) * 1e-9:.3f} s: the bag is not the whole run')
    if reason not in ('program done', 'shutdown') or (reason == 'shutdown' and state != 'done'):
        return f'the recording ended before the program did ({reason}): the bag is not the whole run'
    if end.get('failed'):
        return str(end['failed'])
    if str(end.get('complete', '')).lower() == 'false':  # (simulated time; the record keeps it as JSON text)
        return f'the bag lacks messages the rig published: {end.get("missing")}'
    return ''


def read_session(source: Records) -> dict[str, Any]:
    """The :data:`SESSION_METADATA` record with its JSON objects and arrays decoded ({} when the bag has none)."""
    return decode_metadata(_records(source).get(SESSION_METADATA, {}))


def read_node_parameters(source: Records) -> dict[str, dict[str, Any]]:
    """{node: {parameter: value}} of the :data:`NODE_PARAMETERS_METADATA` record ({} without one); node names
    without their leading slash."""
    out: dict[str, dict[str, Any]] = {}
    for node, text in _records(source).get(NODE_PARAMETERS_METADATA, {}).items():
        try:
            values = json.loads(text)
        except ValueError:
            continue
        if isinstance(values, dict):
            out[node.lstrip('/')] = values
    return out


__all__ = [
    'CAMPAIGN_KEY', 'MIN_STREAM_MESSAGES', 'NODE_PARAMETERS_METADATA', 'SENSOR_STREAMS', 'SESSION_END_METADATA',
    'SESSION_METADATA', 'analysis_geometry_params', 'cut_short', 'near_empty', 'read_node_parameters', 'read_session',
    'read_session_end', 'session_end_record', 'session_metadata', 'session_record',
]
