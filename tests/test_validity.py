"""Validity means consistent with what the car measures; causes are published; bounds truncate honestly."""
import math

import cantools
import numpy as np
import pytest
import scipy.optimize
from scipy.stats import truncnorm

from canest.apps.replay import replay
from canest.config import load_config
from canest.codec.encode import EstimateEncoder
from canest.estimation import validity
from canest.estimation.core import INTEGRATED_NOISE_SPAN
from canest.estimation.measured_noise import MeasuredNoise
from canest.estimation.judge import StateJudge, steered_wheels_std
from canest.estimation.estimate import CAUSES, Estimate
from canest.filters.parameters import truncated
from canest.models.single_track import SingleTrackModel
from canest.sim.simulate import simulate
from tests.conftest import ROOT
from tests.test_config import write_variant

OUTPUT_DBC = ROOT / "dbc" / "canest_estimates.dbc"


@pytest.mark.parametrize("mean, std, bound, side", [(0.05, 0.1, 0.1, 1.0), (-3.0, 0.1, 0.1, 1.0), (0.12, 0.05, 0.1, 1.0),
                                                    (1.35, 0.1, 1.3, -1.0), (0.5, 0.1, 0.1, 1.0)])
def test_truncation_gives_the_truncated_normals_moments(mean, std, bound, side):
    got_mean, got_std = truncated(np.array([mean]), np.array([std]), bound, side)
    low, high = ((bound - mean) / std, np.inf) if side > 0 else (-np.inf, (bound - mean) / std)
    assert got_mean[0] == pytest.approx(truncnorm.mean(low, high, mean, std), rel=1e-9)
    assert got_std[0] == pytest.approx(truncnorm.std(low, high, mean, std), rel=1e-6)


def test_consistency_judges_a_channel_by_its_window():
    consistency = validity.Consistency(("ay", "yaw_rate", "vx_wheel"))
    assert math.isnan(consistency.ratio("yaw_rate"))  # nothing judged yet
    for _ in range(validity.WINDOW):
        consistency.push([1, 2], np.array([1.0, 0.5]))
    assert consistency.ratio("yaw_rate") == pytest.approx(1.0) and consistency.ratio("vx") == pytest.approx(0.5)
    consistency.push([1], np.array([validity.INCONSISTENT * validity.WINDOW]))  # one wrong-sign yaw rate
    assert consistency.ratio("yaw_rate") > validity.INCONSISTENT
    assert validity.judge(True, False, consistency.ratio("yaw_rate")) == "inconsistent"
    assert validity.judge(True, True, 1.0) == "saturated" and validity.judge(False, False, 1.0) == "no_input"


def test_a_cause_holds_for_a_second_after_its_test_last_failed():
    holds = validity.Holds()
    assert holds.apply("beta", "model_regime", 10.0) == "model_regime"
    assert holds.apply("beta", "valid", 10.5) == "model_regime"
    assert holds.apply("beta", "low_speed", 10.6) == "low_speed"  # a present cause is reported as it is
    assert holds.apply("beta", "valid", 10.0 + validity.HOLD + 0.01) == "valid"


def test_kinematic_check_sees_a_slide_the_model_misses():
    dt = 0.01
    check = validity.KinematicCheck(dt)
    vx, yaw_rate = 20.0, 0.15
    steady = [check.inside(-0.01, vx * yaw_rate, yaw_rate, vx) for _ in range(100)]  # ay = r vx: no slide
    assert all(steady)
    slide = [check.inside(-0.01, vx * yaw_rate - 1.0, yaw_rate, vx) for _ in range(100)]  # beta falls 2.9 deg/s
    assert not slide[-1]


