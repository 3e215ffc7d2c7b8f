"""Four-wheel kinematics and loads shared by the two-track estimator models.

ISO 8855 axes (x forward, y left, z up); wheels in the order fl, fr, rl, rr at
body positions ``(a, +tf/2), (a, -tf/2), (-b, +tr/2), (-b, -tr/2)``; only the
front wheels steer, by ``delta``. Every function is vectorized: body states of
shape (N,) give wheel quantities of shape (N, 4).

Wheel centre velocity in the body frame ``(vx - r y_i, vy + r x_i)``, rotated
into the wheel frame by its steer angle gives ``v_long, v_lat``. Then

* slip angle (DICI-GFCKF eq 8, DCKF eq 10), ``alpha = delta_i - atan((vy + x_i r) / (vx - y_i r))``:
  front ``delta - atan((vy + a r) / (vx -+ tf r / 2))``, rear ``-atan((vy - b r) / (vx -+ tr r / 2))``.
  (DCKF eq 10 prints ``u +- L/2 w_r`` for the rear: the track, and the sign of eq 8, are meant.)
* slip ratio (DCKF eq 11), ``s = (R w - v_long) / v_long``, with the wheel-frame
  speed ``v_long`` in place of eq 11's approximate ``sqrt(u^2 + v^2) +- ...``.
* vertical loads (DICI-GFCKF eq 7), from the measured accelerations:
  ``Fz_f{l,r} = m (g b / (2L) - ax h / (2L) -+ ay h b / (tf L))``,
  ``Fz_r{l,r} = m (g a / (2L) + ax h / (2L) -+ ay h a / (tr L))``;
  they sum to ``m g`` and a left turn (ay > 0) unloads the left wheels.
* body-frame resultants of the wheel-frame forces (DICI-GFCKF eqs 1-3, DCKF eqs 2, 4, 5):
  ``m ax = sum Fx_b``, ``m ay = sum Fy_b``, ``Iz dr/dt = sum (x_i Fy_b,i - y_i Fx_b,i)``
  with ``Fx_b = Fx cos(delta_i) - Fy sin(delta_i)``, ``Fy_b = Fx sin(delta_i) + Fy cos(delta_i)``.
  (DCKF eq 4 prints rear ``F_y`` where the rear longitudinal forces belong; eq 3 of
  the DICI-GFCKF paper is this sum written out.)
"""
from __future__ import annotations

import numpy as np

from canest.params import VehicleParams
from canest.models.tire import TireModelParams, cornering_stiffness

GRAVITY = 9.81
FRONT = np.array([True, True, False, False])
MIN_WHEEL_SPEED = 1.0  # m/s, floor of the slip denominators near standstill


