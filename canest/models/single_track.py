"""Three-degree-of-freedom single-track (bicycle) model with linear tires.

This is the model shared by the LMRWEKF (eqs 1-5), MCSCKF and SVD-FCKF (eqs
1-7) papers, derived here from first principles with ISO 8855 axes: x forward,
y left, z up; a positive road wheel angle ``delta`` turns left; yaw rate ``r``
is positive counter-clockwise seen from above; sideslip ``beta = atan2(vy, vx)``.

State ``x = (r, beta, vx)`` (the papers' order), input ``u = (delta, ax, theta)``
with ``ax`` the measured longitudinal acceleration and ``theta`` a scale of both
cornering stiffnesses (1 unless a dual filter estimates it), measurements
``z = (ay, r, vx_wheel, r_2)``: ``r_2`` is a second gyro (the airbag unit's), read where the car sends one; a
vibrating body shakes each gyro on its own, and their average is the quieter yaw rate (on the drawn cars with a
vibrating IMU, ESC 0.3 and ACU 0.4 deg/s, ckf's yaw rate RMSE 0.361 -> 0.332 deg/s,
:meth:`canest.estimation.core.Estimator._gyro_noise` for its std).

Tire slip angles and forces (cornering stiffnesses ``Cf, Cr`` per axle, positive):

    alpha_f = delta - beta - a r / vx        Fyf = theta Cf alpha_f
    alpha_r =       - beta + b r / vx        Fyr = theta Cr alpha_r

Dynamics (body-frame accelerations ``ax = dvx/dt - r vy``, ``ay = dvy/dt + r vx``):

    ay          = (Fyf + Fyr) / m                                  (paper eq 4)
    dr/dt       = (a Fyf - b Fyr) / Iz                             (paper eq 1)
    dbeta/dt    = (ay cos(beta) - ax sin(beta)) cos(beta) / vx - r (paper eq 2)
    dvx/dt      = ax + r vx tan(beta)                              (paper eq 3)

With the papers' negative cornering stiffnesses ``k1 = -Cf, k2 = -Cr`` and
small ``beta`` these are exactly LMRWEKF eqs (1)-(4). The SVD-FCKF paper's
eq (1) prints ``a^2 k1 - b^2 k2`` and ``a k1 + b k2`` where the derivation gives
``a^2 k1 + b^2 k2`` and ``a k1 - b k2``, and drops the factor ``a`` on the
steering term; tests/test_single_track.py checks the signs numerically (a left
turn gives positive yaw rate and lateral acceleration, understeer gradient).

Discretization: classic fourth-order Runge-Kutta over one loop period with the
input held (zero-order hold). At 100 Hz the lateral eigenvalues reach
``(Cf + Cr) / (m vx)`` and ``(a^2 Cf + b^2 Cr) / (Iz vx)``, 40 and 60 1/s at
3 m/s: there one explicit Euler step misses the state change by 38 %, one
RK4 step by 0.2 % (tests/test_single_track.py, against scipy's adaptive
integrator). Below ``min_speed`` the estimator switches to the kinematic
model :meth:`SingleTrackModel.transition_low_speed`.
"""
from __future__ import annotations

import numpy as np

from canest.params import VehicleParams
from canest.models.integrate import rk4

STATE_NAMES = ("yaw_rate", "beta", "vx")
MEASUREMENT_NAMES = ("ay", "yaw_rate", "vx_wheel", "yaw_rate_2")
YAW, BETA, VX = 0, 1, 2
# Denominator guard for sigma points that stray towards standstill.
MIN_DIVISOR_SPEED = 0.5
# Time constant with which sideslip decays to zero while it is not observable.
LOW_SPEED_BETA_TAU = 0.5


