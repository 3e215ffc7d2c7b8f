"""Seven-degree-of-freedom two-track model with per-wheel friction (DCKF paper eqs 1-11).

Joint state ``x = (r, beta, vx, w_fl, w_fr, w_rl, w_rr, mu_fl, mu_fr, mu_rl, mu_rr)``:
the DCKF's vehicle states (yaw, lateral and longitudinal motion plus the four
wheel speeds, rad/s) followed by its parameters (four road friction
coefficients, a random walk). Input ``u = (delta, ax, ay, ax_offset, T_fl, T_fr, T_rl, T_rr)``
with the measured accelerations for the loads (DICI-GFCKF eq 7), the part of ax
the car's speed does not follow (a road grade's gravity, slowing vx beside the
tires' forces: :meth:`canest.models.wheels.WheelGeometry.body_derivatives`) and
the motor torques (N m, positive driving).

Forces per wheel (:mod:`canest.models.tire`): Magic Formula of the slip angle
(eq 10) and the slip ratio (eq 11) with peak ``mu Fz`` and friction-independent
stiffness, limited together by the friction circle. Then (:mod:`canest.models.wheels`)
the body motion of eqs 1-5 and the wheels ``J dw/dt = T - R (Fx + f_r Fz)`` (eq 6 with the rolling
moment, ``vehicle.tire.rolling_resistance``).

Discretization: ``SUBSTEPS`` semi-implicit Euler steps per loop period. A
wheel's slip dynamics are stiff (time constant ``J v / (R^2 K)``, ~2 ms at
80 km/h): each wheel speed takes a linearly implicit step
``w+ = w + h f / (1 - h df/dw)`` with ``df/dw = -R^2 dFx/ds / (J v)`` from the
Magic Formula's slope, stable for any step; the body states take explicit
steps with the forces of the substep's start.

Measurements: ``(ax, ay, r, dr/dt, vx, w_fl, w_fr, w_rl, w_rr, r_2)`` (the paper's ``Z = (ax, ay, r)``, the
gyro's slope (:mod:`canest.estimation.two_track`), the reference speed, the wheel-speed sensors, which observe
the wheel states, and a second gyro where the car sends one, as the single-track model's).
"""
from __future__ import annotations

import numpy as np

from canest.models.tire import friction_circle, magic_formula, magic_formula_slope
from canest.models.wheels import MIN_WHEEL_SPEED, WheelModel

STATE_NAMES = ("yaw_rate", "beta", "vx", "w_fl", "w_fr", "w_rl", "w_rr", "mu_fl", "mu_fr", "mu_rl", "mu_rr")
MEASUREMENT_NAMES = ("ax", "ay", "yaw_rate", "yaw_acceleration", "vx_reference",
                     "wheel_speed_fl", "wheel_speed_fr", "wheel_speed_rl", "wheel_speed_rr", "yaw_rate_2")
YAW, BETA, VX = 0, 1, 2
W = slice(3, 7)
MU = slice(7, 11)
DELTA, AX, AY, AX_OFFSET = 0, 1, 2, 3
TORQUE = slice(4, 8)
PARAMETERS = 4
SUBSTEPS = 4
MU_RANGE = (0.05, 1.5)  # the model clips friction to this range
LOWEST_FRICTION = 0.1  # ice: the lowest friction a road is assumed to have
HIGHEST_FRICTION = 1.3  # race tires on dry asphalt
SENSITIVITY_STEP = 0.02  # mu step of the excitation finite difference
AXLE_SLIP_GRID = np.linspace(0.0, 0.5, 1001)  # rad: slip angles at which an axle's curve is drawn


