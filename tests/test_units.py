"""Unit spellings as cantools users meet them in real DBCs, and the DBC's unit against the config's."""
import math
import re

import pytest

from canest.config import load_config
from canest.signals import G0, normal_unit, si_factor
from tests.test_config import error_of, write_variant

DEG = math.pi / 180.0


@pytest.mark.parametrize("canonical, spellings, factor", [
    ("steering_wheel_angle", ["deg", "degrees", "Degrees", "Deg", "degree", "°", "Unit_DegreOfArc"], DEG),
    ("steering_wheel_angle", ["rad", "radians", "RAD"], 1.0),
    ("yaw_rate", ["deg/s", "deg/sec", "Deg/s", "degrees/sec", "degrees/second", "°/s", "Unit_DegreOfArcPerSecon"], DEG),
    ("yaw_rate", ["rad/s", "radians/second", "rad / s"], 1.0),
    ("wheel_speed_fl", ["rpm", "RPM", "1/min", "Unit_MinutInver"], 2 * math.pi / 60),
    ("ax", ["m/s^2", "m/s2", "mps2", "m/s²", "m/s**2", "meters/sec/sec", "m/sec^2", "Unit_MeterPerSeconSquar"], 1.0),
    ("ax", ["g", "G", "Unit_ForceOfGravi"], G0),
    ("motor_torque_fl", ["Nm", "N m", "NM", "N*m", "Unit_NewtoMeter"], 1.0),
])
def test_spellings_mean_their_unit(canonical, spellings, factor):
    for spelling in spellings:
        assert si_factor(canonical, spelling, 0.3) == pytest.approx(factor), spelling


@pytest.mark.parametrize("spelling, per_hour", [("km/h", 3.6), ("kph", 3.6), ("KPH", 3.6), ("Kph", 3.6),
                                                ("km / h", 3.6), ("kilometer/hour", 3.6),
                                                ("Unit_KiloMeterPerHour", 3.6), ("mph", 3600 / 1609.344),
                                                ("m/s", 1.0), ("meters/sec", 1.0)])
def test_wheel_speeds_as_linear_speed_in_any_spelling(spelling, per_hour):
    assert si_factor("wheel_speed_rr", spelling, 0.5) == pytest.approx(1 / per_hour / 0.5)


def test_units_of_another_quantity_or_unknown_are_refused():
    for canonical, unit in (("ax", "deg/s"), ("steering_wheel_angle", "km/h"), ("yaw_rate", "grad/s"),
                            ("ax", "furlong")):
        with pytest.raises(ValueError, match="is not a unit of"):
            si_factor(canonical, unit, 0.3)
    assert normal_unit("kph/mph") is None and normal_unit("") is None


def dbc_unit(tmp_path, spelling, config_unit):
    """The reference config with the steering angle's DBC unit spelled ``spelling`` and ``unit: config_unit``."""
    def edit(data):
        data["input"]["signals"]["steering_wheel_angle"]["unit"] = config_unit
    path = write_variant(tmp_path, edit)
    dbc = tmp_path / "dbc" / "canest_vehicle.dbc"
    dbc.write_text(dbc.read_text().replace('[-780|780] "deg"', f'[-780|780] "{spelling}"'))
    return path


@pytest.mark.parametrize("spelling", ["degrees", "Deg", "°", "Degrees"])
def test_config_unit_deg_agrees_with_a_dbc_spelling_it_differently(tmp_path, spelling):
    config = load_config(dbc_unit(tmp_path, spelling, "deg"))
    assert config.signals["steering_wheel_angle"].factor == pytest.approx(DEG)


def test_config_unit_contradicting_the_dbc_names_file_line_key(tmp_path):
    path = dbc_unit(tmp_path, "degrees", "rad")
    message = error_of(path)
    assert re.match(rf"{re.escape(str(path))}:\d+: input\.signals\.steering_wheel_angle\.unit: 'rad' contradicts "
                    r"the DBC unit 'degrees'", message), message


def test_a_dbc_unit_canest_does_not_know_is_overridden_by_the_config(tmp_path):
    config = load_config(dbc_unit(tmp_path, "Unitless", "degrees"))
    assert config.signals["steering_wheel_angle"].factor == pytest.approx(DEG)
