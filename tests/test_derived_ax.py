"""ax derived from the wheel speeds when no accelerometer is mapped (canest/estimation/derived_ax.py): the derivative,
its noise formula, the config rules and a simulated drive replayed without ax."""
import math
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from canest.apps.replay import replay
from canest.config import DEFAULT_CONFIG, load_config
from canest.errors import ConfigError
from canest.estimation.derived_ax import TIME_CONSTANT, WheelAx, differentiation_std
from canest.estimation.inputs import WHEEL_SPEEDS, TickInputs
from canest.sim.simulate import simulate
from tests.conftest import ROOT

RADIUS = 0.3
DT = 0.01


def tick(t, speed, stale=False, fresh=True):
    """The inputs of one tick: four equal wheel speeds (rad/s) ``speed``."""
    n = len(WHEEL_SPEEDS)
    return TickInputs(SimpleNamespace(t=t, names=list(WHEEL_SPEEDS), values=[speed] * n, stale=[stale] * n,
                                      fresh=[fresh] * n, ages=[0.0] * n, saturated=[False] * n))


def test_a_constant_acceleration_is_recovered_and_the_input_is_flagged_derived():
    derived = WheelAx(RADIUS, 0.1, DT)
    first = tick(0.0, 10.0)
    derived.add_to(first)
    assert "ax" in first.derived and first.stale["ax"] and not first.has("ax")  # one sample has no slope
    for k in range(1, 200):
        inputs = tick(k * DT, (10.0 + 2.0 * k * DT) / RADIUS)  # 2 m/s^2
        derived.add_to(inputs)
    assert inputs.has("ax") and inputs.fresh["ax"] and inputs.values["ax"] == pytest.approx(2.0, rel=1e-5)
    assert inputs.missing_groups() == ()


def test_held_wheels_give_no_fresh_ax_and_stale_wheels_a_stale_ax_not_reported_as_a_missing_imu():
    derived = WheelAx(RADIUS, 0.1, DT)
    for k in range(3):
        derived.add_to(tick(k * DT, 10.0 + k))
    held = tick(3 * DT, 12.0, fresh=False)
    derived.add_to(held)
    assert held.has("ax") and not held.fresh["ax"]
    stale = tick(4 * DT, 12.0, stale=True)
    derived.add_to(stale)
    assert stale.stale["ax"] and "imu" not in stale.missing_groups() and "wheel_speeds" in stale.missing_groups()


def test_the_noise_formula_matches_the_spread_of_the_derived_ax_on_noisy_wheels():
    wheel_std = 0.1  # rad/s on each wheel
    rng = np.random.default_rng(1)
    derived = WheelAx(RADIUS, wheel_std, DT)
    values = []
    for k in range(20000):
        n = len(WHEEL_SPEEDS)
        inputs = TickInputs(SimpleNamespace(t=k * DT, names=list(WHEEL_SPEEDS),
                                            values=list(30.0 + wheel_std * rng.standard_normal(n)),
                                            stale=[False] * n, fresh=[True] * n, ages=[0.0] * n, saturated=[False] * n))
        derived.add_to(inputs)
        values.append(inputs.values["ax"])
    expected = differentiation_std(RADIUS, wheel_std, DT)
    assert derived.noise == {"ax": expected}
    assert np.std(values[100:]) == pytest.approx(expected, rel=0.05)
    assert expected == pytest.approx(RADIUS * wheel_std / 2 / TIME_CONSTANT, rel=0.15)  # sigma_v / tau for tau >> dt


def config_without(tmp_path, *names):
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    for name in names:
        del data["input"]["signals"][name]
    path = tmp_path / "car.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_a_config_without_ax_but_with_wheel_speeds_is_accepted_and_check_says_ax_is_derived(tmp_path):
    path = config_without(tmp_path, "ax")
    assert "ax" not in load_config(path).signals
    result = subprocess.run([sys.executable, "-m", "canest", "check", "--config", str(path)], capture_output=True,
                            text=True, timeout=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    assert "  ax derived from wheel speeds" in result.stdout and "no imu" not in result.stdout


def test_without_ax_and_a_wheel_speed_the_config_names_both(tmp_path):
    with pytest.raises(ConfigError, match="the estimator needs ax, wheel_speed_rl"):
        load_config(config_without(tmp_path, "ax", "wheel_speed_rl"))


def rmse_and_normal(config, log, truth):
    estimates = []
    replay(config, log, progress=False, on_estimate=estimates.append)
    t = np.array([e.t for e in estimates])
    moving = np.interp(t, truth["t"], truth["vx"]) > 1.0
    errors = {}
    for state in ("vx", "yaw_rate"):
        value = np.array([e.values[state] for e in estimates])
        used = moving & np.isfinite(value)  # published (not before the filter starts)
        assert used.sum() > 0.99 * moving.sum()
        errors[state] = math.sqrt(np.mean((value[used] - np.interp(t, truth["t"], truth[state])[used]) ** 2))
    return errors, np.mean([e.mode == "normal" for e in np.array(estimates)[moving]])


@pytest.mark.parametrize("maneuver, speed", [("launch", 40.0), ("dlc", 80.0)])
def test_a_simulated_drive_replayed_without_ax_stays_accurate_and_normal(tmp_path, maneuver, speed):
    with_ax = load_config(DEFAULT_CONFIG)
    sim = simulate(with_ax, maneuver, speed, 0.85, seed=3)
    log = tmp_path / "drive.log"
    sim.write_log(log)
    measured, _ = rmse_and_normal(with_ax, log, sim.truth)
    derived, normal = rmse_and_normal(load_config(config_without(tmp_path, "ax")), log, sim.truth)
    print(f"\n{maneuver} {speed:g} km/h RMSE with ax {measured}, ax derived {derived}, normal {normal:.3f}")
    assert derived["vx"] < 0.15 and derived["yaw_rate"] < math.radians(0.3)
    assert derived["yaw_rate"] < measured["yaw_rate"] + math.radians(0.05)
    assert normal >= 0.99
