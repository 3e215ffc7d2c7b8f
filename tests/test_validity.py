"""Validity means consistent with what the car measures; causes are published; bounds truncate honestly."""
import math

import cantools
import numpy as np
import pytest
from scipy.stats import truncnorm

from canest.apps.replay import replay
from canest.config import load_config
from canest.codec.encode import EstimateEncoder
from canest.estimation import validity
from canest.estimation.estimate import CAUSES, Estimate
from canest.filters.parameters import truncated
from canest.sim.simulate import simulate
from tests.conftest import ROOT
from tests.test_config import write_variant

OUTPUT_DBC = ROOT / "dbc" / "canest_estimates.dbc"


@pytest.mark.parametrize("mean, std, bound, side", [(0.05, 0.1, 0.1, 1.0), (-3.0, 0.1, 0.1, 1.0), (0.12, 0.05, 0.1, 1.0),
                                                    (1.35, 0.1, 1.3, -1.0), (0.5, 0.1, 0.1, 1.0)])
def test_truncation_gives_the_truncated_normals_moments(mean, std, bound, side):
    got_mean, got_std = truncated(np.array([mean]), np.array([std]), bound, side)
    low, high = ((bound - mean) / std, np.inf) if side > 0 else (-np.inf, (bound - mean) / std)
    assert got_mean[0] == pytest.approx(truncnorm.mean(low, high, mean, std), rel=1e-9)
    assert got_std[0] == pytest.approx(truncnorm.std(low, high, mean, std), rel=1e-6)


def test_consistency_judges_a_channel_by_its_window():
    consistency = validity.Consistency(("ay", "yaw_rate", "vx_wheel"))
    assert math.isnan(consistency.ratio("yaw_rate"))  # nothing judged yet
    for _ in range(validity.WINDOW):
        consistency.push([1, 2], np.array([1.0, 0.5]))
    assert consistency.ratio("yaw_rate") == pytest.approx(1.0) and consistency.ratio("vx") == pytest.approx(0.5)
    consistency.push([1], np.array([validity.INCONSISTENT * validity.WINDOW]))  # one wrong-sign yaw rate
    assert consistency.ratio("yaw_rate") > validity.INCONSISTENT
    assert validity.judge(True, False, consistency.ratio("yaw_rate")) == "inconsistent"
    assert validity.judge(True, True, 1.0) == "saturated" and validity.judge(False, False, 1.0) == "no_input"


def test_a_cause_holds_for_a_second_after_its_test_last_failed():
    holds = validity.Holds()
    assert holds.apply("beta", "model_regime", 10.0) == "model_regime"
    assert holds.apply("beta", "valid", 10.5) == "model_regime"
    assert holds.apply("beta", "low_speed", 10.6) == "low_speed"  # a present cause is reported as it is
    assert holds.apply("beta", "valid", 10.0 + validity.HOLD + 0.01) == "valid"


def test_kinematic_check_sees_a_slide_the_model_misses():
    dt = 0.01
    check = validity.KinematicCheck(dt)
    vx, yaw_rate = 20.0, 0.15
    steady = [check.inside(-0.01, vx * yaw_rate, yaw_rate, vx) for _ in range(100)]  # ay = r vx: no slide
    assert all(steady)
    slide = [check.inside(-0.01, vx * yaw_rate - 1.0, yaw_rate, vx) for _ in range(100)]  # beta falls 2.9 deg/s
    assert not slide[-1]


def test_linear_regime_sees_an_understeering_car(config):
    regime = validity.LinearRegime(config.vehicle, 0.01)
    delta, vx = 0.04, 20.0
    reference = vx * delta / (config.vehicle.wheelbase + regime.understeer * vx**2)
    assert all(regime.inside(delta, vx, reference) for _ in range(100))
    saturated = [regime.inside(delta, vx, 0.5 * reference) for _ in range(100)]  # half the yaw rate the steering asks
    assert not saturated[-1]


def test_the_cause_message_carries_every_cause_the_dbc_documents():
    db = cantools.database.load_file(str(OUTPUT_DBC))
    message = db.get_message_by_name("CE_ValidityCause")
    for signal in ("VxCause", "YawRateCause", "SideslipCause", "ForcesCause", "FrictionCause"):
        assert [str(v) for _, v in sorted(message.get_signal_by_name(signal).choices.items())] == list(CAUSES)
    encoder = EstimateEncoder(OUTPUT_DBC)
    estimate = Estimate(1.0, {}, {"vx": True}, "normal", "ckf",
                        causes={"vx": "valid", "yaw_rate": "inconsistent", "beta": "model_regime"})
    frame = next(f for f in encoder.encode(estimate) if f.arbitration_id == message.frame_id)
    decoded = message.decode(frame.data, decode_choices=True)
    assert (decoded["VxCause"], decoded["YawRateCause"], decoded["SideslipCause"], decoded["ForcesCause"]) == \
        ("valid", "inconsistent", "model_regime", "no_input")


def test_a_wheel_speed_at_its_dbc_limit_is_saturated_not_a_speed(tmp_path):
    """Above what the wheel-speed signal carries the DBC limit is sent: vx is not taken from it, its bit is
    clear with the cause "saturated", and it never publishes the limit as a valid speed. (canest's own DBC
    carries 3200 rpm, 420 km/h at 0.35 m; a DBC capped at 1600 rpm, as canest's was, shows the case.)"""
    path = write_variant(tmp_path, lambda d: None)
    dbc = tmp_path / "dbc" / "canest_vehicle.dbc"
    dbc.write_text(dbc.read_text().replace("(0.1,0) [-3200|3200]", "(0.05,0) [-1600|1600]"))
    config = load_config(path)
    limit = 1600 * 2 * math.pi / 60 * config.vehicle.wheel_radius
    sim = simulate(config, "launch", limit * 3.6 - 12.0, 0.85, duration=5.0, seed=2)  # accelerates past the limit
    sim.write_log(tmp_path / "fast.log")
    estimates = []
    summary = replay(config, tmp_path / "fast.log", progress=False, on_estimate=estimates.append)
    assert summary["saturated_samples"] > 0
    true_vx = np.interp([e.t for e in estimates], sim.truth["t"], sim.truth["vx"])
    beyond = [(e, v) for e, v in zip(estimates, true_vx) if v > limit + 0.5]
    assert len(beyond) > 50
    assert all(not e.valid["vx"] and e.causes["vx"] == "saturated" for e, _ in beyond)
    assert all(abs(e.values["vx"] - v) < 1.0 for e, v in beyond)  # ax integrated, not the limit
