"""The honesty grid, small: what canest flags valid is right within what it publishes.

``tools/honesty.py --small`` (sine and step at 80 km/h on friction 0.35 and
0.85, 4 s each). Asserted here is what canest guarantees today for every filter
in the list (README "How far to trust the output" has the full grid and the
filters and states still outside the issue's targets).
"""
import dataclasses
import json
import sys

import numpy as np
import pytest

from canest.apps.evaluate import Score, counts, read_table, valid_mask
from canest.config import load_config
from canest.signals import WHEELS
from canest.sim.mismatch import PlantMismatch, drawn_mismatch
from tests.conftest import CONFIG, ROOT

sys.path.insert(0, str(ROOT / "tools"))
import honesty  # noqa: E402
import std_scales  # noqa: E402

FILTERS = ("ckf", "mcsckf", "svd-fckf", "jckf", "dici-gfckf")
CALIBRATED = ("ckf", "mcsckf", "svd-fckf", "jckf")  # standard deviations covering the error at +-2 std
VIBRATING = ("ckf", "dekf", "jckf", "dckf")  # replayed on the small grid with the IMU vibrating


def replayed(case, name, workdir, process_noise=None):
    """(estimates as a table, truth) of one filter on one simulated drive, every tick; ``process_noise``: entries
    the replay takes instead of the config's."""
    config = load_config(CONFIG)
    log, truth = honesty.drive(config, case, workdir)
    if process_noise:
        noise = {**config.estimator.process_noise, **process_noise}
        config = dataclasses.replace(config, estimator=dataclasses.replace(config.estimator, process_noise=noise))
    return honesty.replayed(config, name, log)[0], read_table(truth)


def per_wheel(result, name: str, state: str) -> list:
    """The four wheels' scores of ``state`` (``fy`` or ``mu``) for filter ``name`` in one
    :func:`honesty.run_case` result."""
    return [honesty.summarize(f"{state}_{wheel}", result["sums"][name][f"{state}_{wheel}"]) for wheel in WHEELS]


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    args = honesty.parse_args(["--small"])
    results = honesty.grid(CONFIG, FILTERS, honesty.cases_of(args), tmp_path_factory.mktemp("honesty"),
                           report=lambda text: None, scales=True)
    assert not any(r.get("failed") for r in results)
    return results


@pytest.fixture(scope="module")
def scores(results):
    return honesty.pooled(results, FILTERS)


def test_the_per_case_rows_are_the_drives_that_make_the_pooled_score(results, scores):
    """``--per-case``: one row per drive and filter, whose ticks add up to the pooled score's and whose worst
    error is the pool's."""
    rows = honesty.per_case(results, FILTERS, "vx")
    assert [(key, name) for key, name, _ in rows] == [(r["case"].key, name) for r in results for name in FILTERS]
    for name in FILTERS:
        own = [score for _, row_name, score in rows if row_name == name]
        assert sum(score.samples for score in own) == scores[name]["vx"].samples
        assert max(score.max_error for score in own) == scores[name]["vx"].max_error
    table = honesty.per_case_markdown(rows)
    assert len(table.splitlines()) == 2 + len(rows) and results[0]["case"].key in table


def test_the_std_as_published_meets_the_targets_exactly_where_its_factor_1_does(results, scores):
    """``--scales`` judges the factors on the std by the pooled score's own targets (factor 1: the std as
    published); a valid yaw rate of the wrong sign is no std's matter, and none is on this grid."""
    scales = honesty.pooled_scales(results, FILTERS)
    outside = {(name, state) for name, state, _ in honesty.outside_targets(scores)}
    judged = [(name, state) for name, states in scores.items() for state, score in states.items() if score.valid > 0]
    assert len(judged) > 3 * len(FILTERS)
    for name, state in judged:
        assert std_scales.includes_published(scales[name][state]) == ((name, state) not in outside), \
            (name, state, scales[name][state])


@pytest.mark.parametrize("name", FILTERS)
def test_no_valid_yaw_rate_of_the_wrong_sign_and_nothing_valid_but_wrong(scores, name):
    """mcsckf and svd-fckf once published +21.5 deg/s against a true -12.6, flagged valid, on the low-friction sine."""
    assert scores[name]["yaw_rate"].wrong_sign == 0
    for state in ("vx", "yaw_rate", "beta"):
        assert scores[name][state].vbw <= 0.001, (name, state, scores[name][state])


@pytest.mark.parametrize("name", CALIBRATED)
def test_the_published_std_covers_the_error(scores, name):
    for state in ("vx", "yaw_rate", "beta"):
        score = scores[name][state]
        assert 0.90 <= score.cov2 and 0.98 <= score.cov3, (name, state, score)
        assert score.nees <= 2.0, (name, state, score)  # never overconfident on average
        assert score.valid > 0.4, (name, state, score)  # honesty by flagging everything invalid is no answer
    for state in ("vx", "yaw_rate", "beta"):  # nor so wide as to say little (jckf's sideslip NEES 0.25 and vx 0.3 here
        # before its covariance was taken to hold the stiffness's error and its vx noise was its wheels': 0.62, 0.96)
        assert scores[name][state].nees >= 0.5, (name, state, scores[name][state])


