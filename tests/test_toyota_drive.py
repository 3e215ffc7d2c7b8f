"""A simulated drive encoded through opendbc's Toyota DBC as it ships, against the same drive on canest's own DBC.

``configs/toyota_rav4_opendbc.yaml`` reads ``toyota_nodsu_pt_generated``
(lenient load, raw-style ranges overridden, coarse + fine steering, cycle times
given). The baseline is canest's built-in config with the same vehicle,
estimator, inputs and cycle times: what differs is only how the DBCs carry the
values (resolution, offsets, ranges, a composite steering angle).
"""
import math

import numpy as np
import pytest
import yaml

from canest.apps.replay import replay
from canest.config import DEFAULT_CONFIG, load_config
from canest.sim.simulate import simulate
from tests.conftest import ROOT

pytest.importorskip("opendbc", reason="the opendbc extra (pip install canest[opendbc]) is part of the test extra on "
                                      "Python 3.11 and 3.12")

TOYOTA_CONFIG = ROOT / "configs" / "toyota_rav4_opendbc.yaml"
STATES = ("vx", "yaw_rate", "beta")
# KINEMATICS.YAW_RATE comes in steps of 0.244 deg/s: a rounding error of std step / sqrt(12) the finer baseline
# signal does not have; the yaw-rate comparison allows it on top of the baseline's error
YAW_RATE_QUANTIZATION = math.radians(0.244) / math.sqrt(12.0)


def baseline_config(tmp_path, toyota: dict):
    """canest's built-in config reduced to the Toyota's inputs, with its vehicle, estimator and cycle times."""
    data = yaml.safe_load(DEFAULT_CONFIG.read_text())
    data["vehicle"], data["estimator"] = toyota["vehicle"], toyota["estimator"]
    data["input"]["dbc"] = "builtin:canest_vehicle.dbc"
    signals = data["input"]["signals"]
    data["input"]["signals"] = {name: signals[name] for name in toyota["input"]["signals"]}
    cycle = {c["cycle_time"] for c in toyota["input"]["messages"].values()}.pop()
    used = {entry["signal"].split(".")[0] for entry in data["input"]["signals"].values()}
    data["input"]["messages"] = {name: {**checks, "cycle_time": cycle}
                                 for name, checks in data["input"]["messages"].items() if name in used}
    path = tmp_path / "baseline.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return load_config(path)


def drive(config, tmp_path, name):
    """The double lane change at 80 km/h of tests/conftest.py's dlc_run, through ``config``: (summary, errors,
    share of normal ticks)."""
    sim = simulate(config, "dlc", 80.0, 0.85, seed=3)
    log = tmp_path / f"{name}.log"
    sim.write_log(log)
    estimates = []
    summary = replay(config, log, progress=False, on_estimate=estimates.append)
    t = np.array([e.t for e in estimates])
    normal = np.array([e.mode == "normal" for e in estimates])
    moving = np.interp(t, sim.truth["t"], sim.truth["vx"]) > 1.0
    errors = {}
    for state in STATES:
        value = np.array([e.values[state] for e in estimates])
        truth = np.interp(t, sim.truth["t"], sim.truth[state])
        errors[state] = math.sqrt(np.mean((value - truth)[normal & moving] ** 2))
    return summary, errors, normal[moving].mean()


@pytest.fixture(scope="module")
def drives(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("toyota")
    toyota = load_config(TOYOTA_CONFIG)
    baseline = baseline_config(tmp_path, yaml.safe_load(TOYOTA_CONFIG.read_text()))
    return drive(toyota, tmp_path, "toyota"), drive(baseline, tmp_path, "canest")


def test_toyota_drive_runs_normal_with_every_frame_decoded(drives):
    (summary, _, normal), _ = drives
    assert normal >= 0.99
    assert summary["decoded"] == summary["frames"] > 1500  # three messages at 83 Hz for 8 s, none rejected
    assert not [cause for cause in summary if cause.startswith("rejected_")]


def test_toyota_drive_is_as_accurate_as_on_canests_own_dbc(drives):
    (_, toyota, _), (_, canest, canest_normal) = drives
    print({state: (round(toyota[state], 5), round(canest[state], 5)) for state in STATES})
    assert canest_normal >= 0.99
    assert toyota["vx"] <= 1.1 * canest["vx"]
    assert toyota["beta"] <= 1.1 * canest["beta"]
    assert toyota["yaw_rate"] <= 1.1 * math.hypot(canest["yaw_rate"], YAW_RATE_QUANTIZATION)
