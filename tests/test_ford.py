"""A real production car by config alone: a 2017 Ford Fusion's recorded drive through opendbc's DBC, unedited.

The log (20.9 s, 41 250 classic CAN frames, adaptive cruise from about 30 to
80 km/h) and the DBC are in ``shared/realdata/ford_fusion_2017`` (found by ``tests.conftest.realdata``). The
estimates are compared with the car's own speed (``BrakeSysFeatures.Veh_V_ActlBrk``)
and yaw rate (``Yaw_Data_FD1.VehYaw_W_Actl``) decoded with cantools.
"""
import math
import shutil
import subprocess
import sys
from collections import Counter

import can
import cantools
import numpy as np
import pytest

from canest.apps.replay import replay
from canest.config import load_config
from tests.conftest import FORD, ROOT, ford_config, ford_dbc, realdata

LOG = "acc_on_speed_changing_from_30km_to_80km_per_hour.candump"
MOVING = 1.0  # m/s of the car's own speed


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """The log as a ``.log`` file (python-can picks its reader by suffix)."""
    path = tmp_path_factory.mktemp("ford") / "drive.log"
    shutil.copy(realdata(FORD, LOG), path)
    return path


def run(config, log):
    estimates = []
    summary = replay(config, log, progress=False, on_estimate=estimates.append)
    return summary, estimates


def variant(tmp_path, edit):
    """The Ford config with ``edit`` applied to its dict, written beside the test (the DBC path made absolute)."""
    return load_config(ford_config(tmp_path, edit))


def car_signal(log, frame_id, name, factor=1.0):
    """(times, values) of one of the car's own signals, decoded by cantools, physical values times ``factor``."""
    message = cantools.database.load_file(str(ford_dbc())).get_message_by_frame_id(frame_id)
    rows = [(m.timestamp, message.decode(m.data, decode_choices=False)[name] * factor)
            for m in can.LogReader(str(log)) if m.arbitration_id == frame_id]
    return np.array(rows).T


def accounted(summary):
    """Frames decoded, ignored by ID and rejected by cause add up to every frame read."""
    return summary.get("decoded", 0) + summary.get("ignored_id", 0) + sum(
        v for k, v in summary.items() if k.startswith("rejected_"))


@pytest.fixture(scope="module")
def ford_run(drive, tmp_path_factory):
    return run(load_config(ford_config(tmp_path_factory.mktemp("config"))), drive)


def test_ford_log_runs_normal_and_matches_the_cars_own_speed_and_yaw_rate(ford_run, drive):
    summary, estimates = ford_run
    assert summary["frames"] == 41250 and accounted(summary) == 41250
    assert summary["resets"] == 0
    t = np.array([e.t for e in estimates])
    speed_t, speed = car_signal(drive, 0x415, "Veh_V_ActlBrk", 1 / 3.6)
    yaw_t, yaw = car_signal(drive, 0x91, "VehYaw_W_Actl")
    reference_speed = np.interp(t, speed_t, speed)
    moving = reference_speed > MOVING
    assert moving.mean() > 0.95  # the car drives the whole log
    normal = np.array([e.mode == "normal" for e in estimates])
    assert normal[moving].mean() >= 0.99
    vx = np.array([e.values["vx"] for e in estimates])
    yaw_rate = np.array([e.values["yaw_rate"] for e in estimates])
    used = moving & normal
    assert math.sqrt(np.mean((vx[used] - reference_speed[used]) ** 2)) < 0.1
    assert math.degrees(math.sqrt(np.mean((yaw_rate[used] - np.interp(t, yaw_t, yaw)[used]) ** 2))) < 0.1
    settled = [e for e in estimates if e.t - estimates[0].t > 1.0]  # vx waits ~0.5 s for ax's noise to be measured
    assert np.mean([e.valid.get("vx", False) and e.valid.get("yaw_rate", False) for e in settled]) >= 0.99


