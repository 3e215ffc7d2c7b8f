"""Canonical input signals, their SI units, and unit conversion to SI.

Every input the estimator reads has a canonical name independent of any DBC.
A config maps each canonical name to ``MESSAGE.SIGNAL`` of its input DBC with
a unit; :func:`si_factor` turns that unit into the factor to SI.
Signs follow ISO 8855: x forward, y left, z up; a positive steering angle turns
left, a positive yaw rate is counter-clockwise seen from above.
"""
import math

G0 = 9.80665

# quantity -> SI unit, and the units accepted for it with their factor to SI
UNITS = {
    "angle": ("rad", {"rad": 1.0, "deg": math.pi / 180.0}),
    "angular_velocity": ("rad/s", {"rad/s": 1.0, "deg/s": math.pi / 180.0, "rpm": 2.0 * math.pi / 60.0}),
    "acceleration": ("m/s^2", {"m/s^2": 1.0, "m/s2": 1.0, "g": G0}),
    "torque": ("N m", {"N m": 1.0, "Nm": 1.0, "kNm": 1000.0}),
}
# Wheel speeds given as a linear speed are divided by the wheel radius.
LINEAR_SPEED_UNITS = {"m/s": 1.0, "km/h": 1.0 / 3.6, "kph": 1.0 / 3.6, "mph": 0.44704}

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


def si_factor(canonical: str, unit: str, wheel_radius: float) -> float:
    """Factor that turns a value in ``unit`` into the SI unit of ``canonical``.

    Wheel speeds may also be given as the wheel's linear speed (km/h, m/s,
    mph): they become rad/s through ``wheel_radius``. Raises ValueError
    naming the accepted units when ``unit`` does not fit.
    """
    quantity = CANONICAL[canonical]
    accepted = UNITS[quantity][1]
    key = unit.strip()
    if canonical.startswith("wheel_speed_") and key in LINEAR_SPEED_UNITS:
        return LINEAR_SPEED_UNITS[key] / wheel_radius
    if key not in accepted:
        extra = sorted(LINEAR_SPEED_UNITS) if canonical.startswith("wheel_speed_") else []
        raise ValueError(f"unit '{unit}' is not a unit of {quantity}; use one of {sorted(accepted) + extra}")
    return accepted[key]
