"""Online self-calibration (canest/estimation/online_calibration.py), its identities (canest/models/identities.py)
and its state file (canest/estimation/calibration_state.py).

The drive: 45 s of simulated country road by the wrong car of issue 17 (front stiffness x0.7, rear x1.3, steering
offset 1.5 deg, ratio +8 %, gyro bias 0.5 deg/s, ay bias 0.2 m/s^2, wheel radius +3 %, road bank 3 deg).
"""
import dataclasses
import json
import logging
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from canest.calibration import RADIUS_DRIFT, RATIO_MODEL_ERROR, STIFFNESS_MODEL_ERROR, STIFFNESSES
from canest.config import load_config
from canest.errors import ConfigError
from canest.estimation.calibration_blocks import BlockMeans
from canest.estimation.calibration_state import RELOAD_INFLATION, CalibrationStore
from canest.estimation.learned_parameters import NAMES, parameters
from canest.estimation.validity import KINEMATIC_MEMORY
from canest.estimation.online_calibration import (APPLY_EVIDENCE, FIT_FLOOR, MAX_CORRELATION, InnovationSpread,
                                                  OnlineCalibration)
from canest.estimation import stiffness_window
from canest.estimation.stiffness_window import FITTED, LATENCY, WINDOW, FitWorker, WindowFit, fit_window
from canest.models.output_error import Drive, DriveRows
from canest.models import identities
from canest.models.single_track import SingleTrackModel
from canest.models.tire_force import AxDrivenTireForceModel, TireForceModel
from canest.models.two_track import TwoTrackModel
from canest.models.wheels import WheelGeometry
from canest.pipeline import Pipeline
from canest.resample import Sample
from canest.sim.mismatch import PlantMismatch, flat_road_offsets, true_fit, true_vehicle
from canest.sim.sensors import DEFAULT_SENSORS
from canest.sim.simulate import simulate
from tests.conftest import CONFIG, ROOT
from tests.test_config import write_variant

WRONG = PlantMismatch(0.7, 1.3, 1.08, 1.03, math.radians(1.5), math.radians(0.5), 0.2, math.radians(3.0))
SECONDS = 60.0  # the gyro bias, ay and ax offsets converge within it (the steering offset waits for the gyro bias)


@pytest.fixture(scope="module")
def config():
    return load_config(CONFIG)


@pytest.fixture(scope="module")
def drive(config):
    return simulate(config, "country", 80.0, 0.85, duration=SECONDS, seed=3, mismatch=WRONG)


@pytest.fixture(scope="module")
def truth(drive):
    """The plant's true signals with dvx/dt and dvy/dt; the first 0.1 s (the plant settling) and the last tick (a
    one-sided difference) left out."""
    t = drive.truth
    rates = {"vx_rate": np.gradient(t["vx"], t["t"]), "vy_rate": np.gradient(t["vy"], t["t"])}
    return {name: values[10:-1] for name, values in {**t, **rates}.items()}


@pytest.fixture(scope="module")
def car(config):
    return true_vehicle(config.vehicle, WRONG)


def steady_bends(t, low=0.8, high=2.5):
    """Ticks of a steady bend in the linear range: yaw acceleration below 0.01 rad/s^2, |ay| in [low, high]."""
    yaw_acceleration = np.gradient(t["yaw_rate"], t["t"])
    return (np.abs(yaw_acceleration) < 0.01) & (np.abs(t["ay"]) > low) & (np.abs(t["ay"]) < high) & (t["vx"] > 8.0)


# -- identities ------------------------------------------------------------------------------------------------------

def test_lateral_specific_force_is_what_the_plant_accelerometer_reads_on_the_banked_road(truth):
    ay = identities.lateral_specific_force(truth["vx"], truth["yaw_rate"], truth["vy_rate"], WRONG.bank)
    assert np.max(np.abs(ay - truth["ay"])) < 0.01
    flat = identities.lateral_specific_force(truth["vx"], truth["yaw_rate"], truth["vy_rate"])
    assert np.median(flat - truth["ay"]) == pytest.approx(WRONG.bank_acceleration, rel=0.01)  # the bank's sign


def test_longitudinal_specific_force_is_the_plant_ax(truth):
    ax = identities.longitudinal_specific_force(truth["vx_rate"], truth["vy"], truth["yaw_rate"])
    assert np.max(np.abs(ax - truth["ax"])) < 0.01
    assert np.ptp(truth["ax"]) > 1.0  # the drive brakes and accelerates


def test_measured_ay_holds_with_the_sensor_errors_and_the_bank_as_one_offset(truth, config):
    """What the learner fits: s v_w (r_m - b_r) + (b_ay - g sin(bank)) with the true parameters."""
    steady = np.abs(truth["vy_rate"]) < 0.02
    wheel_speed = truth["vx"][steady] / WRONG.wheel_radius_scale  # what the configured radius makes of the wheels
    measured = truth["ay"][steady] + WRONG.ay_bias
    predicted = identities.measured_ay(wheel_speed, truth["yaw_rate"][steady] + WRONG.gyro_bias,
                                       WRONG.wheel_radius_scale, WRONG.gyro_bias,
                                       WRONG.ay_bias - WRONG.bank_acceleration)
    assert steady.sum() > 1000 and np.max(np.abs(predicted - measured)) < 0.03


def test_the_banked_road_holds_the_equivalent_flat_roads_offsets_in_steady_bends(truth, car, config):
    """What the steady identities can learn on a bank: a flat road (ay = v r) with ``flat_road_offsets``."""
    steady = steady_bends(truth)
    t = {name: values[steady] for name, values in truth.items()}
    steering_offset, ay_bias = flat_road_offsets(config.vehicle, WRONG)
    measured = t["steering_wheel_angle"] + WRONG.steering_offset
    flat = identities.steady_steering_wheel_angle(t["vx"], t["yaw_rate"], t["vx"] * t["yaw_rate"], steering_offset,
                                                  car.steering_ratio, car.wheelbase, car.understeer_gradient)
    assert abs(np.median(flat - measured)) < math.radians(0.2)
    assert abs(steering_offset - WRONG.steering_offset) > math.radians(3.0)  # the bank's share is not small
    assert np.median(t["ay"] + WRONG.ay_bias - t["vx"] * t["yaw_rate"]) == pytest.approx(ay_bias, abs=0.02)


def test_understeer_gradient_sign_and_value(car):
    k = identities.understeer_gradient(car.mass, car.cg_to_front, car.cg_to_rear, car.cornering_stiffness_front,
                                       car.cornering_stiffness_rear)
    assert k == pytest.approx(car.understeer_gradient)
    assert k > 0  # front axle x0.7, rear x1.3: this car understeers
    assert identities.understeer_gradient(1500.0, 1.0, 1.5, 1e5, 0.5e5) < 0  # a weak rear axle oversteers


def test_steady_bends_follow_the_single_track_identities(truth, car):
    steady = steady_bends(truth)
    assert steady.sum() > 200
    t = {name: values[steady] for name, values in truth.items()}
    k = car.understeer_gradient
    r = identities.steady_yaw_rate(t["vx"], t["delta"], car.wheelbase, k, WRONG.bank)
    assert np.max(np.abs(r / t["yaw_rate"] - 1.0)) < 0.05
    flat = identities.steady_yaw_rate(t["vx"], t["delta"], car.wheelbase, k)
    assert np.max(np.abs(flat / t["yaw_rate"] - 1.0)) > 0.1  # the bank matters: the road falls to the left
    swa = identities.steady_steering_wheel_angle(t["vx"], t["yaw_rate"], t["ay"], WRONG.steering_offset,
                                                 car.steering_ratio, car.wheelbase, k)
    assert np.max(np.abs(swa - (t["steering_wheel_angle"] + WRONG.steering_offset))) < math.radians(1.0)
    delta = identities.road_wheel_angle(t["steering_wheel_angle"] + WRONG.steering_offset, WRONG.steering_offset,
                                        car.steering_ratio)
    assert np.allclose(delta, t["delta"])
    beta = identities.steady_sideslip(t["vx"], t["yaw_rate"], t["ay"], car.mass, car.cg_to_front, car.cg_to_rear,
                                      car.cornering_stiffness_rear)
    assert np.max(np.abs(beta - t["beta"])) < math.radians(0.05)
    assert np.max(np.abs(t["beta"])) > math.radians(0.1)



# -- the learner on the simulated drive --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def learned(config, drive):
    """(the pipeline after the drive, [(t, learned x, applied, converged)] once a block, the estimates)."""
    pipeline = Pipeline(config)
    calibration = pipeline.calibration
    history, estimates = [], []
    for frame in drive.frames:
        estimates += pipeline.feed(frame)
        if calibration.blocks.count == 0 and (not history or history[-1][0] < frame.timestamp - 0.05):
            history.append((frame.timestamp, calibration.x.copy(), calibration.applied.copy(),
                            calibration.converged.copy()))
    return pipeline, history, estimates


