"""The 6×6 reference and the pose deflection: the exact tangent against the paper's eq. (18) at the lab model, where
K2 sits and its sign, and the deflection of the nonlinear model under a small wrench against C·w."""
from __future__ import annotations


import numpy as np
import pytest


from helpers import run_without_ros
from crane_stiffness.full6.deflection import pose_deflection, rotation_vector
from crane_stiffness.full6.reference import K2_ENTRIES, entry_name, k2_of, reference_at_rest
from crane_stiffness.model import lab_model, solve_equilibrium
from crane_stiffness.model.rotation import quaternion_to_matrix, rotvec_to_matrix, matrix_to_quaternion

LAB = lab_model(0.5, 50.0)


def test_the_tangent_at_rest_is_eq_18_and_k2_sits_where_the_paper_puts_it():
    ref = reference_at_rest(LAB)
    assert ref.paper is not None and ref.coefficients is not None
    np.testing.assert_allclose(ref.tangent, ref.paper, rtol=0, atol=1e-12 * np.abs(ref.paper).max())
    k2 = ref.coefficients.k2
    assert k2 == pytest.approx(17898.6, rel=1e-5)  # N/rad, the lab model at h = 0.5 m, W = 50 N
    for i, j, sign in K2_ENTRIES:
        assert ref.tangent[i, j] == pytest.approx(sign * k2, rel=1e-12)
    assert ref.k2 == pytest.approx(k2, rel=1e-12) and k2_of(ref.paper) == pytest.approx(k2, rel=1e-15)
    # a force along +y at the centre tilts the platform about +x ... with the sign C says
    assert ref.compliance[3, 1] < 0.0 and ref.compliance[4, 0] > 0.0
    np.testing.assert_allclose(ref.compliance @ ref.tangent, np.eye(6), atol=1e-12)
    assert entry_name(1, 3) == 'K[fy, θ_x]' and entry_name(3, 1, compliance=True) == 'C[θ_x, fy]'


def test_eq_18_is_left_out_where_it_does_not_apply():
    ref = reference_at_rest(LAB.replace(com_offset=(0.01, 0.0, 0.02)))
    assert ref.paper is None and ref.coefficients is None and np.all(np.isfinite(ref.tangent))


def test_rotation_vector_inverts_rodrigues_and_reads_quaternions():
    rng = np.random.default_rng(1)
    for _ in range(40):
        w = rng.normal(size=3) * rng.choice([1e-12, 1e-6, 1e-3, 0.5, 1.5])
        if np.linalg.norm(w) >= 3.0:  # the rotation vector of a turn is read for angles below π
            continue
        np.testing.assert_allclose(rotation_vector(rotvec_to_matrix(w)), w, rtol=1e-9, atol=1e-15)
        q = rotvec_to_matrix(w)
        np.testing.assert_allclose(rotation_vector(quaternion_to_matrix(matrix_to_quaternion(q))), w, rtol=1e-9,
                                   atol=1e-15)
    batch = np.array([rotvec_to_matrix(v) for v in rng.normal(size=(5, 3)) * 0.1])
    np.testing.assert_allclose(rotation_vector(batch), [rotation_vector(b) for b in batch], rtol=1e-15)


def test_the_deflection_under_a_small_wrench_is_the_tangent_compliance_times_the_wrench():
    """The deflection's odd part is C·w to third order in the load; its even part (second order) is small."""
    ref = reference_at_rest(LAB)
    rest = ref.equilibrium
    w = np.array([0.2, -0.3, 1.5, 0.05, -0.04, 0.02])  # N, N·m: far inside every slack margin
    plus, minus = (solve_equilibrium(LAB, load=s * w) for s in (1.0, -1.0))
    d_plus, d_minus = (pose_deflection(eq.displacement, eq.rotation, rest.displacement, rest.rotation)
                       for eq in (plus, minus))
    cw = ref.compliance @ w
    np.testing.assert_allclose((d_plus - d_minus) / 2.0, cw, rtol=0, atol=1e-8 * np.abs(cw).max())
    assert np.abs(d_plus + d_minus).max() / 2.0 < 1e-4 * np.abs(cw).max()


def test_the_package_imports_no_ros():
    run_without_ros('''
        for name in ("reference", "deflection", "admissible", "design", "linearity", "full_scale", "program",
                     "statistics", "identify"):
            __import__(f"crane_stiffness.full6.{name}")
        import crane_stiffness.testing.synthetic_full6
    ''')