def test_kinematic_mismatch_remembers_a_slide_the_model_lags_and_not_the_biases():
    """A slide building up at 1.6 deg/s that the model follows at 0.8: inside the window's tolerance each half
    second, yet 2 deg apart after 2.5 s. The remembered mismatch sees it; biases alone (0.13 deg/s) do not."""
    dt, vx, yaw_rate = 0.01, 22.0, 0.2
    biased = validity.KinematicCheck(dt)
    bias = math.radians(0.13)  # rad/s of ay / vx - r
    for _ in range(2000):
        biased.inside(0.0, vx * (yaw_rate + bias), yaw_rate, vx)
    assert math.degrees(biased.mismatch) < 0.02  # held at 0.26 deg, nearly all within the allowance
    lagging = validity.KinematicCheck(dt)
    truth_rate, model_rate = math.radians(-1.6), math.radians(-0.8)
    passed, beta = [], 0.0
    for _ in range(250):
        beta += model_rate * dt
        passed.append(lagging.inside(beta, vx * (yaw_rate + truth_rate), yaw_rate, vx))
    assert all(passed)  # the window's test never fails
    assert math.degrees(lagging.mismatch) > 2.0 / 3.0  # three std of it cover the 2 deg


def test_kinematic_check_takes_a_vibrating_ay_s_noise_and_still_sees_a_slide():
    """ay vibrating by 1.4 m/s^2 correlated over 15 ms (the simulator's vibration 1) integrates to 0.45 deg of
    kinematic sideslip per half second at 80 km/h: the window's 0.5 deg tolerance failed a model that follows
    the car exactly; with ay's density as the estimator measures it, the check passes it and still sees a slide
    the model misses, and the noise leaves less of the mismatch it left (the std's floor: at most 1.4 deg here,
    0.54 in RMS; beyond one std of the noise it measures 1.1 and 0.34).
    """
    dt, vx, yaw_rate, std = 0.01, 22.0, 0.15, 1.4
    a = math.exp(-dt / 0.015)
    noise = np.zeros(1500)
    for k, w in enumerate(np.random.default_rng(1).standard_normal(noise.size)):
        noise[k] = a * noise[k - 1] + math.sqrt(1 - a * a) * std * w
    ay = vx * yaw_rate + noise
    measured = MeasuredNoise(INTEGRATED_NOISE_SPAN)
    for k, value in enumerate(ay):
        measured.add(k * dt, value)
    density = measured.density  # m^2/s^3; that AR(1) noise's, below its correlation: 0.061
    assert 0.6 < density / (std**2 * dt * (1 + a) / (1 - a)) < 1.2
    blind, told = validity.KinematicCheck(dt), validity.KinematicCheck(dt)
    fails_blind = fails_told = 0
    mismatch_blind, mismatch_told = [], []
    for value in ay:
        fails_blind += not blind.inside(0.0, value, yaw_rate, vx)
        fails_told += not told.inside(0.0, value, yaw_rate, vx, density)
        mismatch_blind.append(blind.mismatch)
        mismatch_told.append(told.mismatch)
    assert fails_blind > 0.05 * ay.size and fails_told < 0.01 * ay.size
    blind_rms, told_rms = (math.degrees(math.sqrt(np.mean(np.square(m)))) for m in (mismatch_blind, mismatch_told))
    assert blind_rms > 0.5 and told_rms < 0.7 * blind_rms  # the std's floor, from noise alone
    assert max(mismatch_told) < 0.85 * max(mismatch_blind)
    slide = [told.inside(0.0, value - 3.0, yaw_rate, vx, density) for value in ay[:100]]  # beta falls 7.8 deg/s
    assert not slide[-1]


def test_the_sideslip_model_error_is_held_after_a_bend_and_fades(config):
    """The filter's sideslip error lags the excitation: the model error is the one of the largest steady-state ay
    (``v r``; a tire curve's rear slip angle) of the last second, fading, and a reset forgets it."""
    judge = StateJudge(SingleTrackModel(config.vehicle), config.vehicle, 0.01)
    assert judge.sideslip_model_std(-6.0) == pytest.approx(validity.sideslip_model_std(config.vehicle, 6.0))
    after = [judge.sideslip_model_std(1.0) for _ in range(50)]
    held = 6.0 * math.exp(-0.5 / validity.MODEL_ERROR_MEMORY)
    assert after[-1] == pytest.approx(validity.sideslip_model_std(config.vehicle, held))
    assert after[-1] > validity.sideslip_model_std(config.vehicle, 1.0)
    slip = math.radians(3.0)
    judge.reset()
    assert judge.sideslip_model_std(0.0, slip) == pytest.approx(config.vehicle.cornering_stiffness_uncertainty * slip)
    fading = config.vehicle.cornering_stiffness_uncertainty * slip * math.exp(-0.01 / validity.MODEL_ERROR_MEMORY)
    assert judge.sideslip_model_std(0.0, 0.0) == pytest.approx(fading)
    judge.reset()
    assert judge.sideslip_model_std(0.0) == 0.0


