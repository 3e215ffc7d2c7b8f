"""canest init: a starting config from a DBC that canest check accepts, or one line naming what the DBC lacks;
and check's list of the inputs not mapped, with what each costs (from the model catalog)."""
import os
import subprocess
import sys

import pytest
import yaml

from canest.apps.init import UNMEASURED_RADIUS
from canest.config import DEFAULT_CONFIG, load_config
from canest.config.discover import wheel_of, words_of
from canest.estimation.catalog import BASE_INPUTS, CATALOG, losses
from tests.conftest import ROOT, ford_dbc

CANEST = [sys.executable, "-m", "canest"]

# a small DBC of a car without accelerometers: wheel speeds (km/h), steering (deg), a yaw rate without a unit
NO_ACCELEROMETER = """VERSION ""
NS_ :
BS_:
BU_: ABS SAS
BO_ 416 WHEELS: 8 ABS
 SG_ WHEEL_SPEED_FL : 7|16@0+ (0.01,0) [0|655.35] "km/h" XXX
 SG_ WHEEL_SPEED_FR : 23|16@0+ (0.01,0) [0|655.35] "km/h" XXX
 SG_ WHEEL_SPEED_RL : 39|16@0+ (0.01,0) [0|655.35] "km/h" XXX
 SG_ WHEEL_SPEED_RR : 55|16@0+ (0.01,0) [0|655.35] "km/h" XXX
BO_ 37 STEERING: 8 SAS
 SG_ STEER_ANGLE : 7|16@0- (0.1,0) [-3276.8|3276.7] "deg" XXX
 SG_ YAW_RATE : 23|16@0- (0.01,0) [-327.68|327.67] "" XXX
"""
WITH_ACCELEROMETER = NO_ACCELEROMETER + """BO_ 36 KINEMATICS: 8 SAS
 SG_ ACCEL_X : 7|16@0- (0.001,0) [-32|32] "m/s^2" XXX
 SG_ ACCEL_Y : 23|16@0- (0.001,0) [-32|32] "m/s2" XXX
 SG_ ACCEL_X_REQ : 39|16@0- (0.001,0) [-32|32] "m/s^2" XXX
"""
# Toyota-style KINEMATICS: 10 bits from a negative offset, the DBC range in raw counts [0|65535]
RAW_RANGES = NO_ACCELEROMETER + """BO_ 36 KINEMATICS: 8 SAS
 SG_ YAW_RATE : 1|10@0+ (0.244,-125) [0|65535] "deg/s" XXX
 SG_ ACCEL_X : 17|10@0+ (0.03589,-18.375) [0|65535] "m/s^2" XXX
 SG_ ACCEL_Y : 33|10@0+ (0.03589,-18.375) [0|65535] "m/s^2" XXX
"""


def canest(*args, cwd=ROOT):
    return subprocess.run([*CANEST, *map(str, args)], capture_output=True, text=True, timeout=300, cwd=cwd,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})


def one_line_error(result, status, *parts):
    errors = result.stderr.strip().splitlines()
    assert result.returncode == status, result.stderr
    assert len(errors) == 1 and errors[0].startswith("canest: error: "), result.stderr
    for part in parts:
        assert part in errors[0], errors[0]
    return errors[0]