def test_learns_speed_scale_gyro_bias_and_lateral_offset_on_the_drive(learned):
    calibration = learned[0].calibration
    value = dict(zip(NAMES, calibration.x))
    print({name: round(float(v), 5) for name, v in value.items()})
    # 0.26 % low (the raw wheels: 0.3 %); issue 17 asks 10 % of the radius's 3 % error. The wheels' slip-free speed
    # is within 0.03 % of the true speed on this drive (1.0303 against 1.03): the rest is the learner's. It was 0.16 %
    # while the rolling moment was taken as tire force, a 0.08 % slip the wheels do not have, partly offsetting it.
    assert value["speed"] == pytest.approx(WRONG.wheel_radius_scale, abs=0.003)
    assert value["gyro_bias"] == pytest.approx(WRONG.gyro_bias, abs=math.radians(0.05))
    assert value["ay_bias"] == pytest.approx(WRONG.ay_bias - WRONG.bank_acceleration, abs=0.03)
    assert calibration.updates["kinematic"] > 200 and calibration.updates["steering"] > 200


def test_applied_after_ten_seconds_of_evidence_before_convergence_then_rate_limited(learned):
    pipeline, history, _ = learned
    calibration = pipeline.calibration
    start = np.array([p.start for p in calibration.specs])
    t0 = history[0][0]
    early = [applied for t, _, applied, _ in history if t - t0 < APPLY_EVIDENCE]
    assert len(early) > 80 and all(np.array_equal(applied, start) for applied in early)
    unconverged_but_applied = {NAMES[i] for _, _, applied, converged in history for i in range(len(NAMES))
                               if applied[i] != start[i] and not converged[i]}
    assert unconverged_but_applied  # the learned mean is applied before its std is below the threshold (ax offset)
    assert calibration.converged.any()
    steps = np.abs(np.diff(np.array([applied for _, _, applied, _ in history]), axis=0))
    rates = np.array([p.rate for p in calibration.specs]) * 0.1
    assert np.all(steps <= rates + 1e-12)
    moved = np.abs(calibration.applied - start) > 0
    assert moved.any() and not moved[NAMES.index("understeer")]  # the balance is reported, never applied


def test_vx_and_the_yaw_rate_carry_the_error_of_the_applied_corrections(learned, drive):
    """From the first tick the wheel-speed scale is applied, vx's std holds ``|vx|`` times its error (its learned std
    and the distance the applied value has still to follow, in quadrature), and the yaw rate's the gyro bias's once
    that is applied (within 2 std on 97.7 % of its valid ticks after it, 94.6 % before): the scale is one error every
    tick shares, which no consistency test sees. Before, vx was within
    2 std on 64 % of the valid ticks after the scale was applied (NEES 9.5, valid but wrong 2.3 %; now 100 %, 0.88)."""
    pipeline, history, estimates = learned
    speed = NAMES.index("speed")
    applied_at = next(t for t, _, applied, _ in history if applied[speed] != 1.0)
    after = [e for e in estimates if e.t > applied_at + 0.2 and e.valid["vx"]]
    assert len(after) > 1000
    for e in after:
        scale_std = math.hypot(e.calibration["calib_speed_std"], e.calibration["calib_speed"]
                               - e.calibration["calib_speed_applied"])
        assert e.values["vx_std"] >= abs(e.values["vx"]) * scale_std * (1.0 - 1e-9)
    vx_truth = np.interp([e.t for e in after], drive.truth["t"], drive.truth["vx"])
    error = np.abs(np.array([e.values["vx"] for e in after]) - vx_truth)
    assert np.mean(error < 2.0 * np.array([e.values["vx_std"] for e in after])) > 0.9
    gyro_applied = [e for e in estimates if e.calibration["calib_gyro_bias_applied"] != 0.0 and e.valid["yaw_rate"]]
    assert len(gyro_applied) > 1000  # the gyro bias converged on this road
    yaw_truth = np.interp([e.t for e in gyro_applied], drive.truth["t"], drive.truth["yaw_rate"])
    yaw_error = np.abs(np.array([e.values["yaw_rate"] for e in gyro_applied]) - yaw_truth)
    assert np.mean(yaw_error < 2.0 * np.array([e.values["yaw_rate_std"] for e in gyro_applied])) > 0.96  # was 0.946


def test_before_the_corrections_are_applied_vx_and_the_yaw_rate_carry_the_configs_claim(config):
    """A config that says how well it knows the radius and the gyro's bias (3 %, 0.5 deg/s: this wrong car's
    errors as 1 std) publishes them until the learner applies its own (35 s on this road, flat): over the first
    30 s vx is ``uncertain`` wherever ``|vx|`` times 3 % passes 0.5 m/s and within 2 std on every valid tick (a
    config claiming both exact: none, NEES 628), the yaw rate within 2 std on all; vy keeps its bit there (its std
    holds ``tan(beta)`` times vx's) and is within it. On the banked road of the module: vx 4.2 -> 100 %, yaw rate
    0.7 -> 100 % (README "Online calibration")."""
    flat = simulate(config, "country", 80.0, 0.85, duration=30.0, seed=3, mismatch=dataclasses.replace(WRONG, bank=0.0))
    claiming = dataclasses.replace(
        config, vehicle=dataclasses.replace(config.vehicle, wheel_radius_uncertainty=0.03),
        estimator=dataclasses.replace(config.estimator, gyro_bias_std=math.radians(0.5)))
    runs = {}
    for name, run_config in (("claiming", claiming), ("exact", config)):
        pipeline = Pipeline(run_config)
        runs[name] = [e for frame in flat.frames for e in pipeline.feed(frame)]
        assert pipeline.calibration.correction_std == (None, None)  # nothing applied yet: the claim is published
        assert pipeline.calibration.stiffness_error is None  # no window fitted in 30 s: the stiffnesses' claim
        pipeline.close()

    def within_two_std(estimates, state):
        truth = np.interp([e.t for e in estimates], flat.truth["t"], flat.truth[state])
        error = np.abs(np.array([e.values[state] for e in estimates]) - truth)
        return np.mean(error < 2.0 * np.array([e.values[f"{state}_std"] for e in estimates]))

    # the premise: claimed exact, most fall outside (vx: none within; the yaw rate 28 % within: the ACU's gyro,
    # unbiased, takes a fifth of its weight)
    for state, exact_within in (("vx", 0.1), ("yaw_rate", 0.4)):
        valid = {name: [e for e in estimates if e.valid.get(state)] for name, estimates in runs.items()}
        assert len(valid["claiming"]) > 500 and within_two_std(valid["claiming"], state) > 0.98
        assert within_two_std(valid["exact"], state) < exact_within
    fast = [e for e in runs["claiming"] if abs(e.values["vx"]) * 0.03 > 0.55]
    assert len(fast) > 500 and not any(e.valid.get("vx") for e in fast)
    uncertain = [e for e in fast if e.causes["vx"] == "uncertain" and e.valid["vy"]]
    assert len(uncertain) > 500 and within_two_std(uncertain, "vy") > 0.95


def test_the_learners_prior_is_never_narrower_than_the_configs_claim(config):
    """A config that knows its radius or its gyro's bias less well than the learner's search range widens that
    range: the learned std, which replaces the claim once applied, starts from the claim."""
    speed, gyro = NAMES.index("speed"), NAMES.index("gyro_bias")
    default = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    vague = OnlineCalibration(dataclasses.replace(config.vehicle, wheel_radius_uncertainty=0.1), NAMES_IN, 0.01,
                              gyro_bias_std=math.radians(2.0))
    assert default.std[speed] == 0.03 and default.std[gyro] == pytest.approx(math.radians(0.5))
    assert vague.std[speed] == 0.1 and vague.std[gyro] == pytest.approx(math.radians(2.0))


def test_the_steering_and_lateral_offsets_are_learned_but_never_applied(config):
    """A bank shows as both: applied, its side force is a force the model's tires carry, with every channel
    consistent (the banked road's sideslip below)."""
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    ay, offset = NAMES.index("ay_bias"), NAMES.index("steering_offset")
    calibration.x[ay], calibration.x[offset] = 0.3, math.radians(1.0)
    calibration.evidence[:] = 60.0
    calibration.P = np.diag([p.converged ** 2 / 4.0 for p in calibration.specs])
    assert calibration.converged[ay] and calibration.converged[offset]
    for _ in range(100):
        calibration._follow()
    assert calibration.applied[ay] == 0.0 and calibration.applied[offset] == 0.0


def test_on_a_banked_road_the_sideslip_after_the_first_window_fit_is_within_its_std(learned, drive):
    """With the window fit the offsets converge at its first window (35 s): applied, the bank's side force made
    the sideslip 0.16-0.18 deg off with a std of 0.05 (within 2 std on 23 % of the valid ticks, NEES 7.9)."""
    _, history, estimates = learned
    late = [e for e in estimates if e.t > history[0][0] + WINDOW + LATENCY and e.valid.get("beta")]
    std = np.array([e.values["beta_std"] for e in late])
    error = np.array([e.values["beta"] for e in late]) - np.interp([e.t for e in late], drive.truth["t"],
                                                                     drive.truth["beta"])
    assert len(late) > 1000 and np.mean(np.abs(error) < 2.0 * std) > 0.9 and np.mean((error / std) ** 2) < 2.0


