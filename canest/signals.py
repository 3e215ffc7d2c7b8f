"""Canonical input signals, their SI units, and unit conversion to SI.

Every input the estimator reads has a canonical name independent of any DBC.
A config maps each canonical name to ``MESSAGE.SIGNAL`` of its input DBC with
a unit; :func:`si_factor` turns that unit into the factor to SI.
Signs follow ISO 8855: x forward, y left, z up; a positive steering angle turns
left, a positive yaw rate is counter-clockwise seen from above.
"""
import math

G0 = 9.80665

# quantity -> SI unit, and the units accepted for it (in their normal spelling, :func:`normal_unit`) with their factor
UNITS = {
    "angle": ("rad", {"rad": 1.0, "deg": math.pi / 180.0, "mrad": 1e-3}),
    "angular_velocity": ("rad/s", {"rad/s": 1.0, "deg/s": math.pi / 180.0, "rpm": 2.0 * math.pi / 60.0}),
    "acceleration": ("m/s^2", {"m/s^2": 1.0, "g": G0}),
    "torque": ("N m", {"N m": 1.0, "kN m": 1000.0, "cN m": 0.01}),
}
# Wheel speeds given as a linear speed are divided by the wheel radius.
LINEAR_SPEED_UNITS = {"m/s": 1.0, "km/h": 1.0 / 3.6, "mph": 0.44704}

# Spellings met in real DBCs (opendbc's alone spell units 365 ways), compared without case or spaces, after the
# word replacements of SPELLED_OUT: spelling -> the unit it means. VW's ``Unit_...`` names are matched whole.
SPELLED_OUT = (("**", "^"), ("²", "^2"), ("°", "deg"), ("seconds", "s"), ("second", "s"), ("secs", "s"),
               ("sec", "s"), ("sek", "s"), ("degrees", "deg"), ("degree", "deg"), ("degs", "deg"),
               ("radians", "rad"), ("radian", "rad"), ("kilometers", "km"), ("kilometer", "km"),
               ("meters", "m"), ("meter", "m"), ("metres", "m"), ("metre", "m"), ("hour", "h"), ("hr", "h"))
ALIASES = {
    "rad": "rad", "deg": "deg", "mrad": "mrad", "unit_degreofarc": "deg", "unit_degreeofarc": "deg",
    "rad/s": "rad/s", "deg/s": "deg/s", "dps": "deg/s", "degré/s": "deg/s",
    "unit_degreofarcpersecon": "deg/s", "unit_degreepersecond": "deg/s",
    "rpm": "rpm", "rev/min": "rpm", "1/min": "rpm", "u/min": "rpm", "unit_minutinver": "rpm",
    "m/s^2": "m/s^2", "m/s2": "m/s^2", "m/s/s": "m/s^2", "mps2": "m/s^2", "mpss": "m/s^2", "g": "g",
    "unit_meterpersecondsquar": "m/s^2", "unit_meterpersquaresecond": "m/s^2", "unit_meterperseconsquar": "m/s^2",
    "unit_forceofgravi": "g",
    "nm": "N m", "n.m": "N m", "n*m": "N m", "n-m": "N m", "unit_newtometer": "N m", "knm": "kN m",
    "cnm": "cN m", "unit_centinewtometer": "cN m",
    "m/s": "m/s", "mps": "m/s", "unit_meterpersecon": "m/s", "unit_meterpersecond": "m/s",
    "km/h": "km/h", "kph": "km/h", "kmh": "km/h", "unit_kilometerperhour": "km/h", "mph": "mph", "mi/h": "mph",
}

WHEELS = ("fl", "fr", "rl", "rr")

# canonical name -> physical quantity
CANONICAL = {
    "steering_wheel_angle": "angle",
    **{f"wheel_speed_{w}": "angular_velocity" for w in WHEELS},
    **{f"motor_torque_{w}": "torque" for w in WHEELS},
    "ax": "acceleration",
    "ay": "acceleration",
    "yaw_rate": "angular_velocity",
    "ax_2": "acceleration",
    "ay_2": "acceleration",
    "yaw_rate_2": "angular_velocity",
}

# Inputs the status message reports as missing, one bit each, in this order.
INPUT_GROUPS = {
    "steering": ("steering_wheel_angle",),
    "wheel_speeds": tuple(f"wheel_speed_{w}" for w in WHEELS),
    "motor_torques": tuple(f"motor_torque_{w}" for w in WHEELS),
    "imu": ("ax", "ay", "yaw_rate"),
    "imu_2": ("ax_2", "ay_2", "yaw_rate_2"),
}


def si_unit(canonical: str) -> str:
    return UNITS[CANONICAL[canonical]][0]


def normal_unit(unit: str) -> str | None:
    """The unit a DBC or config spelling means (``Degrees`` -> ``deg``, ``km / h`` -> ``km/h``), None if unknown."""
    key = "".join(unit.split()).casefold()
    if key in ALIASES:
        return ALIASES[key]
    for spelled, short in SPELLED_OUT:
        key = key.replace(spelled, short)
    return ALIASES.get(key)


def si_factor(canonical: str, unit: str, wheel_radius: float) -> float:
    """Factor that turns a value in ``unit`` (any spelling :func:`normal_unit` knows) into the SI unit of ``canonical``.

    Wheel speeds may also be given as the wheel's linear speed (km/h, m/s,
    mph): they become rad/s through ``wheel_radius``. Raises ValueError
    naming the accepted units when ``unit`` does not fit.
    """
    quantity = CANONICAL[canonical]
    accepted = UNITS[quantity][1]
    key = normal_unit(unit)
    wheel = canonical.startswith("wheel_speed_")
    if wheel and key in LINEAR_SPEED_UNITS:
        return LINEAR_SPEED_UNITS[key] / wheel_radius
    if key not in accepted:
        extra = sorted(LINEAR_SPEED_UNITS) if wheel else []
        raise ValueError(f"unit '{unit}' is not a unit of {quantity}; use one of {sorted(accepted) + extra} "
                         "(in any spelling: case, spaces, 'degrees', '°', 'sec', 'kph', 'mps2' ...)")
    return accepted[key]