@pytest.mark.parametrize("delta_deg", [-6.0, 2.8, 15.0])
def test_the_steered_wheels_read_vx_off_by_tan_half_delta_per_lateral_velocity_error(config, delta_deg):
    """``steered_wheels_std`` against the model's own wheel-speed measurement: the vx that keeps the wheels' mean
    speed while vy is off by 0.1 m/s (the sideslip moved at the same yaw rate) differs by ``tan(delta/2)`` of it."""
    model, delta, vx, yaw_rate, error = SingleTrackModel(config.vehicle), math.radians(delta_deg), 20.0, 0.2, 0.1
    u = np.array([delta, 0.0, 1.0])

    def wheels(speed, vy):
        return model.measure(np.array([[yaw_rate, math.atan2(vy, speed), speed]]), u)[0, 2]

    vy = -0.5
    moved = scipy.optimize.brentq(lambda speed: wheels(speed, vy + error) - wheels(vx, vy), vx - 1.0, vx + 1.0)
    assert abs(moved - vx) == pytest.approx(steered_wheels_std(delta, error), rel=1e-3)


def test_lateral_drift_bounds_vx_from_a_lateral_velocity_the_model_misses():
    """dvx/dt = ax + r vy: a sideslip the model does not have moves vx at r times its lateral velocity."""
    dt, vx, yaw_rate = 0.01, 20.0, 0.2
    drift = validity.LateralDrift(dt)
    turning = [drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, False, False) for _ in range(100)]  # ay = r vx
    assert max(turning) < 1e-9  # no slide: the model's lateral velocity is the kinematic one
    sliding = [drift.update(vx * yaw_rate - 2.0, yaw_rate, vx, 0.0, False, False) for _ in range(100)]
    # the car's vy grows at -2 m/s^2 for 1 s: r * integral(vy) = 0.2 * 2 * 1^2 / 2 = 0.2 m/s
    assert sliding[-1] == pytest.approx(0.2, rel=0.02)
    assert drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, True, False) == 0.0  # the wheels measure vx again
    assert drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, False, False) == pytest.approx(
        yaw_rate * 2.0 * dt, rel=0.02)  # the 2 m/s the model misses still move vx
    # a restarted filter's sideslip jumps (to 0.05 rad: vy +1 m/s), the car's does not: its vy is still -2 m/s,
    # 3 m/s from the model's
    restarted = drift.update(vx * yaw_rate, yaw_rate, vx, 0.05, False, False)
    assert restarted == pytest.approx(yaw_rate * (2.0 + 3.0) * dt, rel=0.02)
    drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, True, True)  # sideslip known and vx measured
    assert drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, False, False) == 0.0


def test_a_filter_reset_keeps_the_cars_lateral_velocity_where_the_model_last_knew_it(config):
    """mcsckf, reset four times in a slide with its sideslip 7 deg off, restarted near zero sideslip each time: the
    car's lateral velocity did not jump with it. Carried over as if it had, the drift bound stayed at 0.3 m/s while
    vx ran 0.9 m/s off, flagged valid."""
    dt, vx, yaw_rate = 0.01, 20.0, 0.2
    judge = StateJudge(SingleTrackModel(config.vehicle), config.vehicle, dt)
    drift = judge.lateral_drift
    drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, True, True)  # the sideslip known (0), vx measured
    for _ in range(100):  # the car slides to vy -2 m/s in 1 s; the model keeps vy -0.5
        drift.update(vx * yaw_rate - 2.0, yaw_rate, vx, -0.5 / vx, True, False)
    judge.reset()  # the filter restarts at zero sideslip, 2 m/s from the car's
    assert drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, False, False) == pytest.approx(yaw_rate * 2.0 * dt, rel=0.02)


