"""Issue 17: the tire-force model on what cars send (longitudinal forces from ax and the drive layout), and the
hard drive it must survive."""
import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from canest.config import load_config
from canest.models.wheel_force import DriveLayout
from canest.models.wheels import WheelGeometry
from canest.pipeline import Pipeline
from canest.signals import WHEELS
from canest.sim.simulate import simulate
from tests.conftest import ROOT

NO_TORQUES = ROOT / "configs" / "hard_drive.yaml"


def columns(truth, quantity):
    return np.column_stack([truth[f"{quantity}_{w}"] for w in WHEELS])


def test_forces_from_ax_are_the_simulators_tire_forces_and_reproduce_ax(config):
    """Eq 1 solved with the measured ax: the plant's own Fx within drag and rolling resistance; the body ax exact."""
    vehicle = load_config(NO_TORQUES).vehicle  # all-wheel drive and brakes 50/50, as the simulator's four motors
    truth = simulate(config, "launch", 40.0, 0.85, seed=0).truth  # up to 6 m/s^2: ~2.7 kN per wheel
    fy, fx = columns(truth, "fy"), columns(truth, "fx")
    layout = DriveLayout(vehicle)
    estimated = np.vstack([layout.forces(ax, f[None], delta) for ax, f, delta in zip(truth["ax"], fy, truth["delta"])])
    assert np.abs(fx).max() > 2500.0
    assert np.sqrt(np.mean((estimated - fx) ** 2)) < 50.0 and np.abs(estimated - fx).max() < 200.0
    ax, _, _ = WheelGeometry(vehicle).body_accelerations(estimated, fy, truth["delta"])
    np.testing.assert_allclose(ax, truth["ax"], atol=1e-9)
    rear = DriveLayout(dataclasses.replace(vehicle, drive_front_share=0.0, brake_front_share=0.7))
    driving, braking = rear.forces(2.0, np.zeros((1, 4)), 0.0)[0], rear.forces(-2.0, np.zeros((1, 4)), 0.0)[0]
    np.testing.assert_allclose(driving, [0.0, 0.0, vehicle.mass, vehicle.mass])
    np.testing.assert_allclose(braking, -vehicle.mass * np.array([0.7, 0.7, 0.3, 0.3]))


def test_without_torques_the_tire_force_model_follows_the_torque_driven_one(config):
    """Same drive, same noise and tires: with the torques mapped and without them (forces from ax)."""
    sim = simulate(config, "dlc", 80.0, 0.85, seed=3)
    with_torques = dataclasses.replace(config, estimator=dataclasses.replace(config.estimator, model="tire_force"))
    without = load_config(NO_TORQUES)
    assert not any(name.startswith("motor_torque_") for name in without.signals)
    without = dataclasses.replace(without, vehicle=dataclasses.replace(config.vehicle, drive_front_share=0.5,
                                                                        brake_front_share=0.5),
                                  estimator=with_torques.estimator)
    runs = []
    for variant in (with_torques, without):
        pipeline = Pipeline(variant)
        estimates = [e for frame in sim.frames for e in pipeline.feed(frame)][50:]  # after 0.5 s
        runs.append(np.array([[e.values[name] for name in ("beta", "fy_fl", "fy_fr", "fy_rl", "fy_rr")]
                              for e in estimates]))
        assert pipeline.summary()["resets"] == 0
        assert all(e.valid.get("forces") for e in estimates[-20:])  # straight again: forces valid without torques
    (torque_run, ax_run) = runs
    assert np.degrees(np.sqrt(np.mean((torque_run[:, 0] - ax_run[:, 0]) ** 2))) < 0.02
    assert np.sqrt(np.mean((torque_run[:, 1:] - ax_run[:, 1:]) ** 2)) < 60.0  # N, of peaks near 3 kN
    assert np.abs(torque_run[:, 1:]).max() > 2000.0


@pytest.fixture(scope="module")
def hard_drive():
    result = subprocess.run([sys.executable, str(ROOT / "tools" / "hard_drive.py"), "--json"], capture_output=True,
                            text=True, timeout=600, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def test_hard_drive_loses_nothing_resets_never_and_the_tire_model_tracks_sideslip(hard_drive):
    drive, tires, linear = hard_drive["drive"], hard_drive["tire_force"], hard_drive["single_track"]
    assert drive["max_ay"] > 8.0 and drive["mu"] == 1.0 and drive["vibration"] == 1.0
    for run in (tires, linear):
        assert run["rejected_implausible"] == 0 and run["implausible_samples"] == 0 and run["resets"] == 0
        assert run["decoded"] == run["frames"]
    assert tires["beta_rmse"] <= 0.3  # deg, every tick after 0.5 s
    assert linear["beta_rmse"] > 3 * tires["beta_rmse"]  # the linear tires' error at high ay