def test_frictions_flagged_valid_are_right(scores):
    """jckf's frictions were valid but wrong on 1.8-4.3 % of the grid's ticks: plunging from the prior in a step
    steer on a dry road (0.90 -> 0.15 in 0.25 s, std 0.06), read from a stiffness the model lacks, or kept while
    the car slid. The std now carries the stiffness's error and the range the estimate spanned over a second.
    Measured on low friction: valid on 6.9 % of these 4 s drives' ticks (13-17 % before the limit's yaw test
    took the understeer gradient's std, which shows a limit later; the full grid's 24-28 -> 23-26 %)."""
    for wheel in WHEELS:
        score = scores["jckf"][f"mu_{wheel}"]
        assert score.valid > 0.05 and score.vbw <= 0.001, (wheel, score)  # measured on low friction, never wrong


@pytest.fixture(scope="module")
def vibrating(tmp_path_factory):
    args = honesty.parse_args(["--small", "--vibration", "1"])
    results = honesty.grid(CONFIG, VIBRATING, honesty.cases_of(args), tmp_path_factory.mktemp("vibrating"),
                           report=lambda text: None)
    return honesty.pooled(results, VIBRATING)


@pytest.mark.parametrize("name", ("jckf", "dckf"))
def test_friction_disagreeing_with_the_measured_forces_is_not_valid(vibrating, name):
    """An IMU vibrating as on a real car, under the built-in config's noise: the frictions were flagged valid on
    62-88 % of ticks and wrong on 64-77 % of those (and after a divergence reset, which keeps them, at once).
    The channels that show the tires' forces disagree with the filter: friction is inconsistent, not valid."""
    for wheel in WHEELS:
        score = vibrating[name][f"mu_{wheel}"]
        assert not score.vbw > 0.001, (name, score)
        assert score.valid < 0.05, (name, score)
    assert vibrating[name]["yaw_rate"].wrong_sign == 0


@pytest.mark.parametrize("name", ("ckf", "dekf", "jckf"))  # dckf's is at a tire's limit on these drives: never valid
def test_the_sideslip_on_a_vibrating_imu_is_valid_and_right(vibrating, name):
    """ay vibrating by 1.4 m/s^2 where 0.15 is configured: judged by the configured noise the sideslip was never
    valid on such an IMU (issue 17's real car's ay jumped so). Judged by the noise ay's samples show, with the
    kinematic check's tolerance widened by ay's integrated noise and the model error held over the last second,
    it is valid on part of the ticks and none of them is wrong (in these first 4 s ckf's valid sideslip has a NEES of 2.6:
    README "The sideslip on a vibrating IMU"). dekf's was never valid: its stiffness scale, learned from the residual
    at the posterior that had just taken in ay's coloured noise, ran to 1.35-1.79 (per-drive medians on 0.85:
    ``canest.filters.ekf``)."""
    score = vibrating[name]["beta"]
    assert score.valid > 0.02 and score.vbw <= 0.001 and score.cov2 >= 0.9 and score.cov3 >= 0.98, score


@pytest.mark.parametrize("name", ("jckf", "dckf"))
def test_the_yaw_rate_std_carries_a_vibrating_gyro_s_noise(vibrating, name):
    """The gyro vibrating by 0.3 deg/s beside the configured 0.1: the published yaw rate was 2.7 times too certain
    (NEES 8.6, within 2 std 50 %) and the consistency test could not see it (a coloured noise the prior followed).
    Its std is widened by the gyro's noise as its samples show it (:mod:`canest.estimation.measured_noise`)."""
    score = vibrating[name]["yaw_rate"]
    assert score.valid > 0.9 and score.cov2 >= 0.9 and score.nees <= 2.0, score


def test_vx_integrating_a_vibrating_ax_is_never_more_certain_than_its_shared_random_walk(vibrating):
    """Between the wheels' anchors ckf's vx integrates ax and takes the reference speed, which integrates the same
    ax, every tick as a new measurement: on this grid its vx was 2.6 times too certain (NEES 6.9, within 2 std
    80 %). The walk is one error all those ticks share: the filter's prior holds it, the reference channel's
    std leaves it out, and the published std adds it to the error beside it."""
    score = vibrating["ckf"]["vx"]
    assert score.nees <= 2.0 and score.cov2 >= 0.90 and score.vbw <= 0.001, score


@pytest.mark.parametrize("name, mu, seed", [("ckf", 0.85, 0), ("dici-gfckf", 0.35, 2)])
def test_vx_carries_the_drift_a_sideslip_error_puts_into_it(tmp_path, name, mu, seed):
    """Where the wheels do not roll freely vx integrates ``ax + r vy``, which drifts with the sideslip's error; its
    std carries that drift (:meth:`canest.estimation.judge.StateJudge.lateral_std`). Without it, in the sine at
    80 km/h on drawn cars, ckf's vx on 0.85 (seed 0's car) was valid on 31 % of the ticks and wrong on 16 % of
    those (0.58 m/s off, NEES 9.3), dici-gfckf's on 0.35 (seed 2's) on 5.6 % (NEES 4.4); over the drawn cars'
    grid ckf's 1.17 %, and the validity and honesty tests passed."""
    result = honesty.run_case(CONFIG, [name], honesty.Case("sine", 80.0, mu, seed, car="drawn"), tmp_path)
    score = honesty.summarize("vx", result["sums"][name]["vx"])
    assert score.valid > 0.1 and score.vbw == 0.0 and score.nees <= 2.0, score


