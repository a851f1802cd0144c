"""JCGM 101 Monte Carlo against the additive model of its example 9.2, the adaptive procedure, the validation of
section 8, reproducibility by seed, and the JCGM 102 vector form against an analytic linear case."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import comb

from crane_stiffness.uncertainty.budget import propagate
from crane_stiffness.uncertainty.errors import InputError, MonteCarloError
from crane_stiffness.uncertainty.inputs import InputQuantity
from crane_stiffness.uncertainty.montecarlo import (monte_carlo, monte_carlo_vector, numerical_tolerance,
                                                    shortest_interval, symmetric_interval, validate_gum,
                                                    with_monte_carlo)


def additive(x1, x2, x3, x4):
    """JCGM 101 9.2: Y = X1 + X2 + X3 + X4."""
    return x1 + x2 + x3 + x4


def irwin_hall_quantile(p: float) -> float:
    """The exact p-quantile of the sum of four rectangular R(−√3, √3) (each u = 1): Y = 2√3 (S − 2), S the sum of
    four R(0, 1) (Irwin–Hall CDF)."""
    def cdf(s: float) -> float:
        return sum((-1) ** k * comb(4, k) * (s - k) ** 4 for k in range(int(math.floor(s)) + 1)) / 24.0
    s = brentq(lambda s: cdf(s) - p, 0.0, 4.0, xtol=1e-14)
    return 2.0 * math.sqrt(3.0) * (s - 2.0)


def test_numerical_tolerance_of_jcgm_101_7_9_2():
    # JCGM 101 7.9.2 example: u = 0.028 at 2 digits -> 28 x 10^-3, δ = 0.0005
    assert numerical_tolerance(0.028, 2) == pytest.approx(0.0005)
    assert numerical_tolerance(2.0, 2) == pytest.approx(0.05)
    assert numerical_tolerance(2.0, 1) == pytest.approx(0.5)
    assert numerical_tolerance(1675.4, 2) == pytest.approx(50.0)
    assert numerical_tolerance(9.97, 2) == pytest.approx(0.5)  # rounds to 10: one more digit
    with pytest.raises(InputError, match='significant_digits'):
        numerical_tolerance(1.0, 0)


def test_coverage_intervals_of_jcgm_101_7_7():
    y = np.arange(1.0, 1001.0)  # M = 1000, q = 950, r = 25: y_(25) .. y_(975)
    assert symmetric_interval(y, 0.95) == (25.0, 975.0)
    skewed = np.sort(np.random.default_rng(1).exponential(1.0, 200_000))
    lo, hi = shortest_interval(skewed, 0.95)
    # exponential: the shortest 95 % interval is [0, -ln 0.05] = [0, 2.996]
    assert lo == pytest.approx(0.0, abs=1e-3) and hi == pytest.approx(2.996, abs=0.03)
    assert hi - lo < np.subtract(*symmetric_interval(skewed, 0.95)[::-1])


def test_jcgm_101_9_2_2_normal_inputs_validate_the_gum():
    """Four N(0, 1): printed (Table 2) y = 0.00, u(y) = 2.00, 95 % interval [−3.92, 3.92], GUF validated."""
    inputs = [InputQuantity.normal(f'x{i}', 0.0, 1.0) for i in range(1, 5)]
    gum = propagate(additive, inputs)
    mc = monte_carlo(additive, inputs, seed=11, significant_digits=2)
    assert mc.converged and mc.trials >= 20_000 and mc.trials % 10_000 == 0
    delta = numerical_tolerance(2.0, 2)  # 0.05
    assert abs(mc.mean) <= delta and abs(mc.u - 2.00) <= delta
    assert mc.interval == pytest.approx((-3.92, 3.92), abs=delta)
    assert gum.interval == pytest.approx((-3.92, 3.92), abs=0.005)
    assert validate_gum(gum, mc, 2).validated


def test_jcgm_101_9_2_3_rectangular_inputs():
    """Four R(−√3, √3) (u = 1 each): printed (Table 3) MCM y = 0.00, u(y) = 2.00, shortest 95 % interval
    [−3.88, 3.88] against the GUF's [−3.92, 3.92]: d = 0.04, within δ = 0.05 at 2 significant digits, beyond
    δ = 0.005 at 3."""
    inputs = [InputQuantity.bounded(f'x{i}', 0.0, math.sqrt(3.0), 'rectangular') for i in range(1, 5)]
    mc = monte_carlo(additive, inputs, seed=5, trials=1_000_000)
    exact = irwin_hall_quantile(0.975)
    assert round(exact, 2) == 3.88
    # the 97.5 % point of 10^6 draws scatters by ~0.005 about the exact quantile
    assert mc.interval[1] == pytest.approx(exact, abs=0.02) and mc.interval[0] == pytest.approx(-exact, abs=0.02)
    assert mc.shortest == pytest.approx((-3.88, 3.88), abs=0.02)
    assert mc.u == pytest.approx(2.00, abs=0.005) and mc.mean == pytest.approx(0.0, abs=0.01)
    gum = propagate(additive, inputs)
    check2, check3 = validate_gum(gum, mc, 2), validate_gum(gum, mc, 3)
    assert check2.d_low == pytest.approx(0.04, abs=0.02) and check2.validated
    assert check3.delta == pytest.approx(0.005) and not check3.validated
    result = with_monte_carlo(gum, mc, 3).to_dict()
    assert result['monte_carlo']['validation']['validated'] is False and result['monte_carlo']['trials'] == 10 ** 6


def test_the_adaptive_procedure_stops_at_its_tolerance_and_the_seed_reproduces_it():
    inputs = [InputQuantity.bounded(f'x{i}', 0.0, math.sqrt(3.0), 'rectangular') for i in range(1, 5)]
    one = monte_carlo(additive, inputs, seed=21, significant_digits=2)
    again = monte_carlo(additive, inputs, seed=21, significant_digits=2)
    other = monte_carlo(additive, inputs, seed=22, significant_digits=2)
    assert one == again and one != other
    assert one.converged and one.delta == pytest.approx(0.05)
    # one digit (δ = 0.5) settles after the first two batches; two need more (the interval's ends scatter by
    # ~0.05 per batch of 10^4, so 2·0.05/√h <= 0.05 takes h >= 4)
    coarse = monte_carlo(additive, inputs, seed=21, significant_digits=1)
    assert coarse.converged and coarse.trials == 20_000 and one.trials >= 40_000
    assert one.interval[1] == pytest.approx(irwin_hall_quantile(0.975), abs=one.delta)
    capped = monte_carlo(additive, inputs, seed=21, significant_digits=4, max_trials=30_000)
    assert not capped.converged and capped.trials == 30_000


def test_a_model_that_leaves_its_domain_is_an_error_naming_it():
    inputs = [InputQuantity.normal('x', 0.0, 1.0)]
    with pytest.raises(MonteCarloError, match='non-finite'):
        monte_carlo(lambda x: np.where(x > 0.0, x, np.nan), inputs, trials=1000)


def test_correlated_normal_inputs_are_drawn_jointly():
    inputs = [InputQuantity.normal('x1', 1.0, 0.3), InputQuantity.normal('x2', 2.0, 0.4)]
    mc = monte_carlo(lambda a, b: a + b, inputs, correlations={('x1', 'x2'): 0.5}, trials=400_000, seed=2)
    assert mc.u == pytest.approx(math.sqrt(0.09 + 0.16 + 0.12), rel=0.01)
    with pytest.raises(InputError, match='jointly normal'):
        monte_carlo(lambda a, b: a + b, [inputs[0], InputQuantity.bounded('x2', 0, 1)],
                    correlations={('x1', 'x2'): 0.5}, trials=1000)


def test_the_vector_form_gives_the_covariance_of_a_linear_model():
    """JCGM 102: Y = A X for independent X with u = (1, 2, 0.5): V(Y) = A diag(u²) Aᵀ; the 36 entries of a 6×6
    (here a 3×2 output flattened to 6) come the same way, and a derived quantity's u follows from V."""
    a = np.array([[1.0, 2.0, 0.0], [0.5, -1.0, 3.0], [0.0, 1.0, 1.0], [2.0, 0.0, -1.0], [1.0, 1.0, 1.0],
                  [0.0, 0.0, 2.0]])
    u = np.array([1.0, 2.0, 0.5])
    inputs = [InputQuantity.normal('x1', 1.0, 1.0), InputQuantity.bounded('x2', -1.0, 2.0 * math.sqrt(3.0)),
              InputQuantity.bounded('x3', 0.5, 0.5 * math.sqrt(6.0), 'triangular')]
    result = monte_carlo_vector(lambda *x: np.stack(x, axis=1) @ a.T, inputs, trials=300_000, seed=4)
    expected = a @ np.diag(u ** 2) @ a.T
    assert result.mean == pytest.approx(a @ np.array([1.0, -1.0, 0.5]), abs=0.03)
    # sampling error of a covariance entry ~ sqrt((V_ii V_jj + V_ij²)/M): at most ~0.03 here
    assert np.max(np.abs(result.covariance - expected)) < 0.06
    assert np.allclose(result.covariance, result.covariance.T)
    g = np.array([1.0, -1.0, 0.0, 0.0, 0.0, 0.5])
    assert result.derived_uncertainty(g) == pytest.approx(math.sqrt(g @ expected @ g), rel=0.01)
    assert result.u == pytest.approx(np.sqrt(np.diag(expected)), rel=0.01)
    assert np.diag(result.correlation) == pytest.approx(np.ones(6))
    assert len(result.to_dict()['covariance']) == 6


