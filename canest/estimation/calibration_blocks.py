"""Block means of the raw inputs for the online calibration: one learner update per block of ticks (10 Hz).

Averaging ``ticks`` ticks shrinks the inputs' noise and lets the learner of
:mod:`canest.estimation.online_calibration` run at a tenth of the tick rate.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from canest.estimation.inputs import WHEEL_SPEEDS


@dataclass
class Block:
    """Means of the raw inputs over one block: speed from the wheels (configured radius), yaw rate, ay, ax, swa."""

    wheel_speed: float
    yaw_rate: float
    ay: float
    ax: float | None
    steering_wheel_angle: float


class BlockMeans:
    """Sums the raw inputs tick by tick; a block with any needed input missing, stale or saturated is dropped."""

    def __init__(self, names: tuple, radius: float, ticks: int):
        index = {name: i for i, name in enumerate(names)}
        self.wheels = [index[w] for w in WHEEL_SPEEDS]
        self.others = [index[n] for n in ("yaw_rate", "ay", "steering_wheel_angle")]
        self.ax = index.get("ax")
        self.used = self.wheels + self.others + ([self.ax] if self.ax is not None else [])
        self.radius = radius
        self.ticks = ticks
        self.sums = np.zeros(len(self.used))
        self.count = 0
        self.broken = False

    def add(self, sample):
        """Add one tick; the finished :class:`Block`, or None."""
        used = self.used
        if sample.stale[used].any() or sample.saturated[used].any():
            self.broken = True
        else:
            self.sums += sample.values[used]
        self.count += 1
        if self.count < self.ticks:
            return None
        means, whole = self.sums / self.count, not self.broken
        self.sums[:] = 0.0
        self.count, self.broken = 0, False
        if not whole:
            return None
        wheel_speed = self.radius * float(means[:4].mean())
        return Block(wheel_speed, float(means[4]), float(means[5]), float(means[7]) if self.ax is not None else None,
                     float(means[6]))