def test_vx_is_not_valid_on_a_walk_whose_noise_is_not_yet_measured(tmp_path):
    """ax's noise is measured from its samples after about half a second: until then the reference speed
    integrated a vibrating ax with no random walk in its std, and ckf published vx 0.40 m/s off with a std of
    0.029, valid, at 0.5 s of the small vibrating grid's sine; and when the wheels anchored it on the next tick
    the walk, now measurable, had not reached its variance (0.41 off, std 0.033). vx is "initializing" while the
    reference speed takes an ax of unknown noise, and the walk is taken at the density as measured now: on this
    drive at most 4.1 std off then, was 14 (on the first ticks after the density is known, read from a quarter
    second of residuals, other seeds are still 5-8 std off, was 6-14)."""
    from canest.apps.compare import with_filter
    from canest.apps.evaluate import read_table
    from canest.apps.replay import replay
    config = load_config(CONFIG)
    log, truth_csv = honesty.drive(config, honesty.Case("sine", 80.0, 0.85, 0, duration=1.5, vibration=1.0), tmp_path)
    truth, estimates = read_table(truth_csv), []
    replay(with_filter(config, "ckf"), log, progress=False, on_estimate=estimates.append)
    valid = [e for e in estimates if e.causes["vx"] == "valid"]
    errors = [abs(e.values["vx"] - np.interp(e.t, truth["t"], truth["vx"])) / e.values["vx_std"] for e in valid]
    assert len(valid) > 0.5 * len(estimates) and max(errors) < 5.0, max(errors)


def test_vx_is_never_more_certain_than_its_disagreement_with_the_reference_speed(tmp_path):
    """dckf drives vx by its wheels' forces through frictions it estimates; on a vibrating launch on 0.35 they drifted
    up on the front axle (0.55) and vx ran 1.3-1.9 m/s ahead of the truth, with a std of 0.23-0.36, flagged valid
    for half a second (seed 2: 45 of its 275 valid ticks wrong by more than 3 std, up to 6.9), while the reference
    speed it takes was 0.3-0.5 m/s off with a std of 0.3 (a prior that small keeps the reference's pull weak). The
    published std is never below the disagreement with the reference beyond the reference's own std: vx turns
    "uncertain". Left are ticks where the reference, off the same way, still agreed: over eight seeds 50 of 2 192
    valid ticks, at most 4.5 std (with ay's std 0.15 on every tick, before ``lateral_model_error``: 56 of 2 098,
    4.55; seed 2 3 -> 17 of them, seed 5 25 -> 6, seed 7 27 either way: one seed tells little of this). Since the
    integrated reference's error from ax's offset is one every tick shares (``ReferenceSpeed.integration_std``): 9 of
    1 850, at most 3.9 std; since the offset's evidence counts a vibrating ax's spikes: none of 1 529, 1.9 std."""
    from canest.apps.compare import with_filter
    from canest.apps.evaluate import read_table
    from canest.apps.replay import replay
    config = load_config(CONFIG)
    wrong, valid_ticks, z_max = 0, 0, 0.0
    for seed in range(8):
        case = honesty.Case("launch", 80.0, 0.35, seed, duration=4.0, vibration=1.0)
        log, truth_csv = honesty.drive(config, case, tmp_path)
        truth, estimates = read_table(truth_csv), []
        replay(with_filter(config, "dckf"), log, progress=False, on_estimate=estimates.append)
        errors = np.array([e.values["vx"] - np.interp(e.t, truth["t"], truth["vx"]) for e in estimates])
        stds = np.array([e.values["vx_std"] for e in estimates])
        valid = np.array([e.causes["vx"] == "valid" for e in estimates])
        if seed == 2:
            assert np.nanmax(np.abs(errors)) > 1.0  # the drive still shows the frictions' drift
        wrong += int((valid & (np.abs(errors) > np.maximum(3.0 * stds, 0.5))).sum())
        valid_ticks += int(valid.sum())
        z_max = max(z_max, float(np.max(np.abs(errors[valid]) / stds[valid])))
    assert wrong <= 0.03 * valid_ticks and z_max < 5.0, (wrong, valid_ticks, z_max)


def test_a_drawn_car_grid_drives_one_car_per_seed_as_wrong_as_the_config_admits():
    """``--car drawn``: the drives are cached apart from the exact car's, and each seed's is its own car."""
    config = load_config(CONFIG)
    drawn = honesty.cases_of(honesty.parse_args(["--maneuvers", "sine,step", "--car", "drawn", "--seeds", "2"]))
    exact = honesty.cases_of(honesty.parse_args(["--maneuvers", "sine,step", "--seeds", "2"]))
    assert {case.key for case in drawn}.isdisjoint(case.key for case in exact)
    for case in drawn:
        assert case.mismatch(config) == drawn_mismatch(config.vehicle, case.seed) != PlantMismatch()
    assert len({case.mismatch(config) for case in drawn}) == 2  # one car per seed, whatever the maneuver
    assert all(case.mismatch(config) == PlantMismatch() for case in exact)
    claiming = dataclasses.replace(config, estimator=dataclasses.replace(config.estimator, gyro_bias_std=0.01))
    assert drawn[0].mismatch(claiming) == drawn_mismatch(config.vehicle, drawn[0].seed, 0.01)  # the claim drawn


def test_the_sideslip_std_carries_a_stiffness_error_near_the_tire_limit(tmp_path):
    """On a car drawn as wrong as its config admits (ay bias -0.21), jckf's sideslip in a slide the kinematic test
    missed was 3-4 deg off with stds of 0.8-1.2, valid (23 % of this drive's valid ticks): the stiffness term was
    the linear tire's. It is the estimate's rear slip angle times the stiffness's uncertainty now."""
    result = honesty.run_case(CONFIG, ["jckf"], honesty.Case("sine", 80.0, 0.35, 2, car="drawn"), tmp_path)
    score = honesty.summarize("beta", result["sums"]["jckf"]["beta"])
    assert score.valid > 0.2 and score.vbw == 0.0, score


