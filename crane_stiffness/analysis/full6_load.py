"""Reading a six-axis session for its offline 6×6 analysis (crane_stiffness.analysis.full6): the three streams the
pairs are built from, decoded in bulk (crane_stiffness.bag.BagReader), the load cell's wrench moved to the platform
centre, and the settings the session ran with. Pure: no ROS import.

**Streams** (crane_stiffness.contract.topics): ``/crane/wrench_command`` (the load steps), ``/load_cell/wrench`` and
``/pose_sensor/pose``. Samples with a non-finite value or stamp are left out (the node drops them before pairing);
the sensor streams are put in log-time order (their arrival at the recorder, which decides what is stale as live),
the commands in stamp order.

**Settings**: ``settle_s``, ``max_gap_s``, ``max_age_s`` (crane_stiffness.full6.pairs), ``wrench_noise`` (six
standard deviations [N, N·m] of the load cell per pair; absent or empty: estimated from the steps) and
``confidence`` of the ``stiffness6_estimator`` node as recorded with the session (its running parameters,
``crane_stiffness/node_parameters``, else its section of the parameter files in the session record), else the
defaults. The load cell's mounting (crane_stiffness.estimation.frames.SensorMount: ``sensor_rotation``,
``sensor_position``, ``sensor_reaction``) is read where the 1-D analysis reads it, the ``stiffness_estimator``'s
parameters, unless ``stiffness6_estimator`` declares its own.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numpy.typing import NDArray

from crane_stiffness.contract import topics
from crane_stiffness.analysis.errors import SessionAnalysisError
from crane_stiffness.contract.axes import AXES
from crane_stiffness.bag import BagReader, TopicNotFoundError
from crane_stiffness.estimation.errors import ParameterError
from crane_stiffness.estimation.frames import SensorMount
from crane_stiffness.full6.errors import Full6InputError
from crane_stiffness.full6.full_scale import at_full_scale, check_full_scale, full_scale_note
from crane_stiffness.full6.identify import CONFIDENCE
from crane_stiffness.full6.pairs import DEFAULT_MAX_AGE_S, DEFAULT_MAX_GAP_S
from crane_stiffness.model import CraneGeometry, GeometryError
from crane_stiffness.params.geometry import geometry_from_params
from crane_stiffness.bag.session_metadata import analysis_geometry_params, read_node_parameters, read_session

#: The streams a six-axis session needs.
FULL6_TOPICS = (topics.WRENCH_COMMAND, topics.LOAD_CELL_WRENCH, topics.POSE_SENSOR_POSE)
#: The node whose recorded parameters set the pairing and the fit.
ESTIMATOR6 = 'stiffness6_estimator'
#: settle_s when none is recorded: the first 0.5 s of each step left out (the designed programs' settling) [s].
DEFAULT_SETTLE_S = 0.5
_TYPES = {topics.WRENCH_COMMAND: 'geometry_msgs/msg/WrenchStamped',
          topics.LOAD_CELL_WRENCH: 'geometry_msgs/msg/WrenchStamped',
          topics.POSE_SENSOR_POSE: 'geometry_msgs/msg/PoseStamped'}


@dataclass(frozen=True)
class Full6Settings:
    """How the pairs are built and fitted. settle_s, max_gap_s, max_age_s [s]; wrench_noise (6,) [N, N·m] or None
    (estimated from the steps); confidence of the intervals; mount: the load cell's mounting; source, mount_source:
    where they were read."""

    settle_s: float = DEFAULT_SETTLE_S
    max_gap_s: float = DEFAULT_MAX_GAP_S
    max_age_s: float = DEFAULT_MAX_AGE_S
    wrench_noise: tuple[float, ...] | None = None
    confidence: float = CONFIDENCE
    mount: SensorMount = field(default_factory=SensorMount)
    source: str = 'defaults'
    mount_source: str = 'default (at the platform centre, aligned)'
    full_scale: tuple[float, ...] = (0.0,) * 6
    """The load cell's full scale (6,) [N, N·m], its frame; 0 = unchecked (crane_stiffness.full6.full_scale)."""

    def to_dict(self) -> dict[str, Any]:
        m = self.mount
        return {'settle_s': self.settle_s, 'max_gap_s': self.max_gap_s, 'max_age_s': self.max_age_s,
                'wrench_noise': None if self.wrench_noise is None else list(self.wrench_noise),
                'confidence': self.confidence, 'source': self.source,
                'sensor_rotation': m.rotation.tolist(), 'sensor_position': m.position.tolist(),
                'sensor_reaction': m.reaction, 'mount_source': self.mount_source,
                'load_cell_full_scale': list(self.full_scale)}