def test_the_unexplained_lateral_velocity_is_what_the_admitted_ay_offset_cannot_explain():
    """While the sideslip is unknown, a slide the model misses is the lateral velocity's error; an ay offset within
    the configured noise integrates alike but is no error of the car's: only the excess counts, however long."""
    dt, vx, yaw_rate, ay_bias = 0.01, 20.0, 0.2, 0.1
    drift = validity.LateralDrift(dt, ay_bias)
    drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, True, True)  # the sideslip known (0)
    for _ in range(6000):  # a minute unknown with the ay offset the config admits: nothing unexplained
        drift.update(vx * yaw_rate + ay_bias, yaw_rate, vx, 0.0, True, False)
    assert drift.mismatch == pytest.approx(ay_bias * 60.0, rel=1e-6)
    assert drift.unexplained == pytest.approx(0.0, abs=1e-9)
    drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, True, True)  # known again
    for _ in range(100):  # the car slides to vy -2 m/s in 1 s; the model keeps vy -0.5
        drift.update(vx * yaw_rate - 2.0, yaw_rate, vx, -0.5 / vx, True, False)
    assert drift.unexplained == pytest.approx(1.5 - ay_bias * 1.0, rel=0.02)
    drift.update(vx * yaw_rate, yaw_rate, vx, -0.5 / vx, True, True)
    assert drift.unexplained == 0.0


def test_a_sideslip_stays_unknown_while_the_car_moved_sideways_as_the_model_did_not():
    """A slide the model missed since its sideslip was last known keeps the sideslip from coming back: beyond
    RETURN_TOLERANCE at vx (0.17 m/s at 20 m/s), not within it; the admitted ay offset still explains its share."""
    dt, vx, yaw_rate, ay_bias = 0.01, 20.0, 0.2, 0.1
    drift = validity.LateralDrift(dt, ay_bias)
    drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, True, True)  # the sideslip known (0)
    assert drift.allows_return(vx)
    for _ in range(50):  # 0.5 s unknown, the car's vy moves -0.2 m/s that the model does not follow
        drift.update(vx * yaw_rate - 0.4, yaw_rate, vx, 0.0, True, False)
    assert drift.unexplained == pytest.approx(0.2 - ay_bias * 0.5, rel=0.02)  # 0.15 m/s: inside the tolerance
    assert drift.allows_return(vx)
    for _ in range(50):  # another 0.5 s: -0.4 m/s, 0.3 beyond the offset's share
        drift.update(vx * yaw_rate - 0.4, yaw_rate, vx, 0.0, True, False)
    assert drift.unexplained > validity.RETURN_TOLERANCE * vx
    assert not drift.allows_return(vx)
    drift.update(vx * yaw_rate, yaw_rate, vx, math.atan(-0.4 / vx), True, False)  # the model catches up
    assert drift.allows_return(vx)


def test_a_road_s_bias_never_holds_the_sideslip_shut_for_good():
    """A real road's ay runs off the kinematic identity by more than the configured noise admits (the Ford's
    log: 0.25 m/s^2 against 0.15): integrated, it outgrows any tolerance. The return is tested for
    RETURN_MEMORY s after the sideslip was last known, and never against a start's anchor."""
    dt, vx, yaw_rate, ay_bias = 0.01, 20.0, 0.05, 0.15
    drift = validity.LateralDrift(dt, ay_bias)
    for _ in range(300):  # 3 s of a start, the sideslip not yet known: nothing to test against
        drift.update(vx * yaw_rate + 0.25, yaw_rate, vx, 0.0, True, False)
        assert drift.allows_return(vx)
    drift.update(vx * yaw_rate + 0.25, yaw_rate, vx, 0.0, True, True)  # known once
    returns = []
    for _ in range(int(round(2 * validity.RETURN_MEMORY / dt))):
        drift.update(vx * yaw_rate + 0.25, yaw_rate, vx, 0.0, True, False)
        returns.append(drift.allows_return(vx))
    assert drift.unexplained > validity.RETURN_TOLERANCE * vx  # 0.1 m/s^2 unexplained for 6 s: 0.6 m/s
    first_held = returns.index(False) * dt
    assert first_held < validity.RETURN_MEMORY
    assert returns[-1] and all(returns[int(round(validity.RETURN_MEMORY / dt)):])