def test_converged_corrections_reach_the_estimator(config, learned):
    """The sample the estimator gets: wheel speeds scaled, yaw rate less its bias, steering over the ratio; ay as
    measured (its offset may be a bank)."""
    calibration = learned[0].calibration
    names = tuple(calibration.index)
    values = np.arange(1.0, len(names) + 1.0)
    sample = Sample(0.0, names, values, np.zeros(len(names), bool), np.ones(len(names), bool),
                    np.zeros(len(names)), np.zeros(len(names), bool))
    frozen = OnlineCalibration(config.vehicle, names, 0.01, enabled=False)
    assert frozen.correct(sample) is sample  # off: passed through
    applied = dict(zip(NAMES, calibration.applied))
    corrected = calibration.apply(sample)
    i = calibration.index
    assert corrected.values[i["wheel_speed_fl"]] == pytest.approx(values[i["wheel_speed_fl"]] * applied["speed"])
    assert corrected.values[i["yaw_rate"]] == pytest.approx(values[i["yaw_rate"]] - applied["gyro_bias"])
    assert corrected.values[i["ay"]] == values[i["ay"]]
    assert corrected.values[i["steering_wheel_angle"]] == pytest.approx(values[i["steering_wheel_angle"]]
                                                                        / applied["ratio"])
    assert sample.values[i["yaw_rate"]] == values[i["yaw_rate"]]  # the raw sample untouched


def test_the_kinematic_checks_take_out_the_learned_lateral_offset(config):
    """On a 75 s road c converges at the first window fit (35 s); it is never applied to the inputs. The gyro
    bias applied alone left ``c / v`` in the kinematic sideslip rate, and the published sideslip std (never below
    the kinematic mismatch) was 1.3 deg after 50 s against an error of 0.07; with the learned offsets, three of
    the mismatch's 2 s memories after c's convergence (it fades from 2.8 deg, built up in a bend of 2.9 m/s^2
    before), the model's: 0.05, and 0.11 in the bends that follow; with the part of c (-0.31 on this banked road)
    beyond ay's configured noise through the tires (``validity.sideslip_offset_std``) 0.11, and 0.26."""
    drive = simulate(config, "country", 80.0, 0.85, duration=75.0, seed=3, mismatch=WRONG)
    pipeline = Pipeline(config)
    calibration = pipeline.calibration
    ay, gyro = NAMES.index("ay_bias"), NAMES.index("gyro_bias")
    estimates, converged_at = [], None
    for frame in drive.frames:
        estimates += pipeline.feed(frame)
        if converged_at is None and calibration.converged[ay]:
            converged_at = frame.timestamp
    assert converged_at is not None and converged_at < 40.0 and calibration.applied[ay] == 0.0
    assert calibration.kinematic_offsets == (calibration.x[ay], calibration.x[gyro] - calibration.applied[gyro])
    assert pipeline.estimator.judge.kinematic_offsets == calibration.kinematic_offsets
    late = [e for e in estimates if e.t > converged_at + 3.0 * KINEMATIC_MEMORY]
    std = np.array([e.values["beta_std"] for e in late])
    error = np.array([e.values["beta"] for e in late]) - np.interp([e.t for e in late], drive.truth["t"],
                                                                     drive.truth["beta"])
    assert np.degrees(np.median(std)) < 0.15 and np.degrees(std.max()) < 0.35  # 0.25 in a bend of 3.3 m/s^2
    assert np.mean(np.abs(error) < 2.0 * std) > 0.9


def test_no_kinematic_offset_before_the_lateral_offset_converged(config):
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    ay = NAMES.index("ay_bias")
    calibration.x[ay] = 0.3
    assert calibration._kinematic_offsets() == (0.0, 0.0)
    calibration.evidence[ay], calibration.P[ay, ay] = 60.0, 1e-4
    assert calibration._kinematic_offsets() == (0.3, 0.0)


def test_the_published_stiffness_std_holds_the_linear_tires_error_that_windows_do_not_average(config, learned):
    """The learned stiffnesses' published std never falls below ``STIFFNESS_MODEL_ERROR`` of the value (what a
    linear tire fitted to driving reads off the tires' small-slip stiffness, the same in every window), and covers
    the true factor; the understeer gradient's carries that error too; convergence judges the windows' evidence
    alone."""
    calibration = learned[0].calibration
    report, truth = calibration.report(), true_fit(config.vehicle, WRONG)
    for name in STIFFNESSES:
        i = NAMES.index(name)
        value, std = report[f"calib_{name}"], report[f"calib_{name}_std"]
        print(f"{name}: {value:.4f} +- {std:.4f} (posterior {calibration.std[i]:.4f}), true {truth.value(name):.4f}")
        assert std == pytest.approx(math.hypot(calibration.std[i], STIFFNESS_MODEL_ERROR * value))
        assert abs(value - truth.value(name)) < 2.0 * std
        assert report[f"calib_{name}_converged"]
    car = true_vehicle(config.vehicle, WRONG)
    understeer, understeer_std = report["calib_understeer"], report["calib_understeer_std"]
    print(f"understeer: {understeer:.5f} +- {understeer_std:.5f}, true {car.understeer_gradient:.5f}")
    assert abs(understeer - car.understeer_gradient) < 2.0 * understeer_std
    assert understeer_std > 0.05 * car.mass / car.wheelbase * car.cg_to_rear / car.cornering_stiffness_front


def test_the_published_ratio_std_holds_the_error_that_driving_does_not_average(learned):
    """The learned steering ratio's published std holds ``RATIO_MODEL_ERROR`` of the value in quadrature (on one
    road it would cover the truth without it; the 40 roads behind the term are in the README), and convergence
    judges the posterior alone."""
    calibration = learned[0].calibration
    report, i = calibration.report(), NAMES.index("ratio")
    value, std = report["calib_ratio"], report["calib_ratio_std"]
    print(f"ratio: {value:.4f} +- {std:.4f} (posterior {calibration.std[i]:.4f}), true {WRONG.steering_ratio_scale}")
    assert std == pytest.approx(math.hypot(calibration.std[i], RATIO_MODEL_ERROR * value))
    assert abs(value - WRONG.steering_ratio_scale) < 2.0 * std
    assert report["calib_ratio_converged"] == bool(calibration.converged[i])


def test_the_stiffnesses_are_learned_from_a_window_of_the_drive_and_reach_the_model(config, learned):
    """One 30 s window of the banked road, fitted in the worker process: both axles within 10 % (issue 17), taken
    ``LATENCY`` s after the window closed, applied rate-limited, and the estimator's model runs with them. Closing
    the pipeline (last: the module's other tests read its learner, not its worker) stops the worker."""
    pipeline, history, _ = learned
    calibration = pipeline.calibration
    front, rear = NAMES.index("front"), NAMES.index("rear")
    assert calibration.updates["window"] == len(FITTED)
    assert calibration.window.fits == {"used": 1, "unexcited": 0, "short": 0, "lost": 0}
    assert calibration.x[front] == pytest.approx(WRONG.stiffness_scale_front, rel=0.1)
    assert calibration.x[rear] == pytest.approx(WRONG.stiffness_scale_rear, rel=0.1)
    assert calibration.converged[front] and calibration.converged[rear]
    first = next(t for t, x, _, _ in history if x[front] != 1.0)
    assert first - history[0][0] >= WINDOW + LATENCY - 1.0  # a window of usable driving, then the latency
    assert calibration.applied[front] < 1.0 < calibration.applied[rear]
    vehicle = pipeline.estimator.vehicle
    assert pipeline.estimator.stiffness == (*calibration.stiffness, calibration.stiffness_error)
    # the applied stiffnesses' error, which takes the config's claim's place in the linear tires' sideslip term
    # (the built-in model's): below the claim, at least the linear tires' model error here, and covering the truth
    error = calibration.stiffness_error
    assert STIFFNESS_MODEL_ERROR <= error < config.vehicle.cornering_stiffness_uncertainty
    for axle, true in (("front", WRONG.stiffness_scale_front), ("rear", WRONG.stiffness_scale_rear)):
        applied = calibration.applied[NAMES.index(axle)]
        assert abs(true / applied - 1.0) < 2.0 * error, axle
    assert vehicle.cornering_stiffness_uncertainty == error
    assert vehicle.cornering_stiffness_front == pytest.approx(
        config.vehicle.cornering_stiffness_front * calibration.applied[front])
    assert vehicle.cornering_stiffness_rear == pytest.approx(
        config.vehicle.cornering_stiffness_rear * calibration.applied[rear])
    assert pipeline.estimator.model.vehicle is vehicle and pipeline.estimator.judge.vehicle is vehicle
    worker = calibration.window.worker
    pipeline.close()
    assert worker.process.returncode == 0 and calibration.window.worker is None  # the worker ended with the learner


