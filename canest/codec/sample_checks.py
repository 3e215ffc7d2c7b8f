"""Checks of one mapped signal's value in a frame: its range, its saturation, and a sender stuck on one value.

The range is the DBC's unless the config overrides it (``range: [low, high]``
or ``none``: some DBCs declare raw-style ranges such as ``[0|65535]`` for
signed physical signals). A stuck sender repeats one raw value exactly: a
noisy sensor's value never repeats bit for bit for seconds while the car
moves, so a config may name the time (``stuck_after``) after which an
unchanged value is no longer taken as a measurement.
"""
from __future__ import annotations

MOVING_WHEEL_SPEED = 3.0  # rad/s mean of the mapped wheels (about 1 m/s): the car moves


class SignalBounds:
    """The range of one mapped signal's value and the limits at which it saturates, fixed at start-up."""

    def __init__(self, bounds: tuple, quantum: float):
        self.low, self.high = bounds
        # a value within half a quantum of a non-zero limit: saturated, not measured. A sensor beyond its
        # range sends the limit (a wheel speed above what the signal carries, an accelerometer at full
        # scale); that is a bound, not the value. Zero is a physical value (standstill), never a saturation.
        self.limits = tuple(limit for limit in bounds if limit is not None and limit != 0)
        self.half_quantum = abs(quantum) / 2.0

    def outside(self, value: float) -> bool:
        """``value`` lies outside (low, high); a None bound is open."""
        return ((self.low is not None and value < self.low - 1e-9)
                or (self.high is not None and value > self.high + 1e-9))

    def at_limit(self, value: float) -> bool:
        """``value`` sits at a non-zero limit of the range (within half a quantum): saturated."""
        for limit in self.limits:
            if abs(value - limit) <= self.half_quantum:
                return True
        return False


class StuckDetector:
    """Per canonical input with a ``stuck_after`` time: is its raw value unchanged that long while the car moves?"""

    def __init__(self, stuck_after: dict):
        self.stuck_after = stuck_after  # canonical -> s
        self.runs = {}  # canonical -> (value, time the value was first seen while moving)

    def stuck(self, canonical: str, value: float, t: float, moving: bool) -> bool:
        limit = self.stuck_after.get(canonical)
        if limit is None:
            return False
        run = self.runs.get(canonical)
        if not moving or run is None or run[0] != value:
            self.runs[canonical] = (value, t)
            return False
        return t - run[1] >= limit
