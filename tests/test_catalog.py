"""The model catalog: every filter x model pair `check` accepts runs; every pair it refuses is one clear line."""
import re

import numpy as np
import pytest

from canest.apps.replay import replay
from canest.config import ConfigError, load_config
from canest.estimation import catalog
from canest.filters import FILTERS, fits
from canest.sim.simulate import simulate
from tests.test_config import write_variant

PAIRS = [(model, name) for model in catalog.CATALOG for name in FILTERS]


@pytest.fixture(scope="module")
def short_drive(config, tmp_path_factory):
    """Two seconds of a sine steer at 60 km/h: every input of the built-in config, the second IMU and torques too."""
    folder = tmp_path_factory.mktemp("pairs")
    sim = simulate(config, "sine", 60.0, 0.85, duration=2.0, seed=5)
    sim.write_log(folder / "drive.log")
    return folder / "drive.log"


@pytest.mark.parametrize("model,name", PAIRS)
def test_every_accepted_pair_replays_and_every_refused_pair_is_one_line(model, name, tmp_path, short_drive):
    path = write_variant(tmp_path, lambda d: d["estimator"].update(filter=name, model=model))
    if catalog.misfit(name, model) is None:
        config = load_config(path)
        estimates = []
        replay(config, short_drive, progress=False, on_estimate=estimates.append)
        normal = [e for e in estimates if e.mode == "normal"]
        assert len(normal) > 100, f"{name} on {model}: {len(normal)} normal ticks"
        assert all(np.isfinite(e.values["yaw_rate"]) and np.isfinite(e.values["beta"]) for e in normal)
    else:
        with pytest.raises(ConfigError) as info:
            load_config(path)
        message = str(info.value)
        assert "\n" not in message
        assert re.match(rf"{re.escape(str(path))}:\d+: estimator\.model: filter '{name}' and model '{model}' do not fit: "
                        r"use (filter|model) '[\w-]+' \(.+ (runs with|runs on) [\w, -]+\)$", message), message


def test_the_catalog_agrees_with_the_filters_needs():
    """A filter that needs a parameter block runs only on the two-track model, the DICI-GFCKF only with two IMUs,
    the dual EKF only where a stiffness scale rides in the input; every linearizing filter runs on every
    model without parameter states (central differences where the model has no Jacobian)."""
    table = {model: set(entry.filters) for model, entry in catalog.CATALOG.items()}
    assert table["two_track"] == {"jckf", "dckf"}
    assert {"ekf", "lmrwekf", "dici-gfckf"} <= table["tire_force"] and "dekf" not in table["tire_force"]
    assert "dekf" in table["single_track"] and "dici-gfckf" not in table["single_track"]
    assert all(fits(name, catalog.CATALOG[catalog.model_for(name)].model) for name in FILTERS)


def test_a_model_alone_gets_its_default_filter(tmp_path):
    path = write_variant(tmp_path, lambda d: (d["estimator"].pop("filter", None), d["estimator"].update(model="two_track")))
    assert load_config(path).estimator.filter == catalog.CATALOG["two_track"].default_filter == "jckf"


def test_latency_compensation_is_refused_for_a_model_without_derivatives(tmp_path):
    path = write_variant(tmp_path, lambda d: d["estimator"].update(filter="jckf", latency_compensation=True))
    with pytest.raises(ConfigError, match=r":\d+: estimator\.latency_compensation: model 'two_track' has no derivatives"):
        load_config(path)


def test_every_filter_is_named_in_the_status_message():
    """The output DBC's FilterId names every selectable filter (jckf was once published as 0, 'unknown')."""
    from canest.codec.encode import EstimateEncoder
    from tests.conftest import ROOT

    encoder = EstimateEncoder(ROOT / "dbc" / "canest_estimates.dbc")
    assert set(encoder.filter_ids) == set(FILTERS)
