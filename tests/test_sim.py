"""The simulator's launch maneuver (longitudinal excitation bounded by traction control), friction jump and drawn cars."""
import dataclasses
import math

import numpy as np
import pytest

from canest.commands.simulate import parse_mu_jump
from canest.errors import SimulationError
from canest.signals import WHEELS
from canest.sim.maneuvers import Driver
from canest.models.attitude import level_reading, per_si, tilted_reading
from canest.models.wheels import GRAVITY
from canest.sim.mismatch import (DRAWN_AY_BIAS, DRAWN_GYRO_BIAS, RADIUS_SCALE_LIMITS, STIFFNESS_SCALE_LIMITS,
                                  PlantMismatch, drawn_mismatch)
from canest.sim.simulate import simulate


@pytest.mark.parametrize("mu", [0.85, 0.35])
def test_launch_reaches_the_tire_limit_only_on_low_friction(config, mu):
    truth = simulate(config, "launch", 40.0, mu, seed=1).truth
    slip = np.array([truth[f"kappa_{w}"] for w in WHEELS])
    usage = np.array([np.hypot(truth[f"fx_{w}"], truth[f"fy_{w}"]) / (mu * truth[f"fz_{w}"]) for w in WHEELS])
    assert truth["ax"].max() == pytest.approx(min(6.0, 0.95 * mu * 9.81), rel=0.12)
    if mu < 0.5:  # at the limit: traction control takes over and holds the slip
        assert usage.max() > 0.85 and Driver.TRACTION_SLIP < slip.max() < 0.2
    else:  # below the road's limit: traction control never acts
        assert slip.max() < Driver.TRACTION_SLIP and usage.max() < 0.95
    assert np.all(np.abs(truth["yaw_rate"]) < 1e-3)  # straight


def test_friction_jump_changes_the_road_at_its_time(config):
    truth = simulate(config, "sine", 60.0, 0.85, duration=3.0, mu_jump=(1.5, [0.85, 0.3, 0.85, 0.3])).truth
    before, after = truth["t"] < 1.5, truth["t"] >= 1.5
    assert np.all(truth["mu_fl"] == 0.85) and np.all(truth["mu_fr"][before] == 0.85)
    assert np.all(truth["mu_fr"][after] == 0.3) and np.all(truth["mu_rr"][after] == 0.3)


def test_friction_jump_option_is_checked():
    with pytest.raises(ValueError, match="--mu-jump: expected T:MU"):
        parse_mu_jump("six:0.3")
    with pytest.raises(ValueError, match="--mu-jump: expected one or four values"):
        parse_mu_jump("6:2.5")
    with pytest.raises(ValueError, match=r"--mu-jump: expected T:MU with T >= 0 s"):
        parse_mu_jump("nan:0.3")
    assert parse_mu_jump("6:0.35") == (6.0, 0.35)


def test_a_friction_jump_after_the_drive_is_refused_not_silently_skipped(config):
    with pytest.raises(SimulationError, match="friction jump at 6 s is not within the drive's 5 s"):
        simulate(config, "sine", 60.0, 0.85, duration=5.0, mu_jump=(6.0, 0.3))


