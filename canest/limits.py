"""The physical range of every number a config gives, checked on load (README "Configuration", the table).

Generous, but physical: from a light quadricycle to a loaded truck, so a unit
slip (grams for kilograms, millimetres for metres), a sign error or a
not-a-number is refused with the file, the line and the range instead of
being estimated with.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Range:
    """An interval a number must lie in: ``low <= value <= high`` (``< high`` when ``high_open``)."""

    low: float
    high: float
    unit: str = ""
    high_open: bool = False

    def violation(self, value: float) -> str | None:
        """What is wrong with ``value`` (None if it lies in the range), with the range itself."""
        if not math.isfinite(value):
            problem = "must be a finite number"
        elif value <= 0 < self.low:
            problem = "must be positive"
        elif value < self.low:
            problem = f"must be at least {self.low:g}"
        elif self.high_open and value >= self.high:
            problem = f"must be below {self.high:g}"
        elif value > self.high:
            problem = f"must be at most {self.high:g}"
        else:
            return None
        return f"{problem} ({self})"

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        high = f"below {self.high:g}" if self.high_open else f"{self.high:g}"
        return f"{self.low:g} to {high}{unit}"


VEHICLE = {
    "mass": Range(100.0, 60000.0, "kg"),
    "yaw_inertia": Range(10.0, 1e6, "kg m^2"),
    "cg_to_front": Range(0.1, 10.0, "m"),
    "cg_to_rear": Range(0.1, 10.0, "m"),
    "track_front": Range(0.3, 3.5, "m"),
    "track_rear": Range(0.3, 3.5, "m"),
    "cg_height": Range(0.05, 5.0, "m"),
    "wheel_radius": Range(0.1, 2.0, "m"),
    "wheel_inertia": Range(0.01, 500.0, "kg m^2"),
    "steering_ratio": Range(1.0, 50.0),
    "cornering_stiffness_front": Range(1000.0, 5e6, "N/rad"),
    "cornering_stiffness_rear": Range(1000.0, 5e6, "N/rad"),
}

TIRE = {
    "lateral_shape": Range(0.5, 3.0),
    "lateral_curvature": Range(-10.0, 1.0),
    "load_sensitivity": Range(0.1, 20.0),
    "longitudinal_stiffness": Range(1.0, 100.0, "per unit slip"),
    "longitudinal_shape": Range(0.5, 3.0),
    "longitudinal_curvature": Range(-10.0, 1.0),
    "relaxation_length": Range(0.01, 5.0, "m"),
    "rolling_resistance": Range(0.0, 0.05),
    "nominal_friction": Range(0.05, 2.0),
}

STIFFNESS_UNCERTAINTY = Range(0.0, 1.0)  # vehicle.cornering_stiffness_uncertainty, relative (optional)
RADIUS_UNCERTAINTY = Range(0.0, 0.2)  # vehicle.wheel_radius_uncertainty, relative (optional): no tire is 20 % off
ATTITUDE = {  # vehicle (optional, 0 by default): the body's tilt the accelerometers read, 15: more than a soft SUV's
    "accelerometer_roll_gradient": Range(0.0, 15.0, "deg/g"),
    "accelerometer_pitch_gradient": Range(0.0, 15.0, "deg/g"),
}

DRIVE = {  # vehicle: the axle shares of the longitudinal force, for the tire-force model without motor torques
    "drive_front_share": Range(0.0, 1.0),
    "brake_front_share": Range(0.0, 1.0),
}
DRIVE_LAYOUTS = {"front": 1.0, "rear": 0.0, "all": None}  # vehicle.drive -> front share of a drive force (all: given)

ESTIMATOR = {
    "rate_hz": Range(1.0, 1000.0, "Hz"),
    "min_speed": Range(0.0, 50.0, "m/s"),
    "speed_hysteresis": Range(0.0, 20.0, "m/s"),
    "timeout_cycles": Range(1.0, 1000.0),
    "friction_excitation": Range(1.0, 1e6, "N"),
    "friction_correlation": Range(0.0, 1.0, high_open=True),
    "gyro_bias_std": Range(0.0, 0.1, "rad/s"),  # 0.1 rad/s: 5.7 deg/s, no working yaw-rate sensor's bias
    "lateral_model_error": Range(0.0, 1.0),  # m/s^2 per m/s^2 of |ay|; 1: the model's ay no better than zero
}

NOISE = Range(1e-9, 1e6)  # process noise, measurement noise and initial standard deviations, in their SI units

SIGNAL = {  # input.signals.<name>: SI = sign * scale * unit factor * DBC value + offset
    "scale": Range(1e-9, 1e9),
    "offset": Range(-1e9, 1e9),
    "stuck_after": Range(0.1, 3600.0, "s"),  # exact repetition this long while moving: a stuck sender
    "range": Range(-1e12, 1e12),  # each bound of a range override, in the DBC's physical unit
}

MESSAGE = {  # input.messages.<name>
    "cycle_time": Range(0.0005, 60.0, "s"),  # overrides the DBC's GenMsgCycleTime
}