NO_MAIN_GUARD = f"""
import numpy as np
from canest.config import load_config
from canest.estimation.stiffness_window import FitWorker, WindowFit
from canest.models.output_error import Drive
t = np.arange(0.0, 20.0, 0.02)
yaw = 0.08 * np.sin(0.8 * t - 0.1)
drive = Drive("synthetic", t, 0.5 * np.sin(0.8 * t), yaw, 20.0 * yaw, np.full(len(t), 20.0), t == 0.0)
worker = FitWorker()
worker.submit(load_config({str(CONFIG)!r}).vehicle, drive)
fit = worker.result()
worker.close()
print(fit is None or isinstance(fit, WindowFit), worker.process.returncode)
"""


def test_a_script_without_a_main_guard_fits_windows_in_the_worker(tmp_path):
    """The worker is a subprocess of canest's own module: a user's script is not run again in it (as a spawned
    multiprocessing child would, endlessly, without ``if __name__ == "__main__"``)."""
    script = tmp_path / "my_analysis.py"
    script.write_text(NO_MAIN_GUARD)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=env)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["True", "0"]


def test_a_window_without_bends_teaches_no_stiffness(config):
    """No bend, no yaw dynamics: not fitted (its Jacobian is singular, and the pseudo-inverse called a steering
    exactly 0 with a quantized yaw rate a certain front x4.6; the real Ford log, an ACC speed-up on a straight
    looped to 100 s, used none of its three windows)."""
    t = np.arange(0.0, 30.0, 0.02)
    yaw = np.round(np.random.default_rng(2).normal(0.0, 0.002, len(t)), 3)
    drive = Drive("straight", t, np.zeros(len(t)), yaw, 25.0 * yaw, np.full(len(t), 25.0), t == 0.0)
    assert fit_window(config.vehicle, drive) is None


def window_fit(front, rear, std=0.01, **others):
    """A fit of ``front`` and ``rear``, the others at the learner's start unless given (std 1e-4)."""
    start = {p.name: p.start for p in parameters(load_config(CONFIG).vehicle)}
    values = np.array([front, rear] + [others.get(name, start[name]) for name in FITTED[2:]])
    return WindowFit(FITTED, values, np.diag([std**2, std**2] + [1e-8] * (len(FITTED) - 2)), WINDOW)


def test_a_fit_whose_stiffnesses_disagree_is_left_out_whole_and_three_in_a_row_relearn_them(config, caplog):
    """The pair's gate: a row gated alone let the rear row, conditioned on the front, move front away from the
    fit (1.0 -> 1.002 for a fit of 0.8); a gated fit adds no evidence. New tires: three in a row reopen."""
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    both = [NAMES.index("front"), NAMES.index("rear")]
    calibration._window_update(window_fit(1.0, 1.0))
    x, P, evidence = calibration.x.copy(), calibration.P.copy(), calibration.evidence.copy()
    assert evidence[both].tolist() == [WINDOW, WINDOW]
    calibration._window_update(window_fit(0.8, 0.82))
    assert np.array_equal(calibration.x, x) and np.array_equal(calibration.P, P)
    assert np.array_equal(calibration.evidence, evidence) and calibration.updates["gated"] == 1
    with caplog.at_level(logging.WARNING, logger="canest"):
        calibration._window_update(window_fit(0.8, 0.82))
        calibration._window_update(window_fit(0.8, 0.82))
    assert "3 windows in a row disagreed with the learned cornering stiffnesses" in caplog.text
    assert np.allclose(calibration.std[both], calibration.prior_std[both]) and not calibration.evidence[both].any()
    calibration._window_update(window_fit(0.8, 0.82))
    assert calibration.x[both] == pytest.approx([0.8, 0.82], abs=0.02)
    assert calibration.updates["window"] == 2 * len(FITTED)


def test_a_fit_whose_offsets_disagree_still_teaches_its_stiffnesses(config):
    """A changing bank moves the lateral offset between windows; the stiffnesses do not care, and a gated offset
    must not reopen them."""
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    ay, front = NAMES.index("ay_bias"), NAMES.index("front")
    calibration._window_update(window_fit(0.9, 1.1, ay_bias=0.1))
    learned_ay, evidence_ay = calibration.x[ay], calibration.evidence[ay]
    assert learned_ay == pytest.approx(0.1, abs=0.01) and evidence_ay == WINDOW
    calibration._window_update(window_fit(0.8, 1.0, ay_bias=1.0))  # 0.9 m/s^2 off: far beyond the gate
    assert calibration.x[ay] == learned_ay and calibration.evidence[ay] == evidence_ay
    assert calibration.evidence[front] == 2 * WINDOW and calibration.x[front] < 0.9 and calibration.gated_fits == 0


def test_the_window_fit_teaches_the_offsets_ratio_and_speed_it_fits(config):
    """One window's fit is the strongest evidence of them (the gyro bias +-0.03 deg/s from 30 s of road, the
    kinematic identity +-0.2 deg/s after 30 s): each converges at once."""
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    fit = window_fit(0.7, 1.3, gyro_bias=math.radians(0.5), steering_offset=math.radians(1.5), ratio=1.08,
                     speed=1.03, ay_bias=0.2)
    calibration._window_update(fit)
    for name in FITTED:
        i = NAMES.index(name)
        assert calibration.x[i] == pytest.approx(fit.values[FITTED.index(name)], abs=3.0 * FIT_FLOOR[name]), name
        assert calibration.converged[i], name


def synthetic_rows(seconds=30.0):
    rows = DriveRows()
    for ti in np.arange(0.0, seconds, 0.02):
        r = 0.08 * math.sin(0.8 * ti - 0.1)
        rows.add(ti, 0.5 * math.sin(0.8 * ti), r, 20.0 * r, 20.0)
    return rows


@pytest.fixture
def sigpipe_default():
    """SIGPIPE at its default action, as the command line sets it (``canest check | head`` ends quietly)."""
    previous = signal.signal(signal.SIGPIPE, signal.SIG_DFL)
    yield
    signal.signal(signal.SIGPIPE, previous)


@pytest.mark.parametrize("when", ["before it is given a window", "while it fits one"])
def test_a_worker_that_dies_turns_the_window_off_with_one_warning_and_the_learner_goes_on(config, caplog, when,
                                                                                        sigpipe_default):
    """SIGPIPE at its default: a write into the pipe of the dead worker killed the whole test run (and would the
    daemon) without a word; the socket pair's write is an error the window handles."""
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    window = calibration.window
    window.t = 0.0
    window.worker = FitWorker()
    if when == "before it is given a window":
        window.worker.process.kill()
        window.worker.process.wait()
    window.rows = synthetic_rows()
    with caplog.at_level(logging.WARNING, logger="canest"):
        window._submit()
        if window.enabled:
            window.worker.process.kill()
            window.worker.process.wait()
            assert window._take() is None
    assert "the cornering stiffnesses' worker is gone" in caplog.text and caplog.text.count("is gone") == 1
    assert not window.enabled and window.worker is None and window.fits["lost"] == 1
    for k in range(30):  # the learner goes on, the window is off
        assert calibration.correct(sample(k * 0.01, wheel=20.0)) is not None


def test_at_a_tick_rate_that_is_not_a_multiple_of_50_hz_the_stiffnesses_are_not_learned(config, caplog,
                                                                                      monkeypatch):
    monkeypatch.setattr(stiffness_window, "_warned", False)
    with caplog.at_level(logging.WARNING, logger="canest"):
        calibration = OnlineCalibration(config.vehicle, NAMES_IN, 1.0 / 40.0)
    assert calibration.enabled and not calibration.window.enabled
    assert "not learned online at 40 Hz: the fit needs a sample every 0.02 s" in caplog.text
    assert OnlineCalibration(config.vehicle, NAMES_IN, 1.0 / 200.0).window.enabled


MODELS = {  # each model class with its u (its binding's docstring)
    "single_track": (SingleTrackModel, [0.05, 0.5, 1.0]),
    "tire_force": (TireForceModel, [0.05, 0.5, 2.0, 0.1, 80.0, 80.0, 60.0, 60.0]),
    "tire_force from ax": (AxDrivenTireForceModel, [0.05, 0.5, 2.0, 0.1]),
    "two_track": (TwoTrackModel, [0.05, 0.5, 2.0, 0.1, 40.0, 40.0, 30.0, 30.0])}
BASE_STATE = {"vx": 20.0, "w_": 20.0 / 0.33, "mu_": 0.9}


