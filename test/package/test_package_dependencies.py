"""The package's dependencies as a ROS workspace resolves them: `rosdep install --from-paths src --ignore-src`.

Every third-party module the package imports (crane_stiffness/, the launch file, the node scripts) must be covered
by a key package.xml declares, and every key must be one rosdep resolves: a key of rosdistro's database, or one of
rosdep/crane_stiffness.yaml, the file docs/running.md adds to rosdep's sources for what only PyPI has. The pip
packages behind the keys are requirements.txt's, and everything requirements.txt installs is declared.

No ROS and no network: rosdistro's keys are listed below (ROSDISTRO_KEYS) as checked against it.
"""
from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

from helpers import REPO

SHIPPED_YAML = REPO / 'rosdep' / 'crane_stiffness.yaml'

# The ROS packages the code imports: the rosdep key is the package's name (rosdep resolves it from the ROS
# distribution, to ros-jazzy-<name> on Ubuntu); in the venv they come with requirements.txt's ros-jazzy-* wheels.
ROS_PACKAGES = frozenset({
    'rclpy', 'builtin_interfaces', 'rcl_interfaces', 'rosgraph_msgs', 'geometry_msgs', 'sensor_msgs', 'std_msgs',
    'std_srvs', 'diagnostic_msgs', 'ament_index_python', 'launch', 'launch_ros',
})

# The other third-party imports: import name -> (its distribution in requirements.txt, the rosdep key covering it).
PYTHON_DEPENDENCIES = {
    'numpy': ('numpy', 'python3-numpy'),
    'scipy': ('scipy', 'python3-scipy'),
    'numba': ('numba', 'python3-numba'),
    'yaml': ('PyYAML', 'python3-yaml'),
    'matplotlib': ('matplotlib', 'python3-matplotlib'),
    'tqdm': ('tqdm', 'python3-tqdm'),
    'pymodbus': ('pymodbus', 'python3-pymodbus-pip'),  # PyPI's: Ubuntu's python3-pymodbus predates its API
    'mcap': ('mcap', 'python3-mcap-pip'),
    'zstandard': ('zstandard', 'python3-zstandard-pip'),
    'lz4': ('lz4', 'python3-lz4-pip'),
    'foxglove': ('foxglove-sdk', 'python3-foxglove-sdk-pip'),
}

# Imports that are optional: import name -> the setup.py extra that installs it. Imported only inside a
# try/except ImportError, not declared in package.xml (a workspace without it runs everything else).
OPTIONAL = {'dask': 'dask'}

# The keys taken from rosdistro's database, with what `rosdep resolve KEY --os=ubuntu:noble --rosdistro=jazzy`
# (rosdep 0.27.0) answered against ros/rosdistro at commit 8468e88c (2026-08-22): rosdep/base.yaml and
# rosdep/python.yaml, and jazzy/distribution.yaml for the ROS packages. Not checked here (that needs the network);
# any other key must be defined by the shipped YAML.
ROSDISTRO_KEYS = {
    **{name: ('apt', 'ros-jazzy-' + name.replace('_', '-')) for name in ROS_PACKAGES},
    'python3-numpy': ('apt', 'python3-numpy'),
    'python3-scipy': ('apt', 'python3-scipy'),
    'python3-numba': ('apt', 'python3-numba'),
    'python3-yaml': ('apt', 'python3-yaml'),
    'python3-matplotlib': ('apt', 'python3-matplotlib'),
    'python3-tqdm': ('apt', 'python3-tqdm'),
    'python3-pymodbus-pip': ('pip', 'pymodbus'),
    'python3-pytest': ('apt', 'python3-pytest'),
}

_RUNTIME_TAGS = ('depend', 'exec_depend')
_TYPE_NAME = re.compile(r'([a-z][a-z0-9_]*)/(?:msg|srv|action)/[A-Z][A-Za-z0-9]*')


def _sources() -> list[Path]:
    """Every Python file the package runs: its modules, the launch file, the node scripts."""
    return (sorted((REPO / 'crane_stiffness').rglob('*.py')) + sorted((REPO / 'launch').glob('*.py'))
            + sorted((REPO / 'nodes_bin').iterdir()))


def _parse(path: Path) -> ast.Module:
    return ast.parse(path.read_text(), filename=str(path))


def _imports(tree: ast.Module) -> list[tuple[str, ast.stmt]]:
    """(top-level module name, statement) of every absolute import, at any depth (lazy imports too)."""
    found: list[tuple[str, ast.stmt]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(alias.name.partition('.')[0], node) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.module.partition('.')[0], node))
    return found


def _third_party_imports() -> dict[str, list[str]]:
    """Top-level name -> ['file:line', ...] of every import outside the standard library and the package."""
    found: dict[str, list[str]] = {}
    for path in _sources():
        for name, node in _imports(_parse(path)):
            if name in sys.stdlib_module_names or name == 'crane_stiffness':
                continue
            found.setdefault(name, []).append(f'{path.relative_to(REPO)}:{node.lineno}')
    return found


def _package_keys(tags: tuple[str, ...]) -> list[str]:
    root = ET.parse(REPO / 'package.xml').getroot()
    return [(element.text or '').strip() for element in root if element.tag in tags]


def _normalized(name: str) -> str:
    return re.sub(r'[-_.]+', '-', name).lower()


def _distribution(requirement: str) -> str:
    """'ros-jazzy-rclpy[fastrtps]==7.1.6' -> 'ros-jazzy-rclpy' (normalized)."""
    match = re.match(r'[A-Za-z0-9][A-Za-z0-9._-]*', requirement)
    assert match, f'cannot read the requirement {requirement!r}'
    return _normalized(match.group())