def test_a_sideslip_lost_in_a_slide_does_not_come_back_while_the_car_moved_as_the_model_did_not(tmp_path):
    """A drawn car in gusts (seed 1), step steer on 0.35: a slide of 6-7 deg that jckf read as 3-4.5. Its bit came
    back at 4.93 s, as the kinematic window agreed again in the steady slide, 3.3 deg off with a std of 1.0 (0.4 %
    of that grid's valid ticks, wrong): its model had moved 1.7 deg since the sideslip was last known, the car's
    lateral velocity 0.5 m/s more (``validity.LateralDrift.allows_return``)."""
    case = honesty.Case("step", 80.0, 0.35, 1, car="drawn", crosswind=1.0)
    result = honesty.run_case(CONFIG, ["jckf"], case, tmp_path)
    score = honesty.summarize("beta", result["sums"]["jckf"]["beta"])
    assert score.valid > 0.1 and score.vbw == 0.0, score


@pytest.mark.parametrize("seed", (0, 2))
def test_a_reweighting_filter_s_yaw_rate_of_the_wrong_sign_is_never_valid_on_a_vibrating_gyro(tmp_path, seed):
    """mcsckf reweights the gyro's large innovations down, so in a slide on 0.35 its yaw rate leaves the gyros;
    the yaw rate's consistency test, judged against the filter's own prior spread, is what clears its bit then.
    Judged against the wider prior the published std claims for a vibrating gyro (the filter's last posterior
    scaled by the gyro's measured over configured noise), this step steer on a drawn car had its yaw rate valid on
    every tick (64-67 % now, at most 1.7 deg/s off), 4 of them 2.1-2.5 deg/s off with the sign of the truth wrong
    (10 over the drawn vibrating grid), while the other filters' yaw rate came within 2 std on 97.5-98.3 % instead
    of 98.6-99.0 %: the over-coverage that test would have removed is the price of this one."""
    case = honesty.Case("step", 80.0, 0.35, seed, vibration=1.0, car="drawn")
    result = honesty.run_case(CONFIG, ["mcsckf"], case, tmp_path)
    score = honesty.summarize("yaw_rate", result["sums"]["mcsckf"]["yaw_rate"])
    assert score.valid > 0.5 and score.wrong_sign == 0 and score.vbw <= 0.001, score


def test_an_adaptive_filter_s_yaw_rate_std_counts_a_vibrating_gyro_once(tmp_path):
    """lmrwekf learns the gyro's R from its innovations and its published covariance takes it
    (``canest.filters.adaptive``): a vibrating gyro's noise is in that covariance already. The yaw-rate std's factor
    for the gyro's measured noise was taken over the configured R, and counted the vibration a second time: in this
    sine on 0.35 (a drawn car, seed 2) NEES 0.19, within 1 std on 97 % of the valid ticks. Over the R the covariance
    took: NEES 0.72, within 2 std 97.6 %."""
    case = honesty.Case("sine", 80.0, 0.35, 2, vibration=1.0, car="drawn")
    result = honesty.run_case(CONFIG, ["lmrwekf"], case, tmp_path)
    score = honesty.summarize("yaw_rate", result["sums"]["lmrwekf"]["yaw_rate"])
    assert score.valid > 0.2 and 0.5 <= score.nees <= 2.0 and score.cov2 >= 0.9, score
    assert score.vbw <= 0.001 and score.wrong_sign == 0, score


def test_the_dual_filter_s_sideslip_is_not_valid_on_a_tire_at_a_friction_it_cannot_bound(tmp_path):
    """dckf's frictions carry a bias no covariance bounds (``canest.filters.dual``); where a tire works at its limit
    they set the sideslip. On this car (rear stiffness x1.25) the step steer on 0.85 left its rear frictions at
    0.45-0.55, then one at 0.11, and its sideslip 2-3.5 deg off with a std of 0.9-1.2, valid on 28 % of the ticks
    and wrong on 0.5 % of those. Now it is valid only before the step, where no tire is at its limit (8 %)."""
    result = honesty.run_case(CONFIG, ["dckf"], honesty.Case("step", 80.0, 0.85, 1, car="drawn"), tmp_path)
    score = honesty.summarize("beta", result["sums"]["dckf"]["beta"])
    assert score.valid > 0.05 and score.vbw == 0.0 and score.max_error < 0.5, score


def test_the_lateral_forces_std_is_the_tire_curves_error_not_a_random_walks(tmp_path):
    """The tire-force model's forces relax towards the tire curve; their std was that of a 3000 N/sqrt(s) random
    walk against the relaxation (336 N on every wheel, NEES 0.08-0.61, mean 0.28, on this drive of a car drawn
    with its stiffnesses off). It is now the stiffness uncertainty's share of each force, moving an axle's two
    wheels together, over a 300 N/sqrt(s) floor. The sideslip's covariance holds that error too, as a relaxing
    noise: the stiffness term of the other models added on top of it doubled it (NEES 0.35 on this drive, 1.26
    counted once). It is the std's floor instead: NEES 0.40 here, where the car's stiffnesses are within 13 % of the
    config's and the floor is wider than their error; the next test shows why the floor must be there. (The forces
    and the sideslip share one bit: valid on 31 % of the ticks with a sideslip's return tested for 3 s, 26 % at 5 s,
    ``validity.RETURN_MEMORY``; judged over more than a fifth.)"""
    case = honesty.Case("sine", 80.0, 0.85, 2, car="drawn")
    result = honesty.run_case(CONFIG, ["dici-gfckf"], case, tmp_path)
    scores = per_wheel(result, "dici-gfckf", "fy")
    assert all(score.valid > 0.2 and score.vbw == 0.0 for score in scores), scores
    assert 0.4 <= sum(score.nees for score in scores) / len(scores) <= 2.0, scores
    sideslip = honesty.summarize("beta", result["sums"]["dici-gfckf"]["beta"])
    assert sideslip.valid > 0.2 and sideslip.vbw == 0.0 and 0.38 <= sideslip.nees <= 2.0, sideslip


