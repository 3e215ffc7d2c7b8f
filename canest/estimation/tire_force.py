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
from canest.estimation.lags import FadingMaximum
from canest.estimation.reference_speed import TORQUES
from canest.estimation.roll_lag import LoadAccelerations, accelerations
from canest.models import tire_force
from canest.models.tire import left_shares, relaxation_rate, slip_for_force
from canest.models.tire_force import AxDrivenTireForceModel, TireForceModel
from canest.models.wheels import MIN_WHEEL_SPEED
from canest.models.wheel_force import WheelAcceleration, longitudinal_forces
from canest.signals import WHEELS

LATERAL_FORCES = tuple(f"fy_{w}" for w in WHEELS)
# the tire's load sensitivity ``q`` (:func:`canest.models.tire.cornering_stiffness`) is assumed, never measured:
# the real one taken anywhere within this factor of the configured (log-uniform, ``SPLIT_POINTS`` midpoints); around
# the default 2 that is 1 (a stiffness that stops growing at the static load) to 4 (nearly proportional to the load
# over what a cornering car's wheels carry)
LOAD_SENSITIVITY_SPAN = 2.0
SPLIT_POINTS = 8
FRICTION_POINTS = 8  # midpoints over the frictions the forces admit (:meth:`TireForceEstimator._sideslip_friction_std`)


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
        self.loads = self.model.wheels.static_load  # the wheel loads of the last tick (:meth:`_control`)
        exponents = 2.0 * (np.arange(SPLIT_POINTS) + 0.5) / SPLIT_POINTS - 1.0
        self.other_sensitivities = (config.vehicle.tire.load_sensitivity
                                    * LOAD_SENSITIVITY_SPAN ** exponents)[:, None]
        self.friction_slip = FadingMaximum(self.dt, validity.MODEL_ERROR_MEMORY)  # :meth:`_sideslip_friction_std`

    def reset(self) -> None:
        super().reset()
        self.friction_slip.reset()
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
        self.loads = self.model.wheels.loads(ax, ay)
        offset = self.reference_speed.offset.value
        if not self.torques:
            return np.array([self._road_wheel_angle(inputs), ax, ay, offset])
        speeds = [inputs.values.get(name, 0.0) for name in WHEEL_SPEEDS]
        fx = longitudinal_forces(torques(inputs), self.wheel_acceleration.update(t, speeds),
                                 self.vehicle.wheel_inertia, self.vehicle.wheel_radius,
                                 self.vehicle.tire.rolling_resistance * self.loads)
        return np.array([self._road_wheel_angle(inputs), ax, ay, offset, *fx])

    def _sideslip_friction_std(self) -> float:
        """The sideslip's error (rad) from the friction the tire curve assumes (``tire.nominal_friction``), which
        this model never learns: a friction lower than the nominal needs a larger slip angle for the same force,
        and near its peak much larger, which no relative stiffness error (:func:`validity.sideslip_model_std`)
        holds. The road's friction is at least what the estimate's tires carry now (the largest ``|Fy| / Fz`` of
        its four wheels: one road under all four) and, as far as the model knows, anything up to the nominal;
        taken uniform over that range (midpoints of ``FRICTION_POINTS`` bins), the rear wheels' mean slip angle
        for the forces the estimate carries moves from the nominal friction's by this root mean square; with the
        yaw rate measured the sideslip moves with the rear slip angle. It vanishes in the linear range (every
        friction needs the cornering stiffness's slip angle) and at the nominal's limit; held as the stiffness
        term is (``validity.MODEL_ERROR_MEMORY``), since the per-wheel forces it rests on flicker from tick to
        tick. The uniform prior is an assumption, not a measurement: its lower end puts a tire at its peak. On the
        drawn cars with a vibrating IMU, dici-gfckf's sideslip in the step steer on 0.85 was 1.0-1.7 deg off with
        a std of 0.55-0.6 in the steady turn, flagged valid: its rear tires at 0.8 of their load, the curve's
        friction 0.9, the road's 0.85."""
        if self.low_speed:
            return 0.0
        tire = self.vehicle.tire
        loads = self.loads
        forces = self.filter.x[tire_force.FY]
        if not (np.all(np.isfinite(forces)) and np.all(loads > 0.0)):
            return 0.0
        lowest = min(float(np.max(np.abs(forces) / loads)), tire.nominal_friction)
        bins = (np.arange(FRICTION_POINTS) + 0.5) / FRICTION_POINTS
        frictions = np.append(lowest + (tire.nominal_friction - lowest) * bins, tire.nominal_friction)[:, None]
        stiffness = self.model.wheels.cornering_stiffness(loads, tire)
        rear = slice(2, 4)
        slips = slip_for_force(forces[rear], stiffness[rear], tire.lateral_shape, tire.lateral_curvature,
                               frictions * loads[rear]).mean(axis=1)
        return self.friction_slip.update(float(np.sqrt(np.mean((slips[:-1] - slips[-1]) ** 2))))

    def _split_std(self) -> np.ndarray:
        """Each wheel's error (N) from its axle's left/right split, which no channel observes (ay and the yaw
        acceleration see an axle's sum; a front pair's difference turns the car only through ``sin(delta)``): the
        model splits by the load sensitivity of its tires' cornering stiffness (:func:`left_shares`: the lightly
        loaded inner wheel takes less than half), which the config assumes. With the real one anywhere within
        ``LOAD_SENSITIVITY_SPAN`` of it, the root mean square of the distance between the estimate's left wheel
        and its share of the axle's force under each (the right wheel's is the same: it moves as the left does).
        Measured from the estimate's split, not the model's: that one wanders too (the process noise moves each
        wheel, a vibrating ay the loads). The process noise's stiffness term leaves the split only the
        stiffness's relative error of the wheels' difference (:meth:`_process_noise`): on the drawn cars with a
        vibrating IMU, the inner wheels of dici-gfckf's step on 0.85 carried 800-1000 N against a true 1670 with
        a std of 200 (the simulator's tires: ``q`` 1.5 where the config says 2.0), flagged valid."""
        forces = self.filter.x[tire_force.FY]
        left, axle = forces[0::2], forces[0::2] + forces[1::2]
        shares = left_shares(self.loads, self.model.wheels.static_load, self.other_sensitivities)
        return np.repeat(np.sqrt(np.mean((shares * axle - left) ** 2, axis=0)), 2)

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
        for name, force, force_std, split_std in zip(LATERAL_FORCES, self.filter.x[tire_force.FY],
                                                     std[tire_force.FY], self._split_std()):
            values[name], values[f"{name}_std"] = force, math.hypot(force_std * inflation, split_std)
            valid[name] = cause == "valid"
        valid["forces"] = cause == "valid"
        causes["forces"] = cause