def test_the_road_s_offset_is_learned_from_the_ticks_the_sideslip_was_known():
    """The kinematic lateral velocity leaves the model's at the road's offset (a bank, an ay bias): measured over the
    known ticks, against the prior the config gives (0 within the configured ay noise). A moment of known sideslip
    learns little, a long stretch the road; an old road is forgotten over OFFSET_MEMORY."""
    dt, prior, lateral_std, offset = 0.01, 0.15, 0.05, 0.4
    road = validity.RoadOffset(dt, prior)
    assert (road.rate, road.std) == (0.0, prior)  # nothing learned
    difference = 0.0
    for _ in range(10):  # 0.1 s known: the model's lateral velocity error at the ends outweighs 0.04 m/s of offset
        difference += offset * dt
        road.update(difference, True, lateral_std, 0.0)
    assert road.rate < 0.1 * offset and road.std > 0.9 * prior
    for _ in range(990):  # 10 s known
        difference += offset * dt
        road.update(difference, True, lateral_std, 0.0)
    road.update(difference, False, lateral_std, 0.0)  # the stretch ends
    assert road.rate == pytest.approx(offset, rel=0.01)
    # the error: 2 std of the lateral velocity at the stretch's two ends over its ~10 s
    assert road.std == pytest.approx(validity.KINEMATIC_NOISE_GATE * math.sqrt(2) * lateral_std / 10.0, rel=0.2)
    for _ in range(int(3 * validity.OFFSET_MEMORY / dt)):  # known again, on a flat road: the bank is forgotten
        road.update(difference, True, lateral_std, 0.0)
    assert abs(road.rate) < 0.05 * offset


def test_a_road_s_offset_learned_while_the_sideslip_was_known_holds_no_sideslip_shut():
    """The Ford's log: its ay runs 0.25 m/s^2 off the kinematic identity against a configured 0.15. Taken as the
    configured noise alone, 10 s unknown outgrow any tolerance; learned over the seconds the sideslip was known,
    the road explains it, and a slide on that road is still a slide."""
    dt, vx, yaw_rate, ay_bias, offset = 0.01, 20.0, 0.05, 0.15, 0.25
    learned, unlearned = validity.LateralDrift(dt, ay_bias), validity.LateralDrift(dt, ay_bias)
    for drift, known in ((learned, 500), (unlearned, 1)):
        for _ in range(known):  # 5 s (or a tick) of known sideslip on the road
            drift.update(vx * yaw_rate + offset, yaw_rate, vx, 0.0, True, True, 0.05)
        for _ in range(1000):  # 10 s unknown on the same road, the model's sideslip 0
            drift.update(vx * yaw_rate + offset, yaw_rate, vx, 0.0, True, False, 0.05)
    assert unlearned.unexplained_by_road > 0.5  # m/s: 0.1 m/s^2 beyond the admitted for 10 s
    assert learned.unexplained_by_road < 0.05
    for _ in range(100):  # then a slide on that road the model misses: vy -1 m/s in 1 s, of which the learned
        # offset's error (2 std of 0.05 m/s at the ends of 5 s: 0.03 m/s^2) explains 0.3 m/s after 11 s
        learned.update(vx * yaw_rate + offset - 1.0, yaw_rate, vx, 0.0, True, False, 0.05)
    assert learned.unexplained_by_road > validity.RETURN_TOLERANCE * vx


def test_a_noisy_ay_integrated_while_the_sideslip_was_unknown_does_not_hold_it_shut():
    """A vibrating ay's integral wanders by sqrt(density t): the return test takes KINEMATIC_NOISE_GATE standard
    deviations of it, as the kinematic window test does."""
    dt, vx, yaw_rate, density = 0.01, 20.0, 0.2, 0.02  # m^2/s^3: 1.4 m/s^2 white at 10 ms
    quiet, loud = validity.LateralDrift(dt), validity.LateralDrift(dt)
    for drift, noise in ((quiet, 0.0), (loud, density)):
        drift.update(vx * yaw_rate, yaw_rate, vx, 0.0, True, True, 0.0, noise)
        for _ in range(200):  # 2 s unknown; the kinematic vy is -0.4 m/s off the model's
            drift.update(vx * yaw_rate - 0.2, yaw_rate, vx, 0.0, True, False, 0.0, noise)
    # the noise gate: 2 sqrt(0.02 * 2) = 0.4 m/s, in quadrature with 0.17
    assert not quiet.allows_return(vx)
    assert loud.allows_return(vx)


