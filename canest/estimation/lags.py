"""Two memories of a signal: a first-order lag and a fading maximum.

The judge (:mod:`canest.estimation.validity`, :mod:`canest.estimation.judge`) keeps a model's lagged
steady-state yaw rate and the largest recent excitation with them; the wheel loads
(:mod:`canest.estimation.roll_lag`) lag ay by the body's roll.
"""
from __future__ import annotations

import math

__all__ = ["FadingMaximum", "FirstOrderLag"]


class FirstOrderLag:
    """``x[k] = x[k-1] + alpha (u[k] - x[k-1])``, ``alpha = dt / (time_constant + dt)`` (the backward-Euler step
    of ``time_constant dx/dt = u - x``), starting at the first sample after construction or :meth:`reset`."""

    def __init__(self, dt: float, time_constant: float):
        self.alpha = dt / (time_constant + dt)
        self.value = None

    def reset(self) -> None:
        self.value = None

    def update(self, sample: float) -> float:
        self.value = sample if self.value is None else self.value + self.alpha * (sample - self.value)
        return self.value


class FadingMaximum:
    """The largest value seen, fading with time constant ``memory`` s (a leaky maximum)."""

    def __init__(self, dt: float, memory: float):
        self.decay = math.exp(-dt / memory)
        self.value = 0.0

    def reset(self) -> None:
        self.value = 0.0

    def update(self, value: float) -> float:
        self.value = max(value, self.value * self.decay)
        return self.value
