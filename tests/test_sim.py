"""The simulator's launch maneuver (longitudinal excitation bounded by traction control) and friction jump."""
import numpy as np
import pytest

from canest.commands.simulate import parse_mu_jump
from canest.signals import WHEELS
from canest.sim.maneuvers import Driver
from canest.sim.simulate import simulate


@pytest.mark.parametrize("mu", [0.85, 0.35])
def test_launch_reaches_the_tire_limit_only_on_low_friction(config, mu):
    truth = simulate(config, "launch", 40.0, mu, seed=1).truth
    slip = np.array([truth[f"kappa_{w}"] for w in WHEELS])
    usage = np.array([np.hypot(truth[f"fx_{w}"], truth[f"fy_{w}"]) / (mu * truth[f"fz_{w}"]) for w in WHEELS])
    assert truth["ax"].max() == pytest.approx(min(6.0, 0.95 * mu * 9.81), rel=0.12)
    if mu < 0.5:  # at the limit: traction control takes over and holds the slip
        assert usage.max() > 0.85 and Driver.TRACTION_SLIP < slip.max() < 0.2
    else:  # below the road's limit: traction control never acts
        assert slip.max() < Driver.TRACTION_SLIP and usage.max() < 0.95
    assert np.all(np.abs(truth["yaw_rate"]) < 1e-3)  # straight


def test_friction_jump_changes_the_road_at_its_time(config):
    truth = simulate(config, "sine", 60.0, 0.85, duration=3.0, mu_jump=(1.5, [0.85, 0.3, 0.85, 0.3])).truth
    before, after = truth["t"] < 1.5, truth["t"] >= 1.5
    assert np.all(truth["mu_fl"] == 0.85) and np.all(truth["mu_fr"][before] == 0.85)
    assert np.all(truth["mu_fr"][after] == 0.3) and np.all(truth["mu_rr"][after] == 0.3)


def test_friction_jump_option_is_checked():
    with pytest.raises(ValueError, match="--mu-jump: expected T:MU"):
        parse_mu_jump("six:0.3")
    with pytest.raises(ValueError, match="--mu: expected one or four values"):
        parse_mu_jump("6:2.5")
    assert parse_mu_jump("6:0.35") == (6.0, 0.35)
