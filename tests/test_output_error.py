"""The output-error fit's model (canest/models/output_error.py) against the same linear single track integrated
finely with its steering moving between the samples, as a driver's does."""
import dataclasses
import math

import numpy as np
import pytest

from canest.calibration import SHARED, Fit
from canest.config import load_config
from canest.models.output_error import STEP, Drive, SingleTrackFit
from canest.models.second_gyro import with_second_gyro
from tests.conftest import CONFIG

SPEED = 20.0  # m/s
FINE = 1e-3  # s: the reference integration's step


def steering(t):
    """Steering wheel angle (rad): a 0.5 Hz slalom of 30 deg."""
    return math.radians(30.0) * np.sin(2.0 * math.pi * 0.5 * t)


def reference_yaw_rate(vehicle, times) -> np.ndarray:
    """The fit's model (states vy, r, Ff, Fr; forces relaxing over the tire's length) integrated by RK4 at ``FINE``
    with the steering continuous, sampled at ``times``."""
    a, b, m, iz = vehicle.cg_to_front, vehicle.cg_to_rear, vehicle.mass, vehicle.yaw_inertia
    cf, cr, sigma = vehicle.cornering_stiffness_front, vehicle.cornering_stiffness_rear, vehicle.tire.relaxation_length

    def rate(t, x):
        vy, r, ff, fr = x
        delta = steering(t) / vehicle.steering_ratio
        return np.array([(ff + fr) / m - SPEED * r, (a * ff - b * fr) / iz,
                         (cf * (delta - (vy + a * r) / SPEED) - ff) * SPEED / sigma,
                         (cr * (b * r - vy) / SPEED - fr) * SPEED / sigma])

    x, t, out = np.zeros(4), 0.0, []
    for target in times:
        while t < target - FINE / 2:
            k1 = rate(t, x)
            k2 = rate(t + FINE / 2, x + FINE / 2 * k1)
            k3 = rate(t + FINE / 2, x + FINE / 2 * k2)
            k4 = rate(t + FINE, x + FINE * k3)
            x, t = x + FINE / 6 * (k1 + 2 * k2 + 2 * k3 + k4), t + FINE
        out.append(x[1])
    return np.array(out)


def test_the_fits_model_takes_the_steering_over_each_step_not_held_at_its_start():
    """Held at each sample over the step to the next, the model's steering ran half a step (10 ms) behind the yaw
    rate it is compared with: 3.1 % of this slalom's yaw rate amplitude (enough to read a front stiffness 10 % off
    in a window of one bend, README "Online calibration"); the mean of the step's two ends follows it within 0.08 %."""
    vehicle = load_config(CONFIG).vehicle
    times = np.arange(0.0, 6.0, STEP)
    drive = Drive("slalom", times, steering(times), np.zeros_like(times), np.zeros_like(times),
                  np.full_like(times, SPEED), np.arange(len(times)) == 0)
    model = SingleTrackFit(vehicle, [drive])
    truth = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0])[:, None]
    yaw_rate = model.predict(drive, 0, truth)[0][:, 0]
    reference = reference_yaw_rate(vehicle, times)
    assert np.max(np.abs(yaw_rate - reference)) < 2e-3 * np.max(np.abs(reference))


def test_a_stretch_never_takes_the_next_stretchs_inputs():
    """Stretches of usable driving are joined in one array, and the step from one stretch's last tick to the next
    one's first is no step of the car's: the joined prediction is each stretch's alone (each starts from its own
    samples)."""
    vehicle = load_config(CONFIG).vehicle
    times = np.arange(0.0, 4.0, STEP)
    speed = SPEED + 3.0 * np.sin(times)
    first = Drive("first", times, steering(times), np.zeros_like(times), np.zeros_like(times), speed,
                  np.arange(len(times)) == 0)
    second = Drive("second", times + 10.0, -steering(times + 0.3), np.zeros_like(times), np.zeros_like(times),
                   speed[::-1], np.arange(len(times)) == 0)
    joined = Drive("joined", *(np.concatenate([getattr(first, name), getattr(second, name)])
                               for name in ("t", "steering_wheel_angle", "yaw_rate", "ay", "wheel_speed", "starts")))
    theta = np.array([[0.8, 1.0], [1.2, 1.0], [1.0, 1.1], [0.01, 0.0], [0.0, 0.002], [0.1, 0.0], [1.02, 1.0],
                      [0.0, 0.02]])
    predicted = [np.concatenate(parts) for parts in zip(SingleTrackFit(vehicle, [first]).predict(first, 0, theta),
                                                        SingleTrackFit(vehicle, [second]).predict(second, 0, theta))]
    for alone, together in zip(predicted, SingleTrackFit(vehicle, [joined]).predict(joined, 0, theta)):
        np.testing.assert_allclose(together, alone, rtol=0, atol=1e-12)


def test_calibrate_gives_the_second_gyros_bias_as_the_first_less_their_steady_mean_difference():
    """``b_r2 = b_r - mean(r_m - r_m2)`` over steady ticks (canest/models/second_gyro.py): a minute of bends read by
    an ESC gyro 0.5 deg/s off and an airbag unit's 1.5 deg/s the other way, noisier and 20 ms late; its interval holds
    the first bias's; a drive without the second gyro leaves the fit as it was."""
    rng = np.random.default_rng(3)
    times = np.arange(0.0, 60.0, STEP)
    yaw = 0.2 * np.sin(2.0 * math.pi * times / 7.0) + 0.3 * (np.abs(times - 30.0) < 2.0)  # bends and one swerve
    first, second = math.radians(0.5), math.radians(-1.5)
    late = np.interp(times - 0.02, times, yaw)
    drive = Drive("two gyros", times, np.zeros_like(times), yaw + first, np.zeros_like(times),
                  np.full_like(times, SPEED), np.arange(len(times)) == 0,
                  late + second + math.radians(0.2) * rng.standard_normal(len(times)))
    names = [p.name for p in SHARED]
    correlation = np.eye(len(names))
    correlation[names.index("gyro_bias"), names.index("speed")] = correlation[names.index("speed"),
                                                                               names.index("gyro_bias")] = 0.5
    fit = Fit(names, np.array([first if n == "gyro_bias" else 1.0 for n in names]),
              np.full(len(names), math.radians(0.04)), correlation, {}, 60.0)
    with_second = with_second_gyro(fit, [drive])
    assert with_second.value("gyro_bias_2") == pytest.approx(second, abs=math.radians(0.02))
    assert math.radians(0.04) <= with_second.half_width("gyro_bias_2") < math.radians(0.06)
    matrix = with_second.correlation
    assert np.allclose(matrix, matrix.T) and np.allclose(np.diag(matrix), 1.0)
    assert np.linalg.eigvalsh(matrix).min() > -1e-12
    assert 0.0 < matrix[-1, names.index("speed")] < 0.5  # the first bias's correlation, carried over
    one_gyro = dataclasses.replace(drive, yaw_rate_2=None)
    assert with_second_gyro(fit, [one_gyro]) is fit