def test_init_from_the_ford_dbc_finds_its_inputs_and_check_accepts_the_config(tmp_path):
    out = tmp_path / "fusion.yaml"
    result = canest("init", "--dbc", ford_dbc(), "--out", out)
    assert result.returncode == 0, result.stderr
    assert f"wrote {out}" in result.stderr
    signals = yaml.safe_load(out.read_text())["input"]["signals"]
    assert signals["yaw_rate"] == "Yaw_Data_FD1.VehYaw_W_Actl"
    assert signals["ax"] == "Accel_Data_FD1.VehLong2_A_Actl" and signals["ay"] == "Accel_Data_FD1.VehLat2_A_Actl"
    assert [signals[f"wheel_speed_{w}"] for w in ("fl", "fr", "rl", "rr")] == [
        f"WheelSpeed.Whl{w}_W_Meas" for w in ("Fl", "Fr", "Rl", "Rr")]
    assert set(signals) == set(BASE_INPUTS)
    text = out.read_text()
    assert text.count("# CONFIRM") == len(BASE_INPUTS)
    assert load_config(out).vehicle.wheel_radius_uncertainty == UNMEASURED_RADIUS  # another car's radius, said
    assert "no motor_torques" in text  # what the car's DBC does not give, said in the file
    check = canest("check", "--config", out)
    assert check.returncode == 0, check.stderr
    assert check.stdout.rstrip().endswith("OK")
    assert "no motor_torques (motor_torque_fl" in check.stdout and "model two_track unavailable" in check.stdout \
        and "model tire_force: longitudinal forces from ax and vehicle.drive" \
        in check.stdout


@pytest.mark.parametrize("name", ["ford_pt", "ford_pt.txt"])
def test_a_dbc_named_without_its_suffix_is_read_as_a_dbc_by_init_and_by_check(tmp_path, name):
    """init read it, check did not (cantools takes the format from the suffix): the config init wrote was refused."""
    dbc = tmp_path / name
    dbc.write_bytes(ford_dbc().read_bytes())
    out = tmp_path / "fusion.yaml"
    assert canest("init", "--dbc", dbc, "--out", out).returncode == 0
    check = canest("check", "--config", out)
    assert check.returncode == 0 and check.stdout.rstrip().endswith("OK"), check.stderr


def test_init_never_replaces_a_file(tmp_path):
    out = tmp_path / "mine.yaml"
    out.write_text("# my own config\n")
    one_line_error(canest("init", "--dbc", ford_dbc(), "--out", out), 73, str(out), "never replaces")
    assert out.read_text() == "# my own config\n"
    link = tmp_path / "dangling.yaml"
    link.symlink_to(tmp_path / "nowhere.yaml")
    one_line_error(canest("init", "--dbc", ford_dbc(), "--out", link), 73, "never replaces")
    assert not (tmp_path / "nowhere.yaml").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling.yaml", "mine.yaml"]  # no temporary left
    one_line_error(canest("init", "--dbc", ford_dbc(), "--out", tmp_path), 73, "that is a folder")  # said "exists"


def test_a_dbc_without_accelerometers_is_one_line_naming_the_inputs_it_lacks_and_nothing_is_written(tmp_path):
    dbc = tmp_path / "car.dbc"
    dbc.write_text(NO_ACCELEROMETER)
    error = one_line_error(canest("init", "--dbc", dbc, "--out", tmp_path / "car.yaml"), 2,
                           f"{dbc}: no signal found for ay (", "no model runs", "nothing written")  # ax: derived
    assert "yaw_rate," not in error.split("(")[0]  # the yaw rate without a unit was found
    assert not (tmp_path / "car.yaml").exists()