def test_lateral_drift_spreads_vx_by_the_known_sideslips_own_uncertainty():
    """A sideslip known within its std still moves an integrated vx: at r times std(vy), linearly."""
    dt, vx, yaw_rate, lateral_std = 0.01, 20.0, -0.3, 0.3
    drift = validity.LateralDrift(dt)
    for _ in range(200):  # 2 s of steady cornering, the sideslip valid, the wheels not rolling freely
        drift.update(vx * yaw_rate, yaw_rate, vx, -0.02, False, True, lateral_std)
    assert drift.drift == 0.0  # no slide the model misses
    assert drift.spread == pytest.approx(abs(yaw_rate) * lateral_std * 2.0, rel=0.02)
    drift.update(vx * yaw_rate, yaw_rate, vx, -0.02, True, True, lateral_std)  # the wheels measure vx again
    assert drift.spread == 0.0


def test_vx_std_covers_a_steady_turn_where_the_wheels_do_not_roll_freely(config, tmp_path):
    """The step steer on 0.85: the motors hold the speed (no free rolling), ckf's vx integrates ax + r vy with
    a sideslip 0.9 deg off within its std, and drifted 0.4 m/s in 4 s with a std of 0.11 before the spread."""
    sim = simulate(config, "step", 80.0, 0.85, seed=0)
    sim.write_log(tmp_path / "step.log")
    estimates = []
    replay(config, tmp_path / "step.log", progress=False, on_estimate=estimates.append)
    late = [e for e in estimates if e.t > 6.0 and e.valid.get("vx")]
    assert late
    errors = np.array([e.values["vx"] - np.interp(e.t, sim.truth["t"], sim.truth["vx"]) for e in late])
    stds = np.array([e.values["vx_std"] for e in late])
    assert np.max(np.abs(errors)) > 0.2  # the drift this test is about
    assert np.all(np.abs(errors) < 2 * stds)


def test_vx_of_a_car_sliding_sideways_is_not_valid_but_wrong(config, tmp_path):
    """The DLC at 80 km/h on friction 0.35 spins the car (sideslip to 80 deg) while the model's sideslip stays
    small: integrated ax once took vx 2-4 m/s off with std 0.07, flagged valid (47 % of the drive's ticks)."""
    sim = simulate(config, "dlc", 80.0, 0.35, seed=0)
    sim.write_log(tmp_path / "dlc.log")
    estimates = []
    replay(config, tmp_path / "dlc.log", progress=False, on_estimate=estimates.append)
    t = np.array([e.t for e in estimates])
    vx = np.array([e.values["vx"] for e in estimates])
    std = np.array([e.values["vx_std"] for e in estimates])
    valid = np.array([e.valid.get("vx", False) for e in estimates])
    error = np.abs(vx - np.interp(t, sim.truth["t"], sim.truth["vx"]))
    assert np.nanmax(error) > 2.0  # the case is still hard
    assert not np.any(valid & (error > 3 * std) & (error > 0.5))
    assert valid.mean() > 0.3
    assert any(e.causes.get("vx") == "model_regime" for e in estimates)


def test_linear_regime_sees_an_understeering_car(config):
    regime = validity.LinearRegime(config.vehicle, 0.01)
    delta, vx = 0.04, 20.0
    reference = vx * delta / (config.vehicle.wheelbase + regime.understeer * vx**2)
    assert all(regime.inside(delta, vx, reference) for _ in range(100))
    saturated = [regime.inside(delta, vx, 0.5 * reference) for _ in range(100)]  # half the yaw rate the steering asks
    assert not saturated[-1]


