"""Binding of the 7-state tire-force model (:mod:`canest.models.tire_force`) to the tick core.

Four lateral tire forces beside yaw rate, sideslip and vx, with any
sigma-point filter on the first IMU, or with ``dici-gfckf`` whose local
filters each get one IMU (plus the shared wheel speeds). The model's input
``Fx`` per wheel comes from the motor torques and the wheel accelerations
(DICI-GFCKF eq 4, :mod:`canest.models.wheel_force`); a config that maps no
motor torques gets :class:`~canest.models.tire_force.AxDrivenTireForceModel`,
whose longitudinal forces follow from ax and the drive layout (eq 1), so the
model (and its tire saturation) runs on any car. The lateral channels (ax,
ay) are skipped at low speed, as the single-track binding skips ay.
"""
from __future__ import annotations

import math

import numpy as np

from canest.estimation.channels import rows_of
from canest.estimation import validity
from canest.estimation.core import Estimator
from canest.estimation.inputs import WHEEL_SPEEDS, TickInputs
from canest.estimation.reference_speed import TORQUES
from canest.estimation.roll_lag import LoadAccelerations, accelerations
from canest.models import tire_force
from canest.models.tire import relaxation_rate
from canest.models.tire_force import AxDrivenTireForceModel, TireForceModel
from canest.models.wheels import MIN_WHEEL_SPEED
from canest.models.wheel_force import WheelAcceleration, longitudinal_forces
from canest.signals import WHEELS

LATERAL_FORCES = tuple(f"fy_{w}" for w in WHEELS)


def torques(inputs: TickInputs) -> np.ndarray:
    """The four motor torques as held (0 where not mapped)."""
    return np.array([inputs.values.get(name, 0.0) for name in TORQUES])


class TireForceEstimator(Estimator):
    extra_states = LATERAL_FORCES
    covariance_has_tire_error = True  # :meth:`_process_noise`

    def __init__(self, config):
        self.torques = all(name in config.signals for name in TORQUES)
        model = TireForceModel if self.torques else AxDrivenTireForceModel
        super().__init__(config, model(config.vehicle, config.vehicle.tire))
        self.sensor_sets = np.array(self.model.sensor_sets)
        self.force_inputs = TORQUES if self.torques else ("ax",)  # what the longitudinal forces come from
        self.wheel_acceleration = WheelAcceleration()
        self.load_accelerations = LoadAccelerations(self.dt)

    def reset(self) -> None:
        super().reset()
        self.wheel_acceleration.reset()
        self.load_accelerations.reset()

    def _initial_state(self, inputs: TickInputs) -> np.ndarray:
        """As the single track, and each lateral force at its load share of ``m ay``."""
        x0 = super()._initial_state(inputs)
        ax, ay = accelerations(inputs)
        loads = self.model.wheels.loads(ax, ay)
        x0[tire_force.FY] = self.vehicle.mass * ay * loads / loads.sum()
        return x0

    def _process_noise(self, t: float) -> np.ndarray:
        """The core's Q (with vx's from the measured ax where the forces come from ax) plus the tire curve's error on
        the lateral forces: an axle's cornering stiffness off by
        ``e`` (the stiffness uncertainty) moves the steady-state forces of both its wheels by ``e F``, together (on
        a saturated tire the same term stands for the nominal friction's error). A force that relaxes by
        ``a = exp(-rho dt)`` per tick (``rho = V / sigma``) towards such a steady state keeps an error of ``e F``
        under a white noise of variance ``(1 - a^2) (e F)^2`` per tick: per axle the rank-one
        ``(1 - a^2) e^2 F F^T`` (left and right fully correlated, so their split is left to the configured,
        independent part). None at low speed, where the forces follow their load shares of ``m ay``."""
        Q = super()._process_noise(t)
        if self.low_speed:
            return Q
        x = self.filter.x
        rate = relaxation_rate(max(x[self.vx], MIN_WHEEL_SPEED), self.vehicle.tire.relaxation_length)
        Q = Q.copy()
        for axle in tire_force.AXLE_FORCES:
            error = self.vehicle.cornering_stiffness_uncertainty * x[axle]
            Q[axle, axle] -= math.expm1(-2.0 * rate * self.dt) * np.outer(error, error)
        return Q

    def _control(self, inputs: TickInputs, t: float) -> np.ndarray:
        """u = (delta, ax, ay, ax's offset, Fx per wheel from eq 4); without motor torques (delta, ax, ay, ax's
        offset); ax as held, ay as the loads take it, through the body's roll lag
        (:mod:`canest.estimation.roll_lag`).
        ax's offset from the wheels' acceleration (a road's grade, :mod:`canest.estimation.longitudinal_offset`)
        slows vx beside the tires' forces: without torques vx then follows ax less it, as the single track's vx
        does (the core takes the reference speed's integration error as this model's own, so it must integrate
        the same ax); with torques a grade's gravity no longer runs vx ahead of the reference speed uphill."""
        ax, ay = self.load_accelerations.update(inputs)
        offset = self.reference_speed.offset.value
        if not self.torques:
            return np.array([self._road_wheel_angle(inputs), ax, ay, offset])
        speeds = [inputs.values.get(name, 0.0) for name in WHEEL_SPEEDS]
        fx = longitudinal_forces(torques(inputs), self.wheel_acceleration.update(t, speeds),
                                 self.vehicle.wheel_inertia, self.vehicle.wheel_radius,
                                 self.vehicle.tire.rolling_resistance * self.model.wheels.loads(ax, ay))
        return np.array([self._road_wheel_angle(inputs), ax, ay, offset, *fx])

    def _update(self, channels, inputs: TickInputs, u: np.ndarray, lateral_ok: bool, t: float) -> bool:
        """Non-DICI filters use the first IMU; ``dici-gfckf`` gives local filter j the rows of IMU j."""
        if "sensor_sets" not in self.filter.needs:
            return self._apply(channels, u, t, mask=self.sensor_sets <= 1)
        local_masks = [channels.mask & ((self.sensor_sets == 0) | (self.sensor_sets == j + 1))
                       for j in range(self.filter.sensor_sets)]
        if not any(m.any() for m in local_masks):
            return False
        compensate = self.latency_compensation and not self.low_speed
        given = [rows_of(channels, self.model, compensate, m) if m.any() else None for m in local_masks]
        self.filter.update_sets(given, u)
        return self._diverged(t)

    def _extra_values(self, values: dict, valid: dict, causes: dict, std: np.ndarray, inputs: TickInputs,
                      ratios: dict) -> None:
        """The forces are valid where sideslip is (they are judged by the same lateral channels) and the inputs of
        the longitudinal forces (torques, else ax) are in."""
        cause = causes["beta"] if causes["beta"] != "valid" or inputs.has(*self.force_inputs) else "no_input"
        inflation = validity.inflation(ratios["beta"])
        for name, force, force_std in zip(LATERAL_FORCES, self.filter.x[tire_force.FY], std[tire_force.FY]):
            values[name], values[f"{name}_std"] = force, force_std * inflation
            valid[name] = cause == "valid"
        valid["forces"] = cause == "valid"
        causes["forces"] = cause