@pytest.mark.parametrize("model", sorted(MODELS))
def test_a_model_told_new_stiffnesses_computes_as_one_built_with_them(config, model):
    """``use_vehicle`` (the learned stiffnesses reaching a running model) leaves nothing of the old ones behind."""
    p = config.vehicle
    learned = dataclasses.replace(p, cornering_stiffness_front=0.7 * p.cornering_stiffness_front,
                                  cornering_stiffness_rear=1.3 * p.cornering_stiffness_rear)
    model_class, u = MODELS[model]
    told, built, old = model_class(p), model_class(learned), model_class(p)
    told.use_vehicle(learned)
    base = [next((v for key, v in BASE_STATE.items() if name.startswith(key)), 0.0) for name in told.state_names]
    X = np.array(base) + np.random.default_rng(1).normal(0.0, 0.05, (7, len(base)))
    u = np.array(u)
    np.testing.assert_allclose(told.transition(X, u, 0.01), built.transition(X, u, 0.01), rtol=1e-12)
    np.testing.assert_allclose(told.measure(X, u), built.measure(X, u), rtol=1e-12)
    assert not np.allclose(old.transition(X, u, 0.01), built.transition(X, u, 0.01))  # the stiffnesses matter


# -- the learner on made-up inputs -------------------------------------------------------------------------------------

NAMES_IN = ("steering_wheel_angle", "yaw_rate", "ay", "ax", "wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl",
            "wheel_speed_rr")


def sample(t, swa=0.0, yaw_rate=0.0, ay=0.0, ax=0.0, wheel=0.0, stale=()):
    values = np.array([swa, yaw_rate, ay, ax, wheel, wheel, wheel, wheel])
    n = len(NAMES_IN)
    return Sample(t, NAMES_IN, values, np.array([name in stale for name in NAMES_IN]), np.ones(n, bool), np.zeros(n),
                  np.zeros(n, bool))


def test_gyro_bias_is_learned_at_a_standstill(config):
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    rng = np.random.default_rng(0)
    bias = math.radians(0.4)
    for k in range(6000):  # a minute parked
        calibration.correct(sample(k * 0.01, yaw_rate=bias + math.radians(0.1) * rng.standard_normal()))
    assert calibration.x[NAMES.index("gyro_bias")] == pytest.approx(bias, abs=math.radians(0.02))
    assert calibration.updates["standstill"] > 500 and calibration.updates["kinematic"] == 0


def test_a_second_gyro_is_learned_against_the_first_and_corrected_to_agree_with_it(config):
    """Parked a minute, each gyro with its own bias: the standstill learns the first, the gyros' difference the
    second (the first considered: unmoved by it); the second is corrected to the first's applied bias less the
    difference, so that the two agree. A block whose second gyro was stale leaves out that gyro alone."""
    names = (*NAMES_IN, "yaw_rate_2")
    n = len(names)
    calibration = OnlineCalibration(config.vehicle, names, 0.01)
    rng = np.random.default_rng(1)
    first, second = math.radians(0.4), math.radians(-1.5)
    for k in range(6000):
        values = np.zeros(n)
        values[names.index("yaw_rate")] = first + math.radians(0.1) * rng.standard_normal()
        values[names.index("yaw_rate_2")] = second + math.radians(0.2) * rng.standard_normal()
        stale = np.array([name == "yaw_rate_2" and k % 100 == 7 for name in names])
        corrected = calibration.correct(Sample(k * 0.01, names, values, stale, np.ones(n, bool), np.zeros(n),
                                               np.zeros(n, bool)))
    learned, applied = dict(zip(NAMES, calibration.x)), dict(zip(NAMES, calibration.applied))
    assert learned["gyro_bias"] == pytest.approx(first, abs=math.radians(0.02))
    assert learned["gyro_bias_2"] == pytest.approx(second, abs=math.radians(0.03))
    assert applied["gyro_bias_2"] - applied["gyro_bias"] == pytest.approx(second - first, abs=math.radians(0.03))
    assert calibration.gyro_difference_std < math.radians(0.02)
    gyros = [names.index("yaw_rate"), names.index("yaw_rate_2")]
    assert abs(np.diff(corrected.values[gyros])[0]) < math.radians(0.8)  # one tick's noise, no bias between them
    assert 400 < calibration.updates["gyros"] < 540  # every block but the ones with a stale second gyro


def test_an_accelerometer_reading_high_in_acceleration_teaches_the_ax_offset_not_the_speed_scale(config):
    """A pitching car's ax reads a few percent above the wheels' dv/dt: the longitudinal identity learns the
    difference as the ax offset and leaves the speed scale (the kinematic identity's) alone."""
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    radius = config.vehicle.wheel_radius
    for k in range(3000):  # 30 s, 8 -> 38 m/s at 1 m/s^2 by the wheels, 1.03 m/s^2 by the accelerometer
        t = k * 0.01
        calibration.correct(sample(t, ax=1.03, wheel=(8.0 + t) / radius))
    assert calibration.updates["longitudinal"] > 200
    assert calibration.x[NAMES.index("speed")] == 1.0
    assert calibration.x[NAMES.index("ax_bias")] == pytest.approx(0.03, abs=0.01)


def test_a_block_with_a_stale_input_teaches_nothing(config):
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    for k in range(3000):
        calibration.correct(sample(k * 0.01, yaw_rate=0.05, stale=("ay",) if k % 10 == 3 else ()))
    assert sum(calibration.updates.values()) == 0
    assert np.array_equal(calibration.P, OnlineCalibration(config.vehicle, NAMES_IN, 0.01).P)


def test_the_speed_scale_is_learned_from_the_wheels_without_their_drive_slip(config):
    """With the motor torques mapped, a block's speed is the wheels' without the slip their torques need, as the
    estimator's reference speed takes it: ``R mean(w / (1 + (T / (R Fz) - f_r) / k))`` at the block's loads (the
    rolling moment's share ``f_r`` makes no slip)."""
    names = (*NAMES_IN, "motor_torque_fl", "motor_torque_fr", "motor_torque_rl", "motor_torque_rr")
    vehicle = config.vehicle
    blocks = BlockMeans(names, vehicle, 10)
    torques = np.array([150.0, 150.0, 250.0, 250.0])
    w = np.array([60.0, 61.0, 60.5, 61.5])
    values = np.array([0.0, 0.1, 2.0, 0.5, *w, *torques])
    n = len(names)
    block = None
    for k in range(10):
        block = blocks.add(Sample(k * 0.01, names, values, np.zeros(n, bool), np.ones(n, bool), np.zeros(n),
                                  np.zeros(n, bool)))
    loads = WheelGeometry(vehicle).loads(0.5, 2.0)
    usage = torques / (vehicle.wheel_radius * loads) - vehicle.tire.rolling_resistance
    slip = usage / vehicle.tire.longitudinal_stiffness
    assert block.wheel_speed == pytest.approx(vehicle.wheel_radius * np.mean(w / (1.0 + slip)), rel=1e-12)
    assert block.wheel_speed < vehicle.wheel_radius * w.mean() * (1.0 - 1e-4)  # the slip is taken out
    raw = BlockMeans(NAMES_IN, vehicle, 10)  # no torques mapped: the plain mean
    for k in range(10):
        block = raw.add(sample(k * 0.01, yaw_rate=0.1, ay=2.0, ax=0.5, wheel=60.0))
    assert block.wheel_speed == pytest.approx(vehicle.wheel_radius * 60.0, rel=1e-12)


# -- the state file ----------------------------------------------------------------------------------------------------

def test_state_round_trip_restores_values_and_inflates_the_variance(config, learned, tmp_path):
    calibration = learned[0].calibration
    store = CalibrationStore(tmp_path / "state" / "calibration.json")
    store.save(calibration.state())
    restarted = OnlineCalibration(config.vehicle, tuple(calibration.index), 0.01, store)
    assert np.allclose(restarted.x, calibration.x) and np.allclose(restarted.applied, calibration.applied)
    assert np.allclose(restarted.values, calibration.values)
    others = [i for i, name in enumerate(NAMES) if name not in ("understeer", "speed")]
    assert np.allclose(restarted.std[others] ** 2, RELOAD_INFLATION * calibration.std[others] ** 2)
    speed = NAMES.index("speed")  # and the tires' radius moved since: the published vx carries it from the start
    assert restarted.std[speed] ** 2 == pytest.approx(RELOAD_INFLATION * calibration.std[speed] ** 2 + RADIUS_DRIFT**2)
    assert restarted.correction_std[0] == pytest.approx(math.hypot(restarted.std[speed],
                                                                   restarted.x[speed] - restarted.applied[speed]))
    # saved as K_us with its variance, restored into u = k K_us without the covariance of k and u: wider
    understeer = NAMES.index("understeer")
    assert restarted.std[understeer] ** 2 >= RELOAD_INFLATION * calibration.std[understeer] ** 2
    assert np.allclose(restarted.evidence, calibration.evidence)