def test_linear_regime_follows_the_steering_through_the_yaw_response_lag(config):
    """The reference lags a steering step by ``REGIME_LAG`` (first order): a yaw rate still at the old steady state
    is inside at the step and outside once the reference has moved on."""
    dt, delta, vx = 0.01, 0.04, 20.0
    regime = validity.LinearRegime(config.vehicle, dt)
    before = vx * delta / (config.vehicle.wheelbase + regime.understeer * vx**2)
    assert all(regime.inside(delta, vx, before) for _ in range(100))
    after = [regime.inside(2.0 * delta, vx, before) for _ in range(int(round(5 * validity.REGIME_LAG / dt)))]
    assert after[0] and not after[-1]
    first_out = after.index(False)
    alpha = dt / (validity.REGIME_LAG + dt)
    absolute, relative = validity.REGIME_TOLERANCE
    reference = [2.0 * before - before * (1.0 - alpha) ** (k + 1) for k in range(len(after))]
    assert first_out == next(k for k, r in enumerate(reference) if abs(before - r) > absolute + relative * abs(r))


def test_the_cause_message_carries_every_cause_the_dbc_documents():
    db = cantools.database.load_file(str(OUTPUT_DBC))
    message = db.get_message_by_name("CE_ValidityCause")
    for signal in ("VxCause", "YawRateCause", "SideslipCause", "ForcesCause", "FrictionCause"):
        assert [str(v) for _, v in sorted(message.get_signal_by_name(signal).choices.items())] == list(CAUSES)
    encoder = EstimateEncoder(OUTPUT_DBC)
    estimate = Estimate(1.0, {}, {"vx": True}, "normal", "ckf",
                        causes={"vx": "valid", "yaw_rate": "inconsistent", "beta": "model_regime"})
    frame = next(f for f in encoder.encode(estimate) if f.arbitration_id == message.frame_id)
    decoded = message.decode(frame.data, decode_choices=True)
    assert (decoded["VxCause"], decoded["YawRateCause"], decoded["SideslipCause"], decoded["ForcesCause"]) == \
        ("valid", "inconsistent", "model_regime", "no_input")


def test_a_wheel_speed_at_its_dbc_limit_is_saturated_not_a_speed(tmp_path):
    """Above what the wheel-speed signal carries the DBC limit is sent: vx is not taken from it, its bit is
    clear with the cause "saturated", and it never publishes the limit as a valid speed. (canest's own DBC
    carries 3200 rpm, 420 km/h at 0.35 m; a DBC capped at 1600 rpm, as canest's was, shows the case.)"""
    path = write_variant(tmp_path, lambda d: None)
    dbc = tmp_path / "dbc" / "canest_vehicle.dbc"
    dbc.write_text(dbc.read_text().replace("(0.1,0) [-3200|3200]", "(0.05,0) [-1600|1600]"))
    config = load_config(path)
    limit = 1600 * 2 * math.pi / 60 * config.vehicle.wheel_radius
    sim = simulate(config, "launch", limit * 3.6 - 12.0, 0.85, duration=5.0, seed=2)  # accelerates past the limit
    sim.write_log(tmp_path / "fast.log")
    estimates = []
    summary = replay(config, tmp_path / "fast.log", progress=False, on_estimate=estimates.append)
    assert summary["saturated_samples"] > 0
    true_vx = np.interp([e.t for e in estimates], sim.truth["t"], sim.truth["vx"])
    beyond = [(e, v) for e, v in zip(estimates, true_vx) if v > limit + 0.5]
    assert len(beyond) > 50
    assert all(not e.valid["vx"] and e.causes["vx"] == "saturated" for e, _ in beyond)
    assert all(abs(e.values["vx"] - v) < 1.0 for e, v in beyond)  # ax integrated, not the limit


