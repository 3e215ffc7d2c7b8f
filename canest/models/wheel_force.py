"""Longitudinal tire forces: from the in-wheel motors (DICI-GFCKF paper eq 4), or from ax and the drive layout.

**From the motors.** Each wheel's rotational dynamics, ``J dw/dt = T - R (Fx + f_r Fz)`` (DCKF paper
eq 6, whose ``F_x R w`` carries a stray ``w``, with the rolling moment ``f_r Fz R`` the paper leaves out), give

    Fx = (T - J dw/dt) / R - f_r Fz

The paper's eq 4 prints ``J w`` (an angular momentum, N m s, not a torque); the
derivative is meant. ``dw/dt`` comes from the noisy wheel speeds through
:class:`WheelAcceleration`. ``f_r`` is ``vehicle.tire.rolling_resistance``
(without it, on the simulator's 0.012 Fz, Fx read ~55 N high per wheel). Brake
torque is not in the balance.

**From ax and the drive layout** (:class:`DriveLayout`, for cars that send no
motor torques). The paper's eq 1 is the body's longitudinal balance,

    m ax = (Fx_fl + Fx_fr) cos(delta) - (Fy_fl + Fy_fr) sin(delta) + Fx_rl + Fx_rr.

With the measured ax and the layout's axle shares (``s`` on the front axle,
``1 - s`` on the rear, each axle's share halved between its wheels), every
wheel carries ``Fx_ij = s_ij F`` of one total ``F``, and eq 1 solved for it is

    F = (m ax + (Fy_fl + Fy_fr) sin(delta)) / (s cos(delta) + 1 - s).

``s`` is the drive's front share while ``F >= 0`` and the brake balance while
braking (``F`` is continuous through 0, where both give 0). The forces depend
on the lateral force states, so the model's ax (eq 14's first row) equals the
measured ax identically: ax becomes an input and leaves the measurements.
Aerodynamic drag and rolling resistance are not modelled: the accelerometer
measures the tire forces less the drag, so on the simulator (0.42 N s^2/m^2
drag, 0.012 rolling resistance) the total reads ~200 N (80 km/h) below the
tires' drive force, split over four wheels each carrying several kN at high ay.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

WINDOW = 5  # samples
MEDIAN_SLOPE_NOISE = 1.07  # std of the median of pairwise slopes over a least-squares slope's, white noise


class WheelAcceleration:
    """Wheel angular accelerations from the last ``WINDOW`` tick samples: the median of pairwise slopes.

    The Theil-Sen estimator: the slope of every pair of samples, then the
    median. With 5 samples at 100 Hz one corrupted speed moves it little and
    white speed noise of 0.05 rad/s gives ~1.7 rad/s^2 (7 N of Fx on a 1.5
    kg m^2 wheel of 0.36 m radius); the lag is 20 ms. A vectorized form of
    ``scipy.stats.theilslopes`` for four series at once (which fits one
    series per call).
    """

    def __init__(self, window: int = WINDOW):
        self.window = window
        pairs = np.array(list(combinations(range(window), 2)))
        self.first, self.second = pairs[:, 0], pairs[:, 1]
        self.times = np.zeros(window)
        self.speeds = None
        self.count = 0

    @property
    def samples(self) -> int:
        """How many samples the window holds."""
        return min(self.count, self.window)

    def reset(self) -> None:
        self.count = 0

    def noise_gain(self) -> float:
        """The slope's std per unit std of a white noise on the samples held (1/s; 0 before two samples): a
        least-squares slope's is ``1 / sqrt(sum((t_i - mean(t))^2))``, the median of pairwise slopes'
        ``MEDIAN_SLOPE_NOISE`` times that (7 samples 10 ms apart, 20 000 slopes of a unit white noise: 20.3 / s,
        least squares 18.9)."""
        times = self.times[:self.samples]
        spread = float(np.sqrt(np.sum((times - times.mean()) ** 2))) if self.samples else 0.0
        return MEDIAN_SLOPE_NOISE / spread if spread > 0.0 else 0.0

    def update(self, t: float, wheel_speeds) -> np.ndarray:
        """Add the speeds (rad/s) of tick ``t``; the accelerations (rad/s^2), zero until two samples exist.

        The samples sit in a ring buffer: a pair's slope does not depend on which sample is older."""
        speeds = np.asarray(wheel_speeds, dtype=float)
        if self.speeds is None or self.speeds.shape[1] != speeds.size:
            self.speeds = np.zeros((self.window, speeds.size))
        slot = self.count % self.window
        self.times[slot], self.speeds[slot] = t, speeds
        self.count += 1
        if self.count < 2:
            return np.zeros(speeds.size)
        keep = self.second < self.samples
        first, second = self.first[keep], self.second[keep]
        slopes = (self.speeds[second] - self.speeds[first]) / (self.times[second] - self.times[first])[:, None]
        slopes.sort(axis=0)  # the median by hand: np.median's generality costs more than this whole update
        middle = len(slopes) // 2
        return 0.5 * (slopes[middle] + slopes[-1 - middle])


def longitudinal_forces(torque, wheel_acceleration, wheel_inertia: float, wheel_radius: float,
                        rolling) -> np.ndarray:
    """Eq 4 corrected: ``Fx = (T - J dw/dt) / R - f_r Fz`` per wheel, N; ``rolling``: ``f_r Fz`` per wheel (N), the
    rolling moment's share of the torque, which no tire force carries (:class:`canest.params.TireModelParams`)."""
    return (np.asarray(torque, dtype=float) - wheel_inertia * np.asarray(wheel_acceleration)) / wheel_radius - rolling


class DriveLayout:
    """Per-wheel longitudinal forces from ax by eq 1 and the axle shares of the drive and of the brakes."""

    def __init__(self, vehicle):
        self.mass = vehicle.mass
        self.drive = self.wheel_shares(vehicle.drive_front_share)
        self.brake = self.wheel_shares(vehicle.brake_front_share)

    @staticmethod
    def wheel_shares(front_share: float) -> np.ndarray:
        """(fl, fr, rl, rr) shares of a total force with ``front_share`` on the front axle."""
        return 0.5 * np.array([front_share, front_share, 1.0 - front_share, 1.0 - front_share])

    def forces(self, ax: float, fy: np.ndarray, delta: float) -> np.ndarray:
        """``Fx`` (N, 4) of eq 1 solved for the total force, for lateral forces ``fy`` (N, 4) in the wheel frames."""
        sin_d, cos_d = np.sin(delta), np.cos(delta)
        balance = self.mass * ax + (fy[:, 0] + fy[:, 1]) * sin_d
        shares = np.where(balance[:, None] >= 0.0, self.drive, self.brake)
        total = balance / ((shares[:, 0] + shares[:, 1]) * cos_d + shares[:, 2] + shares[:, 3])
        return shares * total[:, None]