def test_a_state_that_applied_the_offsets_restores_them_learned_not_applied(config, learned, tmp_path):
    """An older canest applied the steering and lateral offsets once converged; this one never does (a bank)."""
    calibration = learned[0].calibration
    state = calibration.state()
    for name in ("ay_bias", "steering_offset"):
        state[name]["applied"] = state[name]["value"]
    store = CalibrationStore(tmp_path / "calibration.json")
    store.save(state)
    restarted = OnlineCalibration(config.vehicle, tuple(calibration.index), 0.01, store)
    for name in ("ay_bias", "steering_offset"):
        i = NAMES.index(name)
        assert restarted.x[i] == pytest.approx(calibration.x[i]) and restarted.x[i] != 0.0
        assert restarted.applied[i] == 0.0


def test_a_pipeline_saves_at_close_and_the_next_applies_the_corrections_at_once(config, learned, tmp_path):
    path = tmp_path / "calibration.json"
    estimator = dataclasses.replace(config.estimator, state_file=str(path))
    pipeline = Pipeline(dataclasses.replace(config, estimator=estimator))
    pipeline.calibration.restore(learned[0].calibration.state())
    assert not path.exists()
    pipeline.close()
    saved = json.loads(path.read_text())["parameters"]
    assert saved["speed"]["value"] == pytest.approx(learned[0].calibration.x[0])
    restarted = Pipeline(dataclasses.replace(config, estimator=estimator))
    assert np.allclose(restarted.calibration.applied, learned[0].calibration.applied)
    stiffness = [NAMES.index("front"), NAMES.index("rear")]
    assert restarted.calibration.converged[stiffness].all()  # the learned stiffnesses count at once
    assert restarted.calibration.stiffness == learned[0].calibration.stiffness
    # restored applied: its error (the saved variances inflated), not the claim
    claim = config.vehicle.cornering_stiffness_uncertainty
    assert learned[0].calibration.stiffness_error <= restarted.calibration.stiffness_error < claim


def test_save_is_atomic_a_failed_rename_keeps_the_old_state_and_leaves_no_temporary(config, tmp_path, monkeypatch):
    path = tmp_path / "calibration.json"
    store = CalibrationStore(path)
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    store.save(calibration.state())
    old = path.read_text()
    renames = []

    def failing_replace(source, target):
        renames.append((os.path.dirname(source), os.fspath(target)))
        raise OSError("disk gone")

    monkeypatch.setattr(os, "replace", failing_replace)
    calibration.x[0] = 1.1
    assert store.save(calibration.state()) is False and store.failed_saves == 1  # warned, never raised
    assert path.read_text() == old and sorted(p.name for p in tmp_path.iterdir()) == ["calibration.json"]
    assert renames == [(str(tmp_path), str(path))]  # written beside the target: the rename cannot cross a filesystem
    monkeypatch.undo()
    assert store.save(calibration.state()) is True and json.loads(path.read_text()) != json.loads(old)


def test_a_state_file_the_disk_refuses_is_warned_about_and_the_replay_goes_on(drive, tmp_path):
    """A full or read-only disk ended the daemon (exit 74) at its first save, mid-drive; /proc takes no folder."""
    log, state = tmp_path / "drive.log", Path("/proc/canest-test/calibration.json")
    drive.write_log(log)
    result = subprocess.run([sys.executable, "-m", "canest", "replay", str(log), "--config", str(CONFIG),
                             "--state-file", str(state), "--json", "--csv", str(tmp_path / "estimates.csv")],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stderr.count(f"cannot save the calibration state to {state}") == 1, result.stderr
    summary = json.loads(result.stdout)
    assert summary["state_save_failures"] >= 1
    rows = (tmp_path / "estimates.csv").read_text().splitlines()
    assert float(rows[-1].split(",")[0]) > drive.truth["t"][-1] - 0.1  # estimated to the drive's end


def test_a_state_of_an_older_canest_restores_what_it_holds_and_the_rest_starts_from_its_prior(config, learned,
                                                                                             tmp_path, caplog):
    """A state file written before the stiffnesses were learned: the car keeps what it learned."""
    path = tmp_path / "calibration.json"
    state = learned[0].calibration.state()
    older = {name: entry for name, entry in state.items() if name not in ("front", "rear")}
    CalibrationStore(path).save(older)
    with caplog.at_level(logging.INFO, logger="canest"):
        restarted = OnlineCalibration(config.vehicle, tuple(learned[0].calibration.index), 0.01, CalibrationStore(path))
    restored = ", ".join(older)
    assert [r.getMessage() for r in caplog.records] == [
        f"{path} holds no front, rear (written by an older canest): learning them from their prior",
        f"restored the calibration state from {path} ({restored}), variances widened {RELOAD_INFLATION:g}x"]
    front, speed = NAMES.index("front"), NAMES.index("speed")
    assert restarted.x[speed] == pytest.approx(state["speed"]["value"]) and restarted.evidence[speed] > 0.0
    assert restarted.x[front] == 1.0 and restarted.std[front] == pytest.approx(restarted.specs[front].std)
    assert restarted.evidence[front] == 0.0 and restarted.applied[front] == 1.0


@pytest.mark.parametrize("text, reason", [
    ("{not json", "Expecting property name"),
    ('{"version": 1, "parameters": []}', "no 'parameters' object"),
    ('{"version": 7, "parameters": {}}', "not a version 1"),
    ('{"version": 1, "parameters": {"wheelbase": {}}}', "no parameter canest learns"),
    ("speed=9", "outside its bounds"),
    ("gyro_bias=nan", "lacks a finite"),
])
def test_a_corrupt_or_implausible_state_is_ignored_with_one_warning_naming_the_file(config, tmp_path, caplog, text,
                                                                                     reason):
    path = tmp_path / "calibration.json"
    if "=" in text:
        name, value = text.split("=")
        state = OnlineCalibration(config.vehicle, NAMES_IN, 0.01).state()
        state[name]["value"] = float(value)
        CalibrationStore(path).save(state)
    else:
        path.write_text(text)
    with caplog.at_level(logging.WARNING, logger="canest"):
        calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01, CalibrationStore(path))
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and str(path) in warnings[0] and reason in warnings[0], warnings
    assert np.array_equal(calibration.x, np.array([p.start for p in parameters(config.vehicle)]))


def test_a_file_that_is_no_calibration_state_is_kept_aside_and_never_written_over(config, tmp_path, caplog):
    """A config named as the state file by mistake survives as ``NAME.unreadable`` (the next one ``.unreadable.1``);
    a canest state with implausible values is the learner's own and is replaced."""
    path = tmp_path / "calibration.json"
    for kept, text in (("calibration.json.unreadable", "vehicle:\n  mass: 1845\n"),
                       ("calibration.json.unreadable.1", '{"version": 7, "parameters": {}}')):
        path.write_text(text)
        with caplog.at_level(logging.WARNING, logger="canest"):
            calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01, CalibrationStore(path))
            calibration.close()
        assert (tmp_path / kept).read_text() == text
        assert any(f"kept it as {tmp_path / kept}" in r.getMessage() for r in caplog.records)
        assert json.loads(path.read_text())["version"] == 1
    state = OnlineCalibration(config.vehicle, NAMES_IN, 0.01).state()
    state["speed"]["value"] = 9.0
    CalibrationStore(path).save(state)
    OnlineCalibration(config.vehicle, NAMES_IN, 0.01, CalibrationStore(path)).close()
    assert json.loads(path.read_text())["parameters"]["speed"]["value"] == 1.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calibration.json", "calibration.json.unreadable",
                                                         "calibration.json.unreadable.1"]


# -- config ------------------------------------------------------------------------------------------------------------

def write_config(tmp_path, estimator: dict):
    return write_variant(tmp_path, lambda data: data["estimator"].update(estimator))


def test_config_defaults_learn_without_a_state_file(config):
    assert config.estimator.online_calibration is True and config.estimator.state_file is None


def test_config_state_file_is_relative_to_the_config(tmp_path):
    config = load_config(write_config(tmp_path, {"state_file": "calibration.json", "online_calibration": False}))
    assert config.estimator.state_file == str(tmp_path / "configs" / "calibration.json")
    assert config.estimator.online_calibration is False
    assert not Pipeline(config).calibration.enabled


@pytest.mark.parametrize("estimator, message", [
    ({"online_calibration": "yes"}, r"estimator\.online_calibration: must be true or false, got 'yes'"),
    ({"state_file": 3}, r"estimator\.state_file: must be a text, got 3"),
    ({"state_file": " "}, r"estimator\.state_file: must name a file"),
    ({"state_file": "."}, r"estimator\.state_file: .* is a directory"),
])
def test_config_rejects_bad_calibration_keys_naming_file_line_and_key(tmp_path, estimator, message):
    with pytest.raises(ConfigError, match=r"car\.yaml:\d+: " + message):
        load_config(write_config(tmp_path, estimator))


# -- command line and service -----------------------------------------------------------------------------------------

