"""The parameters the online calibration learns: start, prior std, physical bounds, drift, convergence, rate.

``front`` and ``rear`` are factors on the configured cornering stiffnesses (learned from windows of driving by
:mod:`canest.estimation.stiffness_window`); the others are learned by the identities of
:mod:`canest.estimation.online_calibration`."""
from __future__ import annotations

import math
from dataclasses import dataclass

from canest.calibration import BOUNDS  # the sensor and steering parameters' are the offline fit's
from canest.params import VehicleParams


@dataclass(frozen=True)
class Learned:
    """One learned parameter: start, prior std, bounds, drift (std per hour), converged std, applied rate (per s)."""

    name: str
    start: float
    std: float
    low: float
    high: float
    drift: float
    converged: float
    rate: float


def parameters(vehicle: VehicleParams, gyro_bias_std: float = 0.0) -> tuple:
    """The learned parameters; the understeer gradient starts at the config's; the speed scale's, the gyro
    biases' and the cornering stiffnesses' prior never narrower than what the config claims of them
    (``vehicle.wheel_radius_uncertainty``, ``estimator.gyro_bias_std``, rad/s,
    ``vehicle.cornering_stiffness_uncertainty``), whose place their learned error takes once applied (the
    stiffnesses': for linear tires, ``Estimator.use_stiffness``)."""
    deg = math.radians(1.0)
    stiffness_std = max(0.3, vehicle.cornering_stiffness_uncertainty)
    gyro = (0.0, max(0.5 * deg, gyro_bias_std), *BOUNDS["gyro_bias"], 0.01 * deg, 0.15 * deg, 0.1 * deg)
    return (
        Learned("speed", 1.0, max(0.03, vehicle.wheel_radius_uncertainty), *BOUNDS["speed"], 0.001, 0.005, 0.01),
        Learned("gyro_bias", *gyro),
        Learned("ay_bias", 0.0, 0.3, *BOUNDS["ay_bias"], 0.01, 0.05, 0.1),
        Learned("steering_offset", 0.0, 2.0 * deg, *BOUNDS["steering_offset"], 0.05 * deg, 0.2 * deg, 1.0 * deg),
        Learned("ratio", 1.0, 0.1, *BOUNDS["ratio"], 0.002, 0.03, 0.025),
        Learned("understeer", vehicle.understeer_gradient, 0.003, -0.01, 0.02, 0.0001, 0.0005, 0.0),
        Learned("ax_bias", 0.0, 0.3, -2.0, 2.0, 0.01, 0.03, 0.0),  # reported, not applied: no rate
        Learned("front", 1.0, stiffness_std, 0.5, 2.0, 0.02, 0.05, 0.05),
        Learned("rear", 1.0, stiffness_std, 0.5, 2.0, 0.02, 0.05, 0.05),
        Learned("gyro_bias_2", *gyro),  # the second gyro's (an airbag unit's), where the car sends one
    )


NAMES = ("speed", "gyro_bias", "ay_bias", "steering_offset", "ratio", "understeer", "ax_bias", "front", "rear",
         "gyro_bias_2")
SPEED, GYRO, AY, OFFSET, RATIO, UNDERSTEER, AX, FRONT, REAR, GYRO_2 = range(len(NAMES))
# the steering and lateral offsets are not applied: a bank shows as both; nor ax's: a road's grade moves it faster
# than a calibration may follow, and the reference speed learns it from the wheels within a second
# (:mod:`canest.estimation.longitudinal_offset`)
APPLIED = (SPEED, GYRO, RATIO, FRONT, REAR, GYRO_2)
STIFFNESS = (FRONT, REAR)  # factors on the configured cornering stiffnesses, learned by the window fit
