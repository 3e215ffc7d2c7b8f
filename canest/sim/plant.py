"""Nonlinear two-track vehicle plant: the simulator's truth.

ISO 8855 axes (x forward, y left, z up). Wheels in the order fl, fr, rl, rr at
body positions ``(a, +tf/2), (a, -tf/2), (-b, +tr/2), (-b, -tr/2)``.

State (16): global X, Y, heading psi; body vx, vy, yaw rate r; wheel speeds
w[4]; relaxed lateral tire forces Fy[4]; lagged body accelerations ax_l, ay_l
used for load transfer (suspension pitch/roll lag ``LOAD_TRANSFER_TAU``).

Per wheel: centre velocity ``(vx - r y_i, vy + r x_i)`` rotated into the wheel
frame by its steer angle gives ``v_long, v_lat``; slip angle
``alpha = -atan(v_lat / |v_long|)``, slip ratio ``kappa = (w R - v_long) / |v_long|``.
Loads (DICI-GFCKF paper eq 7, with lagged accelerations):
``Fz_ij = m (g l_other / (2L) -+ ax h / (2L) -+ ay h l_other / (t L))``.
Tire forces from :mod:`canest.sim.tire`; lateral forces follow the steady
state with relaxation ``dFy/dt = |v_long| / sigma (Fy_ss - Fy)`` (paper eq 6).
Chassis: ``m (dvx/dt - r vy) = sum Fx_b - drag``, ``m (dvy/dt + r vx) = sum Fy_b``,
``Iz dr/dt = sum (x_i Fy_b,i - y_i Fx_b,i)``; a banked road adds gravity's
``bank_acceleration`` (m/s^2) to dvy/dt, which the measured ay (the tires' force) does not see, a road's
grade its ``grade_acceleration`` to dvx/dt, unseen by the measured ax alike (its load transfer is the tires'
force's, as the accelerometer's); a crosswind's ``side_force`` (N, :mod:`canest.sim.wind`), set before each
step, adds to the body's lateral force at ``side_force_arm`` m ahead of the centre of gravity (the measured ay
sees it: a force on the body, not gravity);
wheels: ``J dw/dt = T - R Fx - R f_rr Fz``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from canest.params import VehicleParams
from canest.models.wheels import FRONT, WheelGeometry
from canest.sim.tire import SlipCurves, TireParams, combined_forces

AIR_DENSITY = 1.2
DRAG_AREA = 0.7  # Cd * A, m^2
LOAD_TRANSFER_TAU = 0.08  # s
MIN_SLIP_SPEED = 1.0  # m/s, guards slip definitions near standstill

X, Y, PSI, VX, VY, R = range(6)
W = slice(6, 10)
FY = slice(10, 14)
AXL, AYL = 14, 15
STATE_SIZE = 16


@dataclass
class PlantOutputs:
    """Quantities of one instant that sensors and the truth table need."""

    ax: float
    ay: float
    fx: np.ndarray
    fy: np.ndarray
    fz: np.ndarray
    alpha: np.ndarray
    kappa: np.ndarray


class TwoTrackPlant:
    def __init__(self, vehicle: VehicleParams, mu, tire: TireParams = TireParams(), bank_acceleration: float = 0.0,
                 grade_acceleration: float = 0.0, side_force_arm: float = 0.0):
        self.p = vehicle
        self.tire = tire
        self.bank_acceleration = bank_acceleration
        self.grade_acceleration = grade_acceleration
        self.side_force = 0.0  # N, body-lateral, held over a step (a crosswind's)
        self.side_force_arm = side_force_arm
        self.mu = np.broadcast_to(np.asarray(mu, dtype=float), (4,)).copy()
        self.wheels = WheelGeometry(vehicle)
        self.pos_x, self.pos_y = self.wheels.pos_x, self.wheels.pos_y
        self.fz_static = self.wheels.static_load
        self.slip_curves = SlipCurves.of(tire, FRONT)

    def initial_state(self, speed: float) -> np.ndarray:
        s = np.zeros(STATE_SIZE)
        s[VX] = speed
        s[W] = speed / self.p.wheel_radius
        return s

    def _forces(self, s: np.ndarray, delta: float):
        cos_d, sin_d = self.wheels.rotation(delta)
        v_long, v_lat = self.wheels.wheel_velocities(s[R], s[VX], s[VY], delta, (cos_d, sin_d))
        speed = np.maximum(np.abs(v_long), MIN_SLIP_SPEED)
        alpha = -np.arctan2(v_lat, speed)
        kappa = (s[W] * self.p.wheel_radius - v_long) / speed
        fz = self.wheels.loads(s[AXL], s[AYL])
        fx, fy_ss = combined_forces(alpha, kappa, fz, self.mu, self.fz_static, self.slip_curves)
        return cos_d, sin_d, speed, alpha, kappa, fz, fx, fy_ss

    def derivatives(self, s: np.ndarray, delta: float, torque: np.ndarray):
        p = self.p
        cos_d, sin_d, speed, alpha, kappa, fz, fx, fy_ss = self._forces(s, delta)
        fy = s[FY]
        fx_b = fx * cos_d - fy * sin_d
        fy_b = fx * sin_d + fy * cos_d
        drag = 0.5 * AIR_DENSITY * DRAG_AREA * s[VX] * abs(s[VX])
        ax = (fx_b.sum() - drag) / p.mass
        ay = (fy_b.sum() + self.side_force) / p.mass
        d = np.empty(STATE_SIZE)
        cos_psi, sin_psi = np.cos(s[PSI]), np.sin(s[PSI])
        d[X] = s[VX] * cos_psi - s[VY] * sin_psi
        d[Y] = s[VX] * sin_psi + s[VY] * cos_psi
        d[PSI] = s[R]
        d[VX] = ax + s[R] * s[VY] + self.grade_acceleration
        d[VY] = ay - s[R] * s[VX] + self.bank_acceleration
        d[R] = (self.pos_x @ fy_b - self.pos_y @ fx_b + self.side_force_arm * self.side_force) / p.yaw_inertia
        rolling = self.tire.rolling_resistance * fz * np.tanh(s[W] / 0.5)
        d[W] = (torque - p.wheel_radius * (fx + rolling)) / p.wheel_inertia
        d[FY] = speed / self.tire.relaxation_length * (fy_ss - fy)
        d[AXL] = (ax - s[AXL]) / LOAD_TRANSFER_TAU
        d[AYL] = (ay - s[AYL]) / LOAD_TRANSFER_TAU
        return d, PlantOutputs(ax, ay, fx, fy.copy(), fz, alpha, kappa)

    def step(self, s: np.ndarray, delta: float, torque: np.ndarray, dt: float, slope: np.ndarray | None = None):
        """One RK4 step with steering and torques held; ``slope``: :meth:`derivatives` at ``s``, if known."""
        k1 = self.derivatives(s, delta, torque)[0] if slope is None else slope
        k2, _ = self.derivatives(s + 0.5 * dt * k1, delta, torque)
        k3, _ = self.derivatives(s + 0.5 * dt * k2, delta, torque)
        k4, _ = self.derivatives(s + dt * k3, delta, torque)
        return s + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
