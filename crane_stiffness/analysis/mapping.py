"""Which recorded topics the offline analysis reads and how it turns them into load and displacement: the
counterpart of the stiffness_estimator node's remaps (``-r /load_cell/wrench:=/netft_data``) and of its
``displacement_type``, ``displacement_gain`` and ``displacement_offset`` parameters, for a bag a lab recorded with
its own drivers' topic names and units (``ros2 bag record /netft_data /daq/ch0``), and the geometry to model it with
when the bag does not record one. Pure: no ROS import.

:class:`SensorMapping` is what the caller asks for (``analyze``/``compare`` flags; None: not given);
:func:`resolve_mapping` checks it against the bag's topics and says what was used (:class:`MappingUsed`, written to
the report and the JSON). The conversion of a Float64 reading in volts is the estimator's own
(:meth:`~crane_stiffness.estimation.settings.LiveSettings.volts_to_displacement`), and as live a Float64, which has
no stamp, is taken at its arrival: the bag's log time (the recorder's receipt time) stands in for the sample's
instant as the live node's receipt time does.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from crane_stiffness.analysis.errors import MappingError, SessionAnalysisError
from crane_stiffness.bag import TopicNotFoundError
from crane_stiffness.contract import topics
from crane_stiffness.errors import ParameterError
from crane_stiffness.estimation.settings import DISPLACEMENT_MSG_TYPES, DISPLACEMENT_TYPES, LiveSettings

WRENCH_MSG_TYPE = 'geometry_msgs/msg/WrenchStamped'
#: The estimator parameters a mapping sets (the rest come from the bag's record or a parameter file).
MAPPING_PARAMS = ('displacement_type', 'displacement_gain', 'displacement_offset')


@dataclass(frozen=True)
class SensorMapping:
    """The topics, the displacement's message type and conversion, and the geometry asked for; None (or the
    package's own topic names) where nothing was asked.

    Attributes:
        wrench_topic: the F/T sensor's geometry_msgs/WrenchStamped topic, as recorded.
        displacement_topic: the displacement topic, as recorded.
        displacement_type: 'point_stamped' (PointStamped, point.x in m, header stamp) or 'float64' (std_msgs/Float64
            in V, taken at its log time); None: the bag's message type says which.
        displacement_gain: Float64 channel: metres per volt [m/V]; None: recorded, else the parameter file, else 1.
        displacement_offset: Float64 channel: metres at 0 V [m]; None: as the gain.
        estimator_params: stiffness_estimator parameters from a ROS parameter file (``--params-file``): over the
            recorded ones, under the flags above; ``estimator_params_source`` names the file.
        geometry_params: geometry.* parameters (``--config CRANE.yaml``): over the recorded geometry;
            ``geometry_source`` names where they came from.
    """

    wrench_topic: str = topics.LOAD_CELL_WRENCH
    displacement_topic: str = topics.LVDT_DISPLACEMENT
    displacement_type: str | None = None
    displacement_gain: float | None = None
    displacement_offset: float | None = None
    estimator_params: Mapping[str, Any] | None = None
    estimator_params_source: str = ''
    geometry_params: Mapping[str, Any] | None = None
    geometry_source: str = ''

    def __post_init__(self) -> None:
        for name in ('wrench_topic', 'displacement_topic'):
            value = getattr(self, name)
            if not isinstance(value, str) or not value.startswith('/') or len(value) < 2:
                raise MappingError(name, value, "must be a topic name as the bag records it, starting with '/'")
        if self.wrench_topic == self.displacement_topic:
            raise MappingError('displacement_topic', self.displacement_topic,
                               f'must differ from wrench_topic = {self.wrench_topic!r}')
        if self.displacement_type is not None and self.displacement_type not in DISPLACEMENT_TYPES:
            raise MappingError('displacement_type', self.displacement_type,
                               f'must be one of {", ".join(DISPLACEMENT_TYPES)}')
        given = {k: v for k, v in (('displacement_gain', self.displacement_gain),
                                   ('displacement_offset', self.displacement_offset)) if v is not None}
        if given:
            LiveSettings.from_params(given)  # the estimator's rules and words: finite, a non-zero gain

    def asked_displacement_type(self) -> str | None:
        """The displacement type asked for: the flag's, else the parameter file's, else None (the bag's message
        type decides).

        Raises:
            MappingError: a parameter file's displacement_type that is not one of the choices.
        """
        if self.displacement_type is not None:
            return self.displacement_type
        value = (self.estimator_params or {}).get('displacement_type')
        if value is not None and value not in DISPLACEMENT_TYPES:
            raise MappingError('displacement_type', value, f'must be one of {", ".join(DISPLACEMENT_TYPES)} (from '
                               f'{self.estimator_params_source or "the parameter file"})')
        return value

    def estimator_overrides(self) -> dict[str, Any]:
        """The estimator parameters this mapping sets over the recorded ones: the parameter file's, then the
        flags'."""
        out = dict(self.estimator_params or {})
        for name in MAPPING_PARAMS:
            value = getattr(self, name)
            if value is not None:
                out[name] = value
        return out


