"""What every node shares: parameters declared with descriptions and validated on start and on change, QoS
profiles, a diagnostics publisher, message helpers and ``run`` (the ``main`` of every node).
"""
from __future__ import annotations

import difflib
import json
import math
import sys
import time
from array import array
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Sequence

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidTopicNameException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.validate_topic_name import validate_topic_name
import yaml

from crane_stiffness import topics
from crane_stiffness.serde import stamp_seconds
from crane_stiffness.config import ParamSpec
from crane_stiffness.param_files import ParamFile, applicable_sections, params_files_from_args
from crane_stiffness.sim.sampling import SampleClock


def rclpy_qos(qos: topics.QoS, depth: int | None = None) -> QoSProfile:
    """The rclpy profile of a QoS class of crane_stiffness.topics (KEEP_LAST; ``depth`` overrides the class's)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=qos.depth if depth is None else depth,
                      reliability=ReliabilityPolicy[qos.reliability.upper()],
                      durability=DurabilityPolicy[qos.durability.upper()])


#: The rig's three QoS classes (crane_stiffness.topics.TOPIC_QOS says which topic has which).
RELIABLE_QOS = rclpy_qos(topics.RELIABLE)
SENSOR_QOS = rclpy_qos(topics.SENSOR_DATA)
LATCHED_QOS = rclpy_qos(topics.LATCHED)


#: Modules of the package's nodes (crane_stiffness.nodes.<module>.PARAMS): the parameter names a ``/**`` section of a
#: parameter file may hold.
NODE_MODULES = ('load_program', 'crane_model', 'load_cell', 'lvdt', 'stiffness_estimator', 'session_recorder',
                'session_player', 'netft', 'modbus_lvdt', 'rdt_emulator', 'modbus_emulator')
#: Parameters rclpy declares on every node (plus the ``qos_overrides.`` family).
RCLPY_PARAMS = ('use_sim_time', 'start_type_description_service')


def show(value: Any) -> str:
    """A parameter value as the user wrote it: lists (rclpy hands arrays back as array('d', ...)) as [...]."""
    if isinstance(value, (array, tuple)):
        value = list(value)
    return repr(value)


_KINDS = ((bool, 'true or false', 'booleans'), (float, 'a number', 'numbers'), (int, 'an integer', 'integers'),
          (str, 'a string', 'strings'))


def _kind(default: Any) -> str:
    """What a value of the type of ``default`` is, in words ('a number', 'a list of strings')."""
    if isinstance(default, (list, tuple)):
        plural = next((p for t, _, p in _KINDS if default and isinstance(default[0], t)), None)
        return f'a list of {plural}' if plural else 'a list'
    return next((one for t, one, _ in _KINDS if isinstance(default, t)), 'a value')


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def coerce(spec: ParamSpec, value: Any) -> Any:
    """``value`` in the type of ``spec``'s default: an integer where a float is declared becomes a float (also in
    lists); any other mismatch raises ValueError('name = value: must be ...')."""
    d = spec.default
    if isinstance(value, (array, tuple)):
        value = list(value)
    if isinstance(d, bool):
        ok = isinstance(value, bool)
    elif isinstance(d, float):
        ok = _is_number(value)
        value = float(value) if ok else value
    elif isinstance(d, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(d, str):
        ok = isinstance(value, str)
    elif isinstance(d, (list, tuple)):
        ok = isinstance(value, list)
        if ok and d and isinstance(d[0], float):
            ok = all(_is_number(v) for v in value)
            value = [float(v) for v in value] if ok else value
        elif ok and d:
            ok = all(type(v) is type(d[0]) for v in value)
    else:
        ok = True
    check(ok, spec.name, value, f'must be {_kind(d)}')
    return value


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """The descriptor ``ros2 param describe`` shows: description, range (where the rule is an inclusive range of a
    scalar) and the rule in words."""
    d = ParameterDescriptor(description=spec.description)
    rules = []
    if spec.low is not None or spec.high is not None:
        if isinstance(spec.default, float):
            d.floating_point_range = [FloatingPointRange(
                from_value=float(spec.low if spec.low is not None else -sys.float_info.max),
                to_value=float(spec.high if spec.high is not None else sys.float_info.max), step=0.0)]
        elif isinstance(spec.default, int) and not isinstance(spec.default, bool):
            d.integer_range = [IntegerRange(from_value=int(spec.low if spec.low is not None else -2**63),
                                            to_value=int(spec.high if spec.high is not None else 2**63 - 1),
                                            step=1)]
        rules.append(_range_text(spec))
    if spec.rule:
        rules.append(spec.rule)
    d.additional_constraints = '; '.join(rules)
    return d


def _range_text(spec: ParamSpec) -> str:
    if spec.low is not None and spec.high is not None:
        return f'{spec.low} .. {spec.high}'
    return f'>= {spec.low}' if spec.low is not None else f'<= {spec.high}'


def check_range(spec: ParamSpec, value: Any) -> None:
    """The inclusive range of ``spec`` (low/high), in our words (rclpy enforces the same range at runtime)."""
    if (spec.low is None and spec.high is None) or not _is_number(value):
        return
    ok = math.isfinite(value) and (spec.low is None or value >= spec.low) and (spec.high is None or value <= spec.high)
    check(ok, spec.name, value, f'must be {_range_text(spec)}')


class Params:
    """A node's parameters: declared with descriptions, ranges and rules, validated as a whole on start and on every
    change, by the same code.

    ``validate(values) -> Any`` raises ValueError naming the bad value; its return value (e.g. a built geometry)
    is handed to ``apply``. A rejected change leaves every value as it was and tells the caller why. Integers are
    accepted where a float is declared, at start (``-p name:=1``, parameter files) and at runtime (a pre-set
    callback converts them before rclpy's type check). Errors name the full parameter name.
    """

    def __init__(self, node: Node, specs: Sequence[ParamSpec], validate: Callable[[dict[str, Any]], Any],
                 apply: Callable[[Any, dict[str, Any]], None]) -> None:
        self._node = node
        self._specs = {s.name: s for s in specs}
        self._names = list(self._specs)
        self._validate = validate
        self._apply = apply
        if _start_args is not None:  # started by run(): every key of a --params-file must be known
            check_params_files(params_files_from_args(_start_args), node.get_fully_qualified_name(),
                               set(self._names) | set(node._parameters))
        overrides = node._parameter_overrides
        values = {}
        for spec in specs:
            values[spec.name] = coerce(spec, overrides[spec.name].value) if spec.name in overrides else spec.default
        # Invalid start-up values stop the node with the reason (raised to ``run``), before anything is declared.
        built = self._checked(values)
        for spec in specs:
            node.declare_parameter(spec.name, values[spec.name], descriptor(spec), ignore_override=True)
        self.values = {n: node.get_parameter(n).value for n in self._names}
        self._apply(built, dict(self.values))
        node.add_pre_set_parameters_callback(self._pre_set)
        node.add_on_set_parameters_callback(self._on_set)

    def __getitem__(self, name: str) -> Any:
        return self.values[name]

    def _checked(self, values: dict[str, Any]) -> Any:
        """validate(values) after the ranges; an error names the parameter by its full name."""
        try:
            for name, spec in self._specs.items():
                check_range(spec, values[name])
            return self._validate(dict(values))
        except ValueError as exc:
            raise ValueError(self._qualify(str(exc))) from exc

    def _qualify(self, message: str) -> str:
        """'height = 0.0: ...' (a model error naming a field) as 'geometry.height = 0.0: ...'."""
        head, sep, rest = message.partition(' = ')
        if sep and head not in self._specs:
            full = [n for n in self._names if n.endswith('.' + head)]
            if len(full) == 1:
                return f'{full[0]} = {rest}'
        return message

    def _pre_set(self, params: list[Parameter]) -> list[Parameter]:
        """Integers where a float is declared become floats before rclpy checks the type."""
        out = []
        for p in params:
            spec = self._specs.get(p.name)
            if spec is not None and p.type_ in (Parameter.Type.INTEGER, Parameter.Type.INTEGER_ARRAY):
                try:
                    p = Parameter(p.name, value=coerce(spec, p.value))
                except ValueError:
                    pass  # rclpy rejects the type
            out.append(p)
        return out

    def _on_set(self, params) -> SetParametersResult:
        new = dict(self.values)
        try:
            for p in params:
                if p.name in self._specs:
                    new[p.name] = coerce(self._specs[p.name], p.value)
            built = self._checked(new)
        except (ValueError, TypeError) as exc:
            self._node.get_logger().warning(f'parameter change rejected: {exc}')
            return SetParametersResult(successful=False, reason=str(exc))
        self.values = new
        self._apply(built, new)
        return SetParametersResult(successful=True)


def check(condition: bool, name: str, value: Any, rule: str) -> None:
    """Raise ValueError('name = value: rule') unless condition (the value shown as written, see :func:`show`)."""
    if not condition:
        raise ValueError(f'{name} = {show(value)}: {rule}')


def positive(values: Mapping[str, Any], *names: str) -> None:
    for n in names:
        v = values[n]
        check(_is_number(v) and math.isfinite(v) and v > 0, n, v, 'must be a finite number > 0')


# --- parameter files -------------------------------------------------------------------------------------------

#: The command line of the node run() is building (None otherwise): Params checks its --params-file keys.
_start_args: list[str] | None = None


def package_parameter_names() -> set[str]:
    """Every parameter some node of the package declares (what a ``/**`` section may hold)."""
    import importlib
    names = set(RCLPY_PARAMS)
    for module in NODE_MODULES:
        mod = importlib.import_module(f'crane_stiffness.nodes.{module}')
        names.update(s.name for s in getattr(mod, 'PARAMS', ()))
        names.update(getattr(mod, 'LIST_PARAMS', {}))
    return names


def _one_line(text: str) -> str:
    return ' '.join(str(text).split())


def params_file_problem(path: str) -> str | None:
    """Why ``path`` is not a usable parameter file (one line naming it), or None."""
    try:
        file = ParamFile.read(path)
    except FileNotFoundError:
        return f'{path}: no such parameter file'
    except (OSError, UnicodeDecodeError) as exc:
        return f'{path}: cannot read: {_one_line(exc)}'
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' (line {mark.line + 1}, column {mark.column + 1})' if mark is not None else ''
        return f"{path}: not valid YAML: {_one_line(getattr(exc, 'problem', None) or exc)}{where}"
    if not file.is_mapping:
        return f'{path}: expected "<node>: ros__parameters: ..." at the top level'
    for key, params in file.sections.items():
        if params is None:
            return f'{path}: section {key!r} has no ros__parameters mapping'
    return None


def check_params_files(paths: Sequence[str], node: str, own: set[str]) -> None:
    """Raise ValueError (one line naming the file and the key, with the closest known name) for a key of a section
    applying to ``node`` (fully qualified name) that it does not know: a section naming the node may hold only
    ``own`` parameters, a wildcard section (``/**``) those of any node of the package."""
    package = None
    for path in paths:
        problem = params_file_problem(path)
        if problem:
            raise ValueError(problem)
        file = ParamFile.read(path)
        for section in applicable_sections(file.sections, node):
            known = own | set(RCLPY_PARAMS)
            for key in file.sections[section] or {}:
                if key in known or key.startswith('qos_overrides.'):
                    continue
                if '*' in section:  # another node's parameter is fine in a section for every node
                    package = package_parameter_names() | known if package is None else package
                    if key in package:
                        continue
                    known = package
                close = difflib.get_close_matches(key, sorted(known), n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ''
                whose = 'any node of the package' if '*' in section else node
                raise ValueError(f"{path}: unknown parameter '{key}' in section '{section}' for {whose}{hint}")


def valid_topic_name(name: Any) -> bool:
    """Whether rclpy would accept ``name`` as a topic name (relative, absolute or ``~/``; before remapping)."""
    try:
        validate_topic_name(name)
    except (InvalidTopicNameException, TypeError, ValueError):
        return False
    return isinstance(name, str)


def stamp_to_s(stamp: Time) -> float:
    return stamp_seconds(stamp.sec, stamp.nanosec)


def finite(values: Iterable[float]) -> bool:
    return all(math.isfinite(v) for v in values)


@dataclass
class Counters:
    """Message counters a node reports on /diagnostics."""

    received: int = 0
    dropped_non_finite: int = 0
    dropped_absurd: int = 0
    published: int = 0

    def as_pairs(self) -> list[tuple[str, str]]:
        return [(k, str(v)) for k, v in self.__dict__.items()]


class Diagnostics:
    """Publishes a DiagnosticStatus for the node on /diagnostics at a fixed rate, from a callback."""

    def __init__(self, node: Node, report: Callable[[], tuple[int, str, list[tuple[str, str]]]],
                 period_s: float = 1.0) -> None:
        self._node = node
        self._report = report
        self._pub = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS, 10)
        self._timer = node.create_timer(period_s, self.publish)

    def publish(self) -> None:
        if not self._node.context.ok():
            return  # shutting down (Ctrl-C / SIGTERM): nothing to report to
        level, message, pairs = self._report()
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.status.append(DiagnosticStatus(level=bytes([level]), name=self._node.get_fully_qualified_name(),
                                           message=message, hardware_id=self._node.get_name(),
                                           values=[KeyValue(key=k, value=v) for k, v in pairs]))
        self._pub.publish(msg)



#: Longest a node waits at start (or on a rate change) to put its timer on the clock grid [s].
MAX_ALIGN_WAIT_S = 0.05


def create_grid_timer(node: Node, period_s: float, callback: Callable[[], None]):
    """A timer of ``period_s`` whose calls fall on multiples of the period on the node clock.

    Two sensor nodes publishing buffers at the same rate then deliver them at the same instants, like two channels
    of one DAQ sharing a sample clock: the newest force and displacement samples reach a consumer together, so a
    pair never waits up to a whole buffer for its partner. rcl timers keep their phase (the next call is the
    previous due time plus the period), so aligning the start is enough. The start waits for the next grid instant
    (sleeping, then spinning the last 0.3 ms for precision) when that is at most ``MAX_ALIGN_WAIT_S`` away; longer
    periods and simulated time (no wall-clock grid to share) start at once.
    """
    period_ns = max(1, round(period_s * 1e9))
    clock = node.get_clock()
    if period_s <= MAX_ALIGN_WAIT_S and not getattr(clock, 'ros_time_is_active', False):
        now = clock.now().nanoseconds
        start = (now // period_ns + 1) * period_ns
        if start - now > 300_000:
            time.sleep((start - now - 300_000) * 1e-9)
        while clock.now().nanoseconds < start:
            pass
    return node.create_timer(period_ns * 1e-9, callback)


def check_sensor_params(values: Mapping[str, Any]) -> int | None:
    """The parameters every simulated sensor has: ``sample_rate_hz``, ``publish_rate_hz``, ``frame_id``, ``seed``.
    Raises ValueError naming a bad one; returns the noise seed (None = random)."""
    positive(values, 'sample_rate_hz', 'publish_rate_hz')
    check(isinstance(values['frame_id'], str) and values['frame_id'] != '', 'frame_id', values['frame_id'],
          'must be a non-empty string')
    check(values['seed'] >= -1, 'seed', values['seed'], 'must be -1 (random) or a seed >= 0')
    SampleClock(values['sample_rate_hz'])  # raises for a rate it cannot represent
    return None if values['seed'] < 0 else values['seed']


class SampleSchedule:
    """A simulated sensor's timing: the sample clock (``sample_rate_hz``; stamps on its grid) and the grid timer
    (``publish_rate_hz``) whose ``tick`` publishes the samples due (:meth:`due`).

    :meth:`configure` runs on start and on every parameter change: it re-creates only what changed, and a new
    sample rate continues after the last instant already handed out.
    """

    def __init__(self, node: Node, tick: Callable[[], None]) -> None:
        self._node = node
        self._tick = tick
        self._rates: tuple[float, float] | None = None
        self.clock: SampleClock | None = None
        self.timer = None

    def configure(self, sample_rate_hz: float, publish_rate_hz: float) -> None:
        previous = self._rates or (None, None)
        if self.clock is None or sample_rate_hz != previous[0]:
            self.clock = SampleClock(sample_rate_hz, start_after_ns=None if self.clock is None else self.clock.last_ns)
        if self.timer is None or publish_rate_hz != previous[1]:
            if self.timer is not None:
                self._node.destroy_timer(self.timer)
            self.timer = create_grid_timer(self._node, 1.0 / publish_rate_hz, self._tick)
        self._rates = (sample_rate_hz, publish_rate_hz)

    def due(self):
        """The sample instants since the previous call (int64 ns, ascending; see SampleClock.due)."""
        return self.clock.due(self._node.get_clock().now().nanoseconds)


def make_executor(kind: str, context: Any):
    """'events': rclpy's EventsExecutor (in C++, about a quarter of the CPU per message of the standard one, which
    matters at 1 kHz on two cores); 'single': SingleThreadedExecutor."""
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except ImportError:  # an rclpy without it
            pass
    return SingleThreadedExecutor(context=context)


def run(node_factory: Callable[[], Node], args: Sequence[str] | None = None,
        executor: str | Callable[[Node], str] = 'events') -> int:
    """The ``main`` of every node: init, build, spin until Ctrl-C, SIGTERM or ``node.exit_requested``, clean up.

    A node that cannot start (bad parameter) exits with status 2 and the reason on stderr. ``close()`` (if the node
    has one) runs on every exit, then the node's final counters are printed.
    """
    global _start_args
    name = getattr(node_factory, '__name__', 'node')
    argv = list(sys.argv if args is None else args)
    # A missing or malformed --params-file would make rclpy.init raise (RCLError): say which file and why.
    reason = next(filter(None, map(params_file_problem, params_files_from_args(argv))), None)
    if reason is None:
        try:
            rclpy.init(args=args)
        except Exception as exc:  # e.g. a parameter file rcl reads differently
            reason = _one_line(f'{type(exc).__name__}: {exc}')
    if reason is not None:
        print(f'[{name}] cannot start: {reason}', file=sys.stderr)
        return 2
    _start_args = argv
    try:
        node = node_factory()
    except (ValueError, TypeError) as exc:
        print(f'[{name}] cannot start: {exc}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    except Exception as exc:  # e.g. rclpy's InvalidParameterTypeException from a params file
        print(f'[{name}] cannot start: {type(exc).__name__}: {exc}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    finally:
        _start_args = None
    ex = make_executor(executor(node) if callable(executor) else executor, node.context)
    ex.add_node(node)
    try:
        while rclpy.ok(context=node.context) and not getattr(node, 'exit_requested', False):
            ex.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        close = getattr(node, 'close', None)
        if close is not None:
            close()
        final_counters(node)
        ex.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def final_counters(node: Node) -> None:
    """Print the node's message counters once at exit (``FINAL_COUNTERS <node> {json}``): the totals a benchmark or
    an engineer reads after a run, when /diagnostics has stopped."""
    counters = getattr(node, 'counters', None)
    if counters is None:
        return
    values = counters.__dict__ if hasattr(counters, '__dict__') else counters
    try:
        text = json.dumps({k: v for k, v in dict(values).items() if isinstance(v, (int, float, str))})
    except (TypeError, ValueError):
        return
    print(f'FINAL_COUNTERS {node.get_name()} {text}', flush=True)
