"""Sensor error models: white noise, constant bias and optional heavy-tailed outliers.

Quantization is not modelled here: encoding through the DBC applies each
signal's own resolution. Defaults are typical of series-production sensors
(ESC cluster gyro and accelerometers, ABS wheel-speed sensors, steering angle
sensor, motor controllers); the second IMU (airbag unit) is noisier.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SensorError:
    noise: float  # standard deviation, SI
    bias: float = 0.0  # SI


DEFAULT_SENSORS = {
    "steering_wheel_angle": SensorError(math.radians(0.1)),
    **{f"wheel_speed_{w}": SensorError(0.05) for w in ("fl", "fr", "rl", "rr")},
    **{f"motor_torque_{w}": SensorError(2.0) for w in ("fl", "fr", "rl", "rr")},
    "ax": SensorError(0.05, 0.02),
    "ay": SensorError(0.05, -0.03),
    "yaw_rate": SensorError(math.radians(0.1), math.radians(0.05)),
    "ax_2": SensorError(0.1, -0.04),
    "ay_2": SensorError(0.1, 0.05),
    "yaw_rate_2": SensorError(math.radians(0.2), math.radians(-0.1)),
}

OUTLIER_SCALE = 10.0  # outliers are Student-t(2) draws scaled by this many noise standard deviations


class SensorModel:
    """Adds errors to true values; ``noise_scale`` multiplies every noise and bias."""

    def __init__(self, rng: np.random.Generator, noise_scale: float = 1.0, outlier_probability: float = 0.0,
                 errors: dict = DEFAULT_SENSORS):
        if not 0.0 <= outlier_probability < 1.0:
            raise ValueError(f"outlier probability must be in [0, 1), got {outlier_probability}")
        self.rng = rng
        self.scale = noise_scale
        self.outliers = outlier_probability
        self.errors = errors

    def measure(self, name: str, true_value: float) -> float:
        error = self.errors[name]
        noise = error.noise * self.scale
        value = true_value + error.bias * self.scale + noise * self.rng.standard_normal()
        if self.outliers and self.rng.random() < self.outliers:
            value += OUTLIER_SCALE * noise * self.rng.standard_t(2.0)
        return float(value)
