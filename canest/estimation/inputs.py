"""The held inputs of one tick, by canonical name (from a :class:`canest.resample.Sample`)."""
from __future__ import annotations

import numpy as np

from canest.signals import INPUT_GROUPS, WHEELS

WHEEL_SPEEDS = tuple(f"wheel_speed_{w}" for w in WHEELS)


class TickInputs:
    """Values, staleness, freshness and age of every mapped input at one tick."""

    def __init__(self, sample):
        self.t = sample.t
        names = sample.names
        # Python floats and bools, not numpy scalars: every use below is scalar arithmetic
        self.values = dict(zip(names, np.asarray(sample.values, dtype=float).tolist()))
        self.stale = dict(zip(names, np.asarray(sample.stale, dtype=bool).tolist()))
        self.fresh = dict(zip(names, np.asarray(sample.fresh, dtype=bool).tolist()))
        self.ages = dict(zip(names, np.asarray(sample.ages, dtype=float).tolist()))
        self.at_limit = dict(zip(names, np.asarray(sample.saturated, dtype=bool).tolist()))
        self.derived = set()  # inputs computed from others, not from the bus

    def derive(self, name: str, value: float, stale: bool, fresh: bool, age: float) -> None:
        """Add the input ``name`` computed from other inputs (:mod:`canest.estimation.derived_ax`)."""
        self.values[name], self.stale[name], self.fresh[name], self.ages[name] = value, stale, fresh, age
        self.at_limit[name] = False
        self.derived.add(name)

    def has(self, *names) -> bool:
        """Every one of ``names`` is mapped, not stale and not saturated (a value at its DBC limit is no measurement)."""
        for name in names:  # a loop, not all(...): this runs a dozen times a tick
            if name not in self.values or self.stale[name] or self.at_limit[name]:
                return False
        return True

    def saturated(self, name: str) -> bool:
        """The input's latest sample sat at a limit of its DBC signal (and is not stale)."""
        return bool(self.at_limit.get(name, False)) and not self.stale[name]

    def any_fresh(self, *names) -> bool:
        return any(self.fresh.get(name, False) for name in names)

    def current(self, name: str) -> float:
        """The held value if it is present and not stale, else 0."""
        return self.values[name] if self.has(name) else 0.0

    def any_present(self) -> bool:
        return any(self.has(name) for name in self.values)

    def missing_groups(self) -> tuple:
        """The input groups (status message bits) with a mapped member gone stale (a derived one: its sources)."""
        return tuple(group for group, members in INPUT_GROUPS.items()
                     if any(m in self.values and m not in self.derived and self.stale[m] for m in members))

    def wheel_speed(self, wheel_radius: float) -> float:
        """The wheel-centre speed ``R mean(w)`` of the four wheels."""
        return wheel_radius * sum(self.values[w] for w in WHEEL_SPEEDS) / len(WHEEL_SPEEDS)
