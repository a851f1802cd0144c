"""ROS 2 parameter files (the YAML of ``--params-file``): the one reader behind the offline CLI
(:func:`load_params`), the load programs (crane_stiffness.sim.program.load_program_file) and the
files the session recorder stores with a session. No ROS import.

A file maps node names to ``ros__parameters`` (``<node>: ros__parameters: {name: value}``); nested mappings flatten
to dotted names the way rclpy does (``geometry: {a: 0.1}`` is the parameter ``geometry.a``).

Which sections apply to a node (:func:`section_applies`) follows ROS: a key without a leading '/' gets one
(``crane_model`` is ``/crane_model``), ``*`` stands for one name and ``**`` for any number of them (``/**``: every
node; ``/rig/*``: every node in /rig), the way rclcpp matches keys against a node's fully qualified name (rclpy
knows ``/**`` and the node's own name, a subset of that). The node is given by its fully qualified name
(``/rig/lvdt``) or by its name alone (``lvdt``: that node in whatever namespace; a section of any namespace applies).
Sections with a wildcard apply first, then those naming the node, each group in file order: rclpy's order (``/**``
first, then the node's own section).

A section that applies to no node is read by none, silently, in ROS: ``stiffness_estimater:`` leaves the estimator at
its defaults. :func:`stray_sections` finds them for the nodes a caller knows (the rig launcher knows the rig's,
:func:`load_params` is given the package's), and :func:`check_sections` refuses them naming the closest node.
"""
from __future__ import annotations

import copy
import difflib
import functools
import os
import re
import sys
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import yaml

from crane_stiffness import PACKAGE
from crane_stiffness.params.errors import ConfigError

PARAMETERS_KEY = 'ros__parameters'


class ParamLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also reads the tuples ``yaml.dump`` writes as ``!!python/tuple`` sequences (as lists).

    launch_ros turns every sequence of a launch file's parameter dict into a tuple and writes the dict to a
    temporary ``--params-file`` with ``yaml.dump``; rcl reads the tag as a plain sequence, and so does this reader.
    Nothing else of PyYAML's Python tags is accepted (no object construction).
    """


ParamLoader.add_constructor('tag:yaml.org,2002:python/tuple',
                           lambda loader, node: loader.construct_sequence(node, deep=True))


def load_yaml(text: str) -> Any:
    """Parse a parameter file's text with :class:`ParamLoader`; raises yaml.YAMLError. A copy of the parse, which is
    kept for the same text: a rig host's nodes read the same few files at every session (tens of parses, a tenth of
    a session's CPU in pure-Python YAML)."""
    return copy.deepcopy(_parsed(text))


@functools.lru_cache(maxsize=64)
def _parsed(text: str) -> Any:
    return yaml.load(text, Loader=ParamLoader)  # noqa: S506 - a SafeLoader subclass


