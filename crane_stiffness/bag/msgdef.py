"""ROS 2 message definitions (``ros2msg`` schema text) from installed .msg files, without ROS.

rosbag2 stores each topic type's full definition in the MCAP schema: the type's own .msg text, then for every
dependency, recursively and each once, a newline, a line of 80 ``=``, ``MSG: pkg/Type`` and that type's .msg text.
Dependencies of one file are visited in sorted order (rosbag2 keeps them in a ``std::set``), depth first. This module
rebuilds exactly that text from ``<prefix>/share/<pkg>/msg/<Type>.msg`` under each prefix of ``AMENT_PREFIX_PATH``
(then ``sys.prefix``, which is an ament prefix when ROS comes from PyPI wheels into a venv).

Field types are found the way rosbag2 finds them: the first word of each line (optionally followed by an array
suffix) that is not a primitive type. A type without package (``Point`` inside geometry_msgs) belongs to the same
package. ``Header`` alone means ``std_msgs/Header`` when the package has no Header.msg of its own (the ROS 1
convention that rosbags and mcap readers also follow; rosbag2 would fail to find ``pkg/Header`` there).
"""

from __future__ import annotations

import json
import os
import re
import sys
from functools import lru_cache
from pathlib import Path

from .errors import MessageDefinitionError, UnsupportedTypeError

SEPARATOR = '=' * 80
"""The line rosbag2 puts between definitions in a ros2msg schema."""

_TYPE_RE = re.compile(r'^([A-Za-z0-9_]+)/(?:msg/)?([A-Za-z0-9_]+)$')
# rosbag2's MSG_FIELD_TYPE_REGEX: the type word at the start of a line, optional [..] suffix, then whitespace.
_FIELD_TYPE_RE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
PRIMITIVE_TYPES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32', 'int64',
    'uint64', 'string', 'wstring',
})


def split_type(msg_type: str) -> tuple[str, str]:
    """Split ``pkg/msg/Type`` or ``pkg/Type`` into ``(pkg, Type)``; raise MessageDefinitionError otherwise."""
    match = _TYPE_RE.match(msg_type)
    if not match:
        raise MessageDefinitionError(f'message type {msg_type!r} is not of the form pkg/msg/Type')
    return match.group(1), match.group(2)


def normalize_type(msg_type: str) -> str:
    """Return the ROS 2 spelling ``pkg/msg/Type`` of ``pkg/Type`` or ``pkg/msg/Type``."""
    pkg, name = split_type(msg_type)
    return f'{pkg}/msg/{name}'