@dataclass
class MappingUsed:
    """What the analysis read, as the report and the JSON say it."""

    wrench_topic: str
    wrench_msg_type: str
    displacement_topic: str
    displacement_msg_type: str
    displacement_type: str
    displacement_gain: float
    displacement_offset: float
    conversion: str
    sample_instant: str
    geometry_source: str
    sources: dict[str, str] = field(default_factory=dict)
    """Where each of displacement_type, displacement_gain, displacement_offset came from: 'flag', the parameter
    file, 'recorded' (the session's estimator parameters), 'the bag's message type' or 'default'."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _present(known: Mapping[str, Any]) -> str:
    return ', '.join(f'{t} [{i.msg_type}]' for t, i in sorted(known.items())) or 'none'


def check_topics(mapping: SensorMapping, known: Mapping[str, Any], where: Any) -> str:
    """Check the mapping's topics against the bag's (``known``: topic → info with ``msg_type``) and return the
    displacement type they make: the one asked for, else the one the recorded message type says.

    Raises:
        TopicNotFoundError: a topic not in the bag (named, with the topics present and their types).
        SessionAnalysisError: a topic of another type than expected (both types named).
    """
    for name, topic in (('wrench_topic', mapping.wrench_topic), ('displacement_topic', mapping.displacement_topic)):
        if topic not in known:
            raise TopicNotFoundError(f'{where}: required topic {topic} is not in the bag ({name}; topics present: '
                                     f'{_present(known)})')
    wrench_type = known[mapping.wrench_topic].msg_type
    if wrench_type != WRENCH_MSG_TYPE:
        raise SessionAnalysisError(f'{where}: wrench_topic {mapping.wrench_topic} has type {wrench_type}, expected '
                                   f'{WRENCH_MSG_TYPE}')
    disp_type = known[mapping.displacement_topic].msg_type
    asked = mapping.asked_displacement_type()
    if asked is not None:
        expected = DISPLACEMENT_MSG_TYPES[asked]
        if disp_type != expected:
            raise SessionAnalysisError(f'{where}: displacement_topic {mapping.displacement_topic} has type '
                                       f'{disp_type}, but displacement_type {asked} expects {expected}')
        return asked
    for kind, msg_type in DISPLACEMENT_MSG_TYPES.items():
        if msg_type == disp_type:
            return kind
    accepted = ', '.join(f'{v} ({k})' for k, v in DISPLACEMENT_MSG_TYPES.items())
    raise SessionAnalysisError(f'{where}: displacement_topic {mapping.displacement_topic} has type {disp_type}, '
                               f'expected {accepted}')


def settings_with_mapping(recorded_params: Mapping[str, Any], mapping: SensorMapping
                          ) -> tuple[dict[str, Any], LiveSettings, dict[str, str]]:
    """The estimator parameters and settings the analysis runs with: the recorded ones (``recorded_params``, valid)
    under the mapping's parameter file and flags; and where each mapped parameter came from.

    Raises:
        ParameterError naming the parameter and its value (a parameter file's or a flag's value breaking the
        estimator's rules), and where it came from.
    """
    file_params = dict(mapping.estimator_params or {})
    values = {**recorded_params, **mapping.estimator_overrides()}
    try:
        settings = LiveSettings.from_params(values)
    except ParameterError as exc:
        source = 'flag' if getattr(mapping, exc.field, None) is not None else (
            mapping.estimator_params_source or 'parameter file') if exc.field in file_params else 'recorded'
        raise ParameterError(exc.field, exc.value, f'{exc.rule} (from {source})') from None
    sources: dict[str, str] = {}
    for name in MAPPING_PARAMS:
        if getattr(mapping, name, None) is not None:
            sources[name] = 'flag'
        elif name in file_params:
            sources[name] = mapping.estimator_params_source or 'parameter file'
        elif name == 'displacement_type':
            sources[name] = "the bag's message type"
        elif name in recorded_params:
            sources[name] = 'recorded'
        else:
            sources[name] = 'default'
    return values, settings, sources


def mapping_used(mapping: SensorMapping, known: Mapping[str, Any], displacement_type: str, settings: LiveSettings,
                 sources: dict[str, str], geometry_source: str) -> MappingUsed:
    """The record of what was read and how (:class:`MappingUsed`)."""
    if displacement_type == 'float64':
        offset = settings.displacement_offset
        conversion = (f'reading = {settings.displacement_gain:g} m/V × volts {"-" if offset < 0 else "+"} '
                      f'{abs(offset):g} m (displacement_gain, displacement_offset)')
        instant = 'each sample taken at its log time (a Float64 has no stamp; the recorder\'s receipt time, as ' \
                  'the live estimator takes its own)'
    else:
        conversion = 'point.x in m as recorded'
        instant = 'each sample taken at its header stamp'
    if settings.displacement_delay_s:
        instant += f', less displacement_delay_s = {settings.displacement_delay_s:g} s'
    return MappingUsed(wrench_topic=mapping.wrench_topic, wrench_msg_type=known[mapping.wrench_topic].msg_type,
                       displacement_topic=mapping.displacement_topic,
                       displacement_msg_type=known[mapping.displacement_topic].msg_type,
                       displacement_type=displacement_type, displacement_gain=settings.displacement_gain,
                       displacement_offset=settings.displacement_offset, conversion=conversion,
                       sample_instant=instant, geometry_source=geometry_source, sources=sources)


def mapping_problems(used: MappingUsed, mapping: SensorMapping) -> list[str]:
    """What the report should say about a mapping that does less than asked (a gain on a PointStamped)."""
    out = []
    if used.displacement_type == 'point_stamped' and (mapping.displacement_gain is not None or
                                                      mapping.displacement_offset is not None):
        out.append('displacement_gain and displacement_offset apply to a float64 channel only: not used for the '
                   f'PointStamped {used.displacement_topic} (as the live estimator)')
    if used.displacement_type == 'float64' and used.sources.get('displacement_gain') == 'default' and \
            math.isclose(used.displacement_gain, 1.0):
        out.append(f'{used.displacement_topic} is a float64 channel read with the default displacement_gain 1 m/V: '
                   'give --displacement-gain (and --displacement-offset) as the live estimator has them')
    return out


__all__ = ['MAPPING_PARAMS', 'MappingUsed', 'SensorMapping', 'WRENCH_MSG_TYPE', 'check_topics', 'mapping_problems',
           'mapping_used', 'settings_with_mapping']
