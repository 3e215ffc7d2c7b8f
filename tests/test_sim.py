"""The simulator's launch maneuver: longitudinal excitation bounded by traction control."""
import numpy as np
import pytest

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
