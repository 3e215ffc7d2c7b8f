"""Estimators beyond the single track: four lateral tire forces, and four road friction coefficients.

:class:`TireForceEstimator` runs the 7-state model of
:mod:`canest.models.tire_force` with any sigma-point filter, or with
``dici-gfckf`` whose local filters each get one IMU (plus the shared wheel
speeds). Its input ``Fx`` per wheel comes from the motor torques and the
wheel accelerations (DICI-GFCKF eq 4, :mod:`canest.models.wheel_force`).

:class:`FrictionEstimator` runs the 7-DOF two-track model of
:mod:`canest.models.two_track` with the double CKF (``dckf``). Friction is
observable only while a tire works near its limit: each tick, a wheel whose
force sensitivity ``|dF/dmu|`` one standard deviation below its estimate is below
``estimator.friction_excitation`` (N per unit mu) is frozen for the dual
filter's parameter update (value held; variance growing up to its initial
value, :mod:`canest.filters.dual`). The CAN flags ``Mu..Observable`` say which
wheels were updated this tick; ``Mu..Valid`` that the standard deviation is
below ``MU_VALID_STD``, i.e. excitation was seen recently enough.

Four frictions from three body measurements (ax, ay, r) are not separately
observable: a tire with too much friction and its neighbour with too little
explain the same accelerations. The four wheels usually share one road, so
their prior and random walk are correlated (``estimator.friction_correlation``,
default 0.9): evidence on one wheel moves all four, and a split-mu road still
shows as a slowly growing difference.

Both skip the lateral measurements (ax, ay) at low speed, as the single-track
estimator skips ay.
"""
from __future__ import annotations

import numpy as np

from canest.estimator import WHEEL_SPEEDS, Estimator, _Inputs
from canest.filters import Measurement
from canest.models import tire_force, two_track
from canest.models.tire_force import TireForceModel
from canest.models.two_track import TwoTrackModel
from canest.models.wheel_force import WheelAcceleration, longitudinal_forces
from canest.signals import INPUT_GROUPS, WHEELS

TORQUES = INPUT_GROUPS["motor_torques"]
LATERAL_FORCES = tuple(f"fy_{w}" for w in WHEELS)
FRICTIONS = tuple(f"mu_{w}" for w in WHEELS)
MU_VALID_STD = 0.15
SENSOR_SETS = np.array(tire_force.SENSOR_SETS)

# Which input sample feeds each measurement channel, and whether it is a lateral channel (not at low speed).
CHANNEL_INPUTS = {
    "ax": ("ax", True), "ay": ("ay", True), "yaw_rate": ("yaw_rate", False),
    "ax_2": ("ax_2", True), "ay_2": ("ay_2", True), "yaw_rate_2": ("yaw_rate_2", False),
    **{name: (name, False) for name in WHEEL_SPEEDS},
}


class _ChannelEstimator(Estimator):
    """Measurement updates over named channels: every fresh, available sample is one row."""

    def _channel_mask(self, inputs: _Inputs, lateral_ok: bool) -> tuple[np.ndarray, np.ndarray]:
        names = self.model.measurement_names
        mask = np.zeros(len(names), dtype=bool)
        z = np.zeros(len(names))
        for i, name in enumerate(names):
            if name == "vx_wheel":
                mask[i] = inputs.has(*WHEEL_SPEEDS) and inputs.any_fresh(*WHEEL_SPEEDS)
                z[i] = self._wheel_speed(inputs) if mask[i] else 0.0
                continue
            source, lateral = CHANNEL_INPUTS[name]
            mask[i] = inputs.has(source) and inputs.any_fresh(source) and (lateral_ok or not lateral)
            z[i] = inputs.values.get(source, 0.0)
        return mask, z

    def _rows(self, mask: np.ndarray, z: np.ndarray):
        """(z, Measurement, R) of the rows in ``mask``."""
        rows = np.flatnonzero(mask)
        measurement = Measurement(h=lambda X, u: self.model.measure(X, u)[:, rows], channels=tuple(rows))
        return z[rows], measurement, np.diag(self.r_std[rows] ** 2)

    def _update_rows(self, mask: np.ndarray, z: np.ndarray, u: np.ndarray) -> None:
        z_rows, measurement, R = self._rows(mask, z)
        self.filter.update(z_rows, measurement, u, R)

    def _torques(self, inputs: _Inputs) -> np.ndarray:
        return np.array([inputs.values.get(name, 0.0) for name in TORQUES])

    @staticmethod
    def _accelerations(inputs: _Inputs) -> tuple[float, float]:
        return inputs.current("ax"), inputs.current("ay")


