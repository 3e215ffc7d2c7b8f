"""The learned zero of a relative steering angle (canest/estimation/steering_zero.py)."""
import math

import numpy as np
import pytest

from canest.config import load_config
from canest.estimation import steering_zero as sz
from canest.estimation.inputs import TickInputs
from canest.resample import Sample
from tests.conftest import CONFIG

NAMES = ("steering_wheel_angle", "yaw_rate", "ay", "wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr")
OFFSET = math.radians(62.0)


def tick(t, angle, yaw_rate, ay, speed, radius):
    n = len(NAMES)
    values = np.array([angle, yaw_rate, ay, *([speed / radius] * 4)])
    return TickInputs(Sample(t, NAMES, values, np.zeros(n, bool), np.ones(n, bool), np.zeros(n), np.zeros(n, bool)))


@pytest.fixture()
def learner():
    config = load_config(CONFIG)
    return sz.SteeringZero(config.vehicle, 0.01), config.vehicle


def drive(learner, vehicle, seconds, yaw_rate=0.0, speed=20.0, noise=math.radians(0.5), seed=0, start=0.0):
    """Ticks of steady driving: the angle the model needs for ``yaw_rate``, plus OFFSET and sensor noise."""
    rng = np.random.default_rng(seed)
    needed = vehicle.steering_ratio * yaw_rate * (vehicle.wheelbase + vehicle.understeer_gradient * speed ** 2) / speed
    angles = []
    for k in range(int(seconds * 100)):
        angle = needed + OFFSET + rng.normal(0, noise)
        angles.append(learner.angle(tick(start + 0.01 * k, angle, yaw_rate, 0.0, speed, vehicle.wheel_radius)))
    return np.array(angles)


def test_learned_from_straight_driving_within_a_fraction_of_a_degree(learner):
    zero, vehicle = learner
    drive(zero, vehicle, 1.0)
    assert not zero.learned  # not before LEARN_TIME of straight driving
    angles = drive(zero, vehicle, 2.0, start=1.0)
    assert zero.learned and abs(zero.zero - OFFSET) < math.radians(0.2)
    assert abs(np.mean(angles[-50:])) < math.radians(0.3)  # the corrected angle reads straight ahead


def test_gentle_curves_teach_the_same_zero_and_sharp_ones_nothing(learner):
    zero, vehicle = learner
    drive(zero, vehicle, 3.0, yaw_rate=math.radians(2.0))  # the model's steering for the curve is taken out
    assert zero.learned and abs(zero.zero - OFFSET) < math.radians(0.2)
    fresh = sz.SteeringZero(vehicle, 0.01)
    drive(fresh, vehicle, 3.0, yaw_rate=math.radians(10.0))
    drive(fresh, vehicle, 3.0, speed=3.0)  # too slow to tell
    assert fresh.zero is None and not fresh.learned
    assert fresh.angle(tick(10.0, OFFSET, 0.0, 5.0, 20.0, vehicle.wheel_radius)) == 0.0  # straight ahead until a sample


def test_learned_zero_follows_slowly_and_boundedly(learner):
    zero, vehicle = learner
    drive(zero, vehicle, 3.0)
    learned = zero.zero
    for k in range(100):  # one second of a wildly wrong angle while driving straight (a sensor glitch)
        zero.angle(tick(3.0 + 0.01 * k, OFFSET + math.radians(90), 0.0, 0.0, 20.0, vehicle.wheel_radius))
    moved = zero.zero - learned
    assert 0 < moved <= sz.MAX_PULL * 1.0 / sz.FOLLOW_TIME + 1e-12


def test_one_sample_per_tick(learner):
    zero, vehicle = learner
    inputs = tick(0.0, OFFSET, 0.0, 0.0, 20.0, vehicle.wheel_radius)
    for _ in range(5):
        zero.angle(inputs)
    assert zero.count == 1


def test_an_absolute_angle_keeps_its_dbc_zero():
    config = load_config(CONFIG)
    fixed = sz.steering_zero(config)
    assert fixed.learned and fixed.angle(tick(0.0, 0.3, 0.0, 0.0, 20.0, 0.3)) == 0.3
