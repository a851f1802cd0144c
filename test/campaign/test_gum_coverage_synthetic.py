"""The GUM coverage study in its fast synthetic form (crane_stiffness.testing.synthetic_campaign.synthetic_gum_study):
many synthetic side-force sessions, no ROS and no bag, whose sensors carry true calibration errors drawn from their
declared certificates and the study's coloured noise with drift (config/campaign_coverage_gum_sensors.yaml), each
stated with its GUM uncertainty by the analysis' own function. Seeded: the same counts in every run.

The expanded interval k ± U must cover the truth as often as it says (0.95 inside the fraction's Clopper–Pearson
interval), the statistical-only intervals far less; and a budget that leaves out a component the sensors do have
must be caught (the study on the simulated rig: docs/uncertainty.md, "Coverage")."""
from __future__ import annotations

from crane_stiffness.testing.synthetic_campaign import synthetic_gum_study

SEED = 7


def test_the_expanded_interval_covers_the_truth_95_percent_of_the_time_and_the_statistical_one_far_less():
    study = synthetic_gum_study(800, SEED)
    for branch in ('loading', 'unloading'):
        gum, samples = study[f'k fy {branch}, GUM U'], study[f'k fy {branch}']
        repeatability = study[f'k fy {branch}, repeatability']
        print(gum, gum.interval, repeatability, samples)
        assert gum.total == samples.total == 800
        assert gum.consistent, (gum, gum.interval)  # 0.95 inside the fraction's binomial interval
        # the samples' fit (the live estimator's interval) counts no calibration error: it rarely covers
        assert samples.fraction < 0.2, samples
        # the hold means' statistical interval (few holds, a wide t) covers more, still short of 0.95
        assert repeatability.fraction < gum.fraction and not repeatability.consistent, repeatability


def test_a_budget_without_the_lvdt_s_linearity_is_caught():
    """The LVDT has its linearity error (drawn from its ±0.25 % FS) but its certificate given to the analysis
    states none: the expanded interval is too short and the study says so."""
    study = synthetic_gum_study(400, SEED, declared={'lvdt': {'calibration.linearity_distribution': 'not_stated'}})
    for branch in ('loading', 'unloading'):
        gum = study[f'k fy {branch}, GUM U']
        print(gum, gum.interval)
        assert not gum.consistent and gum.interval[1] < 0.95, (gum, gum.interval)


def test_the_statistical_part_holds_for_coloured_noise_and_drift():
    """Sensors without calibration errors (every component zero), the study's coloured noise and drift: the truth is
    what the sensors read on average, so the statistical part alone must cover it as it says. The hold means' fit
    (the Type A the budget takes: a handful of nearly independent points, n − 2 degrees of freedom) does; the fit of
    the thousands of correlated samples (what the live estimator fits) claims far more than they hold."""
    from crane_stiffness.campaign.coverage import Coverage
    from crane_stiffness.model import axis_stiffness, lab_model, rest_pose, tangent_stiffness
    from crane_stiffness.sim.calibration import LOAD_CELL_COMPONENTS, LVDT_COMPONENTS
    from crane_stiffness.testing.synthetic_campaign import gum_sensor_params, synthetic_gum_session

    geometry = lab_model(0.5, 50.0)
    truth = axis_stiffness(tangent_stiffness(geometry, rest_pose(geometry)), 'fy')
    load_cell = gum_sensor_params('load_cell', {f'calibration.{c.name}': 0.0 for c in LOAD_CELL_COMPONENTS})
    lvdt = gum_sensor_params('lvdt', {f'calibration.{c.name}': 0.0 for c in LVDT_COMPONENTS})
    sessions = 400
    covered: dict[tuple[str, str], int] = {}
    for index in range(sessions):
        result = synthetic_gum_session(index, SEED, truth, load_cell=load_cell, lvdt=lvdt, rate_hz=250.0)
        assert result['errors']['load_cell_nonlinearity'] == 0.0
        for branch in ('loading', 'unloading'):
            for key in ('repeatability', 'statistical'):
                low, high = result[branch][key]
                covered[branch, key] = covered.get((branch, key), 0) + int(low <= truth <= high)
    for branch in ('loading', 'unloading'):
        type_a = Coverage(f'k fy {branch}, repeatability', covered[branch, 'repeatability'], sessions)
        samples = Coverage(f'k fy {branch}', covered[branch, 'statistical'], sessions)
        print(type_a, type_a.interval, samples)
        assert type_a.consistent, (type_a, type_a.interval)
        assert samples.fraction < 0.6, samples
