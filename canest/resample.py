"""Fixed-rate ticks with zero-order hold and staleness.

Frames arrive at their own rates and jitter; the filter runs once every
``dt``. :class:`Resampler` keeps the latest SI value of each input with its
time; at a tick it reports, per input, the held value, whether it is *stale*
(older than its timeout, or never received) and whether it is *fresh* (new
since the previous tick: a measurement update uses only fresh values, so a
sample is never counted twice). :class:`TickClock` lays ticks on the grid
``t0 + k dt`` of the source's clock, anchored at the first frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class Sample:
    t: float
    names: tuple  # canonical input names, the order of the arrays
    values: np.ndarray
    stale: np.ndarray  # bool per input
    fresh: np.ndarray  # bool per input
    ages: np.ndarray  # s since each input's latest frame
    saturated: np.ndarray  # bool per input: its latest sample sat at a limit of its DBC signal


class Resampler:
    def __init__(self, names, timeouts):
        self.names = tuple(names)
        self.index = {name: i for i, name in enumerate(self.names)}
        self.timeouts = np.array([timeouts[name] for name in self.names], dtype=float)
        self.values = np.zeros(len(self.names))
        self.stamps = np.full(len(self.names), -math.inf)
        self.fresh = np.zeros(len(self.names), dtype=bool)
        self.saturated = np.zeros(len(self.names), dtype=bool)

    def set_timeout(self, name: str, seconds: float) -> None:
        """A new timeout for ``name`` (its message's cycle measured on the bus)."""
        self.timeouts[self.index[name]] = seconds

    def hold(self, name: str, value: float, t: float, saturated: bool = False) -> None:
        i = self.index[name]
        self.values[i] = value
        self.stamps[i] = t
        self.fresh[i] = True
        self.saturated[i] = saturated

    def never_held(self) -> list:
        """The inputs no value was ever held for."""
        return [name for name, stamp in zip(self.names, self.stamps) if stamp == -math.inf]

    def sample(self, t: float) -> Sample:
        ages = t - self.stamps
        stale = ages > self.timeouts
        sample = Sample(t, self.names, self.values.copy(), stale, self.fresh & ~stale, ages, self.saturated.copy())
        self.fresh[:] = False
        return sample


class TickClock:
    """Tick times ``t0 + k dt``.

    A frame more than ``max_gap`` after the next tick (a gap, a clock step
    forward) or before it (a clock step back) re-anchors the grid at the
    frame instead of catching up tick by tick or waiting for the clock to
    return; each re-anchoring is counted in ``jumps``.
    """

    def __init__(self, dt: float, max_gap: float = 1.0):
        self.dt = dt
        self.max_gap = max_gap
        self.t0 = None
        self.k = 0
        self.jumps = 0

    @property
    def next_tick(self) -> float:
        return math.inf if self.t0 is None else self.t0 + self.k * self.dt

    def anchor(self, t: float) -> None:
        self.t0, self.k = t, 0

    def due(self, t: float):
        """Yield every tick time strictly before ``t`` that has not been yielded."""
        if self.t0 is None:
            self.anchor(t)
            return
        if abs(t - self.next_tick) > self.max_gap:
            self.jumps += 1
            self.anchor(t)
            return
        while self.next_tick < t:
            yield self.next_tick
            self.k += 1
