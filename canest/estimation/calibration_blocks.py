"""Block means of the raw inputs for the online calibration: one learner update per block of ticks (10 Hz).

Averaging ``ticks`` ticks shrinks the inputs' noise and lets the learner of
:mod:`canest.estimation.online_calibration` run at a tenth of the tick rate.
Where the four motor torques are mapped, each wheel's speed is taken without
the slip its drive force needs (:func:`canest.estimation.reference_speed.slip_free_speed`),
as the estimator's reference speed takes it: the speed scale learned from the
raw wheels held that slip too (0.3 % below the true radius scale on the
simulated road, in bends at 80 km/h), and the estimator took it out a second time.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from canest.estimation.inputs import WHEEL_SPEEDS
from canest.estimation.reference_speed import TORQUES, slip_free_speed, tire_usage
from canest.models.wheels import WheelGeometry
from canest.params import VehicleParams


@dataclass
class Block:
    """Means of the raw inputs over one block: speed from the wheels (configured radius), yaw rate, ay, ax, swa,
    and the second gyro's yaw rate (None where the car sends none, or it was stale or saturated in the block)."""

    wheel_speed: float
    yaw_rate: float
    ay: float
    ax: float | None
    steering_wheel_angle: float
    yaw_rate_2: float | None = None


class BlockMeans:
    """Sums the raw inputs tick by tick; a block with any needed input missing, stale or saturated is dropped (the
    second gyro is not needed: its mean alone is left out)."""

    def __init__(self, names: tuple, vehicle: VehicleParams, ticks: int):
        index = {name: i for i, name in enumerate(names)}
        self.wheels = [index[w] for w in WHEEL_SPEEDS]
        self.others = [index[n] for n in ("yaw_rate", "ay", "steering_wheel_angle")]
        self.ax = index.get("ax")
        self.used = self.wheels + self.others + ([self.ax] if self.ax is not None else [])
        torques = [index.get(name) for name in TORQUES]
        self.torques = torques if self.ax is not None and None not in torques else []  # summed, never required
        self.summed = self.used + self.torques
        self.geometry = WheelGeometry(vehicle)
        self.slip_stiffness = vehicle.tire.longitudinal_stiffness
        self.rolling_resistance = vehicle.tire.rolling_resistance
        self.radius = vehicle.wheel_radius
        self.ticks = ticks
        self.sums = np.zeros(len(self.summed))
        self.count = 0
        self.broken = False
        self.second_gyro = index.get("yaw_rate_2")
        self.second_gyro_sum, self.second_gyro_broken = 0.0, False

    def add(self, sample):
        """Add one tick; the finished :class:`Block`, or None."""
        used = self.used
        if sample.stale[used].any() or sample.saturated[used].any():
            self.broken = True
        else:
            self.sums += sample.values[self.summed]
        second = self.second_gyro
        if second is not None:
            if sample.stale[second] or sample.saturated[second]:
                self.second_gyro_broken = True
            else:
                self.second_gyro_sum += sample.values[second]
        self.count += 1
        if self.count < self.ticks:
            return None
        means, whole = self.sums / self.count, not self.broken
        yaw_rate_2 = (self.second_gyro_sum / self.count
                      if second is not None and not self.second_gyro_broken else None)
        self.sums[:] = 0.0
        self.count, self.broken = 0, False
        self.second_gyro_sum, self.second_gyro_broken = 0.0, False
        if not whole:
            return None
        ay, ax = float(means[5]), float(means[7]) if self.ax is not None else None
        # from the block's means: the torques change little in 0.1 s, and the slip is a fraction of a percent
        usage = (tire_usage(means[len(self.used):], self.geometry.loads(ax, ay), self.radius, self.rolling_resistance)
                 if self.torques else (0.0,) * 4)
        wheel_speed = float(slip_free_speed(means[:4], usage, self.radius, self.slip_stiffness))
        return Block(wheel_speed, float(means[4]), ay, ax, float(means[6]), yaw_rate_2)
