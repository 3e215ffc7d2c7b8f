"""The gyro's held sample brought forward to the tick (first-order hold)."""
import numpy as np
import pytest

from canest.estimation.gyro_hold import GyroHold


def test_a_ramp_is_extrapolated_to_the_tick():
    """A yaw rate rising 150 deg/s^2 (a spin), sampled at 100 Hz 8 ms before each tick: the held value is
    1.2 deg/s behind; the hold's is on the ramp."""
    hold, rate = GyroHold(), np.radians(150.0)
    for k in range(10):
        t = 0.01 * k + 0.008
        at_tick = hold.at(t, rate * 0.01 * k, age=0.008)
    assert at_tick == pytest.approx(rate * t)


def test_a_sample_is_counted_once():
    hold = GyroHold()
    for k in range(5):
        hold.at(0.01 * k, 0.1 * k, age=0.0)  # slope 10 rad/s^2
    held = hold.at(0.045, 0.4, age=0.005)  # the last sample again: not a new point
    assert held == pytest.approx(0.4 + 0.005 * 10.0)
    assert hold.at(0.045, 0.4, age=0.005) == pytest.approx(held)


def test_reset_forgets_the_slope():
    hold = GyroHold()
    for k in range(5):
        hold.at(0.01 * k, 0.1 * k, age=0.0)
    hold.reset()
    assert hold.at(1.0, 0.3, age=0.008) == 0.3  # one sample: no slope yet


@pytest.mark.parametrize("age", (0.005, 0.008))
def test_the_noise_factor_is_the_held_values_scatter_over_the_samples(age):
    """A white noise sampled every 10 ms, brought forward ``age`` s: the held values scatter by ``noise_factor``
    times the samples' (the slope's noise leans on the newest sample), which the published yaw rate's std takes."""
    rng = np.random.default_rng(8855)
    hold, held, factors = GyroHold(), [], []
    for k in range(20000):
        t = 0.01 * k + age
        held.append(hold.at(t, rng.standard_normal(), age=age))
        factors.append(hold.noise_factor(age))
    steady = slice(100, None)
    assert np.std(held[steady]) == pytest.approx(np.mean(factors[steady]), rel=0.05)
    assert np.mean(factors[steady]) > 1.05
    assert hold.noise_factor(0.0) == 1.0