def mass_calibration(m_rc, dm_rc, rho_a, rho_w, rho_r):
    """JCGM 101 9.3: δm = (m_R,c + δm_R,c)(1 + (ρ_a − ρ_a0)(1/ρ_W − 1/ρ_R)) − m_nom [mg], ρ_a0 = 1.2 kg/m³,
    m_nom = 100 g."""
    return (m_rc + dm_rc) * (1.0 + (rho_a - 1.2) * (1.0 / rho_w - 1.0 / rho_r)) - 100_000.0


def test_jcgm_101_9_3_mass_calibration():
    """Inputs (JCGM 101 Table 6): m_R,c = 100 000.000 mg, N(u 0.050 mg); δm_R,c = 1.234 mg, N(u 0.020 mg);
    ρ_a R(1.10, 1.30) kg/m³; ρ_W R(7000, 9000) kg/m³; ρ_R R(7950, 8050) kg/m³. Printed (Table 7): GUF δm =
    1.2340 mg, u = 0.0539 mg, [1.1285, 1.3395] mg; MCM 1.2341 mg, u = 0.0754 mg, shortest 95 % interval
    [1.0834, 1.3825] mg; the GUF (first order) not validated."""
    inputs = [InputQuantity.normal('m_Rc', 100_000.0, 0.050, unit='mg'),
              InputQuantity.normal('dm_Rc', 1.234, 0.020, unit='mg'),
              InputQuantity.bounded('rho_a', 1.2, 0.1, unit='kg/m3'),
              InputQuantity.bounded('rho_W', 8e3, 1e3, unit='kg/m3'),
              InputQuantity.bounded('rho_R', 8e3, 0.05e3, unit='kg/m3')]
    gum = propagate(mass_calibration, inputs)
    assert round(gum.value, 4) == 1.2340 and round(gum.u_c, 4) == 0.0539
    assert [round(x, 4) for x in gum.interval] == [1.1285, 1.3395]
    mc = monte_carlo(mass_calibration, inputs, seed=2, significant_digits=2)
    assert mc.converged and mc.delta == pytest.approx(0.0005)
    assert mc.mean == pytest.approx(1.2341, abs=mc.delta) and mc.u == pytest.approx(0.0754, abs=mc.delta)
    # the shortest interval of this flat-topped distribution moves more between runs than the symmetric one's
    # ends (whose spread the adaptive procedure bounds): a few δ
    assert mc.shortest == pytest.approx((1.0834, 1.3825), abs=0.004)
    check = validate_gum(gum, mc, 2)
    assert not check.validated and check.d_low == pytest.approx(0.044, abs=0.003)


@pytest.mark.parametrize('m', [2, 3, 19, 20, 21, 40, 1000, 12345, 200_000])
@pytest.mark.parametrize('coverage', [0.5, 0.6, 0.9, 0.95, 0.99])
def test_summarise_s_partial_sort_gives_the_full_sort_s_intervals(m, coverage):
    """summarise sorts only the sample's tails: the same order statistics as sorting it all (JCGM 101 7.7)."""
    from crane_stiffness.uncertainty.montecarlo import shortest_interval, summarise, symmetric_interval
    y = np.random.default_rng(m).standard_t(3, m)
    result = summarise(y, coverage, 2, True, 0)
    ordered = np.sort(y)
    assert result.interval == symmetric_interval(ordered, coverage)
    assert result.shortest == shortest_interval(ordered, coverage)
    assert result.mean == pytest.approx(float(np.mean(ordered)), rel=1e-14, abs=1e-14)
    assert result.u == pytest.approx(float(np.std(ordered, ddof=1)), rel=1e-12)