class TwoTrackModel(WheelModel):
    state_names = STATE_NAMES
    measurement_names = MEASUREMENT_NAMES
    # the dual filter's parameter block: the last four states, within the frictions a road can have
    parameters = PARAMETERS  # the last states are the four frictions: bounded parameters of the filter
    parameter_bounds = (LOWEST_FRICTION, HIGHEST_FRICTION)
    # vx is held by the four wheel speeds, states beside it, and what moves it beyond their tires' forces (drag,
    # rolling resistance) is small: its own process noise (README "How far to trust the output", vx's std)
    vx_noise_key = "vx_from_wheel_states"

    def forces(self, X: np.ndarray, u: np.ndarray, stiffness_scale=1.0):
        """Wheel-frame (Fx, Fy), their pure-slip longitudinal slope dFx/ds and the wheel speeds v_long, all (N, 4).

        ``stiffness_scale`` (a scalar or one per row, shape (N, 1)) multiplies both slip stiffnesses."""
        return self._tire_forces(X, u, stiffness_scale)[:4]

    def rear_saturation_slip(self, x: np.ndarray, u: np.ndarray) -> float:
        """The rear wheels' mean slip angle at the state ``x`` (n,) less the slip angle linear tires of the same
        cornering stiffness need for the same lateral forces (rad, in absolute value; after the friction circle: a
        driven wheel's force rests on friction too): the sideslip, ``b r / vx`` less the rear slip angle, that the
        rear tires' saturation at the estimated frictions makes. A lifted wheel (no load, no stiffness) is left out;
        none loaded: 0."""
        _, fy, _, _, alpha, stiffness = self._tire_forces(x[None, :], u)
        fy, alpha = fy[0, 2:], alpha[0, 2:]
        stiffness = np.broadcast_to(stiffness, (1, 4))[0, 2:]  # (4,): one input's loads
        loaded = stiffness > 0.0
        if not loaded.any():
            return 0.0
        return abs(float(alpha[loaded].mean() - (fy[loaded] / stiffness[loaded]).mean()))

    def rear_axle_slips(self, x: np.ndarray, u: np.ndarray, frictions: np.ndarray) -> np.ndarray:
        """The slip angles (K,; rad, absolute) at which rear tires of each row of ``frictions`` (K, 4; the rear two
        taken) carry the rear axle's lateral force at the state ``x`` (n,): the first on ``AXLE_SLIP_GRID`` on the
        rising branch of the axle's curve (each wheel's longitudinal force at ``x`` kept, through the friction
        circle), or the axle's peak's where that force is beyond it. A lifted axle: 0."""
        fx, fy, _, _, _, stiffness = self._tire_forces(x[None, :], u)
        rear = slice(2, 4)
        peak = np.clip(frictions[:, rear], *MU_RANGE) * self.wheels.loads(u[AX], u[AY])[rear]  # (K, 2)
        t = self.tire
        curve = magic_formula(AXLE_SLIP_GRID[:, None, None], np.broadcast_to(stiffness, (1, 4))[0, rear],
                              t.lateral_shape, t.lateral_curvature, peak)  # (G, K, 2)
        _, curve = friction_circle(np.broadcast_to(fx[0, rear], curve.shape), curve, peak)
        axle = curve.sum(axis=2)  # (G, K)
        reached = axle >= abs(float(fy[0, rear].sum()))
        first = np.where(reached.any(axis=0), np.argmax(reached, axis=0), np.argmax(axle, axis=0))
        return AXLE_SLIP_GRID[first]

    def _tire_forces(self, X: np.ndarray, u: np.ndarray, stiffness_scale=1.0):
        """:meth:`forces`, and each wheel's slip angle (N, 4) and cornering stiffness (N, 4; (4,) for a scalar scale)."""
        r, vx = X[:, YAW], np.maximum(X[:, VX], MIN_WHEEL_SPEED)
        v_long, v_lat = self.wheels.wheel_velocities(r, vx, vx * np.tan(X[:, BETA]), u[DELTA])
        alpha = self.wheels.slip_angles(v_long, v_lat)
        slip = self.wheels.slip_ratios(X[:, W], v_long)
        fz = self.wheels.loads(u[AX], u[AY])
        peak = np.clip(X[:, MU], *MU_RANGE) * fz
        t = self.tire
        long_stiffness = stiffness_scale * t.longitudinal_stiffness * fz
        lateral_stiffness = stiffness_scale * self.wheels.cornering_stiffness(fz, t)
        fx = magic_formula(slip, long_stiffness, t.longitudinal_shape, t.longitudinal_curvature, peak)
        fy = magic_formula(alpha, lateral_stiffness, t.lateral_shape, t.lateral_curvature, peak)
        slope = magic_formula_slope(slip, long_stiffness, t.longitudinal_shape, t.longitudinal_curvature, peak)
        fx, fy = friction_circle(fx, fy, peak)
        return fx, fy, slope, np.maximum(v_long, MIN_WHEEL_SPEED), alpha, lateral_stiffness

    def transition(self, X: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        p = self.vehicle
        h = dt / SUBSTEPS
        X = X.copy()
        rolling = self.tire.rolling_resistance * self.wheels.loads(u[AX], u[AY])  # f_r Fz: a wheel rolling forward
        for _ in range(SUBSTEPS):
            fx, fy, slope, v_long = self.forces(X, u)
            rate = (u[TORQUE] - p.wheel_radius * (fx + rolling)) / p.wheel_inertia
            stiffness = p.wheel_radius**2 * np.maximum(slope, 0.0) / (p.wheel_inertia * v_long)
            dr, dbeta, dvx = self.wheels.body_derivatives(X[:, YAW], X[:, BETA], np.maximum(X[:, VX], MIN_WHEEL_SPEED),
                                                          fx, fy, u[DELTA], u[AX_OFFSET])
            X[:, W] += h * rate / (1.0 + h * stiffness)
            X[:, YAW] += h * dr
            X[:, BETA] += h * dbeta
            X[:, VX] += h * dvx
        return X

    def measure(self, X: np.ndarray, u: np.ndarray) -> np.ndarray:
        fx, fy, _, _ = self.forces(X, u)
        ax, ay, yaw_acc = self.wheels.body_accelerations(fx, fy, u[DELTA])
        return np.column_stack([ax, ay, X[:, YAW], yaw_acc, X[:, VX], X[:, W], X[:, YAW]])

    def friction_sensitivity(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """|d|F_ij| / d mu_ij| per wheel (N per unit friction) at the state x: how much a tire says about its mu.

        Near zero while the tire works in its linear range (the force does not
        depend on the peak), growing as it approaches the friction limit.
        Central difference; each wheel's force depends only on its own mu, so
        all four are perturbed at once. ``x`` of shape (n,) gives (4,); states
        of shape (k, n) give (k, 4) from one model evaluation.
        """
        X = np.repeat(np.atleast_2d(x), 2, axis=0)
        X[0::2, MU] += SENSITIVITY_STEP
        X[1::2, MU] -= SENSITIVITY_STEP
        sensitivity = self._central_difference(X, u, 1.0, SENSITIVITY_STEP)
        return sensitivity if np.ndim(x) == 2 else sensitivity[0]

    def stiffness_sensitivity(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """|d|F_ij| / d ln C| per wheel (N) at the state ``x`` of shape (n,): how much a relative error of both slip
        stiffnesses moves each tire's force. Zero deep in saturation (the force is the peak ``mu Fz``), the
        force itself in the linear range."""
        X = np.repeat(np.atleast_2d(x), 2, axis=0)
        scale = 1.0 + SENSITIVITY_STEP * np.array([[1.0], [-1.0]])
        return self._central_difference(X, u, scale, SENSITIVITY_STEP)[0]

    def _central_difference(self, X: np.ndarray, u: np.ndarray, stiffness_scale, step: float) -> np.ndarray:
        """(|F| of the even rows - |F| of the odd rows) / (2 step), in absolute value, per wheel."""
        fx, fy, _, _ = self.forces(X, u, stiffness_scale)
        magnitude = np.hypot(fx, fy)
        return np.abs(magnitude[0::2] - magnitude[1::2]) / (2.0 * step)