def test_replay_state_file_option_learns_and_saves(drive, tmp_path):
    from canest.cli import main
    log, state = tmp_path / "drive.log", tmp_path / "state" / "calibration.json"
    drive.write_log(log)
    with pytest.raises(SystemExit) as exit_status:
        main(["replay", str(log), "--config", str(CONFIG), "--state-file", str(state), "--quiet"])
    assert exit_status.value.code in (0, None)
    saved = json.loads(state.read_text())["parameters"]
    assert saved["speed"]["value"] == pytest.approx(WRONG.wheel_radius_scale, abs=0.01)
    assert saved["speed"]["evidence"] > 10.0


@pytest.mark.parametrize("command", ["replay", "run"])
def test_a_state_file_naming_an_input_or_a_folder_is_refused_before_anything_is_written(drive, tmp_path, command):
    """The state file is written over: naming the config (or the replayed log) by it would destroy it."""
    log = tmp_path / "drive.log"
    drive.write_log(log)
    config = tmp_path / "car.yaml"
    config.write_text(CONFIG.read_text())  # its DBCs are built in
    before = config.read_bytes()
    first = [command, str(log)] if command == "replay" else [command]
    for state, status, says in ((config, 2, "that is the config"), (tmp_path, 73, "that is a folder")):
        result = subprocess.run([sys.executable, "-m", "canest", *first, "--config", str(config), "--state-file",
                                 str(state), "--quiet" if command == "replay" else "--log-level=ERROR"],
                                capture_output=True, text=True, timeout=120, cwd=ROOT)
        assert result.returncode == status and says in result.stderr and "--state-file" in result.stderr, \
            result.stderr
    assert config.read_bytes() == before
    replayed = subprocess.run([sys.executable, "-m", "canest", "replay", str(log), "--config", str(config),
                               "--state-file", str(log), "--quiet"], capture_output=True, text=True, timeout=120,
                              cwd=ROOT)
    assert replayed.returncode == 2 and "that is the input log" in replayed.stderr


def test_run_takes_a_state_file_and_the_units_keep_it_in_their_state_directory():
    from canest.cli import build_parser
    args = build_parser().parse_args(["run", "--state-file", "/var/lib/canest/calibration.json"])
    assert args.state_file == "/var/lib/canest/calibration.json"
    units = Path(__file__).resolve().parents[1] / "tools" / "systemd"
    for unit, directory in (("canest.service", "canest"), ("canest@.service", "canest/%i")):
        text = (units / unit).read_text()
        assert f"\nStateDirectory={directory}\n" in text
        assert f"--state-file %S/{directory}/calibration.json" in text


def synthetic_drive(calibration, vehicle, start, seconds, ay_error=0.0, car=None, gyro_bias=0.0, straight=0.0,
                    drift=0.0):
    """Gentle bends both ways at 15-25 m/s on a flat road from ``start`` s (the first ``straight`` s straight, or
    turning at ``drift`` rad/s), the sensors exact but ay (``ay_error``) and the gyro (``gyro_bias``); the steering
    of ``car`` (steering_offset, ratio scale, understeer gradient; default the config's)."""
    offset, ratio, understeer = car or (0.0, 1.0, vehicle.understeer_gradient)
    for k in range(int(round(seconds / 0.01))):
        t = start + k * 0.01
        v = 20.0 + 5.0 * math.sin(2.0 * math.pi * t / 45.0)
        r = 0.1 * math.sin(2.0 * math.pi * t / 30.0) if t >= straight else drift
        swa = identities.steady_steering_wheel_angle(v, r, v * r, offset, ratio * vehicle.steering_ratio,
                                                     vehicle.wheelbase, understeer)
        ax = 5.0 * 2.0 * math.pi / 45.0 * math.cos(2.0 * math.pi * t / 45.0)  # dv/dt
        calibration.correct(sample(t, swa, r + gyro_bias, v * r + ay_error, ax, v / vehicle.wheel_radius))


def test_steering_ratio_and_understeer_are_learned_while_the_gyro_bias_still_is(config):
    """A gyro bias not yet learned reads as steering (0.5 deg/s: 1.2 deg at 20 m/s); taken as known, it was learned
    as ratio and understeer, and their growing confidence then gated out the bends (here: ratio -16 %, understeer
    of the wrong sign, 524 of 823 steering updates gated; ratio -28 % on the simulator).
    Considered (its uncertainty counted) and with the identity linear in what it learns, the bends teach them."""
    car = (math.radians(1.5), 1.08, 4.0 * config.vehicle.understeer_gradient)
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    synthetic_drive(calibration, config.vehicle, 0.0, 120.0, car=car, gyro_bias=math.radians(0.5), straight=30.0)
    learned = dict(zip(NAMES, calibration.values))
    std = dict(zip(NAMES, calibration.std))
    print({name: (round(float(learned[name]), 5), round(float(std[name]), 5)) for name in NAMES})
    assert learned["ratio"] == pytest.approx(car[1], rel=0.03)
    assert learned["understeer"] == pytest.approx(car[2], rel=0.1)
    assert learned["steering_offset"] == pytest.approx(car[0], abs=math.radians(0.2))
    assert calibration.updates["gated"] == 0
    for name, true in (("ratio", car[1]), ("understeer", car[2]), ("steering_offset", car[0])):
        assert abs(learned[name] - true) < 3.0 * std[name], name  # as certain as it says


def test_a_gentle_bend_below_the_bends_threshold_leaves_the_ratios_error_in_the_offsets_std(config):
    """30 s turning at 0.86 deg/s (``v r`` 0.2-0.4 m/s^2, below ``MIN_BEND_AY``: as a car drifting on a banked
    road's straight) put the prior's ratio and understeer error, 1.8 deg, into the steering offset; with them
    taken as known its std left that out (7.8 std off on the simulator's banked road of seed 9, where it then
    gated out every window fit). Considered, the std holds it and the bends that follow correct the offset."""
    car = (math.radians(1.5), 1.08, 4.0 * config.vehicle.understeer_gradient)
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    synthetic_drive(calibration, config.vehicle, 0.0, 30.0, car=car, straight=30.0, drift=0.015)
    offset = NAMES.index("steering_offset")
    error = calibration.x[offset] - car[0]
    assert abs(error) > math.radians(1.0)  # the prior's ratio and understeer are in it
    assert abs(error) < 3.0 * calibration.std[offset]  # and in its std
    synthetic_drive(calibration, config.vehicle, 30.0, 90.0, car=car, straight=30.0)
    learned = dict(zip(NAMES, calibration.values))
    assert learned["steering_offset"] == pytest.approx(car[0], abs=math.radians(0.2))
    assert learned["ratio"] == pytest.approx(car[1], rel=0.03)
    assert calibration.updates["gated"] == 0


def test_one_maneuver_of_wrong_ay_barely_moves_a_learned_offset(config):
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    synthetic_drive(calibration, config.vehicle, 0.0, 120.0)
    ay_bias = NAMES.index("ay_bias")
    before = calibration.x[ay_bias]
    assert abs(before) < 0.01 and calibration.converged[ay_bias]
    synthetic_drive(calibration, config.vehicle, 120.0, 5.0, ay_error=0.25)  # a maneuver's worth, not a bias
    moved = calibration.x[ay_bias] - before
    assert 0.0 < moved < 0.1, moved  # measured 0.086: the offset and the gyro bias share what v barely tells apart


def test_accelerometers_that_roll_with_the_body_are_read_level_before_the_speed_scale_is_learned(config):
    """Rolling 4 deg/g and pitching 2 deg/g with the body: unknown, the kinematic identity learns the roll as a 7 %
    larger wheel (vx 1.4 m/s off, README "Online calibration"); with the config's gradients each sample is read
    level first and the scale is the wheel's."""
    tilted = dataclasses.replace(WRONG, bank=0.0, roll_gradient=4.0, pitch_gradient=2.0)
    drive = simulate(config, "country", 80.0, 0.85, duration=40.0, seed=3, mismatch=tilted)
    aware = dataclasses.replace(config, vehicle=dataclasses.replace(
        config.vehicle, accelerometer_roll_gradient=4.0, accelerometer_pitch_gradient=2.0))
    learned = {}
    for name, told in (("unaware", config), ("aware", aware)):
        pipeline = Pipeline(told)
        for frame in drive.frames:
            pipeline.feed(frame)
        learned[name] = pipeline.calibration.x[NAMES.index("speed")]
    assert learned["aware"] == pytest.approx(WRONG.wheel_radius_scale, abs=0.01)
    assert learned["unaware"] > WRONG.wheel_radius_scale + 0.04