def test_a_signal_without_a_unit_gets_an_assumed_one_marked_for_the_user_and_check_passes(tmp_path):
    dbc = tmp_path / "car.dbc"
    dbc.write_text(WITH_ACCELEROMETER)
    result = canest("init", "--dbc", "car.dbc", "--out", "car.yaml", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    document = yaml.safe_load((tmp_path / "car.yaml").read_text())
    assert document["input"]["dbc"] == "car.dbc"  # beside the config: relative, moves with it
    signals = document["input"]["signals"]
    assert signals["yaw_rate"] == {"signal": "STEERING.YAW_RATE", "unit": "deg/s"}
    assert signals["ax"] == "KINEMATICS.ACCEL_X"  # not the request
    assert "ASSUMED unit deg/s" in (tmp_path / "car.yaml").read_text()
    config = load_config(tmp_path / "car.yaml")
    assert config.vehicle.mass == load_config(DEFAULT_CONFIG).vehicle.mass  # canest's default, said so
    assert canest("check", "--config", tmp_path / "car.yaml").returncode == 0


def test_raw_style_ranges_get_range_none_and_check_names_each_one_the_config_does_not_override(tmp_path):
    dbc = tmp_path / "car.dbc"
    dbc.write_text(RAW_RANGES)
    result = canest("init", dbc, "--out", tmp_path / "car.yaml")  # the DBC as a positional argument
    assert result.returncode == 0, result.stderr
    signals = yaml.safe_load((tmp_path / "car.yaml").read_text())["input"]["signals"]
    for canonical in ("yaw_rate", "ax", "ay"):
        assert signals[canonical]["range"] == "none" and signals[canonical]["signal"].startswith("KINEMATICS."), signals
    assert signals["wheel_speed_fl"] == "WHEELS.WHEEL_SPEED_FL"  # a physical range [0|655.35] is kept
    config = load_config(tmp_path / "car.yaml")
    assert config.signals["yaw_rate"].range == (None, None)
    check = canest("check", "--config", tmp_path / "car.yaml")
    assert check.returncode == 0 and "raw counts" not in check.stdout, check.stdout
    document = yaml.safe_load((tmp_path / "car.yaml").read_text())
    document["input"]["signals"]["yaw_rate"], document["input"]["signals"]["ay"] = "KINEMATICS.YAW_RATE", \
        "KINEMATICS.ACCEL_Y"
    document["input"]["signals"]["ax"] = {"signal": "KINEMATICS.ACCEL_X", "range": [-18.375, 18.34]}
    (tmp_path / "dbc_ranges.yaml").write_text(yaml.safe_dump(document))
    check = canest("check", "--config", tmp_path / "dbc_ranges.yaml")
    assert check.returncode == 0, check.stderr
    ay, yaw_rate = sorted(line for line in check.stdout.split("DBC ranges in raw counts")[1].splitlines()
                          if line.startswith("  input "))  # ax has its own range: not warned
    assert "input yaw_rate: KINEMATICS.YAW_RATE declares the raw-style range [0|65535]" in yaw_rate \
        and "bits carry -125 to 124.612 deg/s" in yaw_rate and "input.signals.yaw_rate.range: none" in yaw_rate
    assert "input ay: KINEMATICS.ACCEL_Y declares the raw-style range [0|65535]" in ay


def test_the_dbc_is_positional_or_an_option_not_two_different_ones(tmp_path):
    dbc = tmp_path / "car.dbc"
    dbc.write_text(WITH_ACCELEROMETER)
    positional, option = canest("init", dbc), canest("init", "--dbc", dbc)
    assert positional.returncode == option.returncode == 0 and positional.stdout == option.stdout
    assert canest("init", dbc, "--dbc", dbc).stdout == option.stdout
    one_line_error(canest("init", dbc, "--dbc", tmp_path / "other.dbc"), 2, "two DBCs given", "other.dbc")


def test_init_to_standard_output(tmp_path):
    dbc = tmp_path / "car.dbc"
    dbc.write_text(WITH_ACCELEROMETER)
    result = canest("init", "--dbc", dbc)
    assert result.returncode == 0, result.stderr
    assert yaml.safe_load(result.stdout)["input"]["dbc"] == str(dbc)


def test_init_usage_and_input_errors_are_one_line(tmp_path):
    one_line_error(canest("init"), 2, "--dbc", "--car")
    one_line_error(canest("init", "--dbc", tmp_path / "none.dbc"), 66, "none.dbc", "not found")
    (tmp_path / "bad.dbc").write_text("BO_ this is no DBC\n")
    one_line_error(canest("init", "--dbc", tmp_path / "bad.dbc"), 2, "bad.dbc: cannot load DBC")


def test_without_opendbc_an_opendbc_name_is_exit_69_naming_the_extra():
    code = ("import sys; sys.modules['opendbc'] = None; from canest.cli import main; "
            "main(['init', '--dbc', 'opendbc:ford_lincoln_base_pt'])")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)
    one_line_error(result, 69, "opendbc", "pip install 'canest[opendbc]'")


