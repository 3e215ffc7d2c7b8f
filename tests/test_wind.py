"""Crosswind gusts (:mod:`canest.sim.wind`): the side force's spread and memory, and what the plant makes of it."""
import math

import numpy as np
import pytest

from canest.config import DEFAULT_CONFIG, load_config
from canest.sim import wind
from canest.sim.plant import R, VY, TwoTrackPlant


def test_the_gusts_have_the_stated_spread_and_memory():
    dt = 0.01
    gusts = wind.Crosswind(seed=4, scale=1.0, dt=dt)
    speed = np.array([gusts.side_force(1.0) for _ in range(200_000)]) / wind.SIDE_FORCE_FACTOR  # at 1 m/s: K w
    assert speed.std() == pytest.approx(wind.GUST_SPEED, rel=0.1)
    assert abs(speed.mean()) < 0.3 * wind.GUST_SPEED  # gusts, no steady wind
    lag = int(round(wind.GUST_TIME / dt))
    assert np.corrcoef(speed[:-lag], speed[lag:])[0, 1] == pytest.approx(math.exp(-1.0), abs=0.1)


def test_the_side_force_grows_with_speed_and_scale_and_calm_is_none():
    one, two = wind.Crosswind(seed=7, scale=1.0, dt=0.001), wind.Crosswind(seed=7, scale=2.0, dt=0.001)
    first = one.side_force(22.0)
    assert two.side_force(11.0) == pytest.approx(first)  # twice the wind at half the speed
    assert first != 0.0
    calm = wind.Crosswind(seed=7, scale=0.0, dt=0.001)
    assert [calm.side_force(22.0) for _ in range(100)] == [0.0] * 100


def test_the_accelerometer_feels_the_side_force_and_it_turns_the_car():
    """A force on the body, unlike a bank's gravity: ay sees it; it acts ahead of the centre of gravity."""
    vehicle = load_config(DEFAULT_CONFIG).vehicle
    plant = TwoTrackPlant(vehicle, 0.85, side_force_arm=wind.PRESSURE_CENTRE)
    state = plant.initial_state(22.0)
    calm, calm_out = plant.derivatives(state, 0.0, np.zeros(4))
    plant.side_force = 500.0
    gust, gust_out = plant.derivatives(state, 0.0, np.zeros(4))
    assert gust_out.ay - calm_out.ay == pytest.approx(500.0 / vehicle.mass)
    assert gust[VY] - calm[VY] == pytest.approx(500.0 / vehicle.mass)
    assert gust[R] - calm[R] == pytest.approx(wind.PRESSURE_CENTRE * 500.0 / vehicle.yaw_inertia)
