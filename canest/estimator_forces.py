"""Estimators beyond the single track: four lateral tire forces, and four road friction coefficients.

:class:`TireForceEstimator` runs the 7-state model of
:mod:`canest.models.tire_force` with any sigma-point filter, or with
``dici-gfckf`` whose local filters each get one IMU (plus the shared wheel
speeds). Its input ``Fx`` per wheel comes from the motor torques and the
wheel accelerations (DICI-GFCKF eq 4, :mod:`canest.models.wheel_force`).

:class:`FrictionEstimator` runs the 7-DOF two-track model of
:mod:`canest.models.two_track` with the joint CKF (``jckf``, the default) or
the DCKF paper's double CKF (``dckf``). Beyond the paper's measurements it
gives the filter two derived channels: the yaw acceleration from the gyro
(Theil-Sen slope over ``YAW_ACCELERATION_WINDOW`` samples), which with ay
splits the lateral force between the axles, and a reference speed that does
not follow slipping wheels (:mod:`canest.reference_speed`), which makes the
slip ratio, and so a spinning wheel's friction, observable.

Friction is observable only while a tire works near its limit: a wheel is
excited when its force sensitivity ``|dF/dmu|``, at its friction
``LOWER_FRICTION_STDS`` standard deviations below the estimate, reaches
``estimator.friction_excitation`` (N per unit mu). While no wheel is
excited the frictions are frozen (value held; variance growing up to its
initial value, :mod:`canest.filters.parameters`); while any is, all four
update, so evidence from the excited wheels reaches the others through
their correlation. The CAN flags ``Mu..Observable`` say which wheels were
excited this tick; ``Mu..Valid`` that the standard deviation is below
``MU_VALID_STD`` (excitation was seen recently enough) and the estimate is
not within ``MU_VALID_STD`` of the highest friction a road has (an estimate
pressed against that bound says the data only bound friction from below).

Friction may always fall but rises only on a wheel at its limit at the
estimated friction (:meth:`FrictionEstimator._friction_ceiling`): below it
the data bound friction from below only.

A divergence reset restarts the states but keeps the frictions: it says the
states were wrong, not the road.

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

import math

import numpy as np

from canest.estimator import WHEEL_SPEEDS, Estimator, _Inputs
from canest.filters import Measurement
from canest.models import tire_force, two_track
from canest.models.tire_force import TireForceModel
from canest.models.two_track import TwoTrackModel
from canest.models.wheel_force import WheelAcceleration, longitudinal_forces
from canest.reference_speed import ReferenceSpeed
from canest.signals import INPUT_GROUPS, WHEELS

TORQUES = INPUT_GROUPS["motor_torques"]
LATERAL_FORCES = tuple(f"fy_{w}" for w in WHEELS)
FRICTIONS = tuple(f"mu_{w}" for w in WHEELS)
MU_VALID_STD = 0.15
LOWER_FRICTION_STDS = 3.0  # the excitation gate tests each friction this many standard deviations below its estimate
YAW_ACCELERATION_WINDOW = 7
SENSOR_SETS = np.array(tire_force.SENSOR_SETS)

# Which input sample feeds each measurement channel, and whether it is a lateral channel (not at low speed).
CHANNEL_INPUTS = {
    "ax": ("ax", True), "ay": ("ay", True), "yaw_rate": ("yaw_rate", False),
    "ax_2": ("ax_2", True), "ay_2": ("ay_2", True), "yaw_rate_2": ("yaw_rate_2", False),
    **{name: (name, False) for name in WHEEL_SPEEDS},
}


class _ChannelEstimator(Estimator):
    """Measurement updates over named channels: every fresh, available sample is one row.

    Channels the model measures but no sensor sends (the wheel-speed mean
    ``vx_wheel``; the yaw acceleration and reference speed of the friction
    estimator) come from :meth:`_derived`, each with its standard deviation.
    """

    def _derived(self, inputs: _Inputs, t: float, lateral_ok: bool) -> dict:
        """Channels computed from the inputs this tick: name -> (value, standard deviation)."""
        if not (inputs.has(*WHEEL_SPEEDS) and inputs.any_fresh(*WHEEL_SPEEDS)):
            return {}
        return {"vx_wheel": (self._wheel_speed(inputs), self.est.measurement_noise["vx_wheel"])}

    def _channels(self, inputs: _Inputs, t: float, lateral_ok: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(mask, z, standard deviation) over the model's measurement channels; mask: fresh and usable."""
        derived = self._derived(inputs, t, lateral_ok)
        names = self.model.measurement_names
        mask = np.zeros(len(names), dtype=bool)
        z = np.zeros(len(names))
        std = self.r_std.copy()
        for i, name in enumerate(names):
            if name in derived:
                mask[i] = True
                z[i], std[i] = derived[name]
            elif name in CHANNEL_INPUTS:
                source, lateral = CHANNEL_INPUTS[name]
                mask[i] = inputs.has(source) and inputs.any_fresh(source) and (lateral_ok or not lateral)
                z[i] = inputs.values.get(source, 0.0)
        return mask, z, std

    def _rows(self, mask: np.ndarray, z: np.ndarray, std: np.ndarray):
        """(z, Measurement, R) of the rows in ``mask``."""
        rows = np.flatnonzero(mask)
        measurement = Measurement(h=lambda X, u: self.model.measure(X, u)[:, rows], channels=tuple(rows))
        return z[rows], measurement, np.diag(std[rows] ** 2)

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
        mask, z, std = self._channels(inputs, t, lateral_ok)
        sets = SENSOR_SETS
        if not hasattr(self.filter, "sensor_sets"):
            mask &= sets <= 1
            if not mask.any():
                return False
            z_rows, measurement, R = self._rows(mask, z, std)
            self.filter.update(z_rows, measurement, u, R)
            return self._diverged(t)
        local_masks = [mask & ((sets == 0) | (sets == j + 1)) for j in range(self.filter.sensor_sets)]
        if not any(m.any() for m in local_masks):
            return False
        given = [self._rows(m, z, std) if m.any() else None for m in local_masks]
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
        self.yaw_acceleration = WheelAcceleration(YAW_ACCELERATION_WINDOW)
        self.wheel_acceleration = WheelAcceleration()
        self.reference_speed = ReferenceSpeed(self.vehicle.wheel_radius, self.vehicle.tire.longitudinal_stiffness,
                                              self.est.measurement_noise["vx_reference"])
        self.last_friction = None
        correlation = self.est.friction_correlation
        mixing = correlation * np.ones((4, 4)) + (1.0 - correlation) * np.eye(4)
        for matrix in (self.Q, self.p0):  # the four wheels are on one road: correlated prior and random walk
            matrix[two_track.MU, two_track.MU] = matrix[two_track.MU.start, two_track.MU.start] * mixing

    def reset(self) -> None:
        """Forget the state but remember the frictions: a divergence says the states were wrong, not the road."""
        if self.filter is not None and np.all(np.isfinite(self.filter.x[two_track.MU])):
            self.last_friction = self.filter.x[two_track.MU].copy()
        super().reset()
        self.yaw_acceleration.reset()
        self.wheel_acceleration.reset()

    def _initial_state(self, inputs: _Inputs) -> np.ndarray:
        """Wheel speeds as measured; friction as before a reset, else at the tire's nominal value (dry)."""
        x0 = super()._initial_state(inputs)
        x0[two_track.W] = [inputs.values[name] for name in WHEEL_SPEEDS]
        x0[two_track.MU] = self.vehicle.tire.nominal_friction if self.last_friction is None else self.last_friction
        return x0

    def _control(self, inputs: _Inputs, t: float) -> np.ndarray:
        """u = (delta, ax, ay, motor torque per wheel)."""
        return np.array([self._road_wheel_angle(inputs), *self._accelerations(inputs), *self._torques(inputs)])

    def _derived(self, inputs: _Inputs, t: float, lateral_ok: bool) -> dict:
        """The gyro's yaw acceleration (body moment balance, eq 5) and the reference speed (vx without slip)."""
        derived = {}
        if inputs.has("yaw_rate") and inputs.any_fresh("yaw_rate"):
            rate = self.yaw_acceleration.update(t, [inputs.values["yaw_rate"]])[0]
            if lateral_ok and len(self.yaw_acceleration.samples) == YAW_ACCELERATION_WINDOW:
                derived["yaw_acceleration"] = (rate, self.est.measurement_noise["yaw_acceleration"])
        if inputs.has(*WHEEL_SPEEDS, "ax"):
            speeds = np.array([inputs.values[name] for name in WHEEL_SPEEDS])
            ax, ay = self._accelerations(inputs)
            usage = self._torques(inputs) / (self.vehicle.wheel_radius * np.maximum(self.model.wheels.loads(ax, ay), 1.0))
            beta, vx = self.filter.x[[two_track.BETA, two_track.VX]]
            derived["vx_reference"] = self.reference_speed.update(
                t, ax + inputs.current("yaw_rate") * vx * math.tan(beta), speeds, self.wheel_acceleration.update(t, speeds),
                usage)
        return derived

    def _update(self, inputs: _Inputs, u: np.ndarray, lateral_ok: bool, t: float) -> bool:
        mask, z, std = self._channels(inputs, t, lateral_ok)
        states = np.stack([self._plausibly_lower_friction(), self.filter.x])
        excited, at_limit = self.model.friction_sensitivity(states, u) >= self.est.friction_excitation
        self.observable = excited & lateral_ok & inputs.has(*TORQUES)
        self.filter.parameters.frozen = np.full(4, not self.observable.any())
        self.filter.parameters.ceiling = self._friction_ceiling(at_limit)
        if not mask.any():
            return False
        z_rows, measurement, R = self._rows(mask, z, std)
        self.filter.update(z_rows, measurement, u, R)
        return self._diverged(t)

    def _friction_ceiling(self, at_limit: np.ndarray) -> np.ndarray:
        """Per wheel, the highest friction this update may give: unlimited at the tire's limit, else the estimate.

        One-sided evidence: a tire below its limit at the estimated friction
        says only that friction is at least what it uses; a force above what
        the model predicts there is the model's error (its slip or cornering
        stiffness), not friction. Read as friction it pushed the 0.85 launch to
        the upper bound 1.3 (the plant's unloaded front tire is 11 % stiffer
        in slip than the model's). So friction rises only on a tire at its
        limit at the estimate (sensitivity at the estimate itself above
        ``friction_excitation``) and can always fall (README "Tire forces and
        road friction").
        """
        return np.where(at_limit, np.inf, self.filter.x[two_track.MU])

    def _plausibly_lower_friction(self) -> np.ndarray:
        """The state with each friction ``LOWER_FRICTION_STDS`` standard deviations lower (not below ice).

        A tire says something about its friction if it works near its limit at
        a friction the estimate still allows. Testing at the estimate itself
        never opens the gate for an overestimated friction (measured: at 1
        standard deviation three of the joint filter's four estimates never left
        0.90 on the 50 km/h sine on friction 0.35; at 3 they are within 0.1
        after 0.3-0.8 s; README "Tire forces and road friction").
        """
        x = self.filter.x.copy()
        std = np.sqrt(np.maximum(np.diag(self.filter.P)[two_track.MU], 0.0))
        x[two_track.MU] = np.maximum(x[two_track.MU] - LOWER_FRICTION_STDS * std, two_track.LOWEST_FRICTION)
        return x

    def _extra_values(self, values: dict, valid: dict, std: np.ndarray, inputs: _Inputs, lateral_ok: bool) -> None:
        frictions, friction_stds = self.filter.x[two_track.MU], std[two_track.MU]
        for name, mu, mu_std, observable in zip(FRICTIONS, frictions, friction_stds, self.observable):
            values[name], values[f"{name}_std"] = mu, mu_std
            valid[name] = bool(mu_std < MU_VALID_STD and mu < two_track.HIGHEST_FRICTION - MU_VALID_STD)
            valid[f"{name}_observable"] = bool(observable)
        valid["friction"] = any(valid[name] for name in FRICTIONS)
        valid["friction_observable"] = bool(self.observable.any())


ESTIMATORS = {"single_track": Estimator, "tire_force": TireForceEstimator, "two_track": FrictionEstimator}


def make_estimator(config, resampler) -> Estimator:
    """The estimator of the configured model."""
    return ESTIMATORS[config.estimator.model](config, resampler)
