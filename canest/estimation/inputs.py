"""The held inputs of one tick, by canonical name (from a :class:`canest.resample.Sample`)."""
from __future__ import annotations

from canest.signals import INPUT_GROUPS, WHEELS

WHEEL_SPEEDS = tuple(f"wheel_speed_{w}" for w in WHEELS)


class TickInputs:
    """Values, staleness, freshness and age of every mapped input at one tick."""

    def __init__(self, sample):
        self.t = sample.t
        self.values = dict(zip(sample.names, sample.values))
        self.stale = dict(zip(sample.names, sample.stale))
        self.fresh = dict(zip(sample.names, sample.fresh))
        self.ages = dict(zip(sample.names, sample.ages))
        self.at_limit = dict(zip(sample.names, sample.saturated))

    def has(self, *names) -> bool:
        """Every one of ``names`` is mapped, not stale and not saturated (a value at its DBC limit is no measurement)."""
        return all(name in self.values and not self.stale[name] and not self.at_limit[name] for name in names)

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
        """The input groups (status message bits) with a mapped member gone stale."""
        return tuple(group for group, members in INPUT_GROUPS.items()
                     if any(m in self.values and self.stale[m] for m in members))

    def wheel_speed(self, wheel_radius: float) -> float:
        """The wheel-centre speed ``R mean(w)`` of the four wheels."""
        return wheel_radius * sum(self.values[w] for w in WHEEL_SPEEDS) / len(WHEEL_SPEEDS)
