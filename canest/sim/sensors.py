"""Sensor error models: white noise, constant bias, optional heavy-tailed outliers and IMU vibration.

Quantization is not modelled here: encoding through the DBC applies each
signal's own resolution. Defaults are typical of series-production sensors
(ESC cluster gyro and accelerometers, ABS wheel-speed sensors, steering angle
sensor, motor controllers); the second IMU (airbag unit) is noisier.

``vibration`` (a scale, 0 by default) adds what an IMU on a real body
measures beside its motion: coloured noise (first-order, ``VIBRATION_TIME``
correlation, a body's 10 Hz band) and road spikes (a Poisson process of
``SPIKE_RATE`` per second, each a decaying step of random size): at scale 1
about one 10 ms step of ay in six exceeds 2 m/s^2, as measured on a real drive.
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
VIBRATION = {"ax": 1.4, "ay": 1.4, "ax_2": 1.7, "ay_2": 1.7,  # std at scale 1, SI (m/s^2, rad/s)
             "yaw_rate": math.radians(0.3), "yaw_rate_2": math.radians(0.4)}
SPIKE = {"ax": 4.0, "ay": 4.0, "ax_2": 4.0, "ay_2": 4.0}  # road-spike std, m/s^2
VIBRATION_TIME = 0.015  # s
SPIKE_RATE = 0.5  # per s
SPIKE_TIME = 0.02  # s


class Vibration:
    """Coloured noise plus decaying road spikes on one channel, sampled at increasing times."""

    def __init__(self, rng: np.random.Generator, std: float, spike_std: float):
        self.rng, self.std, self.spike_std = rng, std, spike_std
        self.t = None
        self.value = 0.0
        self.spike = 0.0

    def at(self, t: float) -> float:
        if self.t is None:
            self.value = self.std * self.rng.standard_normal()
        elif t > self.t:
            dt = t - self.t
            keep = math.exp(-dt / VIBRATION_TIME)
            self.value = keep * self.value + math.sqrt(1.0 - keep * keep) * self.std * self.rng.standard_normal()
            self.spike *= math.exp(-dt / SPIKE_TIME)
            if self.spike_std and self.rng.random() < SPIKE_RATE * dt:
                self.spike += self.spike_std * self.rng.standard_normal()
        self.t = t if self.t is None else max(self.t, t)
        return self.value + self.spike


class SensorModel:
    """Adds errors to true values; ``noise_scale`` multiplies every noise and bias."""

    def __init__(self, rng: np.random.Generator, noise_scale: float = 1.0, outlier_probability: float = 0.0,
                 errors: dict = DEFAULT_SENSORS, vibration: float = 0.0):
        if not 0.0 <= outlier_probability < 1.0:
            raise ValueError(f"outlier probability must be in [0, 1), got {outlier_probability}")
        self.rng = rng
        self.scale = noise_scale
        self.outliers = outlier_probability
        self.errors = errors
        self.vibration = {name: Vibration(np.random.default_rng(rng.integers(2**32)), vibration * std,
                                          vibration * SPIKE.get(name, 0.0))
                          for name, std in VIBRATION.items()} if vibration else {}

    def measure(self, name: str, true_value: float, t: float = 0.0) -> float:
        error = self.errors[name]
        noise = error.noise * self.scale
        value = true_value + error.bias * self.scale + noise * self.rng.standard_normal()
        if self.outliers and self.rng.random() < self.outliers:
            value += OUTLIER_SCALE * noise * self.rng.standard_t(2.0)
        if name in self.vibration:
            value += self.vibration[name].at(t)
        return float(value)