@dataclass
class Full6Data:
    """A six-axis session read from its bag.

    Attributes:
        path: the bag; session: its session record; geometry: the crane the analysis models (None: not recorded).
        settings: :class:`Full6Settings`.
        command_stamp (n_c,) [s], command_wrench (n_c, 6) [N, N·m]: the commands, stamp order, crane_base.
        wrench_stamp, wrench_log (n_w,) [s]: the load cell's stamps and log times, log-time order;
        wrench (n_w, 6) [N, N·m]: its wrench at the platform centre in crane_base, applied to the platform.
        pose_stamp, pose_log (n_p,) [s]; position (n_p, 3) [m]; quaternion (n_p, 4) [x, y, z, w], body → crane_base.
        counts: messages per topic in the bag; dropped: non-finite samples left out per topic.
        start_ns, end_ns: the bag's first and last log time [ns].
        saturated: load-cell samples left out at full scale, per axis (6,) (crane_stiffness.full6.full_scale).
        sensors: the recorded parameters of each node by name (the sensors' declared calibrations among them).
    """

    path: Path
    session: dict[str, Any]
    geometry: CraneGeometry | None
    settings: Full6Settings
    command_stamp: NDArray[np.float64]
    command_wrench: NDArray[np.float64]
    wrench_stamp: NDArray[np.float64]
    wrench_log: NDArray[np.float64]
    wrench: NDArray[np.float64]
    pose_stamp: NDArray[np.float64]
    pose_log: NDArray[np.float64]
    position: NDArray[np.float64]
    quaternion: NDArray[np.float64]
    counts: dict[str, int]
    dropped: dict[str, int]
    start_ns: int | None
    end_ns: int | None
    saturated: NDArray[np.int64] = field(default_factory=lambda: np.zeros(6, dtype=np.int64))
    sensors: dict[str, dict[str, Any]] = field(default_factory=dict)


def is_full6_bag(path: str | Path) -> bool:
    """True when the bag at ``path`` holds pose sensor messages (``/pose_sensor/pose``): a six-axis session."""
    with BagReader(Path(path)) as reader:
        info = reader.topics.get(topics.POSE_SENSOR_POSE)
        return info is not None and info.count > 0