def test_ford_steering_zero_is_learned_and_sideslip_stays_small(ford_run):
    _, estimates = ford_run
    causes = [e.causes["beta"] for e in estimates]
    first_learned = next(i for i, c in enumerate(causes) if c != "initializing" and c != "no_input")
    assert 1.5 <= estimates[first_learned].t - estimates[0].t <= 5.0  # LEARN_TIME of straight driving, then learned
    assert "initializing" not in causes[first_learned:]
    assert all(not e.valid.get("beta", False) for e in estimates[:first_learned])
    assert sum(e.valid.get("beta", False) for e in estimates) > len(estimates) / 3
    # an almost straight road at up to 80 km/h: the sideslip of a sedan stays well below a degree
    assert max(abs(e.values["beta"]) for e in estimates[first_learned:]) < math.radians(1.0)


def test_the_dbc_as_declared_rejects_every_classic_frame(tmp_path, drive):
    """Without fd: false every frame of the mapped (CAN FD in the DBC) messages is rejected, by cause, and no input."""
    def declared(data):
        for entry in data["input"]["messages"].values():
            entry.pop("fd")
    summary, estimates = run(variant(tmp_path, declared), drive)
    assert summary.get("decoded", 0) == 0 and accounted(summary) == summary["frames"] == 41250
    assert summary["rejected_fd_mismatch"] == 41250 - summary["ignored_id"]
    assert {e.mode for e in estimates} == {"no_input"}


def test_absolute_steering_flagged_faulty_is_rejected_by_cause(tmp_path, drive):
    """StePinComp_An_Est reads -1600 with its quality flag 0 'Faulty': every one of its frames is rejected,
    counted, and sideslip is never published valid from it; speed and yaw rate stay right."""
    def absolute(data):
        data["input"]["signals"]["steering_wheel_angle"] = {
            "signal": "SteeringPinion_Data_Alt.StePinComp_An_Est",
            "valid": {"signal": "StePinCompAnEst_D_Qf", "values": ["OK"]}}
    summary, estimates = run(variant(tmp_path, absolute), drive)
    steering_frames = sum(1 for m in can.LogReader(str(drive)) if m.arbitration_id == 0x85)
    assert summary["rejected_invalid_signal"] == summary["invalid_signal_samples"] == steering_frames
    assert accounted(summary) == summary["frames"]
    assert summary["resets"] == 0
    assert not any(e.valid.get("beta", False) for e in estimates)
    assert Counter(e.mode for e in estimates[10:]) == {"degraded": len(estimates) - 10}  # no steering, no lateral model
    assert np.mean([e.valid.get("vx", False) for e in estimates if e.t - estimates[0].t > 1.0]) >= 0.99


def test_check_names_where_each_cycle_time_comes_from(tmp_path):
    out = subprocess.run([sys.executable, "-m", "canest", "check", "--config", str(ford_config(tmp_path))],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    rows = {line.split()[0]: line for line in out.stdout.splitlines() if line.split()}
    assert "10ms (config)" in rows["yaw_rate"] and "10ms (config)" in rows["ax"]
    assert "10ms (DBC)" in rows["wheel_speed_fl"] and "zero learned" in rows["steering_wheel_angle"]
    assert "fd=classic" in out.stdout and out.stdout.rstrip().endswith("OK")


def test_the_real_data_is_found_through_canest_realdata_and_its_absence_fails_naming_where_it_was_looked_for(
        tmp_path, monkeypatch):
    (tmp_path / FORD).mkdir()
    monkeypatch.setenv("CANEST_REALDATA", str(tmp_path))
    assert realdata(FORD) == tmp_path / FORD
    with pytest.raises(pytest.fail.Exception, match=f"{FORD}/nothing.dbc not found in {tmp_path}; set CANEST_REALDATA"):
        realdata(FORD, "nothing.dbc")
    monkeypatch.delenv("CANEST_REALDATA")
    assert realdata(FORD, LOG).stat().st_size > 1_000_000  # found above the checkout, wherever it lies