def test_the_tire_force_sideslip_std_is_never_below_a_stiffness_error_held_steadily(tmp_path):
    """This car's rear stiffness is x0.77 of its config's (within the 15 % it claims at 1.6 std). The tire-force
    model's covariance holds a stiffness error as a noise relaxing within the tires' relaxation length, and in the
    step steer's steady state the measurements average it away: on a vibrating IMU, whose kinematic check cannot
    see 1.2 deg, dici-gfckf's sideslip was 1.2 deg off with a std of 0.36, valid but wrong on 57 % of its valid
    ticks. The stiffness term is now the std's floor. Since the kinematic check reads both accelerometers' mean
    the sideslip is valid on 43 % of the ticks (7 % before), and in the steady turn it was 1.0-1.7 deg off with a
    std of 0.55-0.6, flagged valid (3 % of its valid ticks wrong): the rear tires at 0.8 of their load, the tire
    curve's friction 0.9 and the road's 0.85. The friction the curve assumes is a term of its own now
    (``TireForceEstimator._sideslip_friction_std``)."""
    case = honesty.Case("step", 80.0, 0.85, 0, vibration=1.0, car="drawn")
    result = honesty.run_case(CONFIG, ["dici-gfckf"], case, tmp_path)
    score = honesty.summarize("beta", result["sums"]["dici-gfckf"]["beta"])
    assert score.valid > 0.3 and score.vbw == 0.0 and score.max_error > 1.0, score


@pytest.mark.parametrize("car", ("drawn", "exact"))
def test_a_sideslip_on_frictions_pressed_against_their_bound_is_never_valid_and_wrong(tmp_path, car):
    """A step steer on 0.35 with a vibrating IMU. The drawn car: jckf reads the slide as a split of frictions (the
    left wheels' at 0.12-0.17, the right's at 0.45-0.5), pressed against their lower bound on one tick, free the
    next. The sideslip's ``at_bound`` was not held as every failed test is, and between such ticks it was 2 deg
    off with a std of 0.6, flagged valid (15 % of that drive's valid ticks wrong). Held now where the car showed a
    tire's limit (this slide), it is valid on fewer than half of the ticks, none of them wrong. The exact car: the
    frictions, pressed until 3.9 s, came free of the bound at 4.9 s with the sideslip 2 deg off and climbing back
    slower than the car's, flagged valid with a std of 0.6-1.0 (31 ticks): ``at_bound`` now lasts while the limit
    the frictions were pressed in still shows. Since the rolling moment is no tire force the drawn car's sideslip
    is within 3 std on every tick, valid or not (at most 2.2 deg off, 2.6 before; 49 ticks beyond 3 std): there the
    test guards the outcome, the exact car the hold. Replayed with vx's process noise of before (0.3: since it is
    0.05, ``vx_from_wheel_states``, jckf's sideslip on this drive is at most 1.7 / 2.3 deg off and within 3 std on
    every tick, valid or not, and this test could not fail): the hold must hold for a filter that errs."""
    table, truth = replayed(honesty.Case("step", 80.0, 0.35, 1, vibration=1.0, car=car), "jckf", tmp_path,
                            process_noise={"vx_from_wheel_states": 0.3})
    every_tick = counts(table, truth, "beta", only_valid=False, skip=honesty.SKIP)
    flagged = counts(table, truth, "beta", skip=honesty.SKIP)
    assert every_tick["max"] > 2.0 and (car == "drawn" or every_tick["wrong"] > 0)  # deg: the drive has the error
    assert flagged["wrong"] == 0 and flagged["n"] < 0.5 * every_tick["n"], flagged


def test_the_sideslip_is_initializing_until_ay_s_noise_is_measured(tmp_path):
    """Until ay's samples show its noise the filter takes ay at its configured noise, and before its channels'
    consistency had 10 samples nothing judged the sideslip: on a vibrating IMU ckf's sideslip was valid on the
    first 9 ticks of this drive, 5 of them more than 3 std off (the 3-DOF filters' sideslip NEES over the first
    half second of the drawn cars' grid 3.1, 0.6 after it)."""
    table, truth = replayed(honesty.Case("step", 80.0, 0.85, 2, vibration=1.0, car="drawn"), "ckf", tmp_path)
    valid = valid_mask(table, "beta")
    assert not valid[table["t"] < table["t"][0] + 0.2].any()
    error = np.abs(table["beta"] - np.interp(table["t"], truth["t"], truth["beta"]))
    flagged = valid & (table["t"] < table["t"][0] + 0.5)
    assert not np.any(error[flagged] > 3.0 * table["beta_std"][flagged])
    assert valid.any()  # and later judged, and valid