def _number(params: Mapping[str, Any], name: str, default: float, ok: Any, rule: str, problems: list[str]) -> float:
    value = params.get(name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or not ok(value):
        problems.append(f'{ESTIMATOR6} parameter {name} = {value!r} is invalid ({rule}): using {default:g}')
        return default
    return float(value)


def read_settings(params: Mapping[str, Mapping[str, Any]], problems: list[str]) -> Full6Settings:
    """:class:`Full6Settings` from the recorded parameters ``{node: {parameter: value}}`` (module docstring); a bad
    value is named in ``problems`` and replaced by its default."""
    own = dict(params.get(ESTIMATOR6) or {})
    one_axis = dict(params.get('stiffness_estimator') or {})
    settle = _number(own, 'settle_s', DEFAULT_SETTLE_S, lambda v: v >= 0.0, 'a number >= 0 (s)', problems)
    gap = _number(own, 'max_gap_s', DEFAULT_MAX_GAP_S, lambda v: v > 0.0, 'a number > 0 (s)', problems)
    age = _number(own, 'max_age_s', DEFAULT_MAX_AGE_S, lambda v: v > 0.0, 'a number > 0 (s)', problems)
    confidence = _number(own, 'confidence', CONFIDENCE, lambda v: 0.0 < v < 1.0, 'in (0, 1)', problems)
    noise = own.get('wrench_noise')
    wrench_noise: tuple[float, ...] | None = None
    if noise is not None and len(noise):
        values = np.asarray(noise, dtype=float).reshape(-1) if isinstance(noise, (list, tuple)) else np.zeros(0)
        if values.shape == (6,) and np.all(np.isfinite(values) & (values >= 0.0)):
            wrench_noise = tuple(float(v) for v in values)
        else:
            problems.append(f'{ESTIMATOR6} parameter wrench_noise = {noise!r} is invalid (six standard deviations '
                            '>= 0, N and N·m): estimated from the steps instead')
    has_own_mount = any(k in own for k in SensorMount.PARAM_NAMES)
    mount_params, mount_source = (own, f'{ESTIMATOR6} parameters') if has_own_mount else \
        (one_axis, 'stiffness_estimator parameters (as the 1-D analysis)')
    if not any(k in mount_params for k in SensorMount.PARAM_NAMES):
        mount_params, mount_source = {}, Full6Settings.mount_source
    try:
        mount = SensorMount.from_params(mount_params)
    except ParameterError as exc:
        problems.append(f'the load cell\'s recorded mounting is invalid ({exc}): taken at the platform centre')
        mount, mount_source = SensorMount(), Full6Settings.mount_source
    full_scale: tuple[float, ...] = (0.0,) * 6
    if 'load_cell_full_scale' in own:
        try:
            full_scale = tuple(float(v) for v in check_full_scale(own['load_cell_full_scale']))
        except (Full6InputError, TypeError, ValueError) as exc:
            problems.append(f'{ESTIMATOR6} parameter {exc}: no sample checked against a full scale')
    source = f'{ESTIMATOR6} parameters' if own else 'defaults (no stiffness6_estimator parameters recorded)'
    return Full6Settings(settle, gap, age, wrench_noise, confidence, mount, source, mount_source, full_scale)


def _geometry(session: dict[str, Any], nodes: dict[str, dict[str, Any]], problems: list[str]) -> CraneGeometry | None:
    params = analysis_geometry_params(session, nodes)
    if params is None:
        problems.append('no rig geometry recorded: no comparison with the model')
        return None
    try:
        return geometry_from_params(params)
    except (GeometryError, ValueError) as exc:
        problems.append(f'recorded geometry invalid: {exc}: no comparison with the model')
        return None


def load_full6(path: str | Path, problems: list[str]) -> Full6Data:
    """Read a six-axis session (module docstring); problems found on the way are appended to ``problems``.

    Raises:
        BagNotFoundError / BagFormatError: no readable bag at ``path``.
        TopicNotFoundError: one of :data:`FULL6_TOPICS` is missing (named, with the topics present).
        SessionAnalysisError: a topic of another message type.
    """
    path = Path(path)
    with BagReader(path) as reader:
        known = reader.topics
        for topic in FULL6_TOPICS:
            if topic not in known or not known[topic].count:
                present = ', '.join(f'{t} [{i.msg_type}]' for t, i in sorted(known.items())) or 'none'
                raise TopicNotFoundError(f'{path}: the 6×6 analysis needs {topic}, which the bag does not hold '
                                         f'(topics present: {present})')
            if known[topic].msg_type != _TYPES[topic]:
                raise SessionAnalysisError(f'{topic} has type {known[topic].msg_type}, expected {_TYPES[topic]}')
        session = read_session(reader)
        nodes = read_node_parameters(reader)
        recorded = session.get('sensors')
        params = dict(recorded) if isinstance(recorded, dict) else {}
        params.update(nodes)
        if topics.REJECTED_COMMAND in known and known[topics.REJECTED_COMMAND].count:
            problems.append(f'{known[topics.REJECTED_COMMAND].count} command(s) were rejected by the crane model: '
                            'their stretches are labelled as commanded (the load cell measured what was applied)')
        arrays = reader.decode_topics(list(FULL6_TOPICS), columns=True)
        start_ns, end_ns = reader.start_ns, reader.end_ns
        counts = {t: i.count for t, i in known.items()}
    settings = read_settings(params, problems)
    c, w, p = (arrays[t] for t in FULL6_TOPICS)
    c_wrench = np.column_stack([c[k] for k in AXES]).astype(float)
    keep = np.isfinite(c['stamp_s']) & np.all(np.isfinite(c_wrench), axis=1)
    c_order = np.flatnonzero(keep)[np.argsort(c['stamp_s'][keep], kind='stable')]
    w_raw = np.column_stack([w[k] for k in AXES]).astype(float)
    w_keep = np.isfinite(w['stamp_s']) & np.all(np.isfinite(w_raw), axis=1)
    at = at_full_scale(np.where(np.isfinite(w_raw), w_raw, 0.0), settings.full_scale) & w_keep[:, None]
    saturated = at.sum(axis=0).astype(np.int64)  # per axis; a sample at full scale on any axis is left out
    w_keep &= ~at.any(axis=1)
    w_order = np.flatnonzero(w_keep)[np.argsort(w['log_time_ns'][w_keep], kind='stable')]
    p_raw = np.column_stack([p[k] for k in ('x', 'y', 'z', 'qx', 'qy', 'qz', 'qw')]).astype(float)
    p_keep = np.isfinite(p['stamp_s']) & np.all(np.isfinite(p_raw), axis=1) & (np.abs(p_raw[:, 3:]).sum(axis=1) > 0)
    p_order = np.flatnonzero(p_keep)[np.argsort(p['log_time_ns'][p_keep], kind='stable')]
    dropped = {topics.WRENCH_COMMAND: int((~keep).sum()), topics.LOAD_CELL_WRENCH: int((~w_keep).sum()),
               topics.POSE_SENSOR_POSE: int((~p_keep).sum())}
    for topic, n in dropped.items():
        if n:
            problems.append(f'{n} message(s) of {topic} with a non-finite value or stamp were left out')
    if saturated.any():
        problems.append(f'{int(at.any(axis=1).sum())} message(s) of {topics.LOAD_CELL_WRENCH}: '
                        + full_scale_note(saturated))
    wrench = w_raw[w_order] if settings.mount.is_identity else settings.mount.apply(w_raw[w_order])
    return Full6Data(path=path, session=session, geometry=_geometry(session, nodes, problems), settings=settings,
                     command_stamp=c['stamp_s'][c_order], command_wrench=c_wrench[c_order],
                     wrench_stamp=w['stamp_s'][w_order], wrench_log=w['log_time_ns'][w_order] * 1e-9,
                     wrench=wrench, pose_stamp=p['stamp_s'][p_order], pose_log=p['log_time_ns'][p_order] * 1e-9,
                     position=p_raw[p_order, :3], quaternion=p_raw[p_order, 3:], counts=counts, dropped=dropped,
                     start_ns=start_ns, end_ns=end_ns, saturated=saturated,
                     sensors={k: dict(v) for k, v in params.items() if isinstance(v, dict)})


__all__ = ['DEFAULT_SETTLE_S', 'ESTIMATOR6', 'FULL6_TOPICS', 'Full6Data', 'Full6Settings', 'is_full6_bag',
           'load_full6', 'read_settings']
