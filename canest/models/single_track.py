"""Three-degree-of-freedom single-track (bicycle) model with linear tires.

This is the model shared by the LMRWEKF (eqs 1-5), MCSCKF and SVD-FCKF (eqs
1-7) papers, derived here from first principles with ISO 8855 axes: x forward,
y left, z up; a positive road wheel angle ``delta`` turns left; yaw rate ``r``
is positive counter-clockwise seen from above; sideslip ``beta = atan2(vy, vx)``.

State ``x = (r, beta, vx)`` (the papers' order), input ``u = (delta, ax)`` with
``ax`` the measured longitudinal acceleration, measurements
``z = (ay, r, vx_wheel)``.

Tire slip angles and forces (cornering stiffnesses ``Cf, Cr`` per axle, positive):

    alpha_f = delta - beta - a r / vx        Fyf = Cf alpha_f
    alpha_r =       - beta + b r / vx        Fyr = Cr alpha_r

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

from canest.config import VehicleParams

STATE_NAMES = ("yaw_rate", "beta", "vx")
MEASUREMENT_NAMES = ("ay", "yaw_rate", "vx_wheel")
YAW, BETA, VX = 0, 1, 2
# Denominator guard for sigma points that stray towards standstill.
MIN_DIVISOR_SPEED = 0.5
# Time constant with which sideslip decays to zero while it is not observable.
LOW_SPEED_BETA_TAU = 0.5


class SingleTrackModel:
    """Vectorized transition and measurement functions of the 3-DOF model."""

    state_names = STATE_NAMES
    measurement_names = MEASUREMENT_NAMES

    def __init__(self, vehicle: VehicleParams):
        self.vehicle = vehicle

    def axle_forces(self, X: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Front and rear axle lateral forces (N) for points ``X`` of shape (N, 3)."""
        p = self.vehicle
        r, beta = X[:, YAW], X[:, BETA]
        vx = np.maximum(X[:, VX], MIN_DIVISOR_SPEED)
        delta = u[0]
        front = p.cornering_stiffness_front * (delta - beta - p.cg_to_front * r / vx)
        rear = p.cornering_stiffness_rear * (-beta + p.cg_to_rear * r / vx)
        return front, rear

    def derivatives(self, X: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Continuous-time dx/dt of eqs (1)-(3), shape (N, 3)."""
        p = self.vehicle
        front, rear = self.axle_forces(X, u)
        r, beta = X[:, YAW], X[:, BETA]
        vx = np.maximum(X[:, VX], MIN_DIVISOR_SPEED)
        ax = u[1]
        ay = (front + rear) / p.mass
        cos_beta = np.cos(beta)
        out = np.empty_like(X)
        out[:, YAW] = (p.cg_to_front * front - p.cg_to_rear * rear) / p.yaw_inertia
        out[:, BETA] = (ay * cos_beta - ax * np.sin(beta)) * cos_beta / vx - r
        out[:, VX] = ax + r * X[:, VX] * np.tan(beta)
        return out

    def transition(self, X: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
        """One RK4 step of length ``dt`` with ``u`` held; X of shape (N, 3)."""
        k1 = self.derivatives(X, u)
        k2 = self.derivatives(X + 0.5 * dt * k1, u)
        k3 = self.derivatives(X + 0.5 * dt * k2, u)
        k4 = self.derivatives(X + dt * k3, u)
        return X + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

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
        """Measurements (ay, yaw rate, mean wheel-frame longitudinal speed), shape (N, 3).

        ``vx_wheel`` is the mean over the four wheels of the wheel centre's
        speed along the wheel's heading: rear ``vx -+ r t/2``, front
        ``(vx -+ r t/2) cos(delta) + (vy + a r) sin(delta)``; the left/right
        yaw terms cancel in the mean.
        """
        p = self.vehicle
        front, rear = self.axle_forces(X, u)
        delta = u[0]
        r, vx = X[:, YAW], X[:, VX]
        vy = vx * np.tan(X[:, BETA])
        out = np.empty_like(X)
        out[:, 0] = (front + rear) / p.mass
        out[:, 1] = r
        out[:, 2] = 0.5 * vx * (1.0 + np.cos(delta)) + 0.5 * (vy + p.cg_to_front * r) * np.sin(delta)
        return out

    def lateral_velocity(self, x: np.ndarray) -> float:
        return float(x[VX] * np.tan(x[BETA]))
