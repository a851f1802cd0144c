"""`crane-stiffness analyze` and `compare` give the same numbers, to the last digit, on a session copied by the
independent ``rosbags`` writer into rosbag2's sqlite3 storage, into zstd-compressed files (``.mcap.zstd``,
``.db3.zstd``) and with zstd-compressed messages, as on the original bag.

The copies hold the session's streams but not this package's session record (rosbag2 has no place for it), so they
are compared like for like: every copy's whole JSON result against the plain MCAP copy's (the same bag without the
record, analysed the same way), and the fits, pairs and streams of all against the original's.
"""
from __future__ import annotations

import json

import pytest

from crane_stiffness.cli.exit_codes import EXIT_NOT_OK
from crane_stiffness.cli.main import main as cli_main
from crane_stiffness.model import lab_model
from crane_stiffness.sim.program import LoadProgram, Segment
from crane_stiffness.testing.synthetic import write_synthetic_session

from helpers.rosbag2_copy import copy_bag

COPIES = {'mcap': ('mcap', ''), 'sqlite3': ('sqlite3', ''), 'mcap_file_zstd': ('mcap', 'file'),
          'sqlite3_file_zstd': ('sqlite3', 'file'), 'sqlite3_message_zstd': ('sqlite3', 'message'),
          'mcap_message_zstd': ('mcap', 'message')}
#: What names the bag itself (its path and directory name, the output files) or the time the analysis took.
NOT_COMPARED = ('bag', 'session', 'timings_s', 'files')
#: What the original has from its session record (program, geometry: the steps and cycles of the recorded program,
#: the model curves, notes) and a copy has not, or says it has not (problems), beside the NOT_COMPARED keys. All the
#: rest (branch and hold fits, pairing, counts, the live estimate's comparison, stream delays) is identical.
SESSION_RECORD_KEYS = {'bag', 'cycle_fits', 'files', 'geometry', 'mapping', 'model', 'notes', 'problems', 'program',
                       'recorded_with', 'session', 'steps', 'timings_s',
                       'uncertainty',  # (the sensors' declared calibrations are in the session record)
                       'model_disagreements', 'verdict'}  # (no geometry, no model to disagree with)


def side_force_program() -> LoadProgram:
    segs = [Segment('hold', 'fy', 0.0, 0.6)]
    for level in (4.0, 8.0, 12.0, 8.0, 4.0, 0.0):
        segs += [Segment('ramp', 'fy', level, 0.4), Segment('hold', 'fy', level, 0.6)]
    return LoadProgram(segs, repeats=2, name='side_force_short', rate_hz=100.0)


@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    root = tmp_path_factory.mktemp('storages')
    write_synthetic_session(root / 'original', side_force_program(), geometry=lab_model(0.5, 50.0), seed=5,
                            live=True, chunk_size=128 * 1024)
    out = {'original': root / 'original'}
    for name, (storage, compression) in COPIES.items():
        out[name] = copy_bag(root / 'original', root / name, storage=storage, compression=compression)
    return out


def analyze_json(bag, out, capsys) -> dict:
    # The side force to 12 N slackens wires: the fits are no straight line (their scatter is refused), so the verdict
    # is NOT OK, on every storage alike (the original also far from the model's tangent: it has the geometry).
    assert cli_main(['analyze', str(bag), '--out', str(out), '--json', '--quiet']) == EXIT_NOT_OK
    result = json.loads(capsys.readouterr().out)
    assert result['verdict']['level'] == 'NOT OK'
    assert any('scatter' in reason for reason in result['verdict']['reasons'])
    return result


def test_analyze_gives_the_same_numbers_on_every_storage(bags, capsys, tmp_path):
    files = {name: sorted(p.name for p in path.iterdir()) for name, path in bags.items()}
    assert any(f.endswith('.db3') for f in files['sqlite3'])
    assert any(f.endswith('.mcap.zstd') for f in files['mcap_file_zstd'])
    assert any(f.endswith('.db3.zstd') for f in files['sqlite3_file_zstd'])
    results = {name: analyze_json(path, tmp_path / name, capsys) for name, path in bags.items()}
    reference = {k: v for k, v in results['mcap'].items() if k not in NOT_COMPARED}
    assert reference['branch_fits']['loading']['stiffness'] > 0
    for name in COPIES:
        got = {k: v for k, v in results[name].items() if k not in NOT_COMPARED}
        assert got == reference, name
    original = results['original']
    different = {key for key in original if any(results[name][key] != original[key] for name in COPIES)}
    assert different == SESSION_RECORD_KEYS, ' '.join(sorted(different))
    assert {'branch_fits', 'hold_fits', 'pairing', 'counts', 'live'} <= set(original) - different
    assert original['live'] is not None and original['branch_fits']['loading'] is not None
    # the mapping differs only in where the geometry came from: the session record, which the copies lack
    for name in COPIES:
        assert ({**results[name]['mapping'], 'geometry_source': None}
                == {**original['mapping'], 'geometry_source': None}), name
    assert (original['mapping']['geometry_source'], results['mcap']['mapping']['geometry_source']) == (
        'recorded with the session', 'none')
    # compare reads them alike
    assert cli_main(['compare', str(bags['original']), str(bags['sqlite3']), str(bags['mcap_file_zstd']),
                     '--out', str(tmp_path / 'compare'), '--quiet']) == 0
    assert (tmp_path / 'compare' / 'compare.md').is_file()