def flatten_params(values: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """Nested mappings as dotted parameter names, the way rclpy flattens a parameter file
    (``{geometry: {a: 0.1}}`` → ``{'geometry.a': 0.1}``)."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            out.update(flatten_params(value, name + '.'))
        else:
            out[name] = value
    return out


def _key_pattern(key: str) -> re.Pattern[str]:
    """rclcpp's rule: the key with a leading '/', ``/*`` → one name, ``/**`` → any number of names."""
    parts = key.strip('/').split('/')
    return re.compile(''.join(r'(/\w+)*' if p == '**' else r'/\w+' if p == '*' else '/' + re.escape(p)
                              for p in parts))


def section_applies(key: str, node: str) -> bool:
    """Whether the parameter file section ``key`` applies to ``node`` (see the module docstring)."""
    if node.startswith('/'):
        return _key_pattern(key).fullmatch(node) is not None
    return key.rstrip('/').rsplit('/', 1)[-1] in (node, '*', '**')  # the node in some namespace


def _is_wildcard(key: str) -> bool:
    return '*' in key


def applicable_sections(keys: Iterable[str], node: str | None) -> list[str]:
    """The keys that apply to ``node`` in the order their parameters apply (wildcards first, then the node's own,
    each in file order); every key in file order when ``node`` is None."""
    keys = list(keys)
    if node is None:
        return keys
    chosen = [k for k in keys if section_applies(k, node)]
    return [k for k in chosen if _is_wildcard(k)] + [k for k in chosen if not _is_wildcard(k)]


def closest(name: str, known: Iterable[str]) -> str | None:
    """The known name ``name`` most likely stands for (difflib's closest, at least 0.6 alike), or None."""
    close = difflib.get_close_matches(name, sorted(set(known)), n=1)
    return close[0] if close else None


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest known name, or '' when none is close."""
    match = closest(name, known)
    return f" (did you mean '{match}'?)" if match else ''


def stray_sections(keys: Iterable[str], nodes: Iterable[str]) -> list[str]:
    """The section keys (in file order) that apply to none of ``nodes`` (names, or fully qualified names): read
    by no node of them. A wildcard key (``/**``, ``/rig/*``) is never stray: it may be meant for any node."""
    nodes = list(nodes)
    return [k for k in keys if not _is_wildcard(k) and not any(section_applies(k, n) for n in nodes)]


def _node_name(key: str) -> str:
    return key.rstrip('/').rsplit('/', 1)[-1]


def check_sections(path: str | os.PathLike, keys: Iterable[str], nodes: Iterable[str], *, only_typos: bool = False,
                   who: str = 'the rig') -> None:
    """ConfigError naming the file, the first section of ``keys`` that applies to none of ``nodes`` and the closest
    node, e.g. ``sensors.yaml: section 'stiffness_estimater' applies to no node of the rig (did you mean
    'stiffness_estimator'?)``. ``only_typos``: refuse only a section close to a node's name (one that can only be a
    typo; a file may hold sections for other packages' nodes), the others pass."""
    nodes = list(nodes)
    names = [_node_name(n) for n in nodes]
    for key in stray_sections(keys, nodes):
        match = closest(_node_name(key), names)
        if match is None and only_typos:
            continue
        hint = f" (did you mean '{match}'?)" if match else f"; its nodes: {', '.join(sorted(set(names)))}"
        raise ConfigError(f'{path}: section {key!r} applies to no node of {who}{hint}: its parameters would be '
                          'read by none')


class NodeSections:
    """The section keys that apply to one node, as a container: ``key in NodeSections('session_recorder')``."""

    def __init__(self, node: str) -> None:
        self.node = node

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and section_applies(key, self.node)

    def __repr__(self) -> str:
        return f'NodeSections({self.node!r})'


@dataclass(frozen=True)
class ParamFile:
    """One parameter file as read: its path, text and YAML document."""

    path: Path
    text: str
    document: Any

    @classmethod
    def read(cls, path: str | os.PathLike) -> ParamFile:
        """Read and parse ``path``; raises OSError, UnicodeDecodeError or yaml.YAMLError (callers say which file
        and why in their own terms)."""
        path = Path(path)
        text = path.read_text(encoding='utf-8')
        return cls(path, text, load_yaml(text))

    @property
    def is_mapping(self) -> bool:
        """False when the top level is not ``<node>: ...`` at all (an empty file, a list, a scalar)."""
        return isinstance(self.document, Mapping)

    @cached_property
    def sections(self) -> dict[str, dict[str, Any] | None]:
        """Every top-level section in file order: its flat parameters, or None where it has no ros__parameters
        mapping (``ros__parameters:`` left empty counts as no parameters)."""
        out: dict[str, dict[str, Any] | None] = {}
        for key, body in (self.document.items() if self.is_mapping else ()):
            params = body.get(PARAMETERS_KEY, False) if isinstance(body, Mapping) else False
            if params is None:
                params = {}
            out[str(key)] = flatten_params(params) if isinstance(params, Mapping) else None
        return out

    def params(self, keys: Iterable[str]) -> dict[str, Any]:
        """The parameters of the sections ``keys`` (well-formed ones), later ones overriding earlier ones."""
        out: dict[str, Any] = {}
        for key in keys:
            out.update(self.sections[key] or {})
        return out


def _ros_args(args: Sequence[str] | None) -> list[tuple[str, str | None]]:
    """(argument, the one after it or None) for each argument inside ``--ros-args`` … ``--`` of a command line
    (sys.argv when None)."""
    argv = list(sys.argv if args is None else args)
    out: list[tuple[str, str | None]] = []
    in_ros = False
    for i, arg in enumerate(argv):
        if arg == '--ros-args':
            in_ros = True
        elif arg == '--':
            in_ros = False
        elif in_ros:
            out.append((arg, argv[i + 1] if i + 1 < len(argv) else None))
    return out


def params_files_from_args(args: Sequence[str] | None) -> list[str]:
    """The ``--params-file`` paths in the ROS arguments of a command line (sys.argv when None)."""
    return [following for arg, following in _ros_args(args) if arg == '--params-file' and following is not None]


def param_names_from_args(args: Sequence[str] | None) -> list[str]:
    """The parameter names set by ``-p``/``--param name:=value`` in the ROS arguments of a command line (sys.argv
    when None), in order."""
    return [following.partition(':=')[0] for arg, following in _ros_args(args)
            if arg in ('-p', '--param') and following is not None and ':=' in following]


def read_params_files(paths: Sequence[str]) -> tuple[list[dict[str, str]], dict[str, dict[str, Any]], list[str]]:
    """(files as {path, text}, sections {key: flat params} merged in file order, problems) of parameter files:
    what a recorder stores with a session. A file that cannot be read is a problem, not an error."""
    files: list[dict[str, str]] = []
    sections: dict[str, dict[str, Any]] = {}
    problems: list[str] = []
    for path in paths:
        try:
            file = ParamFile.read(path)
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            problems.append(f'{path}: {exc}')
            continue
        files.append({'path': str(file.path.resolve()), 'text': file.text})
        for key, params in file.sections.items():
            if params is not None:
                sections.setdefault(key, {}).update(params)
    return files, sections, problems


def load_params(path: str | os.PathLike, node_name: str | None = None,
                known_nodes: Iterable[str] | None = None) -> dict[str, Any]:
    """Flat parameters of a ROS parameter YAML file for the node ``node_name`` (its name, or its fully qualified
    name), the sections applied the way ROS applies them (:func:`applicable_sections`: ``/**`` and other
    wildcards first, then the node's own). Without ``node_name`` every section is merged in file order.
    ``known_nodes``: the package's node names; a section close to one of them that applies to none
    (``crane_modle:``) can only be a typo and is refused (:func:`check_sections`).
    """
    path = Path(path)
    try:
        file = ParamFile.read(path)
    except FileNotFoundError:
        raise ConfigError(f'{path}: no such config file') from None
    except yaml.YAMLError as exc:
        raise ConfigError(f'{path}: not valid YAML: {exc}') from None
    if not file.is_mapping:
        raise ConfigError(f'{path}: expected "<node>: ros__parameters: ..." at the top level')
    if known_nodes is not None:
        check_sections(path, file.sections, known_nodes, only_typos=True, who='this package')
    keys = applicable_sections(file.sections, node_name)
    for key in keys:
        if file.sections[key] is None:
            raise ConfigError(f'{path}: section {key!r} has no ros__parameters mapping')
    return file.params(keys)


def share_dir() -> Path:
    """The package's share directory: via the ament index when one is set (a sourced workspace), else the venv's
    share/ (``make install``), else next to the sources. A plain shell (no ``AMENT_PREFIX_PATH``: ament_index raises
    OSError) is not an error: the package's own files are used."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
        try:
            share = Path(get_package_share_directory(PACKAGE))
            if (share / 'config').is_dir():
                return share
        except (PackageNotFoundError, OSError):  # not in the index, or no index at all (nothing sourced)
            pass
    except ImportError:  # offline analysis without ROS
        pass
    candidate = Path(sys.prefix) / 'share' / PACKAGE
    if (candidate / 'config').is_dir():
        return candidate
    return Path(__file__).resolve().parents[2]


def config_path(name: str) -> Path:
    """A file of the installed config/ directory (``name`` with or without .yaml), or ``name`` itself if it exists."""
    p = Path(name)
    if p.exists():
        return p
    fname = name if name.endswith('.yaml') else name + '.yaml'
    found = share_dir() / 'config' / fname
    if not found.exists():
        raise ConfigError(f'{name}: not a file, and no {fname} in {share_dir() / "config"}')
    return found