@pytest.mark.parametrize("name, wheel", [
    ("WhlFl_W_Meas", "fl"), ("WHEEL_SPEED_RR", "rr"), ("ESP_VL_Radgeschw_02", "fl"), ("ESP_HR_Radgeschw_02", "rr"),
    ("ESP_wheelSpeedFrL", "fl"), ("ESP_wheelSpeedReR", "rr"), ("WheelSpeedFrontLeft", "fl"), ("FR", "fr"),
    ("WHL_SPD_RL", "rl"), ("VehicleSpeed", None), ("FL_FR_AVG", None),
])
def test_the_wheel_a_name_points_to(name, wheel):
    assert wheel_of(words_of(name)) == wheel


def test_losses_come_from_the_catalog():
    everything = {name for entry in CATALOG.values() for name in entry.required_inputs} | {"ax_2", "ay_2",
                                                                                             "yaw_rate_2"}
    assert losses(everything) == []
    no_torques = losses(everything - {"motor_torque_rl"})
    assert len(no_torques) == 1 and no_torques[0].startswith("no motor_torques (motor_torque_rl)")
    needing = [name for name, entry in CATALOG.items() if "motor_torque_rl" in entry.required_inputs]
    assert needing and f"model {', '.join(needing)} unavailable" in no_torques[0]
    assert "single_track" not in no_torques[0]  # it runs without them
    assert losses(everything - {"ax"}) == ["ax derived from wheel speeds"]  # required unless wheel speeds are mapped
    no_ax, = [line for line in losses(everything - {"ax", "wheel_speed_fl"}) if "(ax)" in line]
    assert "no model runs" in no_ax
    no_ay, = [line for line in losses(everything - {"ay"}) if "(ay)" in line]
    assert "no model runs" in no_ay and "vx" in no_ay
    second_imu, = losses(everything - {"yaw_rate_2"})
    assert "filter dici-gfckf (on tire_force) unavailable" in second_imu and "every state still estimated" \
        in second_imu


def test_check_lists_nothing_for_a_config_that_maps_every_input():
    result = canest("check")
    assert result.returncode == 0, result.stderr
    assert "inputs not mapped" not in result.stdout


@pytest.mark.parametrize("length, signed, scale, offset, bounds, raw", [
    (10, False, 0.244, -125, (0, 65535), True),  # Toyota KINEMATICS.YAW_RATE
    (10, False, 0.244, -125, (0, 1023), True),  # its own bit field's raw counts
    (8, True, 0.5, 100, (-128, 127), True),  # signed raw counts of a signal carrying 36 to 163.5
    (16, True, 0.01, 0, (-32768, 32767), False),  # raw counts, but admitting all the bits carry (+-327.68)
    (16, False, 0.01, -67.67, (0, 250), False),  # Toyota WHEEL_SPEEDS: a physical range cutting off reversing
    (16, True, 1, 0, (-32768, 32767), False),  # raw and physical are one
    (8, False, 0.5, 0, (0, 255), False),  # raw counts, but admits everything the bits carry
    (12, True, 1.5, 0, (-500, 500), False),  # Toyota STEER_ANGLE: physical, inside what the bits carry
])
def test_a_raw_style_range_is_integer_limits_cutting_off_values_the_bits_carry(length, signed, scale, offset,
                                                                                bounds, raw):
    from types import SimpleNamespace

    from canest.codec.raw_range import raw_style

    signal = SimpleNamespace(length=length, is_signed=signed, scale=scale, offset=offset, minimum=bounds[0],
                             maximum=bounds[1], is_float=False)
    assert raw_style(signal) == raw
