"""Vehicle and tire parameter types, in SI units.

The models take these; the YAML loader (:mod:`canest.config`) fills them. They
sit below both so that no model imports the configuration.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TireModelParams:
    """The estimators' tire coefficients (config ``vehicle.tire``); textbook passenger-car defaults.

    The cornering stiffness at static load comes from the vehicle's axle
    cornering stiffnesses; these set the shape of the curve around it.
    """

    lateral_shape: float = 1.3  # C (Pacejka's textbook value for side force)
    lateral_curvature: float = -0.3  # E
    load_sensitivity: float = 2.0  # q of the degressive cornering stiffness
    longitudinal_stiffness: float = 15.0  # K / Fz, per unit slip ratio
    longitudinal_shape: float = 1.65  # C (textbook value for brake/drive force)
    longitudinal_curvature: float = 0.0
    relaxation_length: float = 0.5  # m
    # F_r / Fz of the rolling moment (a passenger tire on asphalt: 0.010-0.015): part of a motor's torque that turns
    # no tire force, so makes no slip (a wheel rolling forward: J dw/dt = T - R (Fx + f_r Fz))
    rolling_resistance: float = 0.012
    nominal_friction: float = 0.9  # mu of the 7-state tire-force model



@dataclass(frozen=True)
class VehicleParams:
    """Vehicle parameters in SI units. Cornering stiffnesses are per axle, positive."""

    name: str
    mass: float
    yaw_inertia: float
    cg_to_front: float
    cg_to_rear: float
    track_front: float
    track_rear: float
    cg_height: float
    wheel_radius: float
    wheel_inertia: float
    steering_ratio: float
    cornering_stiffness_front: float
    cornering_stiffness_rear: float
    tire: TireModelParams = TireModelParams()
    drive_front_share: float = 1.0  # front axle's share of a drive force (config drive: front 1, rear 0, all: given)
    brake_front_share: float = 0.7  # front axle's share of a braking force (brake balance)
    # relative (1 std) error of the cornering stiffnesses: 0.3 for textbook values, less once identified
    # (``canest calibrate``); the published sideslip std carries it (estimation.validity)
    cornering_stiffness_uncertainty: float = 0.3
    # relative (1 std) error of ``wheel_radius`` as the effective rolling radius: from the tire's size code, taken
    # 2-3 % below its unloaded radius (README "Your car"), within ~2 % (wear takes up to 2.5 % over a tread's life,
    # pressure and load ~1 %); the published vx carries it until the online calibration applies its own scale
    # (estimation.judge.StateJudge.widen)
    wheel_radius_uncertainty: float = 0.02
    # deg/g (the field's unit) of body roll and nose-up pitch that the accelerometers read as gravity
    # (canest.models.attitude); 0: the ESC publishes ax and ay level
    accelerometer_roll_gradient: float = 0.0
    accelerometer_pitch_gradient: float = 0.0

    @property
    def wheelbase(self) -> float:
        return self.cg_to_front + self.cg_to_rear

    @property
    def understeer_gradient(self) -> float:
        """K_us of the linear single-track model (s^2/m): steady road wheel angle = r (L + K_us vx^2) / vx."""
        cf, cr = self.cornering_stiffness_front, self.cornering_stiffness_rear
        return self.mass * (self.cg_to_rear * cr - self.cg_to_front * cf) / (self.wheelbase * cf * cr)