def ament_prefixes() -> list[Path]:
    """Prefixes searched for share/<pkg>/msg: AMENT_PREFIX_PATH entries in order, then sys.prefix."""
    prefixes = [Path(p) for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    if Path(sys.prefix) not in prefixes:
        prefixes.append(Path(sys.prefix))
    return prefixes


INTERFACES_RESOURCE = Path('share') / 'ament_index' / 'resource_index' / 'rosidl_interfaces'
"""Where each interface package lists its interfaces (``msg/Type.msg``, ``msg/Type.idl``, one per line)."""


def interface_prefix(msg_type: str, prefixes: list[Path] | None = None) -> Path:
    """The ament prefix whose index lists ``msg_type`` (``pkg/msg/Type`` or ``pkg/Type``) as an interface.

    This is how a type named in a bag is trusted before its Python module is imported: only packages registered
    in the ament index (``<prefix>/share/ament_index/resource_index/rosidl_interfaces/<pkg>``, the lookup of
    ``ament_index_python``) that list the type resolve; any other name in a bag (``os/msg/Foo``, ``this/msg/Foo``)
    is refused, so a bag cannot make the player import an arbitrary module.

    Raises:
        UnsupportedTypeError: naming the type and the prefixes searched.
    """
    try:
        pkg, name = split_type(msg_type)
    except MessageDefinitionError as exc:
        raise UnsupportedTypeError(str(exc)) from None
    if msg_type.count('/') == 2 and msg_type.split('/')[1] != 'msg':
        raise UnsupportedTypeError(f'message type {msg_type!r} is not a message (pkg/msg/Type)')
    searched = prefixes if prefixes is not None else ament_prefixes()
    wanted = {f'msg/{name}.msg', f'msg/{name}.idl'}
    for prefix in searched:
        entry = prefix / INTERFACES_RESOURCE / pkg
        try:
            listed = entry.read_text(encoding='utf-8').splitlines()
        except (OSError, UnicodeDecodeError):
            continue
        if wanted & {line.strip() for line in listed}:
            return prefix
    where = ', '.join(str(p) for p in searched) or '(none)'
    raise UnsupportedTypeError(
        f'message type {msg_type!r} is not an installed interface: no package {pkg!r} listing msg/{name} in the '
        f'ament index (share/ament_index/resource_index/rosidl_interfaces) of the prefixes {where}')


def _find_share_file(pkg: str, name: str, suffix: str, prefixes: tuple[Path, ...]) -> Path | None:
    for prefix in prefixes:
        candidate = prefix / 'share' / pkg / 'msg' / f'{name}{suffix}'
        if candidate.is_file():
            return candidate
    return None


def find_msg_file(msg_type: str, prefixes: list[Path] | None = None) -> Path:
    """Path of the .msg file of ``msg_type``; MessageDefinitionError naming the prefixes searched if none."""
    pkg, name = split_type(msg_type)
    searched = tuple(prefixes if prefixes is not None else ament_prefixes())
    found = _find_share_file(pkg, name, '.msg', searched)
    if found is None:
        where = ', '.join(str(p) for p in searched) or '(none)'
        raise MessageDefinitionError(
            f'no definition of {msg_type}: share/{pkg}/msg/{name}.msg is under none of the prefixes {where} '
            f'(set AMENT_PREFIX_PATH, or pass message_definition= explicitly)'
        )
    return found


def parse_dependencies(text: str, package: str, prefixes: tuple[Path, ...] = ()) -> list[str]:
    """Sorted, distinct non-primitive field types of one .msg text, as ``pkg/Type`` (rosbag2's spelling)."""
    deps: set[str] = set()
    for match in _FIELD_TYPE_RE.finditer(text):
        field_type = match.group(1)
        if field_type in PRIMITIVE_TYPES:
            continue
        if '/' in field_type:
            deps.add(field_type)
        elif field_type == 'Header' and _find_share_file(package, 'Header', '.msg', prefixes) is None:
            deps.add('std_msgs/Header')
        else:
            deps.add(f'{package}/{field_type}')
    return sorted(deps)


@lru_cache(maxsize=256)
def _message_definition(msg_type: str, prefixes: tuple[Path, ...]) -> str:
    seen: set[str] = set()
    texts: dict[str, tuple[str, list[str]]] = {}

    def load(type_name: str) -> tuple[str, list[str]]:
        if type_name not in texts:
            pkg, _ = split_type(type_name)
            text = find_msg_file(type_name, list(prefixes)).read_text(encoding='utf-8')
            texts[type_name] = (text, parse_dependencies(text, pkg, prefixes))
        return texts[type_name]

    def append(type_name: str, depth: int) -> str:
        if depth <= 0:
            raise MessageDefinitionError(f'recursion too deep resolving the definition of {msg_type}')
        text, deps = load(type_name)
        out = [text]
        for dep in deps:
            if dep not in seen:
                seen.add(dep)
                out.append(f'\n{SEPARATOR}\nMSG: {dep}\n')
                out.append(append(dep, depth - 1))
        return ''.join(out)

    return append(msg_type, 50)


def message_definition(msg_type: str, prefixes: list[Path] | None = None) -> str:
    """Full ros2msg definition text of ``msg_type`` (``pkg/msg/Type``) as rosbag2 writes it into MCAP schemas."""
    split_type(msg_type)
    return _message_definition(msg_type, tuple(prefixes if prefixes is not None else ament_prefixes()))


def type_description_hash(msg_type: str, prefixes: list[Path] | None = None) -> str:
    """The REP-2011 type hash (``RIHS01_<sha256 hex>``) from the installed ``<Type>.json``, or '' if unavailable."""
    pkg, name = split_type(msg_type)
    path = _find_share_file(pkg, name, '.json', tuple(prefixes if prefixes is not None else ament_prefixes()))
    if path is None:
        return ''
    try:
        hashes = json.loads(path.read_text(encoding='utf-8')).get('type_hashes', [])
    except (OSError, ValueError):
        return ''
    wanted = normalize_type(msg_type)
    for entry in hashes:
        if entry.get('type_name') == wanted:
            return str(entry.get('hash_string', ''))
    return ''
