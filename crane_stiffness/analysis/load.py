"""Reading a recorded session for its offline analysis: the bag's records (session, node parameters, program,
geometry, the estimator's settings) and its streams decoded in bulk into numpy arrays
(crane_stiffness.bag.BagReader), plus the few messages read one by one (program state, the live estimator's last
estimate and input reports, from the ends of the bag only).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from crane_stiffness.contract import topics
from crane_stiffness.analysis.errors import SessionAnalysisError
from crane_stiffness.analysis.mapping import (MappingUsed, SensorMapping, check_topics, mapping_problems,
                                              mapping_used, settings_with_mapping)
from crane_stiffness.bag import BagReader
from crane_stiffness.contract.axes import AXES
from crane_stiffness.estimation.live import VALUE_FIELDS
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.serde.bulk import Columns
from crane_stiffness.serde import CdrError, decode_diagnostic_array, decode_float64_multiarray, decode_string
from crane_stiffness.bag.session_metadata import analysis_geometry_params, read_node_parameters, read_session
from crane_stiffness.sim.program import LoadProgram

OPTIONAL_TOPICS = (topics.WRENCH_COMMAND, topics.PROGRAM_STATE, topics.STIFFNESS_VALUES,
                   topics.PREDICTED_AXIS_STIFFNESS, topics.STIFFNESS)


@dataclass
class SessionData:
    """What :func:`load_session` read from a bag: its records, the recorded settings and the decoded streams."""

    path: Path
    session: dict[str, Any]
    counts: dict[str, int]
    topic_types: dict[str, str]
    program: LoadProgram | None
    program_record: dict[str, Any] | None
    geometry_params: dict[str, Any] | None
    settings: LiveSettings
    sensors: dict[str, Any]
    # The decoded streams, one column per field (serde.bulk.Columns: c['stamp_s'], c.size).
    force: Columns | None = None
    disp: Columns | None = None
    command: Columns | None = None
    rejected: Columns | None = None  # the crane model's rejected commands (/crane/rejected_command)
    live_series: Columns | None = None
    prediction: Columns | None = None
    states: list[tuple[int, dict[str, Any]]] = field(default_factory=list)
    live_values: tuple[int, np.ndarray] | None = None
    live_inputs: list[tuple[int, dict[str, str]]] = field(default_factory=list)
    start_ns: int | None = None
    end_ns: int | None = None
    message_count: int = 0
    #: The topics, displacement type and conversion and the geometry's source the analysis used.
    mapping: MappingUsed | None = None


def _program_from_record(record: Any, problems: list[str]) -> LoadProgram | None:
    if not isinstance(record, dict):
        return None
    try:
        return LoadProgram.from_params(record, strict=False)
    except (ValueError, TypeError) as exc:
        problems.append(f'recorded program is invalid ({exc}); steps come from the commands alone')
        return None


def _dominant_axis(program: LoadProgram | None) -> str | None:
    if program is None:
        return None
    axes = [s.axis for s in program.segments if s.kind != 'hold' or s.target != 0.0]
    return max(set(axes), key=axes.count) if axes else program.segments[0].axis


def _last_live_values(reader: BagReader, problems: list[str]) -> tuple[int, np.ndarray] | None:
    """(log time, rows) of the last recorded estimate with a finite stiffness, reading only the end of the bag."""
    end, start = reader.end_ns, reader.start_ns
    if end is None or start is None:  # an empty bag (both are None together)
        return None
    span = 2_000_000_000
    width = len(VALUE_FIELDS)
    while True:
        lo = None if end - span <= start else end - span
        last = None
        for msg in reader.messages([topics.STIFFNESS_VALUES], start_ns=lo):
            try:
                dims, data = decode_float64_multiarray(msg.data)
            except CdrError as exc:
                problems.append(f'unreadable {topics.STIFFNESS_VALUES} message at {msg.log_time_ns}: {exc}')
                continue
            if data.size != 2 * width:
                problems.append(f'{topics.STIFFNESS_VALUES} has {data.size} values, expected 2 x {width} '
                                f'({", ".join(VALUE_FIELDS)}); live comparison skipped')
                return None
            rows = data.reshape(2, width)
            if np.isfinite(rows[:, 0]).any():
                last = (msg.log_time_ns, rows)
        if last is not None or lo is None:
            return last
        span *= 8


def _input_status(data: bytes) -> dict[str, str] | None:
    try:
        statuses = decode_diagnostic_array(data)
    except (CdrError, UnicodeDecodeError):
        return None
    for _, name, _, _, values in statuses:
        if name.endswith(': input') and 'pairs' in values:
            return values
    return None


def _live_input_reports(reader: BagReader) -> list[tuple[int, dict[str, str]]]:
    """The first and the last input status the estimator published (/stiffness/estimate), reading only the start
    and the end of the bag."""
    start, end = reader.start_ns, reader.end_ns
    if start is None or end is None:
        return []
    window = 10_000_000_000

    def reports(lo: int | None, hi: int | None) -> list[tuple[int, dict[str, str]]]:
        out = []
        for msg in reader.messages([topics.STIFFNESS_ESTIMATE], start_ns=lo, end_ns=hi):
            values = _input_status(msg.data)
            if values is not None:
                out.append((msg.log_time_ns, values))
        return out

    head = reports(None, start + window)
    tail = reports(max(start + window, end - window), None)
    if not head or not tail:
        head = tail = reports(None, None)
    found = sorted({t: (t, v) for t, v in head[:1] + tail[-1:]}.values(), key=lambda r: r[0])
    return found



def load_session(path: Path, axis: str | None, problems: list[str], missing: list[str],
                 mapping: SensorMapping | None = None) -> SessionData:
    """Read a session's bag: records, settings and the streams the analysis needs, decoded in bulk.

    ``mapping`` (:mod:`crane_stiffness.analysis.mapping`) names the sensor topics (default the rig's,
    /load_cell/wrench and /lvdt/displacement), the displacement's type and conversion, estimator parameters from a
    file and a geometry, over what the bag records.

    ``axis`` overrides the analysed axis (default: the estimator's recorded ``force_axis``, else the program's
    dominant axis). Problems found on the way are appended to ``problems``, absent optional topics to ``missing``.

    Raises:
        BagNotFoundError / BagFormatError: no readable bag at ``path``.
        TopicNotFoundError: a sensor topic is missing (named, with the topics present).
        SessionAnalysisError: an unknown axis, or a sensor topic of an unexpected type (both types named).
        ParameterError / MappingError: a mapped value breaking the estimator's rules (named).
    """
    mapping = mapping or SensorMapping()
    reader = BagReader(path)
    try:
        known = reader.topics
        displacement_type = check_topics(mapping, known, path)
        for topic in OPTIONAL_TOPICS:
            if topic not in known or known[topic].count == 0:
                missing.append(topic)
        session = read_session(reader)
        nodes = read_node_parameters(reader)
        program_record = session.get('program') if isinstance(session.get('program'), dict) else None
        if 'segments.kind' in nodes.get('load_program', {}):  # what the load_program node actually ran
            program_record = {**nodes['load_program'], 'source': 'load_program node parameters'}
        program = _program_from_record(program_record, problems)
        recorded_sensors = session.get('sensors')
        sensors = dict(recorded_sensors) if isinstance(recorded_sensors, dict) else {}
        sensors.update(nodes)
        est_params = dict(sensors.get('stiffness_estimator') or sensors.get('/stiffness_estimator') or {})
        try:
            LiveSettings.from_params(est_params)
        except ValueError as exc:
            problems.append(f'recorded stiffness_estimator parameters are invalid ({exc}); using the defaults')
            est_params = {}
        # The mapping's parameter file and flags over the recorded parameters (ParameterError when they are bad).
        est_params, settings, sources = settings_with_mapping(est_params, mapping)
        chosen = axis or (est_params.get('force_axis') if 'force_axis' in est_params else None) \
            or _dominant_axis(program) or settings.force_axis
        if chosen not in AXES:
            raise SessionAnalysisError(f'axis = {chosen!r}: must be one of {", ".join(AXES)}')
        settings = replace(settings, force_axis=chosen)
        # The crane_model node's geometry as it ran, unless the record says the simulated crane differs from the
        # nominal one on purpose (a campaign's true crane): then the nominal one, as the analysis of a real crane;
        # a geometry given with the mapping (--config) over either.
        geometry_params = analysis_geometry_params(session, nodes)
        geometry_source = 'recorded with the session' if geometry_params is not None else 'none'
        if mapping.geometry_params is not None:
            geometry_params = dict(mapping.geometry_params)
            geometry_source = mapping.geometry_source or 'given'
        if geometry_params is None:
            problems.append('no rig geometry recorded: no model curves (give --config CRANE.yaml)')
        used = mapping_used(mapping, known, displacement_type, settings, sources, geometry_source)
        problems += mapping_problems(used, mapping)
        data = SessionData(path=path, session=session, counts={t: i.count for t, i in known.items()},
                     topic_types={t: i.msg_type for t, i in known.items()}, program=program,
                     program_record=program_record, geometry_params=geometry_params, settings=settings,
                     sensors=sensors, start_ns=reader.start_ns, end_ns=reader.end_ns,
                     message_count=reader.message_count, mapping=used)
        wanted = [mapping.wrench_topic, mapping.displacement_topic]
        for topic, msg_type in ((topics.WRENCH_COMMAND, 'geometry_msgs/msg/WrenchStamped'),
                                (topics.REJECTED_COMMAND, 'geometry_msgs/msg/WrenchStamped'),
                                (topics.PREDICTED_AXIS_STIFFNESS, 'std_msgs/msg/Float64'),
                                (topics.STIFFNESS, 'std_msgs/msg/Float64')):
            if topic in known and known[topic].count and known[topic].msg_type == msg_type:
                wanted.append(topic)
        arrays = reader.decode_topics(wanted, columns=True)
        data.force = arrays[mapping.wrench_topic]
        data.disp = arrays[mapping.displacement_topic]
        data.command = arrays.get(topics.WRENCH_COMMAND)
        data.rejected = arrays.get(topics.REJECTED_COMMAND)
        data.prediction = arrays.get(topics.PREDICTED_AXIS_STIFFNESS)
        data.live_series = arrays.get(topics.STIFFNESS)
        if topics.PROGRAM_STATE in known and known[topics.PROGRAM_STATE].count:
            for msg in reader.messages([topics.PROGRAM_STATE]):
                try:
                    state = json.loads(decode_string(msg.data))
                except (CdrError, ValueError):
                    continue
                if isinstance(state, dict):
                    data.states.append((msg.log_time_ns, state))
        if topics.STIFFNESS_VALUES in known and known[topics.STIFFNESS_VALUES].count:
            data.live_values = _last_live_values(reader, problems)
        if topics.STIFFNESS_ESTIMATE in known and known[topics.STIFFNESS_ESTIMATE].count:
            data.live_inputs = _live_input_reports(reader)
        return data
    finally:
        reader.close()