def test_an_axle_s_split_the_model_assumes_is_in_its_wheels_forces_std(tmp_path):
    """No channel sees how an axle's force splits between its wheels: the model splits it by its tires' load
    sensitivity, the config's assumption (the simulator's tire is more degressive). In this step steer on 0.85 the
    inner wheels carried 1000 N against a true 1670, 3-4 std off, flagged valid (fy_fl wrong on 2.8 % of the
    drive's valid ticks): the std held the stiffness's error of the wheels' difference only. It holds the split's
    under any load sensitivity within ``tire_force.LOAD_SENSITIVITY_SPAN`` of the configured now."""
    case = honesty.Case("step", 80.0, 0.85, 0, vibration=1.0, car="drawn")
    table, truth = replayed(case, "dici-gfckf", tmp_path)
    for wheel in WHEELS:
        flagged = counts(table, truth, f"fy_{wheel}", skip=honesty.SKIP)
        assert flagged["valid"] > 0.3 * flagged["ticks"] and flagged["wrong"] == 0, (wheel, flagged)


@pytest.mark.parametrize("seed", (0, 2))
def test_a_slide_on_two_vibrating_accelerometers_is_checked_on_their_mean(tmp_path, seed):
    """Two IMUs on one body read one ay; a vibrating ay (1.4 m/s^2) left the kinematic check a noise gate of 0.82
    of its 1.26 deg tolerance, and in this lane change's slide onset on 0.35 (seed 0) dici-gfckf's sideslip was
    1.3-1.9 deg off with a std of 0.36, flagged valid. The check takes both accelerometers' mean where it is
    quieter than ay, its noise read from its own samples: the slide is seen, and the sideslip is never valid and
    wrong. Seed 2's car drew an ay bias of -0.21 m/s^2, and the mean's noise read the slide's onset 0.5-0.7 deg
    short: the window passed it while the sideslip was 1.4-1.9 deg off with a std of 0.45, flagged valid. The
    remembered mismatch beyond one std of its noise is the std's floor now (two hid 1.3 deg of it)."""
    table, truth = replayed(honesty.Case("dlc", 80.0, 0.35, seed, vibration=1.0, car="drawn"), "dici-gfckf",
                            tmp_path)
    every_tick = counts(table, truth, "beta", only_valid=False, skip=honesty.SKIP)
    flagged = counts(table, truth, "beta", skip=honesty.SKIP)
    assert every_tick["max"] > 1.3 and flagged["wrong"] == 0, flagged  # deg: the drive has the error


def test_a_vibrating_ay_does_not_move_force_between_an_axle_s_wheels(tmp_path):
    """The wheel loads took each vibrating ay sample: on this drive the rear left force fell from 1 612 to 826 N in
    30 ms (the rear right rose by as much; no measurement row sees an axle's split), 4 std off, flagged valid. The
    loads take ay through the body's roll lag (:mod:`canest.estimation.roll_lag`)."""
    case = honesty.Case("step", 80.0, 0.85, 2, vibration=1.0)
    result = honesty.run_case(CONFIG, ["dici-gfckf"], case, tmp_path)
    scores = per_wheel(result, "dici-gfckf", "fy")
    assert all(score.valid > 0.3 and score.vbw == 0.0 for score in scores), scores


@pytest.mark.parametrize("mu", (0.85, 0.35))
def test_a_friction_split_on_one_road_is_published_as_uncertain(tmp_path, mu):
    """A car drawn with its rear stiffness x0.77 (seed 0): the step steer on 0.85 split jckf's rear frictions to
    0.88 and 0.62 in four seconds, the low one flagged valid with a std of 0.07 (22 % of its valid ticks wrong).
    A friction's std is never below its distance from the four wheels' mean now, and that step never showed a
    tire's limit (the yaw rate stayed on the linear one): what split the frictions was the stiffness's error, and
    none is valid. On 0.35 the limit shows and the frictions are measured, where they are right."""
    result = honesty.run_case(CONFIG, ["jckf"], honesty.Case("step", 80.0, mu, 0, car="drawn"), tmp_path)
    scores = per_wheel(result, "jckf", "mu")
    assert not any(score.vbw > 0.0 for score in scores), scores
    share = sum(score.valid for score in scores) / len(scores)
    assert (share == 0.0) if mu == 0.85 else (share > 0.3), scores  # measured only where the car showed its limit


@pytest.mark.parametrize("maneuver, mu, seed", [("dlc", 0.85, 0), ("step", 0.35, 2)])
def test_a_friction_its_neighbours_disagree_with_is_never_valid_and_wrong(tmp_path, maneuver, mu, seed):
    """The floor of a friction's std at its distance from the four wheels' mean is what keeps these honest. Without
    it, on the drawn car of seed 0 (rear stiffness x0.77) jckf's rear right friction in the DLC on 0.85 ran to 0.14
    against 0.85, flagged valid on 5.8 % of the ticks and 0.71 off on 57 % of those, and on the car of seed 2 the
    rear left one in the step on 0.35 was wrong on 10 % of its valid ticks; over the drawn cars' grid 0.37-0.88 %
    of the frictions' valid ticks were wrong. With it, within 2 std is 100 % there (NEES 0.31-0.65): an
    over-coverage this floor costs, as README "How far to trust the output" says."""
    result = honesty.run_case(CONFIG, ["jckf"], honesty.Case(maneuver, 80.0, mu, seed, car="drawn"), tmp_path)
    scores = per_wheel(result, "jckf", "mu")
    assert not any(score.vbw > 0.0 for score in scores), scores
    assert max(score.valid for score in scores) > 0.05, scores  # measured where it can be


