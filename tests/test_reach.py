"""`canest check` warns where a mapped signal's range cannot carry what cars reach (wheel speed to 300 km/h at a
0.35 m radius, yaw rate +-180 deg/s; published vx 90 m/s, sideslip +-30 deg), and is silent where it can."""
import json
import re

from canest.codec.reach import input_shortfalls, output_shortfalls
from canest.codec.dbc import load_database
from canest.config import load_config
from tests.conftest import CONFIG, ROOT
from tests.test_cli import canest
from tests.test_config_dbc import config_for


def test_canest_dbcs_carry_what_cars_reach():
    config = load_config(CONFIG)
    assert input_shortfalls(config.signals) == []
    assert output_shortfalls(load_database(ROOT / "dbc" / "canest_estimates.dbc", "output.dbc")) == []
    assert "warning" not in canest("check", "--config", CONFIG).stdout


def test_a_1600_rpm_wheel_speed_and_a_125_deg_s_gyro_are_named(tmp_path):
    text = (ROOT / "dbc" / "canest_vehicle.dbc").read_text()
    text = re.sub(r"(WheelSpeed_F[LR] : \S+ \S+) \[-3200\|3200\]", r"\1 [-1600|1600]", text)
    text = re.sub(r"(SG_ YawRate : \S+ \S+) \[-300\|300\]", r"\1 [-125|125]", text)
    wheels = {f"wheel_speed_{w}": f"ESC_WheelSpeeds{'Front' if w[0] == 'f' else 'Rear'}.WheelSpeed_{w.upper()}"
              for w in ("fl", "fr", "rl", "rr")}
    out = canest("check", "--config", config_for(tmp_path, text, **wheels)).stdout
    warned = out.split("warning: signal ranges short of what cars reach:")[1]
    assert "input wheel_speed_fl (ESC_WheelSpeedsFront.WheelSpeed_FL) carries [-167.552, 167.552] rad/s" in warned
    assert "cars reach [open, 238.095] rad/s (300 km/h at a 0.35 m radius)" in warned
    assert "input yaw_rate (ESC_IMU.YawRate) carries [-125, 125] deg/s; cars reach [-180, 180] deg/s" in warned
    assert "wheel_speed_rl" not in warned  # the rear wheels keep 3200 rpm
    assert out.rstrip().endswith("OK")  # a warning, not a refusal
    report = json.loads(canest("check", "--config", tmp_path / "car.yaml", "--json").stdout)
    assert report["ok"] and report["range_warnings"] == [line.strip() for line in warned.strip().splitlines()[:3]]
    table_rows = [line for line in out.splitlines() if line.split(" ")[0] in report_canonicals(report)]
    assert len(report["signals"]) == len(table_rows) == 8  # steering, four wheels, ax, ay, yaw rate


def report_canonicals(report) -> set:
    return {row["canonical"] for row in report["signals"]}


def test_a_narrow_output_sideslip_is_named(tmp_path):
    text = (ROOT / "dbc" / "canest_estimates.dbc").read_text()
    text = re.sub(r"(SG_ Sideslip : \S+ \S+) \[-3.2768\|3.2767\]", r"\1 [-0.2|0.2]", text)
    (tmp_path / "out.dbc").write_text(text)
    shortfalls = output_shortfalls(load_database(tmp_path / "out.dbc", "output.dbc"))
    assert shortfalls == ["output beta (CE_YawSideslip.Sideslip) carries [-11.4592, 11.4592] deg; cars reach "
                          "[-30, 30] deg: beyond it the value is sent saturated"]