def _requirement_names(path: Path) -> set[str]:
    lines = (line.partition('#')[0].strip() for line in path.read_text().splitlines())
    return {_distribution(line) for line in lines if line and not line.startswith('-')}


def _setup_extras() -> dict[str, list[str]]:
    for node in ast.walk(_parse(REPO / 'setup.py')):
        if isinstance(node, ast.keyword) and node.arg == 'extras_require':
            return ast.literal_eval(node.value)
    raise AssertionError('setup.py has no extras_require')


def _shipped() -> dict:
    return yaml.safe_load(SHIPPED_YAML.read_text())


def test_every_third_party_import_has_a_key():
    unknown = {name: where for name, where in _third_party_imports().items()
               if name not in ROS_PACKAGES and name not in PYTHON_DEPENDENCIES and name not in OPTIONAL}
    assert not unknown, ('imports no rosdep key covers (declare the dependency in package.xml, requirements.txt '
                         f'and this test\'s tables): {unknown}')


def test_message_packages_named_by_type_are_ros_packages():
    """Message types the code imports by name (importlib, from 'pkg/msg/Type' strings) are declared packages too."""
    named = {}
    for path in _sources():
        for node in ast.walk(_parse(path)):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                match = _TYPE_NAME.fullmatch(node.value)
                if match:
                    named.setdefault(match.group(1), f'{path.relative_to(REPO)}:{node.lineno}')
    assert named, 'no message type names found: the pattern no longer matches the code'
    assert not {pkg: where for pkg, where in named.items() if pkg not in ROS_PACKAGES}


def test_package_xml_declares_exactly_the_keys_the_imports_need():
    declared = _package_keys(_RUNTIME_TAGS)
    assert len(declared) == len(set(declared)), f'a key declared twice: {declared}'
    imported = _third_party_imports()
    needed = {name: name for name in ROS_PACKAGES if name in imported}
    needed |= {PYTHON_DEPENDENCIES[name][1]: name for name in imported if name in PYTHON_DEPENDENCIES}
    missing = {key: imported[name] for key, name in needed.items() if key not in declared}
    assert not missing, f'package.xml does not declare (key: imported at): {missing}'
    # ament_index_python's resources and launch's files: the ROS packages are all imported, nothing is left over.
    assert set(declared) == set(needed), f'declared, not imported: {sorted(set(declared) - set(needed))}'


def test_every_declared_key_resolves_from_rosdistro_or_the_shipped_yaml():
    shipped = _shipped()
    assert not set(shipped) & set(ROSDISTRO_KEYS), 'a shipped key would be shadowed by rosdistro\'s'
    unresolved = [key for key in _package_keys(_RUNTIME_TAGS + ('test_depend', 'build_depend'))
                  if key not in shipped and key not in ROSDISTRO_KEYS]
    assert not unresolved, f'keys neither rosdistro nor rosdep/crane_stiffness.yaml define: {unresolved}'
    assert set(shipped) <= set(_package_keys(_RUNTIME_TAGS)), 'a shipped key package.xml does not use'


def test_pip_packages_behind_the_keys_are_the_requirements():
    requirements = _requirement_names(REPO / 'requirements.txt')
    pip_of_key = {key: pip for pip, key in PYTHON_DEPENDENCIES.values()}
    for key, rules in _shipped().items():
        assert set(rules) == {'debian', 'ubuntu'}, key
        for os_name, rule in rules.items():
            # A pip rule for every version of the OS: {'pip': {'packages': [...]}}.
            assert rule == {'pip': {'packages': [pip_of_key[key]]}}, (key, os_name, rule)
        assert _normalized(pip_of_key[key]) in requirements, (key, pip_of_key[key])
    for key, (installer, package) in ROSDISTRO_KEYS.items():
        if installer == 'pip':
            assert _normalized(package) == _normalized(pip_of_key[key]) and _normalized(package) in requirements
    # Everything requirements.txt installs is covered by a declared key (the ros-jazzy-* wheels are the ROS
    # packages, which rosdep installs as ros-jazzy-* debs).
    covered = {_normalized(pip) for pip, _ in PYTHON_DEPENDENCIES.values()}
    without_key = {name for name in requirements if not name.startswith('ros-jazzy-')} - covered
    assert not without_key, f'requirements.txt installs what no declared key covers: {sorted(without_key)}'
    assert covered <= requirements, f'not in requirements.txt: {sorted(covered - requirements)}'


def test_optional_imports_are_guarded_and_an_extra():
    extras = {name: {_distribution(req) for req in reqs} for name, reqs in _setup_extras().items()}
    for module, extra in OPTIONAL.items():
        assert module in extras.get(extra, set()), (module, extra, extras)
    for path in _sources():
        tree = _parse(path)
        guarded = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Try) and any(_catches_import_error(h) for h in node.handlers):
                guarded |= {id(n) for statement in node.body for n in ast.walk(statement)}
        for name, node in _imports(tree):
            if name in OPTIONAL:
                assert id(node) in guarded, f'{path.relative_to(REPO)}:{node.lineno}: {name} imported unguarded'


def _catches_import_error(handler: ast.ExceptHandler) -> bool:
    caught = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
    return any(isinstance(c, ast.Name) and c.id in ('ImportError', 'ModuleNotFoundError') for c in caught)


def test_running_md_adds_the_shipped_yaml_to_rosdep():
    text = (REPO / 'docs' / 'running.md').read_text()
    assert 'yaml file://$PWD/src/crane_stiffness/rosdep/crane_stiffness.yaml' in text
    assert 'rosdep install --from-paths src --ignore-src' in text