class WheelGeometry:
    def __init__(self, vehicle: VehicleParams):
        a, b, L, h, m = vehicle.cg_to_front, vehicle.cg_to_rear, vehicle.wheelbase, vehicle.cg_height, vehicle.mass
        tf, tr = vehicle.track_front, vehicle.track_rear
        self.vehicle = vehicle
        self.pos_x = np.array([a, a, -b, -b])
        self.pos_y = np.array([tf / 2, -tf / 2, tr / 2, -tr / 2])
        self.static_load = m * GRAVITY * np.array([b, b, a, a]) / (2 * L)
        self.load_per_ax = m * h / (2 * L) * np.array([-1.0, -1.0, 1.0, 1.0])
        self.load_per_ay = m * h / L * np.array([-b / tf, b / tf, -a / tr, a / tr])

    def loads(self, ax, ay):
        """Vertical loads (N) of eq 7 for accelerations of shape (N,) or scalars; never negative."""
        ax, ay = np.asarray(ax, dtype=float)[..., None], np.asarray(ay, dtype=float)[..., None]
        return np.maximum(self.static_load + self.load_per_ax * ax + self.load_per_ay * ay, 0.0)

    def steer(self, delta):
        """Steer angle of each wheel, shape (..., 4)."""
        return np.where(FRONT, np.asarray(delta, dtype=float)[..., None], 0.0)

    def rotation(self, delta):
        """(cos, sin) of each wheel's steer angle, shape (..., 4)."""
        steer = self.steer(delta)
        return np.cos(steer), np.sin(steer)

    def wheel_velocities(self, r, vx, vy, delta, rotation=None):
        """(v_long, v_lat): each wheel centre's velocity in its own frame, shape (N, 4) (scalars: (4,)).

        ``rotation``: :meth:`rotation` of ``delta``, where the caller has it already (the plant's hot loop).
        """
        vx_w = vx[..., None] - r[..., None] * self.pos_y
        vy_w = vy[..., None] + r[..., None] * self.pos_x
        cos_d, sin_d = self.rotation(delta) if rotation is None else rotation
        return vx_w * cos_d + vy_w * sin_d, -vx_w * sin_d + vy_w * cos_d

    @staticmethod
    def slip_angles(v_long, v_lat):
        """``alpha = -atan(v_lat / v_long)`` (equal to eq 8), denominators floored near standstill."""
        return -np.arctan2(v_lat, np.maximum(v_long, MIN_WHEEL_SPEED))

    def slip_ratios(self, wheel_speed, v_long):
        """``(R w - v_long) / v_long`` per wheel (DCKF eq 11)."""
        v = np.maximum(v_long, MIN_WHEEL_SPEED)
        return (self.vehicle.wheel_radius * wheel_speed - v) / v

    def body_accelerations(self, fx, fy, delta):
        """(ax, ay, dr/dt) of eqs 1-3 for wheel-frame forces of shape (N, 4)."""
        cos_d, sin_d = self.rotation(delta)
        fx_b = fx * cos_d - fy * sin_d
        fy_b = fx * sin_d + fy * cos_d
        p = self.vehicle
        return (fx_b.sum(axis=-1) / p.mass, fy_b.sum(axis=-1) / p.mass,
                (fy_b @ self.pos_x - fx_b @ self.pos_y) / p.yaw_inertia)

    def body_derivatives(self, r, beta, vx, fx, fy, delta, ax_offset):
        """(dr/dt, dbeta/dt, dvx/dt) of points driven by wheel-frame forces (N, 4); vx already floored.

        ``dvx/dt = ax + r vy - ax_offset``, ``dvy/dt = ay - r vx`` (DCKF eqs 1, 3, on a road whose grade's gravity
        is ``ax_offset = g sin(grade)``: the tires' forces are what an accelerometer reads, and gravity slows the
        car beside them; the papers' roads are flat) and, for ``beta = atan(vy / vx)``,
        ``dbeta/dt = (vx dvy/dt - vy dvx/dt) / (vx^2 + vy^2)``.
        """
        vy = vx * np.tan(beta)
        ax, ay, yaw_acc = self.body_accelerations(fx, fy, delta)
        dvx = ax + r * vy - ax_offset
        dvy = ay - r * vx
        return yaw_acc, (vx * dvy - vy * dvx) / (vx * vx + vy * vy), dvx

    def static_cornering_stiffness(self):
        """Cornering stiffness (N/rad) of each wheel at static load: half its configured axle's."""
        p = self.vehicle
        return 0.5 * np.array([p.cornering_stiffness_front] * 2 + [p.cornering_stiffness_rear] * 2)

    def cornering_stiffness(self, fz, tire):
        """Cornering stiffness (N/rad) of each wheel at loads ``fz`` (:func:`canest.models.tire.cornering_stiffness`)."""
        return cornering_stiffness(self.static_cornering_stiffness(), fz, self.static_load, tire.load_sensitivity)


class WheelModel:
    """What the two models on four tire curves (tire force, two track) are built on: the vehicle's parameters, its
    wheels' geometry and the estimators' tire."""

    def __init__(self, vehicle: VehicleParams, tire: TireModelParams = TireModelParams()):
        self.tire = tire
        self.use_vehicle(vehicle)

    def use_vehicle(self, vehicle: VehicleParams) -> None:
        """Take ``vehicle``'s parameters (the online calibration's learned cornering stiffnesses)."""
        self.vehicle = vehicle
        self.wheels = WheelGeometry(vehicle)
