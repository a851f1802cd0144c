"""ROS parameter files: one reader and one section rule for the CLI's config, the load programs and the recorder."""
from __future__ import annotations

from pathlib import Path

import pytest

from crane_stiffness.params.errors import ConfigError
from crane_stiffness.params.files import load_params
from crane_stiffness.params.files import (NodeSections, applicable_sections, params_files_from_args,
                                         read_params_files, section_applies)
from crane_stiffness.sim.program import load_program_file

PROGRAM = ('    segments.kind: [ramp]\n    segments.axis: [fx]\n    segments.target: [1.0]\n'
           '    segments.duration: [2.0]\n')


@pytest.mark.parametrize('key, node, applies', [
    ('/**', 'lvdt', True), ('**', '/rig/lvdt', True), ('lvdt', 'lvdt', True), ('/lvdt', 'lvdt', True),
    ('lvdt', '/lvdt', True), ('/lvdt', '/rig/lvdt', False), ('/rig/lvdt', 'lvdt', True),
    ('/rig/lvdt', '/lvdt', False), ('/rig/*', '/rig/lvdt', True), ('/rig/*', '/rig/a/lvdt', False),
    ('/rig/**', '/rig/a/lvdt', True), ('/**/lvdt', '/lvdt', True), ('/**/lvdt', '/a/b/lvdt', True),
    ('/*', '/lvdt', True), ('/*', '/rig/lvdt', False), ('load_cell', 'lvdt', False),
    ('/**/load_cell', '/lvdt', False),
])
def test_section_rule_is_ros_with_wildcards(key, node, applies):
    assert section_applies(key, node) is applies


def test_wildcard_sections_apply_first_then_the_nodes_own_in_file_order():
    keys = ['lvdt', '/**', 'load_cell', '/rig/*', '/lvdt']
    assert applicable_sections(keys, 'lvdt') == ['/**', '/rig/*', 'lvdt', '/lvdt']
    assert applicable_sections(keys, None) == keys
    own = NodeSections('session_recorder')
    assert '/**' in own and 'session_recorder' in own and '/session_recorder' in own and 'lvdt' not in own


def test_cli_config_and_load_program_read_the_same_sections(tmp_path: Path):
    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    rate_hz: 50.0\n    name: wild\n'
                    'other:\n  ros__parameters:\n    name: other\n'
                    f'/rig/load_program:\n  ros__parameters:\n    name: own\n{PROGRAM}')
    params = load_params(path, 'load_program')
    assert params['name'] == 'own' and params['rate_hz'] == 50.0 and params['segments.kind'] == ['ramp']
    program = load_program_file(path, node='load_program')
    assert (program.name, program.rate_hz) == ('own', 50.0)
    assert load_params(path, '/load_program') == {'rate_hz': 50.0, 'name': 'wild'}


def test_reader_errors_keep_each_callers_terms(tmp_path: Path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('a: [unclosed\n')
    with pytest.raises(ConfigError, match='not valid YAML'):
        load_params(bad)
    with pytest.raises(ConfigError, match='no such config file'):
        load_params(tmp_path / 'absent.yaml')
    odd = tmp_path / 'odd.yaml'
    odd.write_text('lvdt: 3\n/**:\n  ros__parameters:\n    a: 1\n')
    with pytest.raises(ConfigError, match="section 'lvdt' has no ros__parameters"):
        load_params(odd, 'lvdt')
    assert load_params(odd, 'load_cell') == {'a': 1}
    files, sections, problems = read_params_files([str(odd), str(bad), str(tmp_path / 'absent.yaml')])
    assert [f['text'] for f in files] == [odd.read_text()] and sections == {'/**': {'a': 1}}
    assert len(problems) == 2 and problems[0].startswith(str(bad))


def test_params_files_from_ros_arguments():
    argv = ['node', '--params-file', 'x', '--ros-args', '--params-file', 'a.yaml', '-p', 'k:=1', '--',
            '--params-file', 'y', '--ros-args', '--params-file', 'b.yaml']
    assert params_files_from_args(argv) == ['a.yaml', 'b.yaml']


def test_a_section_that_can_only_be_a_typo_is_refused_naming_the_closest_node(tmp_path):
    """A section read by no node is silent in ROS; given the package's nodes, load_params refuses one close to a
    node's name (the CLI's --config), and lets pass one like none (another package's node in a shared file)."""
    from crane_stiffness.nodes import NODES
    path = tmp_path / 'crane.yaml'
    path.write_text('/**:\n  ros__parameters:\n    geometry.height: 0.5\n'
                    'crane_modle:\n  ros__parameters:\n    x: 1\n')
    with pytest.raises(ConfigError, match=rf"{path}: section 'crane_modle' applies to no node of this package "
                                          r"\(did you mean 'crane_model'\?\)"):
        load_params(path, 'crane_model', known_nodes=NODES)
    assert load_params(path, 'crane_model') == {'geometry.height': 0.5}  # without the list: ROS's silence
    path.write_text('/**:\n  ros__parameters:\n    geometry.height: 0.5\n'
                    'camera_driver:\n  ros__parameters:\n    x: 1\n/rig/crane_model:\n  ros__parameters:\n    y: 2\n')
    assert load_params(path, 'crane_model', known_nodes=NODES) == {'geometry.height': 0.5, 'y': 2}
