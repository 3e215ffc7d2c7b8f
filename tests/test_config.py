"""Config validation: every error names the file, the line and the key."""
import json
import math
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
import yaml

from canest import limits
from canest.config import BUILTIN_DIR, BUILTIN_PREFIX, DEFAULT_CONFIG, ConfigError, load_config
from canest.estimation import catalog
from canest.filters import FILTERS, make_filter
from canest.filters.ekf import ExtendedKalmanFilter
from canest.yamldoc import MAX_BYTES, MAX_NODES
from tests.conftest import CONFIG, ROOT
from tests.test_cli import canest


def write_variant(tmp_path, edit):
    """Copy the reference config beside copies of the DBCs it reads, apply ``edit`` to its dict, return the path."""
    (tmp_path / "dbc").mkdir(exist_ok=True)
    for dbc in (ROOT / "dbc").glob("*.dbc"):
        shutil.copy(dbc, tmp_path / "dbc" / dbc.name)
    data = yaml.safe_load(CONFIG.read_text())
    for section in ("input", "output"):  # the copies, not the built-in DBCs
        data[section]["dbc"] = "../dbc/" + data[section]["dbc"].removeprefix(BUILTIN_PREFIX)
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


def test_two_inputs_from_one_signal_are_refused_but_four_wheel_speeds_may_share_one(tmp_path):
    """ax and ay both read from the lateral accelerometer passed ``check`` and ran as if the car drove sideways."""
    path = write_variant(tmp_path, lambda d: d["input"]["signals"].update(ax={"signal": "ESC_IMU.LatAccel",
                                                                            "unit": "m/s^2"}))
    assert re.search(r"input\.signals\.ay\.signal: ESC_IMU\.LatAccel is ax's already: two inputs read from one "
                     r"signal", error_of(path)), error_of(path)
    def one_speed_for_all(data):
        data["input"]["signals"].update({f"wheel_speed_{w}": data["input"]["signals"]["wheel_speed_fl"]
                                         for w in ("fr", "rl", "rr")})
        data["input"]["messages"].pop("ESC_WheelSpeedsRear")  # its checks would never run
    one_speed = write_variant(tmp_path, one_speed_for_all)
    signals = load_config(one_speed).signals
    assert {signals[f"wheel_speed_{w}"].signal for w in ("fl", "fr", "rl", "rr")} == {signals["wheel_speed_fl"].signal}


