"""Seven-state tire-force model of the DICI-GFCKF paper (its eqs 1-14 combined).

State ``x = (r, beta, vx, Fy_fl, Fy_fr, Fy_rl, Fy_rr)``: the paper's vehicle
states ``x_a`` (eq 9) and wheel lateral forces ``x_b`` (eq 12) in one vector,
so that the yaw and lateral motion are driven by the force states instead of
the linear tire of eq 10. Lateral forces are in each wheel's own frame, N,
positive to the left (ISO 8855).

Input ``u = (delta, ax, ay, ax_offset, Fx_fl, Fx_fr, Fx_rl, Fx_rr)``: road wheel angle,
the measured accelerations (for the loads of eq 7, and at low speed for the
forces' sum ``m ay``; the estimator passes ay through the body's roll lag,
:mod:`canest.estimation.roll_lag`), the part of ax the car's speed does not
follow (a road grade's gravity, :mod:`canest.estimation.longitudinal_offset`)
and the longitudinal
tire forces from the in-wheel motors (eq 4, :mod:`canest.models.wheel_force`).
:class:`AxDrivenTireForceModel` is the same model for cars without motor
torques: ``u = (delta, ax, ay, ax_offset)`` and the longitudinal forces follow from ax
and the drive layout by eq 1 (:class:`canest.models.wheel_force.DriveLayout`),
so ax is its input and not its measurement.

Dynamics (:mod:`canest.models.wheels` for eqs 1-3, 7 and 8, :mod:`canest.models.tire`
for eqs 5, 6 and 13), with ``vy = vx tan(beta)``:

    (ax_m, ay_m, dr/dt) = body resultants of (Fx, Fy)           eqs 1-3
    dvx/dt = ax_m + r vy - ax_offset,   dvy/dt = ay_m - r vx,   dbeta/dt from both (WheelGeometry.body_derivatives)
    dFy_ij/dt = V / sigma (Fy_ss,ij - Fy_ij)                    eqs 6, 13 (sign corrected)
    Fy_ss,ij = MF(alpha_ij; K = k_ij Fz_ij, D = mu_nominal Fz_ij), limited by the friction circle with Fx_ij

Measurements (eq 14 plus the gyro and the wheel speeds), one row per channel:
``(ax, ay, r, vx_wheel, ax_2, ay_2, r_2)``; the ``_2`` rows are the second
IMU's. ``SENSOR_SETS`` tells which local filter of the DICI-GFCKF uses which
rows (0: every local filter).

Low speed (below the estimator's ``min_speed``): slip angles are meaningless,
so sideslip decays, vx integrates ax less its offset, yaw rate is a random walk (as in the
single-track kinematic model) and each lateral force relaxes within
``LOW_SPEED_FORCE_TAU`` to its load share of ``m ay``.
"""
from __future__ import annotations

import numpy as np

from canest.params import VehicleParams
from canest.models.integrate import rk4
from canest.models.tire import friction_circle, magic_formula, relaxation_rate
from canest.models.wheel_force import DriveLayout
from canest.models.wheels import MIN_WHEEL_SPEED, WheelModel

STATE_NAMES = ("yaw_rate", "beta", "vx", "fy_fl", "fy_fr", "fy_rl", "fy_rr")
MEASUREMENT_NAMES = ("ax", "ay", "yaw_rate", "vx_wheel", "ax_2", "ay_2", "yaw_rate_2")
SENSOR_SETS = (1, 1, 1, 0, 2, 2, 2)
YAW, BETA, VX = 0, 1, 2
FY = slice(3, 7)
AXLE_FORCES = (slice(3, 5), slice(5, 7))  # front (fl, fr), rear (rl, rr)
DELTA, AX, AY, AX_OFFSET = 0, 1, 2, 3
FX = slice(4, 8)
LOW_SPEED_BETA_TAU = 0.5  # s
LOW_SPEED_FORCE_TAU = 0.1  # s