@pytest.mark.parametrize("maneuver", ("slalom", "sine"))
def test_a_friction_still_moving_is_never_valid_and_wrong(tmp_path, maneuver):
    """A road's friction does not change within a second, so what the estimate spanned over the last second
    (``two_track.SETTLE_WINDOW``) is part of its std. Without that term, on the drawn car of seed 0 (rear stiffness
    x0.77) on 0.85, jckf's frictions were valid on 69-81 % of the ticks of the slalom and the sine at 80 km/h
    (0.1-33 % with it) and up to 0.41 off, wrong on up to 24 % of a wheel's valid ticks (over the drawn cars' grid
    0.22-2.73 % of the frictions' valid ticks), and the honesty, force-estimator, vibration and dual-filter tests
    passed."""
    result = honesty.run_case(CONFIG, ["jckf"], honesty.Case(maneuver, 80.0, 0.85, 0, car="drawn"), tmp_path)
    scores = per_wheel(result, "jckf", "mu")
    assert not any(score.vbw > 0.0 for score in scores), scores


def test_the_drives_are_cached_per_simulator_source(tmp_path):
    """The cache folder of the tools' drives is named by the config, its input DBC and the files the simulator
    imports and the config loader, not the estimators' (whose changes are what the grid measures): keyed by the
    config alone, a changed plant replayed stale drives."""
    import drive_cache

    sources = {path.relative_to(ROOT).as_posix() for path in drive_cache.simulator_sources()}
    made_of = {"canest/sim/plant.py", "canest/sim/sensors.py", "canest/models/tire.py", "canest/config/vehicle.py"}
    assert made_of <= sources
    assert not any(name.startswith(("canest/filters/", "canest/apps/")) for name in sources)
    assert "canest/estimation/core.py" not in sources
    plant, dbc = tmp_path / "plant.py", load_config(CONFIG).input_dbc
    plant.write_text("MU = 0.85\n")
    before = drive_cache.folder(tmp_path, CONFIG, dbc, [plant])
    assert drive_cache.folder(tmp_path, CONFIG, dbc, [plant]) == before
    plant.write_text("MU = 0.35\n")
    assert drive_cache.folder(tmp_path, CONFIG, dbc, [plant]) != before
    assert drive_cache.folder(tmp_path, CONFIG, ROOT / "dbc" / "production_example.dbc", [plant]) != before


@pytest.mark.parametrize("maneuver, mu, seed, duration", [("country", 0.85, 3, 30.0), ("launch", 0.35, 0, None)])
def test_a_friction_is_valid_only_after_the_car_showed_a_tire_s_limit(tmp_path, maneuver, mu, seed, duration):
    """On a country road's gentle curves (ay up to 2.4 m/s^2 on 0.85) jckf's frictions fell from 0.90 to
    0.25-0.35 (the cubature points' tail saturates its tires on any curve) and were flagged valid on 2-26 % of the
    ticks of 30 s drives, 72-100 % of those wrong. A friction is valid only within seconds of a yaw response that
    left the linear one or a wheel slipping beyond its linear slip (the launch on 0.35: measured there, and
    right)."""
    case = honesty.Case(maneuver, 80.0, mu, seed, duration=duration)
    result = honesty.run_case(CONFIG, ["jckf"], case, tmp_path)
    scores = per_wheel(result, "jckf", "mu")
    if maneuver == "launch":
        assert all(score.valid > 0.1 and score.vbw == 0.0 for score in scores), scores
    else:  # no tire's limit on these curves: the frictions are not measured, whatever the model made of them
        assert all(score.valid == 0.0 for score in scores), scores
        assert honesty.summarize("beta", result["sums"]["jckf"]["beta"]).valid > 0.5  # the sideslip still measured


def test_a_sideslip_resting_on_a_saturation_the_car_has_not_shown_carries_it_in_its_std(tmp_path):
    """On a vibrating country road's gentle curves on 0.85 jckf's frictions fall towards the friction the car uses
    (README "Still weak") and its model's rear tires saturate where the plant's do not: the sideslip was 2-4 deg off
    with a std below a third of that, valid (54-56 s into this drive: 1.3 % of its valid ticks). While the car shows
    no tire's limit, the std holds half the sideslip the estimate's rear saturation makes beyond linear tires."""
    case = honesty.Case("country", 80.0, 0.85, 4, duration=60.0, vibration=1.0)
    score = honesty.summarize("beta", honesty.run_case(CONFIG, ["jckf"], case, tmp_path)["sums"]["jckf"]["beta"])
    assert score.max_error > 2.0 and score.valid > 0.3 and score.vbw == 0.0, score


def test_vx_on_a_hill_is_right_within_its_std(tmp_path):
    """Uphill at 6 % the accelerometer reads 0.59 m/s^2 of gravity that the speed does not follow. The reference
    speed compared the wheels' acceleration with ax itself, so no wheel was ever in step, and it integrated ax for
    the whole climb: on 40 s of this road ckf's vx ran up to 3.6 m/s off with a std of 0.08, valid but wrong on 61 %
    of its valid ticks (jckf 3 %, dici-gfckf 57 %; over these 30 s ckf was valid on 81 % of the ticks). The wheels now measure ax's offset while they roll freely
    (``canest.estimation.longitudinal_offset``), the reference and the single-track model take ax less it."""
    case = honesty.Case("country", 80.0, 0.85, 3, duration=30.0, grade=6.0)
    result = honesty.run_case(CONFIG, ["ckf", "dici-gfckf"], case, tmp_path)
    for name in ("ckf", "dici-gfckf"):
        score = honesty.summarize("vx", result["sums"][name]["vx"])
        assert score.valid > 0.9 and score.vbw == 0.0 and score.rmse < 0.2, (name, score)