def test_an_output_id_the_car_sends_on_the_same_bus_is_refused_by_the_config_and_by_run(tmp_path):
    """Two senders of one ID on one bus garble each other's frames: the output DBC's CE_Velocity renumbered to the
    IMU's 0x130 (304) is refused where the config puts both on vcan0, and where run's options do."""
    clash = (ROOT / "dbc" / "canest_estimates.dbc").read_text().replace("BO_ 1280 CE_Velocity", "BO_ 304 CE_Velocity")
    assert clash != (ROOT / "dbc" / "canest_estimates.dbc").read_text()

    def variant(channel):
        def edit(data):
            data["output"]["dbc"] = "../dbc/clash.dbc"
            data["output"]["bus"] = {"interface": "virtual", "channel": channel}
            data["input"]["bus"] = {"interface": "virtual", "channel": "car"}
        (tmp_path / channel).mkdir()
        path = write_variant(tmp_path / channel, edit)
        (tmp_path / channel / "dbc" / "clash.dbc").write_text(clash)
        return path
    same = variant("car")
    assert re.search(r"car\.yaml:\d+: output\.bus: output message CE_Velocity has ID 0x130, which the input DBC's "
                     r"ESC_IMU has too, on the same bus", error_of(same)), error_of(same)
    apart = variant("estimates")
    assert load_config(apart).output_bus.channel == "estimates"
    refused = canest("check", "--config", same, "--json", check=False)  # a script reading stdout learns it too
    assert refused.returncode == 2 and json.loads(refused.stdout) == {
        "config": str(same), "ok": False, "error": error_of(same)}, refused.stdout
    result = subprocess.run([sys.executable, "-m", "canest", "run", "--config", str(apart), "--output-channel", "car"],
                            capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 2 and result.stderr.startswith("canest: error: virtual:car: output message "
                                                               "CE_Velocity has ID 0x130"), result.stderr


def test_a_dbc_path_naming_a_folder_says_so(tmp_path):
    path = write_variant(tmp_path, lambda d: d["input"].update(dbc="../dbc"))  # it said "DBC file not found"
    assert re.search(r"car\.yaml:\d+: input\.dbc: .*dbc is a folder; name the DBC file in it", error_of(path))


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


def test_cornering_stiffness_uncertainty_is_read_within_its_range_and_defaults_to_textbook_values(tmp_path):
    assert load_config(CONFIG).vehicle.cornering_stiffness_uncertainty == 0.15  # the built-in car's own
    path = write_variant(tmp_path, lambda d: d["vehicle"].pop("cornering_stiffness_uncertainty"))
    assert load_config(path).vehicle.cornering_stiffness_uncertainty == 0.3
    path = write_variant(tmp_path, lambda d: d["vehicle"].update(cornering_stiffness_uncertainty=1.5))
    assert re.search(r":\d+: vehicle\.cornering_stiffness_uncertainty: .*0 to 1", error_of(path))


@pytest.mark.parametrize("section, key, built_in, unless_given, given, beyond, allowed", [
    ("vehicle", "wheel_radius_uncertainty", 0.0, 0.02, 0.01, 0.5, "0 to 0.2"),
    ("estimator", "gyro_bias_std", 0.0, 0.0, 0.01, -0.01, "0 to 0.1 rad/s"),
    ("estimator", "lateral_model_error", 0.05, 0.05, 0.0, 1.5, "0 to 1"),
])
def test_what_a_config_claims_of_its_errors_is_read_within_its_range(tmp_path, section, key, built_in, unless_given,
                                                                     given, beyond, allowed):
    """What the config says it knows of the rolling radius and the gyro's bias, and ay's model error per m/s^2 of
    ay (README "How far to trust the output"): the built-in simulated car's radius is exact; a car that says
    nothing of its radius gets a tire size's 2 %."""
    assert getattr(getattr(load_config(CONFIG), section), key) == built_in
    path = write_variant(tmp_path, lambda d: d[section].pop(key, None))
    assert getattr(getattr(load_config(path), section), key) == unless_given
    path = write_variant(tmp_path, lambda d: d[section].update({key: given}))
    assert getattr(getattr(load_config(path), section), key) == given
    path = write_variant(tmp_path, lambda d: d[section].update({key: beyond}))
    assert re.search(rf":\d+: {section}\.{key}: .*{re.escape(allowed)}", error_of(path))


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
    """An unknown option names the filter's own (it showed Python's "RuleFilter.__init__() got an unexpected keyword
    argument"), an option the catalog sets is not one, and a width or window must be positive (-3 passed)."""
    def options(filter_name, **given):
        return error_of(write_variant(tmp_path, lambda d: d["estimator"].update(filter=filter_name,
                                                                                filter_options=given)))
    assert re.search(r":\d+: estimator\.filter_options\.windw: lmrwekf has no option 'windw'; did you mean "
                     r"'window'\?", options("lmrwekf", windw=3))
    assert "estimator.filter_options.window: ckf has no option 'window'; it takes none" in options("ckf", window=3)
    assert "has no option 'x0'" in options("lmrwekf", x0=3)
    assert "estimator.filter_options.kernel_width: must be a number above 0 (default 3), got -3" in options(
        "mcsckf", kernel_width=-3)
    assert "forgetting must be in [0.95, 0.995]" in options("lmrwekf", forgetting=0.5)


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


# Issue 18: nothing silently accepted. Each case below was accepted (or ended in a traceback) before.

def check_error(path) -> str:
    """The one stderr line of a failing ``canest check`` (exit 2)."""
    result = canest("check", "--config", path, check=False)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "OK" not in result.stdout, result.stdout + result.stderr
    return lines[0]


def test_a_typo_in_input_messages_is_refused_not_every_crc_check_switched_off(tmp_path):
    path = write_variant(tmp_path, lambda d: d["input"].update(mesages=d["input"].pop("messages")))
    line = yaml_line(path, "mesages")
    assert check_error(path) == f"canest: error: {path}:{line}: input.mesages: unknown key; did you mean 'messages'?"


def yaml_line(path, key) -> int:
    """The line of ``key:`` in the file."""
    return next(n for n, text in enumerate(path.read_text().splitlines(), 1) if text.strip().startswith(f"{key}:"))


@pytest.mark.parametrize("edit, expected", [
    (lambda d: d["input"].update(dbcc=d["input"].pop("dbc")), r"input\.dbcc: unknown key; did you mean 'dbc'\?"),
    (lambda d: d["input"]["bus"].update(chanel=d["input"]["bus"].pop("channel")),
     r"input\.bus\.chanel: unknown key; did you mean 'channel'\?"),
    (lambda d: d["output"].update(buss={}), r"output\.buss: unknown key; did you mean 'bus'\?"),
    (lambda d: d["output"]["bus"].update(bitrate=500000),
     r"output\.bus\.bitrate: unknown key; valid keys: channel, interface, options \(python-can keywords go under "
     r"'options:'\)"),
    (lambda d: d.update(logging={"level": "debug"}),
     r"logging: unknown key; valid keys: estimator, input, output, vehicle"),
    (lambda d: d["input"]["signals"].update(yawrate="ESC_IMU.YawRate"),
     r"input\.signals\.yawrate: unknown canonical signal; did you mean 'yaw_rate'\?"),
])
def test_unknown_keys_are_refused_everywhere_with_the_nearest_valid_one(tmp_path, edit, expected):
    path = write_variant(tmp_path, edit)
    assert re.fullmatch(rf"{re.escape(str(path))}:\d+: {expected}", error_of(path))


def test_bus_options_are_python_can_keywords_checked_where_python_can_would_ignore_them(tmp_path):
    path = write_variant(tmp_path, lambda d: None)
    assert load_config(path).input_bus.kwargs() == {"interface": "socketcan", "channel": "vcan0", "fd": True}
    assert " on socketcan:vcan0 (fd=True)\n" in canest("check", "--config", path).stdout
    path = write_variant(tmp_path, lambda d: d["input"]["bus"]["options"].update(fdd=True))
    assert "input.bus.options.fdd: not an option of python-can's socketcan bus; did you mean 'fd'?" in error_of(path)
    path = write_variant(tmp_path, lambda d: d["input"]["bus"]["options"].update(fd="yes"))
    assert "input.bus.options.fd: must be true or false, got 'yes'" in error_of(path)
    path = write_variant(tmp_path, lambda d: d["input"]["bus"]["options"].update(can_filters=[]))
    assert "input.bus.options.can_filters: set by canest, not an option" in error_of(path)
    path = write_variant(tmp_path, lambda d: d["input"]["bus"].update(interface="sockectan"))
    assert "input.bus.interface: no python-can interface 'sockectan'; did you mean 'socketcan'?" in error_of(path)
    # A driver with keywords of its own (python-can's PCAN documentation): passed on as given.
    path = write_variant(tmp_path, lambda d: d["input"].update(bus={"interface": "pcan", "channel": "PCAN_USBBUS1",
                                                                    "options": {"bitrate": 500000, "fd": False}}))
    assert load_config(path).input_bus.kwargs() == {"interface": "pcan", "channel": "PCAN_USBBUS1",
                                                    "bitrate": 500000, "fd": False}


@pytest.mark.parametrize("section, key, value, expected", [
    (("vehicle",), "mass", math.nan, "must be a finite number (100 to 60000 kg), got nan"),
    (("vehicle",), "mass", math.inf, "must be a finite number (100 to 60000 kg), got inf"),
    (("vehicle",), "mass", 1.845, "must be at least 100 (100 to 60000 kg), got 1.845"),
    (("vehicle",), "mass", 10 ** 400, "must be a finite number (100 to 60000 kg), got inf"),
    (("vehicle",), "wheel_radius", 359.0, "must be at most 2 (0.1 to 2 m), got 359.0"),
    (("vehicle",), "steering_ratio", 0.5, "must be at least 1 (1 to 50), got 0.5"),
    (("vehicle", "tire"), "nominal_friction", 9.0, "must be at most 2 (0.05 to 2), got 9.0"),
    (("vehicle",), "accelerometer_roll_gradient", 20.0, "must be at most 15 (0 to 15 deg/g), got 20.0"),
    (("vehicle", "tire"), "lateral_curvature", 1.5, "must be at most 1 (-10 to 1), got 1.5"),
    (("estimator",), "rate_hz", 0.001, "must be at least 1 (1 to 1000 Hz), got 0.001"),
    (("estimator",), "rate_hz", 5000, "must be at most 1000 (1 to 1000 Hz), got 5000"),
    (("estimator",), "min_speed", -1.0, "must be at least 0 (0 to 50 m/s), got -1.0"),
    (("estimator",), "timeout_cycles", 0.5, "must be at least 1 (1 to 1000), got 0.5"),
    (("estimator",), "friction_correlation", 1.0, "must be below 1 (0 to below 1), got 1.0"),
    (("estimator",), "friction_correlation", -0.2, "must be at least 0 (0 to below 1), got -0.2"),
    (("estimator", "process_noise"), "vx", math.nan, "must be a finite number (1e-09 to 1e+06), got nan"),
    (("estimator", "measurement_noise"), "ay", 0.0, "must be positive (1e-09 to 1e+06), got 0.0"),
    (("input", "signals", "ay"), "scale", math.inf, "must be a finite number (1e-09 to 1e+09), got inf"),
    (("input", "signals", "ay"), "offset", math.nan, "must be a finite number (-1e+09 to 1e+09), got nan"),
    (("estimator", "filter_options"), "r_floor", math.nan, "must be a finite number, got nan"),
])
def test_every_number_has_a_physical_range(tmp_path, section, key, value, expected):
    def edit(d):
        target = d
        for name in section:
            target = target.setdefault(name, {})
        target[key] = value

    message = error_of(write_variant(tmp_path, edit))
    assert re.search(rf":\d+: {re.escape('.'.join(section + (key,)))}: {re.escape(expected)}", message), message


def test_rate_and_mass_that_ran_into_nonsense_are_refused_by_check(tmp_path):
    """rate_hz 0.001 gave estimates like 1.97e+30 flagged valid; mass .nan gave 811 resets; both passed check."""
    path = write_variant(tmp_path, lambda d: d["estimator"].update(rate_hz=0.001))
    assert check_error(path).endswith("estimator.rate_hz: must be at least 1 (1 to 1000 Hz), got 0.001")
    path = write_variant(tmp_path, lambda d: d["vehicle"].update(mass=math.nan))
    assert check_error(path).endswith("vehicle.mass: must be a finite number (100 to 60000 kg), got nan")


def test_readme_table_states_every_range():
    """The README's configuration table is the one in canest/limits.py."""
    text = (ROOT / "README.md").read_text()
    tables = [("vehicle", limits.VEHICLE), ("vehicle", limits.ATTITUDE), ("vehicle.tire", limits.TIRE),
              ("estimator", limits.ESTIMATOR), ("input.signals.*", limits.SIGNAL)]
    for prefix, table in tables:
        for key, allowed in table.items():
            assert f"| `{prefix}.{key}` | {allowed} |" in text, f"{prefix}.{key}: {allowed}"
    assert f"| `estimator.process_noise.*`, `measurement_noise.*`, `initial_std.*` | {limits.NOISE} |" in text


def test_a_missing_dbc_is_an_error_not_a_silent_built_in(tmp_path):
    path = write_variant(tmp_path, lambda d: d["input"].update(dbc="../nowhere/canest_vehicle.dbc"))
    assert re.search(r":\d+: input\.dbc: DBC file not found: .*/nowhere/canest_vehicle\.dbc "
                     r"\(canest's own is 'builtin:canest_vehicle\.dbc'\)$", error_of(path))
    path = write_variant(tmp_path, lambda d: d["input"].update(dbc="../dbc/canest\0vehicle.dbc"))
    assert error_of(path).endswith("input.dbc: a path cannot hold a NUL character, got '../dbc/canest\\x00vehicle.dbc'")
    path = write_variant(tmp_path, lambda d: d["input"].update(dbc="builtin:canest_vehicel.dbc"))
    assert error_of(path).endswith("input.dbc: no built-in DBC 'canest_vehicel.dbc'; built in: "
                                   "builtin:canest_estimates.dbc, builtin:canest_vehicle.dbc")


def test_built_in_dbcs_by_their_built_in_names_wherever_the_config_is(tmp_path):
    """The default config names builtin: DBCs, so it loads as installed (a copy, not a link into the source tree)."""
    copy = tmp_path / "dici_ev.yaml"
    copy.write_text(DEFAULT_CONFIG.read_text())
    config = load_config(copy)
    assert config.input_dbc == (BUILTIN_DIR / "canest_vehicle.dbc").resolve()
    assert config.output_dbc == (BUILTIN_DIR / "canest_estimates.dbc").resolve()
    assert load_config(DEFAULT_CONFIG).input_dbc == config.input_dbc


def test_yaml_alias_bomb_is_refused_at_once(tmp_path):
    """A "billion laughs" config (9^9 values once expanded) kept `canest check` busy for minutes."""
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"a{n}: &a{n} [{', '.join([f'*a{n - 1}'] * 9)}]" for n in range(1, 9)]
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("\n".join(lines) + "\n")
    result = subprocess.run([sys.executable, "-m", "canest", "check", "--config", str(bomb)], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 2
    assert result.stderr == (f"canest: error: {bomb}: YAML expands to more than {MAX_NODES} values "
                             "(aliases repeating an anchor?); a config needs a few hundred\n")


@pytest.mark.parametrize("text, expected", [
    ("a: &x [*x]\n", ":1: a: nested more than 32 levels deep (or an alias inside its own anchor)"),
    ("[" * 5000 + "]" * 5000 + "\n", ": YAML nested too deeply (more than 32 levels)"),
    ("vehicle: 1\nvehicle: 2\n", ":2: vehicle: given twice (first at line 1)"),
    ("base: &b {mass: 1}\nvehicle:\n  <<: *b\n", ":3: vehicle: merge keys (<<) are not supported; write the keys out"),
    ("vehicle: !!set {a, b}\n", ":1: vehicle: the tag tag:yaml.org,2002:set is not supported; write a plain mapping"),
    ("vehicle: !!python/object/apply:os.system [ls]\n", ":1: vehicle: the tag tag:yaml.org,2002:python/object/apply"),
    ("vehicle:\n  mass: !!python/name:os.system\n", ":2: vehicle.mass: could not determine a constructor for the tag"),
    ("? [a, b]\n: 1\n", ":1: top level: a key must be a name"),
    ("\"vehicle\\n\": 1\n", ":1: vehicle\\n: unknown key; did you mean 'vehicle'?"),
    ("vehicle:\n  mass: 1" + "0" * 5000 + "\n", ":2: vehicle.mass: Exceeds the limit (4300 digits) for integer string"),
    ("vehicle: \x07\n", ":1: invalid YAML: special characters are not allowed at position 9"),
    ("vehicle:\n  name: Citro\xebn\n", ":2: invalid YAML: invalid continuation byte at position 22 (utf-8): save the "
                                      "file as UTF-8"),  # a Latin-1 file
    ("a: 1\n---\nb: 2\n", ": invalid YAML, line 2: expected a single document in the stream, but found another"),
])
def test_yaml_that_no_config_needs_is_one_error_line(tmp_path, text, expected):
    path = tmp_path / "car.yaml"
    path.write_bytes(text.encode("latin-1"))  # UTF-8 for every text but the one that is not
    message = error_of(path)
    assert message.startswith(f"{path}{expected}") and "\n" not in message, message


def test_an_exponent_float_as_yaml_1_2_writes_it_is_a_number(tmp_path):
    """``1.05e5`` was text to PyYAML (YAML 1.1 wants ``1.05e+5``): "must be a number, got '1.05e5'"."""
    for written in ("1.05e5", "105e3", "1.05E+5", "1.05e+5"):
        path = write_variant(tmp_path, lambda d: d["vehicle"].update(cornering_stiffness_front="@"))
        path.write_text(path.read_text().replace("'@'", written))
        assert load_config(path).vehicle.cornering_stiffness_front == 105000.0, written
    path.write_text(path.read_text().replace("1.05e+5", "'1.05e5'"))  # quoted: text, as meant
    assert "vehicle.cornering_stiffness_front: must be a number, got '1.05e5'" in error_of(path)


def test_a_config_larger_than_the_limit_is_refused_unread(tmp_path):
    path = tmp_path / "car.yaml"
    path.write_text("# padding\n" * (MAX_BYTES // 10 + 1))
    assert error_of(path) == f"{path}: config larger than 1024 KiB; a config is a few kilobytes"
    assert error_of(tmp_path) == f"{tmp_path}: cannot read config: Is a directory"


def test_drive_layout_keys(tmp_path):
    """vehicle.drive gives the front axle's share of a drive force (all: drive_front_share); front by default."""
    vehicle = load_config(write_variant(tmp_path, lambda d: None)).vehicle
    assert (vehicle.drive_front_share, vehicle.brake_front_share) == (1.0, 0.7)
    path = write_variant(tmp_path, lambda d: d["vehicle"].update(drive="all", drive_front_share=0.4, brake_front_share=0.6))
    vehicle = load_config(path).vehicle
    assert (vehicle.drive_front_share, vehicle.brake_front_share) == (0.4, 0.6)
    assert load_config(write_variant(tmp_path, lambda d: d["vehicle"].update(drive="rear"))).vehicle.drive_front_share == 0
    path = write_variant(tmp_path, lambda d: d["vehicle"].update(drive="fwd"))
    assert re.search(r":\d+: vehicle\.drive: unknown drive 'fwd'; available: all, front, rear$", error_of(path))
    path = write_variant(tmp_path, lambda d: d["vehicle"].update(drive="front", drive_front_share=0.6))
    assert re.search(r"vehicle\.drive_front_share: only with drive: all \(drive: front puts 100% of the drive force "
                     r"on the front axle\)$", error_of(path))
    path = write_variant(tmp_path, lambda d: d["vehicle"].update(brake_front_share=1.5))
    assert "vehicle.brake_front_share: must be at most 1 (0 to 1), got 1.5" in error_of(path)


def check_in_process(capsys, *args):
    from canest.cli import main
    with pytest.raises(SystemExit) as end:
        main(["check", *map(str, args)])
    assert end.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("name", list(FILTERS))
def test_check_names_the_factorization_the_filter_really_runs(name, tmp_path, capsys):
    def edit(data):
        data["estimator"].pop("factorization")  # the filter's own default
        data["estimator"].update(filter=name, model=catalog.model_for(name))
    config = write_variant(tmp_path, edit)
    found = json.loads(check_in_process(capsys, "--config", config, "--json"))["filter"]
    line = next(line for line in check_in_process(capsys, "--config", config).splitlines()
                if line.startswith("filter"))
    model = catalog.CATALOG[found["model"]].model
    n = len(model.state_names)
    built = make_filter(name, np.zeros(n), np.eye(n), model)
    if isinstance(built, ExtendedKalmanFilter):
        assert found["factorization"] is None and "no square root" in line
    else:  # what the built filter (or its first inner filter: dckf, dici-gfckf) holds
        inner = getattr(built, "states", None) or getattr(built, "locals", [built])[0]
        runs = getattr(built, "factorization", None) or inner.factorization
        assert found["factorization"] == runs in ("cholesky", "svd")
        assert f"{name} ({runs} square root of P) on model {found['model']}" in line
    assert "None" not in line and found["name"] == name


def test_vx_from_ax_and_from_wheel_states_default_to_a_configs_own_vx_noise(tmp_path):
    """``vx_from_ax`` (the noise of a vx that integrates ax) and ``vx_from_wheel_states`` (of a vx held by wheel
    speeds that are states) are the built-in 0.1 and 0.05 where a config sets none, what a config says, and a
    config's ``vx`` where it sets only that (written before they were told apart)."""
    def noise(edit):
        return load_config(write_variant(tmp_path, edit)).estimator.process_noise

    def only_vx(data):
        data["estimator"]["process_noise"] = {"vx": 0.4}

    def neither(data):
        data["estimator"].pop("process_noise")

    def both(data):
        data["estimator"]["process_noise"] = {"vx": 0.4, "vx_from_ax": 0.05}

    assert noise(only_vx)["vx_from_ax"] == noise(only_vx)["vx_from_wheel_states"] == 0.4
    assert (noise(neither)["vx"], noise(neither)["vx_from_ax"], noise(neither)["vx_from_wheel_states"]) == (0.3, 0.1, 0.05)
    assert (noise(both)["vx"], noise(both)["vx_from_ax"], noise(both)["vx_from_wheel_states"]) == (0.4, 0.05, 0.4)
