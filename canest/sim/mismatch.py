"""A simulated car that differs from its config: the "wrong config" a calibration has to correct.

The config describes the car as its user believes it is; :class:`PlantMismatch`
says how the simulated car really is: cornering stiffnesses scaled (the plant's
Magic Formula tire, :class:`canest.sim.tire.TireParams`), a steering ratio and an
effective wheel radius off by a factor, sensor biases (steering wheel angle,
gyro, lateral accelerometer, second gyro) in place of the defaults of
:mod:`canest.sim.sensors`, and a road bank: a constant tilt of the road about
the car's x axis, positive when the road falls to the left, so that gravity
pulls the car to the left with ``g sin(bank)`` (which the accelerometer, measuring
the tires' force, does not see), a road grade (positive uphill: gravity slows the car by ``g sin(grade)``,
which the accelerometer does not see either), and the body's roll and pitch gradients its accelerometers read
(:mod:`canest.models.attitude`; deg/g, None: the config's). :func:`true_vehicle` gives the parameters of the
car the plant drives, as a config would state them were it right, :func:`true_fit` the
calibration that would be exact. :func:`drawn_mismatch` draws a car as wrong as its config admits, the
honesty grid's test of whether the published standard deviations cover a real car's error;
:func:`flat_road_offsets` the offsets a banked road shows as.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from canest.calibration import BOUNDS, SHARED, Fit
from canest.models.wheels import GRAVITY, WheelGeometry
from canest.params import VehicleParams
from canest.sim.sensors import DEFAULT_SENSORS, SensorError
from canest.sim.tire import TireParams


BIASED_SENSORS = {"steering_offset": "steering_wheel_angle", "gyro_bias": "yaw_rate", "ay_bias": "ay",
                  "gyro_bias_2": "yaw_rate_2"}  # field: sensor


@dataclass(frozen=True)
class PlantMismatch:
    """How the simulated car differs from its config; the defaults change nothing. Angles in rad, SI."""

    stiffness_scale_front: float = 1.0
    stiffness_scale_rear: float = 1.0
    steering_ratio_scale: float = 1.0
    wheel_radius_scale: float = 1.0
    steering_offset: float | None = None  # rad at the steering wheel: measured = true + offset
    gyro_bias: float | None = None  # rad/s
    ay_bias: float | None = None  # m/s^2
    bank: float = 0.0  # rad
    roll_gradient: float | None = None  # deg/g the accelerometers read; None: the config's
    pitch_gradient: float | None = None  # deg/g
    grade: float = 0.0  # rad, positive uphill
    gyro_bias_2: float | None = None  # rad/s, the second (airbag unit's) gyro's

    def tire(self, tire: TireParams = TireParams()) -> TireParams:
        """The plant's tire with the lateral stiffnesses scaled."""
        return dataclasses.replace(tire,
                                   lateral_stiffness_front=tire.lateral_stiffness_front * self.stiffness_scale_front,
                                   lateral_stiffness_rear=tire.lateral_stiffness_rear * self.stiffness_scale_rear)

    def sensor_errors(self) -> dict:
        """The sensor error table with the biases this mismatch sets (noise as by default)."""
        errors = dict(DEFAULT_SENSORS)
        for field, sensor in BIASED_SENSORS.items():
            if getattr(self, field) is not None:
                errors[sensor] = SensorError(errors[sensor].noise, getattr(self, field))
        return errors

    def biases(self) -> dict:
        """The sensors' biases the plant's car has, by the calibration's names (:data:`BIASED_SENSORS`): this
        mismatch's, or the simulator's defaults where it leaves them unset."""
        errors = self.sensor_errors()
        return {field: errors[sensor].bias for field, sensor in BIASED_SENSORS.items()}

    @property
    def bank_acceleration(self) -> float:
        """Gravity's component along the car's y axis, m/s^2."""
        return GRAVITY * math.sin(self.bank)

    @property
    def grade_acceleration(self) -> float:
        """Gravity's component along the car's x axis, m/s^2 (negative uphill)."""
        return -GRAVITY * math.sin(self.grade)


def grade_angle(percent: float) -> float:
    """A road's grade in percent (rise per 100 m run, positive uphill) as :attr:`PlantMismatch.grade` (rad)."""
    return math.atan(percent / 100.0)


DRAWN_AY_BIAS = 0.1  # m/s^2, std: a production ESC accelerometer's residual offset plus a road's crown (2 % is 0.2)
DRAWN_GYRO_BIAS = math.radians(0.05)  # rad/s, std: what the built-in config's gyro noise (0.11 deg/s) leaves for bias
STIFFNESS_SCALE_LIMITS = (0.5, 1.5)
RADIUS_SCALE_LIMITS = BOUNDS["speed"]  # what a calibration may find