def test_a_launch_uphill_integrates_ax_less_the_grade_the_wheels_measured_before(tmp_path):
    """The launch on 0.35 spins the wheels: the reference integrates ax, which on a 6 % grade held 0.59 m/s^2 of
    gravity (ckf's vx 1.8 m/s off, valid but wrong on 38 % of its valid ticks). The wheels rolling uphill before
    the launch measured it."""
    case = honesty.Case("launch", 80.0, 0.35, 0, grade=6.0)
    result = honesty.run_case(CONFIG, ["ckf"], case, tmp_path)
    score = honesty.summarize("vx", result["sums"]["ckf"]["vx"])
    assert score.valid > 0.9 and score.vbw == 0.0 and score.rmse < 0.1, score


def test_a_car_without_motor_torques_on_a_hill_integrates_ax_less_the_grade(tmp_path):
    """The tire-force model without torques takes its longitudinal forces, and so vx, from ax: uphill at 6 % on
    30 s of this road its vx was 2.4 m/s off in RMS, valid but wrong on 43 % of its valid ticks
    (``configs/hard_drive.yaml``). With the reference speed taking the grade out and the model not, its vx lagged
    gravity's pull between anchors: 0.037 m/s in RMS on these 20 s. It takes ax less the wheels' offset too: 0.017."""
    case = honesty.Case("country", 80.0, 1.0, 3, duration=20.0, grade=6.0)
    result = honesty.run_case(ROOT / "configs" / "hard_drive.yaml", ["ckf"], case, tmp_path)
    score = honesty.summarize("vx", result["sums"]["ckf"]["vx"])
    assert score.valid > 0.9 and score.vbw == 0.0 and score.rmse < 0.025, score


def test_per_case_names_the_states_it_knows_when_given_one_it_does_not(capsys, tmp_path):
    assert honesty.main(["--small", "--per-case", "speed", "--workdir", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert "'speed'" in error and "vx" in error and "mu_fl" in error
    assert not any(tmp_path.iterdir())  # nothing simulated


def test_a_score_is_outside_the_targets_exactly_when_it_misses_one_and_says_which():
    """The band's ends are inside; a state never valid is not judged; every miss is named."""
    def score(**changes):
        inside = dict(state="beta", unit="deg", rmse=0.3, mae=0.2, max_error=1.0, samples=100, valid=0.5,
                      cov1=0.7, cov2=0.98, cov3=0.99, nees=0.5, vbw=0.001)
        return Score(**{**inside, **changes})
    scores = {"ckf": {"beta": score(), "vx": score(state="vx", cov2=0.90, nees=2.0),
                      "yaw_rate": score(state="yaw_rate", valid=0.0, cov2=0.5, nees=9.0, vbw=0.5)},
              "jckf": {"beta": score(cov2=0.981, nees=0.49), "vx": score(state="vx", vbw=0.0011),
                       "yaw_rate": score(state="yaw_rate", wrong_sign=2)}}
    assert honesty.outside_targets(scores) == [
        ("jckf", "beta", ["within 2 std 98.1 %", "NEES 0.49"]), ("jckf", "vx", ["valid but wrong 0.11 %"]),
        ("jckf", "yaw_rate", ["2 valid ticks of the wrong sign"])]
    assert "- jckf beta: within 2 std 98.1 %, NEES 0.49" in honesty.outside_markdown(honesty.outside_targets(scores))
    assert honesty.outside_markdown([]).endswith(": none")


def test_check_fails_the_command_when_a_state_is_outside_the_targets(capsys, tmp_path):
    """``--check``: exit status 1 exactly when the grid's JSON lists a state outside the targets, each listed one
    missing a target by its own score."""
    args = ["--small", "--filters", "ckf", "--workdir", str(tmp_path), "--json"]
    assert honesty.main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert honesty.main(args + ["--check"]) == (1 if out["outside"] else 0)
    for row in out["outside"]:
        s = out[row["filter"]][row["state"]]
        assert (s["vbw"] > 0.001 or not 0.90 <= s["cov2"] <= 0.98 or not 0.5 <= s["nees"] <= 2.0
                or s["wrong_sign"] > 0), row


def test_scales_prints_the_factors_on_the_std_as_json_and_as_a_table(capsys, tmp_path):
    args = ["--small", "--filters", "ckf", "--workdir", str(tmp_path), "--scales"]
    assert honesty.main(args + ["--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    outside = {row["state"] for row in out["outside"]}
    assert set(out["scales"]["ckf"]) == {"vx", "yaw_rate", "beta"}
    assert {s for s, runs in out["scales"]["ckf"].items() if not std_scales.includes_published(runs)} == outside
    assert honesty.main(args) == 0
    table = capsys.readouterr().out.split("Constant factors on the published std")[1]
    assert "| ckf | beta |" in table and "| ckf | vx |" in table


def test_a_windy_drive_is_cached_apart_from_the_calm_one_whose_name_is_unchanged():
    calm, gusty = honesty.Case("launch", 80.0, 0.85, 0), honesty.Case("launch", 80.0, 0.85, 0, crosswind=1.0)
    assert calm.key == "launch-80kmh-mu0.85-s0-vib0"  # the drives cached before crosswind existed
    assert gusty.key == "launch-80kmh-mu0.85-s0-vib0-wind1"
