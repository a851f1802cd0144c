"""A node's parameters: declared with descriptions, ranges and rules (visible to ``ros2 param describe``), checked
on start and on every change by the same code, integers taken where floats are declared, errors naming the full
parameter and the value as written; and the --params-file checks (a missing or malformed file, a key no node knows)
that ``run`` makes before a node starts.
"""
from __future__ import annotations

import difflib
import math
import sys
from array import array
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Mapping, Sequence

import yaml
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidTopicNameException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.validate_topic_name import validate_topic_name

from crane_stiffness.params.geometry import GEOMETRY_PARAMS
from crane_stiffness.params.spec import ParamSpec, check_spec, is_number as _is_number
from crane_stiffness.params.files import ParamFile, applicable_sections, param_names_from_args, params_files_from_args


#: Parameters the package's files share across nodes under ``/**`` (the geometry): known to be some node's without
#: importing every node module (package_parameter_names costs ~1.4 s at each start).
SHARED_PARAMS = frozenset(spec.name for spec in GEOMETRY_PARAMS)
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
    scalar) and the whole rule in words (:meth:`ParamSpec.rule_text`)."""
    d = ParameterDescriptor(description=spec.description)
    if spec.low is not None or spec.high is not None:
        if isinstance(spec.default, float):
            d.floating_point_range = [FloatingPointRange(
                from_value=float(spec.low if spec.low is not None else -sys.float_info.max),
                to_value=float(spec.high if spec.high is not None else sys.float_info.max), step=0.0)]
        elif isinstance(spec.default, int) and not isinstance(spec.default, bool):
            d.integer_range = [IntegerRange(from_value=int(spec.low if spec.low is not None else -2**63),
                                            to_value=int(spec.high if spec.high is not None else 2**63 - 1),
                                            step=1)]
    d.additional_constraints = spec.rule_text()
    return d


def check_range(spec: ParamSpec, value: Any) -> None:
    """The declared rule of ``spec`` (choices, ``above``, ``at_least``/``at_most``, the inclusive range low/high;
    rclpy enforces the range at runtime too), in our words: ParameterError, a ValueError ('name = value: must be
    ...'). Lists are the owner's to check."""
    if not isinstance(value, (list, tuple, array)):
        check_spec(spec, value)


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
                               set(self._names) | declared_names(node))
        overrides = node._parameter_overrides  # the values given at start (rclpy has no public read of them)
        written = {s.name: overrides[s.name].value for s in specs if s.name in overrides}
        self._written: dict[str, Any] = {}  # the values of a runtime change as sent, before _pre_set converted them
        values = {}
        for spec in specs:
            values[spec.name] = coerce(spec, written[spec.name]) if spec.name in written else spec.default
        # Invalid start-up values stop the node with the reason (raised to ``run``), before anything is declared.
        built = self._checked(values, written)
        for spec in specs:
            node.declare_parameter(spec.name, values[spec.name], descriptor(spec), ignore_override=True)
        self.values = {n: node.get_parameter(n).value for n in self._names}
        self._apply(built, dict(self.values))
        node.add_pre_set_parameters_callback(self._pre_set)
        node.add_on_set_parameters_callback(self._on_set)

    def __getitem__(self, name: str) -> Any:
        return self.values[name]

    def _checked(self, values: dict[str, Any], written: Mapping[str, Any]) -> Any:
        """validate(values) after the ranges; an error names the parameter by its full name and shows the value as
        ``written`` (-1, not the -1.0 it became)."""
        try:
            for name, spec in self._specs.items():
                check_range(spec, values[name])
            return self._validate(dict(values))
        except ValueError as exc:
            raise ValueError(self._as_written(self._qualify(str(exc)), values, written)) from exc

    @staticmethod
    def _as_written(message: str, values: Mapping[str, Any], written: Mapping[str, Any]) -> str:
        """'geometry.a = -1.0: must be > 0' as 'geometry.a = -1: must be > 0' when the user wrote -1."""
        name, sep, rest = message.partition(' = ')
        if sep and name in written and name in values:
            shown = show(values[name])
            if rest.startswith(shown + ':'):
                return f'{name} = {show(written[name])}{rest[len(shown):]}'
        return message

    def _qualify(self, message: str) -> str:
        """'height = 0.0: ...' (a model error naming a field) as 'geometry.height = 0.0: ...'."""
        head, sep, rest = message.partition(' = ')
        if sep and head not in self._specs:
            full = [n for n in self._names if n.endswith('.' + head)]
            if len(full) == 1:
                return f'{full[0]} = {rest}'
        return message

    def _pre_set(self, params: list[Parameter]) -> list[Parameter]:
        """Integers where a float is declared become floats before rclpy checks the type. A value of another type
        rclpy refuses with its own reason, which names neither the parameter nor the value (``Wrong parameter type,
        expected 'Type.DOUBLE' got 'Type.STRING'``): the node's log says which, as at start."""
        out = []
        for p in params:
            spec = self._specs.get(p.name)
            if spec is not None:
                if p.type_ in (Parameter.Type.INTEGER, Parameter.Type.INTEGER_ARRAY):
                    self._written[p.name] = p.value
                try:
                    value = coerce(spec, p.value)
                except ValueError as exc:
                    self._node.get_logger().warning(f'parameter change rejected: {exc}')
                else:
                    if p.type_ in (Parameter.Type.INTEGER, Parameter.Type.INTEGER_ARRAY):
                        p = Parameter(p.name, value=value)
            out.append(p)
        return out

    def _on_set(self, params) -> SetParametersResult:
        new = dict(self.values)
        written, self._written = self._written, {}
        written = {p.name: written.get(p.name, p.value) for p in params}
        try:
            for p in params:
                if p.name in self._specs:
                    new[p.name] = coerce(self._specs[p.name], p.value)
            built = self._checked(new, written)
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


@contextmanager
def started_with(argv: Sequence[str]) -> Iterator[None]:
    """While ``run`` builds a node from this command line, its :class:`Params` check the --params-file keys."""
    global _start_args
    _start_args = list(argv)
    try:
        yield
    finally:
        _start_args = None


def node_modules() -> dict[str, Any]:
    """The package's nodes: {name: module} for each of :data:`crane_stiffness.nodes.NODES` (each has ``PARAMS`` and a
    ``main``, and its executable nodes_bin/<name>, which setup.py installs). Imports them all (~1.4 s): only for a
    key a ``/**`` section names that is not the geometry's."""
    import importlib

    from crane_stiffness.nodes import NODES
    return {name: importlib.import_module(f'crane_stiffness.nodes.{name}') for name in NODES}


def declared_names(node: Node) -> set[str]:
    """The names of every parameter ``node`` has declared (its own and rclpy's)."""
    return set(node.list_parameters([], 0).names)  # no prefix, depth 0: all of them


def package_parameter_names() -> set[str]:
    """Every parameter some node of the package declares (what a ``/**`` section may hold)."""
    names = set(RCLPY_PARAMS)
    for module in node_modules().values():
        names.update(s.name for s in module.PARAMS)
        names.update(getattr(module, 'LIST_PARAMS', {}))
    return names


def one_line(text: object) -> str:
    """``text`` (str() of it) on one line (white space folded)."""
    return ' '.join(str(text).split())


def params_file_problem(path: str) -> str | None:
    """Why ``path`` is not a usable parameter file (one line naming it), or None."""
    try:
        file = ParamFile.read(path)
    except FileNotFoundError:
        return f'{path}: no such parameter file'
    except (OSError, UnicodeDecodeError) as exc:
        return f'{path}: cannot read: {one_line(exc)}'
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' (line {mark.line + 1}, column {mark.column + 1})' if mark is not None else ''
        return f"{path}: not valid YAML: {one_line(getattr(exc, 'problem', None) or exc)}{where}"
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
                if '*' in section and key in SHARED_PARAMS:  # the common case, without importing every node
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


def check_command_line_params(argv: Sequence[str], node: str, declared: set[str]) -> None:
    """Raise ValueError (one line, with the closest known name) for a ``-p name:=value`` of the command line that the
    node (``node``, its name) does not declare: rclpy would ignore it and the node would run with the default."""
    known = set(declared) | set(RCLPY_PARAMS)
    for name in param_names_from_args(argv):
        if name in known or name.startswith('qos_overrides.'):
            continue
        close = difflib.get_close_matches(name, sorted(known), n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ''
        raise ValueError(f"--ros-args -p {name}:=...: unknown parameter for {node}{hint}")


def valid_topic_name(name: Any) -> bool:
    """Whether rclpy would accept ``name`` as a topic name (relative, absolute or ``~/``; before remapping)."""
    try:
        validate_topic_name(name)
    except (InvalidTopicNameException, TypeError, ValueError):
        return False
    return isinstance(name, str)
