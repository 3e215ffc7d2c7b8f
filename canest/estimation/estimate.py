"""What the estimator publishes each tick: :class:`Estimate`, its validity bits and modes.

Outputs, evaluation and batch read these without importing the estimator.
"""
from __future__ import annotations

from dataclasses import dataclass

from canest.signals import INPUT_GROUPS

OUTPUT_STATES = ("vx", "vy", "beta", "yaw_rate")
# Bit i of the published validity mask (CAN ``ValidFlags``, CSV ``valid``).
VALID_BITS = ("vx", "vy", "beta", "yaw_rate", "forces", "friction", "friction_observable")
MODES = ("initializing", "normal", "low_speed", "degraded", "no_input")


@dataclass
class Estimate:
    """Everything published for one tick. ``values`` holds states and ``<name>_std`` in SI units."""

    t: float
    values: dict
    valid: dict
    mode: str
    filter: str
    nis: float = 0.0
    missing: tuple = ()
    resets: int = 0

    @property
    def valid_flags(self) -> int:
        return sum(1 << i for i, name in enumerate(VALID_BITS) if self.valid.get(name, False))

    @property
    def missing_mask(self) -> int:
        return sum(1 << i for i, name in enumerate(INPUT_GROUPS) if name in self.missing)