def drawn_mismatch(config_vehicle: VehicleParams, seed: int, gyro_bias_std: float = 0.0) -> PlantMismatch:
    """A car as wrong as its config admits, the same for every run of ``seed``: each axle's cornering stiffness
    scaled by ``1 + e N(0, 1)`` (``e`` the config's ``cornering_stiffness_uncertainty``, within
    :data:`STIFFNESS_SCALE_LIMITS`), lateral accelerometer and gyro biases drawn with :data:`DRAWN_AY_BIAS` and
    ``hypot(DRAWN_GYRO_BIAS, gyro_bias_std)`` (the config's ``estimator.gyro_bias_std``: a bias beyond what its
    gyro noise admits), the wheel radius scaled by ``1 + e_r N(0, 1)`` (``e_r`` the config's
    ``wheel_radius_uncertainty``, within :data:`RADIUS_SCALE_LIMITS`; the fifth draw, so a config claiming 0 draws
    the cars it drew before)."""
    normal = np.random.default_rng([seed, 8855]).standard_normal(5)
    low, high = STIFFNESS_SCALE_LIMITS
    scale = np.clip(1.0 + config_vehicle.cornering_stiffness_uncertainty * normal[:2], low, high)
    return PlantMismatch(stiffness_scale_front=float(scale[0]), stiffness_scale_rear=float(scale[1]),
                         wheel_radius_scale=float(np.clip(1.0 + config_vehicle.wheel_radius_uncertainty * normal[4],
                                                          *RADIUS_SCALE_LIMITS)),
                         ay_bias=float(DRAWN_AY_BIAS * normal[2]),
                         gyro_bias=float(math.hypot(DRAWN_GYRO_BIAS, gyro_bias_std) * normal[3]))


def true_vehicle(config_vehicle: VehicleParams, mismatch: PlantMismatch,
                 tire: TireParams = TireParams()) -> VehicleParams:
    """The car the plant drives: ratio and wheel radius scaled, the axle cornering stiffnesses of its tire
    at static load and its accelerometers' tilt (what a right config would say)."""
    geometry = WheelGeometry(config_vehicle)
    loads = geometry.static_load
    scaled = mismatch.tire(tire)
    return dataclasses.replace(
        config_vehicle,
        steering_ratio=config_vehicle.steering_ratio * mismatch.steering_ratio_scale,
        wheel_radius=config_vehicle.wheel_radius * mismatch.wheel_radius_scale,
        cornering_stiffness_front=float(scaled.lateral_stiffness_front * loads[:2].sum()),
        cornering_stiffness_rear=float(scaled.lateral_stiffness_rear * loads[2:].sum()),
        **{f"accelerometer_{axis}_gradient": value for axis, value in (("roll", mismatch.roll_gradient),
                                                                        ("pitch", mismatch.pitch_gradient))
           if value is not None})


def flat_road_offsets(config_vehicle: VehicleParams, mismatch: PlantMismatch) -> tuple:
    """The steering offset (rad) and the ay bias (m/s^2) of the *equivalent flat road*: in the steady single-track
    equations a bank shows only as a change of these two, ``offset - R K_us g sin(bank)`` and ``bias - g
    sin(bank)`` (the tires carry ``m (v r - g sin(bank))``, the accelerometer reads their force), so these are
    what a calibration can learn on this road (README "Online calibration"); ``R`` and ``K_us`` the car's own, the
    biases the sensors' (:meth:`PlantMismatch.biases`). Linear tires': with the plant's curve under the
    bank's side force, the offline fit over 120 s finds 0.2-0.3 deg more (3 deg of bank, seeds 8 and 9: -2.67
    and -2.57 where this gives -2.38)."""
    truth = true_vehicle(config_vehicle, mismatch)
    biases, side = mismatch.biases(), mismatch.bank_acceleration
    return (biases["steering_offset"] - truth.steering_ratio * truth.understeer_gradient * side,
            biases["ay_bias"] - side)


def true_fit(config_vehicle: VehicleParams, mismatch: PlantMismatch, banks=(0.0,)) -> Fit:
    """The calibration that would be exact for this car (intervals 0), in the terms of :mod:`canest.models.output_error`;
    ``banks`` (rad) per log, and the second gyro's bias (:mod:`canest.models.second_gyro`). Written with
    :func:`canest.apps.calibrated_config.write_calibrated` it is the right config, the baseline a calibrated one is
    measured against."""
    truth = true_vehicle(config_vehicle, mismatch)
    values = {"front": truth.cornering_stiffness_front / config_vehicle.cornering_stiffness_front,
              "rear": truth.cornering_stiffness_rear / config_vehicle.cornering_stiffness_rear,
              "ratio": mismatch.steering_ratio_scale, "speed": mismatch.wheel_radius_scale,
              **mismatch.biases()}
    names = [*(p.name for p in SHARED), *(f"bank[{i}]" for i in range(len(banks))), "gyro_bias_2"]
    exact = np.array([*(values[p.name] for p in SHARED), *banks, values["gyro_bias_2"]])
    return Fit(names, exact, np.zeros(len(names)), np.eye(len(names)), {}, 0.0)