def test_a_drawn_car_is_as_wrong_as_its_config_admits(config):
    """The honesty grid's ``--car drawn``: per seed one car, its axles' cornering stiffnesses spread by the config's
    ``cornering_stiffness_uncertainty``, its accelerometer and gyro biased as production sensors are."""
    cars = [drawn_mismatch(config.vehicle, seed) for seed in range(400)]
    assert drawn_mismatch(config.vehicle, 7) == cars[7] and cars[7] != cars[8]
    for axle in ("front", "rear"):
        scales = np.array([getattr(car, f"stiffness_scale_{axle}") for car in cars])
        assert np.mean(scales) == pytest.approx(1.0, abs=0.03)
        assert np.std(scales) == pytest.approx(config.vehicle.cornering_stiffness_uncertainty, rel=0.15)
        assert np.all((STIFFNESS_SCALE_LIMITS[0] <= scales) & (scales <= STIFFNESS_SCALE_LIMITS[1]))
    assert np.std([car.ay_bias for car in cars]) == pytest.approx(DRAWN_AY_BIAS, rel=0.15)
    assert np.std([car.gyro_bias for car in cars]) == pytest.approx(DRAWN_GYRO_BIAS, rel=0.15)
    claimed = [drawn_mismatch(config.vehicle, seed, math.radians(0.5)).gyro_bias for seed in range(400)]
    assert np.std(claimed) == pytest.approx(math.hypot(DRAWN_GYRO_BIAS, math.radians(0.5)), rel=0.15)
    scale = math.hypot(DRAWN_GYRO_BIAS, math.radians(0.5)) / DRAWN_GYRO_BIAS
    assert np.allclose(claimed, scale * np.array([car.gyro_bias for car in cars]))  # the same draws, scaled
    assert all(car.wheel_radius_scale == 1.0 for car in cars)  # the config claims its radius exact
    tire_sized = dataclasses.replace(config.vehicle, wheel_radius_uncertainty=0.02)
    radii = np.array([drawn_mismatch(tire_sized, seed).wheel_radius_scale for seed in range(400)])
    assert np.std(radii) == pytest.approx(0.02, rel=0.15) and abs(np.mean(radii) - 1.0) < 0.004
    assert drawn_mismatch(tire_sized, 7) == dataclasses.replace(cars[7], wheel_radius_scale=radii[7])  # same draws
    vague = dataclasses.replace(config.vehicle, wheel_radius_uncertainty=0.2)
    radii = np.array([drawn_mismatch(vague, seed).wheel_radius_scale for seed in range(400)])
    assert radii.min() == RADIUS_SCALE_LIMITS[0] and radii.max() == RADIUS_SCALE_LIMITS[1]  # what a calibration finds
    front = np.array([car.stiffness_scale_front for car in cars])
    rear = np.array([car.stiffness_scale_rear for car in cars])
    assert abs(np.corrcoef(front, rear)[0, 1]) < 0.15  # the two axles' tires are off independently
    plant = simulate(config, "step", 60.0, 0.85, duration=2.0, mismatch=cars[0]).truth
    exact = simulate(config, "step", 60.0, 0.85, duration=2.0).truth
    assert not np.allclose(plant["beta"], exact["beta"])  # the drawn car drives differently


def test_accelerometers_on_the_body_read_its_roll_and_pitch_as_gravity(config):
    """A body rolling 4 deg/g reads a 0.5 g bend 7 % high, in either bend; read level again exactly; the plant
    drives as before, only its accelerometers read differently (the config's tilt unless the car says)."""
    roll = per_si(4.0)
    ay = tilted_reading(0.5 * GRAVITY, roll)
    assert ay == pytest.approx(0.5 * GRAVITY * 1.069, rel=1e-3)
    assert tilted_reading(-0.5 * GRAVITY, roll) == pytest.approx(-ay)
    assert tilted_reading(2.0, per_si(2.0)) == pytest.approx(2.0 * (1.0 + math.radians(2.0)), rel=1e-3)
    readings = np.linspace(-12.0, 12.0, 49)
    for gradient in (per_si(4.0), per_si(15.0)):
        assert np.allclose(tilted_reading(level_reading(readings, gradient), gradient), readings, atol=1e-3)
    tilted = simulate(config, "step", 60.0, 0.85, duration=2.0, noise_scale=0.0,
                      mismatch=PlantMismatch(roll_gradient=4.0, pitch_gradient=2.0))
    level = simulate(config, "step", 60.0, 0.85, duration=2.0, noise_scale=0.0)
    assert np.array_equal(tilted.truth["ay"], level.truth["ay"])
    assert [f.data for f in tilted.frames] != [f.data for f in level.frames]
    rolling = dataclasses.replace(config, vehicle=dataclasses.replace(config.vehicle, accelerometer_roll_gradient=4.0))
    assert [f.data for f in simulate(rolling, "step", 60.0, 0.85, duration=2.0, noise_scale=0.0).frames] != \
        [f.data for f in level.frames]  # the config's tilt, when the car does not say otherwise


def test_a_road_grade_slows_the_car_by_gravity_that_its_accelerometer_reads(config):
    """Uphill at 6 % the accelerometer, reading the tires' force, shows ``g sin(grade)`` more than the speed's change
    (straight ahead: no ``r vy``); the speed controller then holds the speed with the force gravity's pull needs."""
    grade = math.atan(0.06)
    truth = simulate(config, "step", 80.0, 0.85, duration=6.0, amplitude_deg=0.0,
                     mismatch=PlantMismatch(grade=grade)).truth
    unseen = truth["ax"] - np.gradient(truth["vx"], truth["t"])
    assert unseen[5:-5] == pytest.approx(GRAVITY * math.sin(grade), abs=0.01)
    assert truth["vx"][-1] == pytest.approx(80.0 / 3.6, abs=0.3)


def test_the_grade_option_is_checked():
    from canest.commands.simulate import parse_mismatch
    from canest.cli import build_parser
    args = build_parser().parse_args(["simulate", "--out", "x.log", "--truth", "x.csv", "--grade", "40"])
    with pytest.raises(ValueError, match="--grade: percent from -30 to 30, got 40"):
        parse_mismatch(args)
    args.grade = 6.0
    assert parse_mismatch(args).grade == pytest.approx(math.atan(0.06))
