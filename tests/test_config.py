"""Config validation: every error names the file, the line and the key."""
import math
import re
import shutil

import pytest
import yaml

from canest.config import ConfigError, load_config
from tests.conftest import CONFIG, ROOT


def write_variant(tmp_path, edit):
    """Copy the reference config beside copies of the DBCs, apply ``edit`` to its dict, return the path."""
    (tmp_path / "dbc").mkdir(exist_ok=True)
    for dbc in (ROOT / "dbc").glob("*.dbc"):
        shutil.copy(dbc, tmp_path / "dbc" / dbc.name)
    data = yaml.safe_load(CONFIG.read_text())
    edit(data)
    path = tmp_path / "configs" / "car.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def error_of(path):
    with pytest.raises(ConfigError) as info:
        load_config(path)
    return str(info.value)


def test_reference_configs_load(config):
    assert config.vehicle.mass == 1845.0
    assert config.signals["yaw_rate"].factor == pytest.approx(math.pi / 180)
    assert load_config(ROOT / "configs" / "dckf_1525kg.yaml").vehicle.mass == 1525.0


def test_unknown_signal_names_file_line_key_and_message(tmp_path):
    path = write_variant(tmp_path, lambda d: d["input"]["signals"].update(ay={"signal": "ESC_IMU.LatAcc", "unit": "m/s^2"}))
    message = error_of(path)
    assert re.match(rf"{re.escape(str(path))}:\d+: input\.signals\.ay\.signal: no signal 'LatAcc' in message 'ESC_IMU'", message)


def test_unknown_message(tmp_path):
    path = write_variant(tmp_path, lambda d: d["input"]["signals"].update(ax="NOPE.LongAccel"))
    assert "input.signals.ax.signal: no message 'NOPE'" in error_of(path)


def test_unit_of_the_wrong_quantity(tmp_path):
    path = write_variant(tmp_path, lambda d: d["input"]["signals"]["yaw_rate"].update(unit="m/s^2"))
    assert "input.signals.yaw_rate.unit" in error_of(path)


def test_unit_that_contradicts_the_dbc(tmp_path):
    path = write_variant(tmp_path, lambda d: d["input"]["signals"]["yaw_rate"].update(unit="rad/s"))
    assert "contradicts the DBC unit 'deg/s'" in error_of(path)


def test_missing_required_signal(tmp_path):
    path = write_variant(tmp_path, lambda d: d["input"]["signals"].pop("ay"))
    assert "input.signals: the estimator needs ay" in error_of(path)


def test_missing_dbc_file(tmp_path):
    path = write_variant(tmp_path, lambda d: d["input"].update(dbc="../dbc/missing.dbc"))
    assert "input.dbc: DBC file not found" in error_of(path)


def test_unknown_filter_lists_the_available_ones(tmp_path):
    path = write_variant(tmp_path, lambda d: d["estimator"].update(filter="magic"))
    assert "estimator.filter: unknown filter 'magic'; available: ckf" in error_of(path)


def test_negative_mass(tmp_path):
    path = write_variant(tmp_path, lambda d: d["vehicle"].update(mass=-3))
    assert re.search(r":\d+: vehicle\.mass: must be positive", error_of(path))


def test_typo_in_a_key(tmp_path):
    path = write_variant(tmp_path, lambda d: d["estimator"].update(rate_hzz=50))
    assert "estimator.rate_hzz: unknown key" in error_of(path)


def test_bad_yaml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("vehicle: [unclosed\n")
    assert error_of(bad).startswith(f"{bad}: invalid YAML")
    assert "config file not found" in error_of(tmp_path / "nope.yaml")


def test_broken_dbc_names_the_dbc(tmp_path):
    path = write_variant(tmp_path, lambda d: None)
    (tmp_path / "dbc" / "canest_vehicle.dbc").write_text("BO_ 12 broken")
    assert "canest_vehicle.dbc: cannot load DBC" in error_of(path)


def test_production_dbc_through_config_only():
    """Motorola byte order, extended ID, multiplexed km/h wheel speeds, inverted signs, no torques."""
    config = load_config(ROOT / "configs" / "production_example.yaml")
    assert config.signals["steering_wheel_angle"].factor == pytest.approx(-math.pi / 180)
    assert config.signals["wheel_speed_rl"].factor == pytest.approx(1 / 3.6 / config.vehicle.wheel_radius)
    assert config.signals["wheel_speed_rl"].multiplexer_value == 1
    assert "motor_torque_fl" not in config.signals


def test_every_filter_is_selectable_by_config(tmp_path):
    from canest.filters import FILTERS

    for name in FILTERS:
        path = write_variant(tmp_path, lambda d: d["estimator"].update(filter=name, factorization="svd"))
        assert load_config(path).estimator.filter == name


def test_wrong_filter_option_names_the_key(tmp_path):
    path = write_variant(tmp_path, lambda d: d["estimator"].update(filter="lmrwekf", filter_options={"windw": 3}))
    assert re.search(r":\d+: estimator\.filter_options: lmrwekf: .*windw", error_of(path))
    path = write_variant(tmp_path, lambda d: d["estimator"].update(filter="lmrwekf", filter_options={"forgetting": 0.5}))
    assert "forgetting must be in [0.95, 0.995]" in error_of(path)


def test_models_and_filters_must_fit(tmp_path):
    path = write_variant(tmp_path, lambda d: d["estimator"].update(filter="dckf", model="single_track"))
    assert re.search(r":\d+: estimator\.model: filter 'dckf' and model 'single_track' do not fit: use model 'two_track'",
                     error_of(path))
    path = write_variant(tmp_path, lambda d: d["estimator"].update(filter="ckf", model="two_track"))
    assert "use filter 'jckf'" in error_of(path)
    path = write_variant(tmp_path, lambda d: d["estimator"].update(filter="gfckf", model="tire_force"))
    assert load_config(path).estimator.model == "tire_force"  # the paper's comparison: any sigma-point filter
    path = write_variant(tmp_path, lambda d: d["estimator"].update(filter="dici-gfckf"))
    assert load_config(path).estimator.model == "tire_force"  # implied by the filter


def test_dici_needs_the_second_imu_and_force_models_the_torques(tmp_path):
    def drop(names, **estimator):
        def edit(d):
            d["estimator"].update(**estimator)
            for name in names:
                del d["input"]["signals"][name]
        return edit

    path = write_variant(tmp_path, drop(["ay_2"], filter="dici-gfckf"))
    assert "input.signals: filter 'dici-gfckf' needs ay_2" in error_of(path)
    path = write_variant(tmp_path, drop(["motor_torque_rr"], filter="dckf"))
    assert "model 'two_track' needs motor_torque_rr" in error_of(path)


def test_tire_section_is_validated(tmp_path):
    path = write_variant(tmp_path, lambda d: d["vehicle"].update(tire={"relaxation_length": 0.4, "lateral_curvature": -0.5}))
    tire = load_config(path).vehicle.tire
    assert tire.relaxation_length == 0.4 and tire.lateral_curvature == -0.5
    path = write_variant(tmp_path, lambda d: d["vehicle"].update(tire={"relaxaton_length": 0.4}))
    assert re.search(r":\d+: vehicle\.tire\.relaxaton_length: unknown key", error_of(path))
    path = write_variant(tmp_path, lambda d: d["estimator"].update(friction_correlation=1.0))
    assert "friction_correlation: must be below 1" in error_of(path)