def test_an_imu_that_vibrates_as_a_real_cars_teaches_nothing_more_certainly_than_it_knows(config):
    """The simulator's ``vibration 1`` (the issue's real car: ay 1.4 m/s^2 RMS in a 10 Hz band, road spikes) on a
    flat road. Each block's ay mean then scatters 0.77 m/s^2 against the configured 0.1: learned as if quiet, the
    speed scale came out 1.086 +- 0.007 (true 1.03), the ratio 0.66, the understeer gradient 0, the gyro bias
    -0.33 deg/s (0.5) and the front stiffness at its bound, most of them flagged converged. Each identity's noise is
    now the spread its innovations show, the steering identity's bend is ``v r`` (not the vibrating ay), and the
    window fit chooses its ticks by ``v r``: every value is within 3 std of the truth, and the offsets and the
    speed scale are learned, however slowly (the stiffnesses are not, in 60 s)."""
    level = dataclasses.replace(WRONG, bank=0.0)
    drive = simulate(config, "country", 80.0, 0.85, duration=SECONDS, seed=3, mismatch=level, vibration=1.0)
    pipeline = Pipeline(config)
    for frame in drive.frames:
        pipeline.feed(frame)
    calibration = pipeline.calibration
    true = {"speed": level.wheel_radius_scale, "gyro_bias": level.gyro_bias, "ay_bias": level.ay_bias,
            "steering_offset": level.steering_offset, "ratio": level.steering_ratio_scale,
            "understeer": true_vehicle(config.vehicle, level).understeer_gradient,
            "ax_bias": DEFAULT_SENSORS["ax"].bias, "front": level.stiffness_scale_front,
            "rear": level.stiffness_scale_rear, "gyro_bias_2": level.biases()["gyro_bias_2"]}
    values, std = dict(zip(NAMES, calibration.values)), dict(zip(NAMES, calibration.std))
    print({name: (round(float(values[name]), 5), round(float(std[name]), 5)) for name in NAMES})
    assert calibration.updates["kinematic"] > 200 and calibration.updates["gated"] < 0.05 * sum(
        calibration.updates[kind] for kind in ("kinematic", "steering", "longitudinal"))
    for name in NAMES:
        assert abs(values[name] - true[name]) < 3.0 * std[name], name
    prior = dict(zip(NAMES, (spec.std for spec in calibration.specs)))
    for name in ("speed", "ay_bias", "steering_offset", "ax_bias"):  # learned, however slowly
        assert std[name] < 0.8 * prior[name], name


def test_an_outlier_is_gated_against_the_noise_measured_before_it_and_widens_that_noise_only_to_the_gate(config):
    """The noise an update uses is measured from the innovations before it, and an innovation enters that
    measurement clipped at the gate: taken in whole and first, a 50 sigma pothole widened its own gate (never
    gated) and the noise for the next 20 s."""
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    ay = NAMES.index("ay_bias")
    H = np.zeros(len(NAMES))
    H[ay] = 1.0
    for z in np.random.default_rng(0).normal(0.0, 0.5, 40):  # an ay five times noisier than configured
        calibration._update(float(z), float(calibration.x[ay]), H, 0.1, "kinematic")
    measured = calibration.spread["kinematic"].noise()
    assert 0.5 * 0.25 < measured < 2.0 * 0.25
    before, gated = calibration.x.copy(), calibration.updates["gated"]
    calibration._update(50.0, float(calibration.x[ay]), H, 0.1, "kinematic")
    assert calibration.updates["gated"] == gated + 1 and np.array_equal(calibration.x, before)
    assert calibration.spread["kinematic"].noise() < 3.0 * measured


def test_the_innovations_correlation_is_measured_between_consecutive_blocks_only():
    """Innovations equal in pairs of consecutive blocks, the pairs a second apart and of alternating sign: the
    noise is as correlated as it gets; paired across the gaps, it read as uncorrelated."""
    spread, a = InnovationSpread(), 0.3
    for pair in range(20):
        for block in range(2):
            spread.add((-1) ** pair * a, 0.0, 10.0, pair * 1.0 + block * 0.1)
    assert spread.noise() == pytest.approx(a * a * (1 + MAX_CORRELATION) / (1 - MAX_CORRELATION))


def test_at_a_slow_tick_rate_consecutive_blocks_are_still_paired(config):
    """At 5 Hz a block is one 0.2 s tick: paired by BLOCK's 0.1 s, no two innovations ever were."""
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.2)
    spread, a = calibration.spread["kinematic"], 0.3
    for k in range(20):
        spread.add(a, 0.0, 10.0, k * 0.2)  # the same error in every block: as correlated as it gets
    assert spread.pairs == 19


def test_a_parameter_the_window_tells_no_better_than_the_prior_is_left_out(config):
    """At a constant speed the fit knows the gyro bias, c and the steering offset only as a combination (stds of
    8 deg/s, 3.1 m/s^2 and 42 deg on a 45 s sine steer): taken whole, that combination carried the learner's
    error in one of them into the others."""
    calibration = OnlineCalibration(config.vehicle, NAMES_IN, 0.01)
    fit = window_fit(0.7, 1.3, gyro_bias=0.03, ay_bias=0.8, steering_offset=0.16)
    loose = [FITTED.index(name) for name in ("steering_offset", "gyro_bias", "ay_bias")]
    std = np.sqrt(np.diag(fit.covariance))
    std[loose] = [0.73, 0.14, 3.1]
    correlation = np.eye(len(FITTED))
    correlation[np.ix_(loose, loose)] = 0.999
    np.fill_diagonal(correlation, 1.0)
    calibration._window_update(WindowFit(FITTED, fit.values, correlation * np.outer(std, std), WINDOW))
    for name in ("steering_offset", "gyro_bias", "ay_bias"):
        i = NAMES.index(name)
        assert calibration.x[i] == 0.0 and calibration.evidence[i] == 0.0, name
    for name in ("front", "rear", "ratio", "speed"):
        assert calibration.evidence[NAMES.index(name)] == WINDOW, name


@pytest.mark.parametrize("filter_name, learned", [("ckf", True), ("jckf", False), ("dici-gfckf", False)])
def test_the_learned_stiffness_error_replaces_the_claim_for_linear_tires_only(config, filter_name, learned):
    """Linear tires' sideslip term is the stiffness's error, which the learner measures; a tire curve's term also
    stands for its shape, the longitudinal slip stiffness and the nominal friction (the forces' process noise,
    the frictions' term), which it does not: those models keep the config's claim."""
    from canest.apps.compare import with_filter
    from canest.estimation import validity

    pipeline = Pipeline(with_filter(config, filter_name))
    try:
        estimator, claim = pipeline.estimator, config.vehicle.cornering_stiffness_uncertainty
        estimator.use_stiffness(0.9, 1.1, None)
        claimed = validity.sideslip_model_std(estimator.judge.vehicle, 4.0)
        assert estimator.vehicle.cornering_stiffness_uncertainty == claim
        estimator.use_stiffness(0.9, 1.1, 0.05)
        vehicle = estimator.judge.vehicle
        assert vehicle is estimator.vehicle and vehicle.cornering_stiffness_rear == pytest.approx(
            1.1 * config.vehicle.cornering_stiffness_rear)
        assert vehicle.cornering_stiffness_uncertainty == (0.05 if learned else claim)
        assert (validity.sideslip_model_std(vehicle, 4.0) < claimed) == learned
    finally:
        pipeline.close()


def test_a_second_gyro_far_off_is_learned_against_the_first_and_the_yaw_rate_is_valid_again(config):
    """An airbag unit's gyro 2 deg/s off (ten times its configured noise): the two gyros disagree, and until the
    learner corrects the second the yaw rate reads ``inconsistent``, honestly; the learner finds their difference
    within 30 s and corrects the second gyro to agree with the first as applied; from then on the yaw rate is valid
    and within its std (:meth:`OnlineCalibration._gyros_update`, ``_follow``). Measured: valid from 49 s of this
    60 s road, the applied correction 0.01 deg/s from the true difference."""
    bias = math.radians(2.0)
    drive = simulate(config, "country", 80.0, 0.85, duration=60.0, seed=3, mismatch=PlantMismatch(gyro_bias_2=bias))
    pipeline = Pipeline(config)
    estimates = [e for frame in drive.frames for e in pipeline.feed(frame)]
    early = [e for e in estimates if 5.0 < e.t - estimates[0].t < 20.0]
    assert all(e.causes["yaw_rate"] == "inconsistent" for e in early)  # the premise: the gyros disagree
    calibration = pipeline.calibration
    applied = dict(zip(NAMES, calibration.applied))
    difference = bias - PlantMismatch().biases()["gyro_bias"]  # the second gyro's bias less the first's
    assert applied["gyro_bias_2"] - applied["gyro_bias"] == pytest.approx(difference, abs=math.radians(0.05))
    assert calibration.updates["gyros"] > 400
    late = [e for e in estimates if e.t - estimates[0].t > 52.0]
    assert len(late) > 700 and all(e.valid["yaw_rate"] for e in late)
    truth = np.interp([e.t for e in late], drive.truth["t"], drive.truth["yaw_rate"])
    error = np.abs(np.array([e.values["yaw_rate"] for e in late]) - truth)
    assert np.mean(error < 2.0 * np.array([e.values["yaw_rate_std"] for e in late])) > 0.9
