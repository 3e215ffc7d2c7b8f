"""A signal map `check` accepts decodes: shared frame IDs and unreachable multiplexer pages are config errors.

Before, both passed `canest check` ("OK") and failed or fell silent at run
time: two messages on one ID gave ``KeyError: 'ax'`` in the replay, wheel
speeds on a multiplexer page the multiplexer cannot carry never arrived.
"""
import re
import shutil

import pytest
import yaml

from tests.conftest import ROOT
from tests.test_cli import canest

HERE = ROOT / "tests" / "dbc"
SIGNALS = {
    "steering_wheel_angle": "SAS_Status.SteeringWheelAngle",
    **{f"wheel_speed_{w}": f"ESC_WheelSpeeds.WheelSpeed_{w.upper()}" for w in ("fl", "fr", "rl", "rr")},
    "ax": "ESC_IMU.LongAccel",
    "ay": "ESC_IMU.LatAccel",
    "yaw_rate": "ESC_IMU.YawRate",
}


def config_for(tmp_path, dbc_text: str, **signals):
    """A config reading ``dbc_text`` (beside it as car.dbc) through SIGNALS updated by ``signals``."""
    (tmp_path / "car.dbc").write_text(dbc_text)
    data = yaml.safe_load((ROOT / "configs" / "dckf_1525kg.yaml").read_text())
    data["input"] = {"dbc": "car.dbc", "signals": {**SIGNALS, **signals}}
    data["output"]["dbc"] = "builtin:canest_estimates.dbc"
    path = tmp_path / "car.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def line_of(path, text: str) -> int:
    return next(n for n, line in enumerate(path.read_text().splitlines(), 1) if text in line)


@pytest.mark.parametrize("name", ["car.dbc", "drive.log"])
def test_a_binary_file_given_as_the_dbc_is_one_line(tmp_path, name):
    """A log named as the DBC by mistake (read as a DBC: its suffix names no cantools format) or a .dbc that is no
    text ended in a UnicodeDecodeError traceback from the repair's reading of its text."""
    path = config_for(tmp_path, "")
    (tmp_path / name).write_bytes(b"\x7fELF\x02\x01" + bytes(range(256)) * 4)
    path.write_text(path.read_text().replace("dbc: car.dbc", f"dbc: {name}"))
    result = canest("check", "--config", path, check=False)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith(f"canest: error: {tmp_path / name}: cannot load DBC (referenced by {path}: "
                                    "input.dbc): not DBC text (byte ") and "is no cp1252 character" in result.stderr


def test_two_messages_on_one_frame_id_are_a_check_error_naming_both(tmp_path):
    dbc = (HERE / "two_messages_one_id.dbc").read_text()
    path = config_for(tmp_path, dbc, yaw_rate="ESC_YawRate.YawRate")
    result = canest("check", "--config", path, check=False)
    assert result.returncode == 2 and "OK" not in result.stdout
    assert result.stderr.strip().splitlines()[-1] == (
        f"canest: error: {path}:{line_of(path, 'ax:')}: input.signals.ax.signal: message 'ESC_IMU' shares frame ID "
        f"0x130 with 'ESC_YawRate' in {tmp_path / 'car.dbc'}: its frames cannot be told apart; give each message "
        "its own ID")
    fixed = config_for(tmp_path, dbc.replace("BO_ 304 ESC_YawRate", "BO_ 305 ESC_YawRate"),
                       yaw_rate="ESC_YawRate.YawRate")
    assert canest("check", "--config", fixed).stdout.rstrip().endswith("OK")


def test_a_mapped_signal_on_a_page_its_multiplexer_cannot_select_is_a_check_error(tmp_path):
    dbc = (HERE / "mux_page_out_of_range.dbc").read_text()
    path = config_for(tmp_path, dbc)
    result = canest("check", "--config", path, check=False)
    assert result.returncode == 2 and "OK" not in result.stdout
    assert result.stderr == (
        f"canest: error: {path}:{line_of(path, 'wheel_speed_rl:')}: input.signals.wheel_speed_rl.signal: "
        f"ESC_WheelSpeeds.WheelSpeed_RL never decodes from {tmp_path / 'car.dbc'}: a frame with "
        "WheelSpeed_Page = 2 cannot be built (Unsigned integer value 2 out of range.)\n")
    fixed = config_for(tmp_path, dbc.replace(" m2 ", " m1 "))
    out = canest("check", "--config", fixed).stdout
    assert re.search(r"wheel_speed_rl +ESC_WheelSpeeds\.WheelSpeed_RL ", out) and out.rstrip().endswith("OK")


@pytest.mark.parametrize("entry, expected", [
    ({"ESC_IMU": {"counter": "ESC_IMU_Counter"}}, "input.messages.ESC_IMU.counter: no signal 'ESC_IMU_Counter'"),
    ({"SAS_Status": {"countr": "X"}}, "input.messages.SAS_Status.countr: unknown key; did you mean 'counter'?"),
])
def test_integrity_checks_name_signals_of_their_message(tmp_path, entry, expected):
    path = config_for(tmp_path, (HERE / "mux_page_out_of_range.dbc").read_text().replace(" m2 ", " m1 "))
    data = yaml.safe_load(path.read_text())
    data["input"]["messages"] = entry
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    assert expected in canest("check", "--config", path, check=False).stderr


def test_checks_on_a_message_no_signal_comes_from_are_an_error_not_checks_that_never_run(tmp_path):
    shutil.copy(ROOT / "dbc" / "canest_vehicle.dbc", tmp_path / "car.dbc")
    data = yaml.safe_load((ROOT / "configs" / "dckf_1525kg.yaml").read_text())
    data["input"]["dbc"] = "car.dbc"
    data["output"]["dbc"] = "builtin:canest_estimates.dbc"
    for name in ("ax_2", "ay_2", "yaw_rate_2"):
        del data["input"]["signals"][name]
    path = tmp_path / "car.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    assert canest("check", "--config", path, check=False).stderr.strip().endswith(
        "input.messages.ACU_IMU: no signal of input.signals comes from this message, so its checks would never run; "
        "map one of its signals or remove the entry")