class SingleTrackModel:
    """Vectorized transition and measurement functions of the 3-DOF model."""

    state_names = STATE_NAMES
    measurement_names = MEASUREMENT_NAMES
    input_parameter = 2  # u[2]: the scale theta of both cornering stiffnesses (a dual filter estimates it)
    linear_tires = True  # no tire saturation: the published sideslip std adds the degressive stiffness error
    vx_noise_key = "vx_from_ax"  # vx integrates the measured ax (eq 3): its process noise is the accelerometer's

    def __init__(self, vehicle: VehicleParams):
        self.use_vehicle(vehicle)

    def use_vehicle(self, vehicle: VehicleParams) -> None:
        """Take ``vehicle``'s parameters (the online calibration's learned cornering stiffnesses)."""
        self.vehicle = vehicle
        cf, cr = vehicle.cornering_stiffness_front, vehicle.cornering_stiffness_rear
        a, b, m, iz = vehicle.cg_to_front, vehicle.cg_to_rear, vehicle.mass, vehicle.yaw_inertia
        # Coefficients of (ay, dr/dt) per unit of beta, r/vx and delta, at theta = 1.
        self._per_beta = np.array([-(cf + cr) / m, -(a * cf - b * cr) / iz])
        self._per_yaw = np.array([(b * cr - a * cf) / m, -(a * a * cf + b * b * cr) / iz])
        self._per_delta = np.array([cf / m, a * cf / iz])

    def axle_forces(self, X: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Front and rear axle lateral forces (N) for points ``X`` of shape (N, 3)."""
        p = self.vehicle
        r, beta = X[:, YAW], X[:, BETA]
        vx = np.maximum(X[:, VX], MIN_DIVISOR_SPEED)
        delta, theta = u[0], u[2]
        front = theta * p.cornering_stiffness_front * (delta - beta - p.cg_to_front * r / vx)
        rear = theta * p.cornering_stiffness_rear * (-beta + p.cg_to_rear * r / vx)
        return front, rear

    def _lateral(self, X: np.ndarray, u: np.ndarray):
        """``ay`` and ``dr/dt`` as columns of an (N, 2) array, and ``1/vx``.

        Both are affine in ``beta`` and ``r/vx`` (eqs 1 and 4), so one
        broadcast product per term computes them for every point at once.
        """
        inv_v = 1.0 / np.maximum(X[:, VX:], MIN_DIVISOR_SPEED)
        theta = u[2]
        lateral = X[:, BETA:VX] * (theta * self._per_beta)
        lateral += (X[:, YAW:BETA] * inv_v) * (theta * self._per_yaw)
        lateral += (theta * u[0]) * self._per_delta
        return lateral, inv_v[:, 0]

    def derivatives(self, X: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Continuous-time dx/dt of eqs (1)-(3), shape (N, 3)."""
        lateral, inv_v = self._lateral(X, u)
        r, beta = X[:, YAW], X[:, BETA]
        ax = u[1]
        sin_beta, cos_beta = np.sin(beta), np.cos(beta)
        out = np.empty_like(X)
        out[:, YAW] = lateral[:, 1]
        out[:, BETA] = (lateral[:, 0] * cos_beta - ax * sin_beta) * cos_beta * inv_v - r
        out[:, VX] = ax + r * X[:, VX] * sin_beta / cos_beta
        return out

    def transition(self, X: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """One RK4 step of length ``dt`` with ``u`` held; X of shape (N, 3)."""
        return rk4(self.derivatives, X, u, dt)

    def transition_low_speed(self, X: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """Kinematic model for low speed, standstill and reversing.

        The tire model divides by vx and sideslip is not observable from
        lateral acceleration near standstill, so: yaw rate is a random walk
        (corrected by the gyro), sideslip decays to zero with time constant
        ``LOW_SPEED_BETA_TAU``, and vx integrates the measured ax.
        """
        out = X.copy()
        out[:, BETA] *= np.exp(-dt / LOW_SPEED_BETA_TAU)
        out[:, VX] += u[1] * dt
        return out

    def measure(self, X: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Measurements (ay, yaw rate, mean wheel-frame longitudinal speed, the second gyro's yaw rate), shape (N, 4).

        ``vx_wheel`` is the mean over the four wheels of the wheel centre's
        speed along the wheel's heading: rear ``vx -+ r t/2``, front
        ``(vx -+ r t/2) cos(delta) + (vy + a r) sin(delta)``; the left/right
        yaw terms cancel in the mean.
        """
        p = self.vehicle
        lateral, _ = self._lateral(X, u)
        delta = u[0]
        r, vx = X[:, YAW], X[:, VX]
        vy = vx * np.tan(X[:, BETA])
        out = np.empty_like(X, shape=(X.shape[0], len(MEASUREMENT_NAMES)))
        out[:, 0] = lateral[:, 0]
        out[:, 1] = out[:, 3] = r
        out[:, 2] = 0.5 * vx * (1.0 + np.cos(delta)) + 0.5 * (vy + p.cg_to_front * r) * np.sin(delta)
        return out

    # Exact Jacobians for the extended Kalman filters (checked against complex-step derivatives in the tests).

    def _force_gradients(self, x, u):
        """Gradients of Fyf and Fyr with respect to (r, beta, vx), and of both with respect to theta."""
        p = self.vehicle
        r, beta, v = x
        clamped = v < MIN_DIVISOR_SPEED
        v = max(v, MIN_DIVISOR_SPEED)
        theta = u[2]
        cf, cr = theta * p.cornering_stiffness_front, theta * p.cornering_stiffness_rear
        a, b = p.cg_to_front, p.cg_to_rear
        d_front = np.array([-cf * a / v, -cf, 0.0 if clamped else cf * a * r / v**2])
        d_rear = np.array([cr * b / v, -cr, 0.0 if clamped else -cr * b * r / v**2])
        front, rear = self.axle_forces(x[None, :], u)
        return d_front, d_rear, float(front[0]), float(rear[0]), v, clamped

    def derivatives_jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """d(dx/dt)/dx of :meth:`derivatives` at one state, shape (3, 3)."""
        p = self.vehicle
        r, beta, vx = x
        ax = u[1]
        d_front, d_rear, front, rear, v, clamped = self._force_gradients(x, u)
        ay = (front + rear) / p.mass
        d_ay = (d_front + d_rear) / p.mass
        c, s = np.cos(beta), np.sin(beta)
        J = np.empty((3, 3))
        J[YAW] = (p.cg_to_front * d_front - p.cg_to_rear * d_rear) / p.yaw_inertia
        numerator = ay * c * c - ax * s * c
        J[BETA] = d_ay * c * c / v
        J[BETA, YAW] -= 1.0
        J[BETA, BETA] += (-2.0 * ay * s * c - ax * np.cos(2.0 * beta)) / v
        if not clamped:
            J[BETA, VX] -= numerator / v**2
        J[VX] = [vx * np.tan(beta), r * vx / c**2, r * np.tan(beta)]
        return J

    def transition_jacobian(self, x: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """d x_{k+1} / d x_k of the RK4 step (chain rule through the four stages)."""
        eye = np.eye(3)
        X = x[None, :]
        k1 = self.derivatives(X, u)
        J1 = self.derivatives_jacobian(x, u)
        x2 = (X + 0.5 * dt * k1)[0]
        J2 = self.derivatives_jacobian(x2, u) @ (eye + 0.5 * dt * J1)
        k2 = self.derivatives(x2[None, :], u)
        x3 = (X + 0.5 * dt * k2)[0]
        J3 = self.derivatives_jacobian(x3, u) @ (eye + 0.5 * dt * J2)
        k3 = self.derivatives(x3[None, :], u)
        J4 = self.derivatives_jacobian((X + dt * k3)[0], u) @ (eye + dt * J3)
        return eye + dt / 6.0 * (J1 + 2.0 * J2 + 2.0 * J3 + J4)

    def transition_low_speed_jacobian(self, x: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        return np.diag([1.0, np.exp(-dt / LOW_SPEED_BETA_TAU), 1.0])

    def measure_jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """d z / d x of :meth:`measure`, shape (4, 3)."""
        p = self.vehicle
        r, beta, vx = x
        delta = u[0]
        d_front, d_rear, *_ = self._force_gradients(x, u)
        H = np.zeros((len(MEASUREMENT_NAMES), 3))
        H[0] = (d_front + d_rear) / p.mass
        H[1, YAW] = H[3, YAW] = 1.0
        sd = np.sin(delta)
        H[2] = [0.5 * p.cg_to_front * sd, 0.5 * vx * sd / np.cos(beta) ** 2,
                0.5 * (1.0 + np.cos(delta)) + 0.5 * np.tan(beta) * sd]
        return H

    def measure_parameter_jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """d z / d theta: ay is linear in theta; the yaw rates and the wheel speed do not depend on it."""
        front, rear = self.axle_forces(x[None, :], u)
        return np.array([(front[0] + rear[0]) / (u[2] * self.vehicle.mass), 0.0, 0.0, 0.0])