class TireForceEstimator(_ChannelEstimator):
    extra_states = LATERAL_FORCES

    def __init__(self, config, resampler):
        super().__init__(config, resampler, TireForceModel(config.vehicle, config.vehicle.tire))
        self.wheel_acceleration = WheelAcceleration()

    def reset(self) -> None:
        super().reset()
        self.wheel_acceleration.reset()

    def _initial_state(self, inputs: _Inputs) -> np.ndarray:
        """As the single track, and each lateral force at its load share of ``m ay``."""
        x0 = super()._initial_state(inputs)
        ax, ay = self._accelerations(inputs)
        loads = self.model.wheels.loads(ax, ay)
        x0[tire_force.FY] = self.vehicle.mass * ay * loads / loads.sum()
        return x0

    def _control(self, inputs: _Inputs, t: float) -> np.ndarray:
        """u = (delta, ax, ay, Fx per wheel from eq 4)."""
        speeds = [inputs.values.get(name, 0.0) for name in WHEEL_SPEEDS]
        fx = longitudinal_forces(self._torques(inputs), self.wheel_acceleration.update(t, speeds),
                                 self.vehicle.wheel_inertia, self.vehicle.wheel_radius)
        return np.array([self._road_wheel_angle(inputs), *self._accelerations(inputs), *fx])

    def _update(self, inputs: _Inputs, u: np.ndarray, lateral_ok: bool, t: float) -> bool:
        """Non-DICI filters use the first IMU; ``dici-gfckf`` gives local filter j the rows of IMU j."""
        mask, z = self._channel_mask(inputs, lateral_ok)
        sets = SENSOR_SETS
        if not hasattr(self.filter, "sensor_sets"):
            mask &= sets <= 1
            if not mask.any():
                return False
            self._update_rows(mask, z, u)
            return self._diverged(t)
        local_masks = [mask & ((sets == 0) | (sets == j + 1)) for j in range(self.filter.sensor_sets)]
        if not any(m.any() for m in local_masks):
            return False
        given = [self._rows(m, z) if m.any() else None for m in local_masks]
        self.filter.update_sets(given, u)
        return self._diverged(t)

    def _extra_values(self, values: dict, valid: dict, std: np.ndarray, inputs: _Inputs, lateral_ok: bool) -> None:
        ok = lateral_ok and inputs.has(*TORQUES, *WHEEL_SPEEDS)
        for name, force, force_std in zip(LATERAL_FORCES, self.filter.x[tire_force.FY], std[tire_force.FY]):
            values[name], values[f"{name}_std"] = force, force_std
            valid[name] = ok
        valid["forces"] = ok


class FrictionEstimator(_ChannelEstimator):
    extra_states = FRICTIONS

    def __init__(self, config, resampler):
        super().__init__(config, resampler, TwoTrackModel(config.vehicle, config.vehicle.tire))
        self.observable = np.zeros(len(FRICTIONS), dtype=bool)
        correlation = self.est.friction_correlation
        mixing = correlation * np.ones((4, 4)) + (1.0 - correlation) * np.eye(4)
        for matrix in (self.Q, self.p0):  # the four wheels are on one road: correlated prior and random walk
            matrix[two_track.MU, two_track.MU] = matrix[two_track.MU.start, two_track.MU.start] * mixing

    def _initial_state(self, inputs: _Inputs) -> np.ndarray:
        """Wheel speeds as measured, friction at the tire's nominal value (dry until excitation says otherwise)."""
        x0 = super()._initial_state(inputs)
        x0[two_track.W] = [inputs.values[name] for name in WHEEL_SPEEDS]
        x0[two_track.MU] = self.vehicle.tire.nominal_friction
        return x0

    def _control(self, inputs: _Inputs, t: float) -> np.ndarray:
        """u = (delta, ax, ay, motor torque per wheel)."""
        return np.array([self._road_wheel_angle(inputs), *self._accelerations(inputs), *self._torques(inputs)])

    def _update(self, inputs: _Inputs, u: np.ndarray, lateral_ok: bool, t: float) -> bool:
        mask, z = self._channel_mask(inputs, lateral_ok)
        excited = self.model.friction_sensitivity(self._plausibly_lower_friction(), u) >= self.est.friction_excitation
        self.observable = excited & lateral_ok & inputs.has(*TORQUES)
        self.filter.frozen = ~self.observable
        if not mask.any():
            return False
        self._update_rows(mask, z, u)
        return self._diverged(t)

    def _plausibly_lower_friction(self) -> np.ndarray:
        """The state with each friction one standard deviation lower (not below ice, ``LOWEST_FRICTION``).

        A tire says something about its friction if it works near its limit at
        a friction the estimate still allows. Testing at the estimate itself
        never opens the gate for an overestimated friction; testing far below
        it (two standard deviations) opens it where the data only bound the
        friction from below (measured on high friction: the estimates fell to
        0.1-0.6; README "Tire forces and road friction").
        """
        x = self.filter.x.copy()
        std = np.sqrt(np.maximum(np.diag(self.filter.P)[two_track.MU], 0.0))
        x[two_track.MU] = np.maximum(x[two_track.MU] - 1.0 * std, two_track.LOWEST_FRICTION)
        return x

    def _extra_values(self, values: dict, valid: dict, std: np.ndarray, inputs: _Inputs, lateral_ok: bool) -> None:
        frictions, friction_stds = self.filter.x[two_track.MU], std[two_track.MU]
        for name, mu, mu_std, observable in zip(FRICTIONS, frictions, friction_stds, self.observable):
            values[name], values[f"{name}_std"] = mu, mu_std
            valid[name] = bool(mu_std < MU_VALID_STD)
            valid[f"{name}_observable"] = bool(observable)
        valid["friction"] = any(valid[name] for name in FRICTIONS)
        valid["friction_observable"] = bool(self.observable.any())


ESTIMATORS = {"single_track": Estimator, "tire_force": TireForceEstimator, "two_track": FrictionEstimator}


def make_estimator(config, resampler) -> Estimator:
    """The estimator of the configured model."""
    return ESTIMATORS[config.estimator.model](config, resampler)
