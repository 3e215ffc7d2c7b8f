"""The reference speed: the wheels while they roll freely, the integrated acceleration while they slip."""
import numpy as np
import pytest

from canest.estimation.reference_speed import DRIFT, MAX_GAP, ReferenceSpeed

RADIUS, STIFFNESS, ANCHORED_STD = 0.3, 15.0, 0.05
ROLLING = np.zeros(4)


def reference():
    return ReferenceSpeed(RADIUS, STIFFNESS, ANCHORED_STD)


def test_free_rolling_wheels_give_the_speed_less_their_linear_slip():
    ref = reference()
    usage = np.full(4, 0.06)  # a gentle drive: each tire needs slip usage / stiffness
    speed, std = ref.update(0.0, 0.5, np.full(4, 50.0), np.full(4, 0.5 / RADIUS), usage)
    assert speed == pytest.approx(RADIUS * 50.0 / (1 + 0.06 / STIFFNESS))
    assert std == pytest.approx(ANCHORED_STD)


def test_spinning_wheels_are_not_followed_and_the_uncertainty_grows():
    ref = reference()
    ref.update(0.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    dt, ax = 0.01, 3.0
    for k in range(1, 101):  # one second of a launch: wheels spin up three times faster than the car
        wheels = np.full(4, 50.0 + 3 * ax * k * dt / RADIUS)
        speed, std = ref.update(k * dt, ax, wheels, np.full(4, 3 * ax / RADIUS), np.full(4, 0.4))
    assert speed == pytest.approx(RADIUS * 50.0 + ax * 1.0)
    assert std == pytest.approx(np.hypot(ANCHORED_STD, DRIFT * 1.0))


def test_a_wheel_out_of_step_with_the_imu_stops_the_anchoring_even_without_torque():
    ref = reference()
    ref.update(0.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    locking = np.array([-20.0, 0.0, 0.0, 0.0])  # rad/s^2: one wheel decelerating on its own
    speed, std = ref.update(0.01, 0.0, np.array([49.8, 50.0, 50.0, 50.0]), locking, ROLLING)
    assert speed == pytest.approx(RADIUS * 50.0) and std > ANCHORED_STD


def test_a_gap_in_the_inputs_takes_the_wheels_again():
    ref = reference()
    ref.update(0.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    ref.update(0.01, 2.0, np.full(4, 60.0), np.full(4, 30.0), np.full(4, 0.4))
    speed, std = ref.update(0.01 + 2 * MAX_GAP, 2.0, np.full(4, 60.0), np.full(4, 30.0), np.full(4, 0.4))
    assert speed == pytest.approx(RADIUS * 60.0 / (1 + 0.4 / STIFFNESS)) and std == pytest.approx(ANCHORED_STD)