def test_vx_std_takes_the_reference_speeds_walk_apart_or_as_a_floor(config):
    """A model integrating ax holds the reference's walk in its prior and leaves it out of the reference channel:
    its covariance after the update is the error beside the walk, which the published std adds in quadrature.
    Another model took the walk inside the reference's std: its vx is never published below it."""
    judge = StateJudge(SingleTrackModel(config.vehicle), config.vehicle, 0.01)
    index = {"yaw_rate": 2, "vx": 1, "beta": 0}
    ratios = {"yaw_rate": 1.0, "vx": 1.0, "beta": 1.0}
    std = np.array([0.01, 0.05, 0.001])
    apart = judge.widen(std, index, ratios, 0.0, walk=0.12, walk_apart=True)
    floor = judge.widen(std, index, ratios, 0.0, walk=0.12)
    assert apart[1] == pytest.approx(0.13) and floor[1] == pytest.approx(0.12)
    assert judge.widen(std, index, ratios, 0.0, walk=0.01)[1] == pytest.approx(0.05)  # a small walk: the filter's
    np.testing.assert_array_equal(apart[[0, 2]], floor[[0, 2]])


def test_vx_std_is_never_below_its_remembered_distance_from_the_reference_speed(config):
    """A floor, not a term: the distance from the reference beyond its std bounds vx's error from below; it is
    remembered over validity.HOLD s, so a distance that alternates tick by tick does not flicker vx's bit."""
    judge = StateJudge(SingleTrackModel(config.vehicle), config.vehicle, 0.01)
    index = {"yaw_rate": 2, "vx": 1, "beta": 0}
    ratios = {"yaw_rate": 1.0, "vx": 1.0, "beta": 1.0}
    std = np.array([0.01, 0.05, 0.001])
    assert judge.widen(std, index, ratios, 0.0, reference_gap=0.03)[1] == pytest.approx(0.05)  # the filter's
    assert judge.widen(std, index, ratios, 0.0, reference_gap=0.6)[1] == pytest.approx(0.6)
    assert judge.widen(std, index, ratios, 0.0)[1] == pytest.approx(0.6 * math.exp(-0.01 / validity.HOLD))
    judge.reset()
    assert judge.widen(std, index, ratios, 0.0)[1] == pytest.approx(0.05)


def test_the_sideslip_std_carries_the_learned_ay_offset_beyond_what_ay_s_noise_admits(config):
    """An ay offset the online calibration learned and does not apply (a bias or a bank) moves the sideslip by up
    to ``m c / (C_f + C_r)``; the part within ay's configured noise is the noise's already."""
    vehicle = config.vehicle
    judge = StateJudge(SingleTrackModel(vehicle), vehicle, 0.01, ay_noise=0.11)
    assert judge.sideslip_offset_std() == 0.0  # nothing learned
    judge.use_kinematic_offsets(0.08, 0.0)
    assert judge.sideslip_offset_std() == 0.0  # within the noise
    judge.use_kinematic_offsets(-0.31, 0.0)  # a bank of 3 deg less a bias of 0.2
    per_side_force = vehicle.mass / (vehicle.cornering_stiffness_front + vehicle.cornering_stiffness_rear)
    assert judge.sideslip_offset_std() == pytest.approx(0.2 * per_side_force)


@pytest.mark.parametrize("filter_name", ["ckf", "dici-gfckf"])
def test_every_model_publishes_the_learned_ay_offset_in_its_sideslip_std(config, filter_name):
    """The tire-force model's Q holds its tires' error (its std does not add it again), not a learned ay offset:
    every model's published sideslip std is at least the offset's term, from ay's configured noise."""
    import dataclasses

    from canest.pipeline import Pipeline
    from canest.sim.simulate import simulate

    est = dataclasses.replace(config.estimator, filter=filter_name, online_calibration=False,
                              model="tire_force" if filter_name == "dici-gfckf" else "single_track")
    pipeline = Pipeline(dataclasses.replace(config, estimator=est))
    estimator = pipeline.estimator
    assert estimator.judge.ay_noise == config.estimator.measurement_noise["ay"]
    estimator.judge.use_kinematic_offsets(-1.0, 0.0)  # a large offset, as if learned (the learner is off)
    sim = simulate(config, "step", 80.0, 0.85, duration=2.0, seed=1)
    stds = [e.values["beta_std"] for frame in sim.frames for e in pipeline.feed(frame)
            if math.isfinite(e.values["beta_std"])]
    floor = estimator.judge.sideslip_offset_std()
    assert floor > 0.002 and len(stds) > 100 and min(stds) >= floor * (1 - 1e-12)