class TireForceModel(WheelModel):
    state_names = STATE_NAMES
    measurement_names = MEASUREMENT_NAMES
    sensor_sets = SENSOR_SETS

    def longitudinal_forces(self, X: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Fx (N, 4) of points X: the input's, from the motor torques (eq 4)."""
        return np.broadcast_to(u[FX], (X.shape[0], 4))

    def steady_state_forces(self, r, vx, vy, u, fx):
        """Fy_ss (N, 4) of the Magic Formula at the slip angles of eq 8 and the loads of eq 7, within the friction
        circle with the longitudinal forces ``fx``."""
        v_long, v_lat = self.wheels.wheel_velocities(r, vx, vy, u[DELTA])
        alpha = self.wheels.slip_angles(v_long, v_lat)
        fz = self.wheels.loads(u[AX], u[AY])
        peak = self.tire.nominal_friction * fz
        fy = magic_formula(alpha, self.wheels.cornering_stiffness(fz, self.tire), self.tire.lateral_shape,
                           self.tire.lateral_curvature, peak)
        return friction_circle(fx, fy, peak)[1]

    def derivatives(self, X: np.ndarray, u: np.ndarray) -> np.ndarray:
        r, beta = X[:, YAW], X[:, BETA]
        vx = np.maximum(X[:, VX], MIN_WHEEL_SPEED)
        fy = X[:, FY]
        fx = self.longitudinal_forces(X, u)
        out = np.empty_like(X)
        out[:, YAW], out[:, BETA], out[:, VX] = self.wheels.body_derivatives(r, beta, vx, fx, fy, u[DELTA],
                                                                                  u[AX_OFFSET])
        speed = vx / np.cos(beta)
        rate = relaxation_rate(speed, self.tire.relaxation_length)
        out[:, FY] = rate[:, None] * (self.steady_state_forces(r, vx, vx * np.tan(beta), u, fx) - fy)
        return out

    def transition(self, X: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """One RK4 step (the relaxation rate V / sigma is 44 1/s at 80 km/h: V dt / sigma = 0.44 at 100 Hz)."""
        return rk4(self.derivatives, X, u, dt)

    def transition_low_speed(self, X: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        out = X.copy()
        out[:, BETA] *= np.exp(-dt / LOW_SPEED_BETA_TAU)
        out[:, VX] += (u[AX] - u[AX_OFFSET]) * dt
        fz = self.wheels.loads(u[AX], u[AY])
        share = self.vehicle.mass * u[AY] * fz / fz.sum()
        out[:, FY] += (1.0 - np.exp(-dt / LOW_SPEED_FORCE_TAU)) * (share - X[:, FY])
        return out

    def measure(self, X: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Rows of MEASUREMENT_NAMES for points X (N, 7): eq 14, the gyro, the mean wheel-frame speed."""
        r, vx = X[:, YAW], X[:, VX]
        vy = vx * np.tan(X[:, BETA])
        ax_m, ay_m, _ = self.wheels.body_accelerations(self.longitudinal_forces(X, u), X[:, FY], u[DELTA])
        v_long, _ = self.wheels.wheel_velocities(r, vx, vy, u[DELTA])
        imu = np.column_stack([ax_m, ay_m, r])
        return np.column_stack([imu, v_long.mean(axis=1), imu])


class AxDrivenTireForceModel(TireForceModel):
    """The tire-force model on what every car sends: longitudinal forces from ax and the drive layout (eq 1).

    ``u = (delta, ax, ay, ax_offset)``. The model's ax equals the measured ax by
    construction, so the ax rows (``ax``, ``ax_2``) are not measurements here.
    """

    measurement_names = tuple(name for name in MEASUREMENT_NAMES if not name.startswith("ax"))
    vx_noise_key = "vx_from_ax"  # its Fx sum is m ax: vx integrates the measured ax, as the single track's
    sensor_sets = tuple(s for name, s in zip(MEASUREMENT_NAMES, SENSOR_SETS) if not name.startswith("ax"))
    KEPT = np.array([MEASUREMENT_NAMES.index(name) for name in measurement_names])

    def use_vehicle(self, vehicle: VehicleParams) -> None:
        """Take ``vehicle``'s parameters, the drive layout's too."""
        super().use_vehicle(vehicle)
        self.layout = DriveLayout(vehicle)

    def longitudinal_forces(self, X: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Fx (N, 4) of eq 1 solved with the measured ax, each point's lateral forces and the drive layout."""
        return self.layout.forces(u[AX], X[:, FY], u[DELTA])

    def measure(self, X: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Rows of ``measurement_names``: the tire-force model's without ax."""
        return super().measure(X, u)[:, self.KEPT]
