"""Longitudinal tire forces from the in-wheel motors (DICI-GFCKF paper eq 4).

Each wheel's rotational dynamics, ``J dw/dt = T - R Fx`` (DCKF paper eq 6,
whose ``F_x R w`` carries a stray ``w``), give

    Fx = (T - J dw/dt) / R

The paper's eq 4 prints ``J w`` (an angular momentum, N m s, not a torque); the
derivative is meant. ``dw/dt`` comes from the noisy wheel speeds through
:class:`WheelAcceleration`. Rolling resistance and brake torque are not in the
balance: on the simulator (0.012 Fz rolling resistance) this reads ~55 N high
per wheel.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

WINDOW = 5  # samples


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


def longitudinal_forces(torque, wheel_acceleration, wheel_inertia: float, wheel_radius: float) -> np.ndarray:
    """Eq 4 corrected: ``Fx = (T - J dw/dt) / R`` per wheel, N."""
    return (np.asarray(torque, dtype=float) - wheel_inertia * np.asarray(wheel_acceleration)) / wheel_radius
