"""Many cranes' rest tangents at once (model/draws.py) against the one-crane path, draw by draw, including draws
far enough from the nominal crane (slack wires) that the robust path has to take them."""
from __future__ import annotations

import numpy as np
import pytest

from crane_stiffness.model import GeometryError, lab_model, rest_pose, tangent_stiffness
from crane_stiffness.model.draws import geometry_of_draw, rest_stiffness_draws


def test_each_draw_is_the_tangent_at_its_own_rest_pose(monkeypatch):
    g = lab_model(0.5, 50.0)
    rng = np.random.default_rng(9)
    n = 40
    draws = dict(a=g.a + rng.uniform(-5e-4, 5e-4, n), b=g.b + rng.uniform(-5e-4, 5e-4, n),
                 height=0.5 + rng.uniform(-5e-4, 5e-4, n), weight=50.0 + rng.normal(0.0, 0.5, n),
                 wire_diameter=1.08e-3 + rng.normal(0.0, 1e-5, n),
                 youngs_modulus=g.youngs_modulus * (1.0 + rng.normal(0.0, 0.03, n)),
                 length_offsets=rng.uniform(-5e-6, 5e-6, (n, 6)), com_offset=rng.uniform(-2e-3, 2e-3, (n, 3)))
    draws['length_offsets'][:4] = rng.uniform(-5e-4, 5e-4, (4, 6))  # wires go slack: the robust path's cases
    import crane_stiffness.model.draws as module
    solved = []
    monkeypatch.setattr(module, 'rest_pose', lambda geometry, **kw: solved.append(geometry) or rest_pose(geometry))
    k = rest_stiffness_draws(g, **draws)
    # the nominal crane's rest pose, then the robust path for draws the fast one did not settle (slack wires)
    assert solved[0] is g and 1 <= len(solved) - 1 <= 4
    assert k.shape == (n, 6, 6)
    for i in range(n):
        gi = geometry_of_draw(g, draws, i)
        expected = tangent_stiffness(gi, rest_pose(gi))
        assert np.max(np.abs(k[i] - expected)) <= 1e-9 * np.max(np.abs(expected)), i


def test_scalars_broadcast_and_the_nominal_fills_the_rest():
    g = lab_model(0.4, 30.0, com_offset=(1e-3, 0.0, 2e-3))
    k = rest_stiffness_draws(g, weight=np.array([30.0, 31.0]))
    assert np.allclose(k[0], tangent_stiffness(g, rest_pose(g)), rtol=1e-10, atol=1e-9)
    assert np.allclose(k[1], tangent_stiffness(g.replace(weight=31.0), rest_pose(g.replace(weight=31.0))),
                       rtol=1e-10, atol=1e-9)


def test_bad_draws_are_refused_naming_the_field():
    g = lab_model(0.5, 50.0)
    with pytest.raises(GeometryError, match='height'):
        rest_stiffness_draws(g, height=np.array([0.5, -0.1]))
    with pytest.raises(GeometryError, match='wire_length'):
        rest_stiffness_draws(g, wire_length=np.array([0.5]))
    with pytest.raises(GeometryError, match='a = '):
        rest_stiffness_draws(g, a=np.array([0.1, np.nan]))


def test_one_row_broadcasts_to_every_crane():
    g = lab_model(0.5, 50.0)
    k = rest_stiffness_draws(g, com_offset=[0.0, 0.0, 2e-3], weight=np.array([50.0, 52.0]))
    assert k.shape == (2, 6, 6)
    single = rest_stiffness_draws(g, com_offset=[0.0, 0.0, 2e-3])
    assert single.shape == (1, 6, 6)
    moved = g.replace(com_offset=(0.0, 0.0, 2e-3))
    assert np.allclose(single[0], tangent_stiffness(moved, rest_pose(moved)), rtol=1e-10, atol=1e-9)
    assert np.allclose(k[0], single[0], rtol=1e-12, atol=1e-12)
