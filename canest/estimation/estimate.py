"""What the estimator publishes each tick: :class:`Estimate`, its validity bits and modes.

Outputs, evaluation and batch read these without importing the estimator.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from canest.signals import INPUT_GROUPS, WHEELS

OUTPUT_STATES = ("vx", "vy", "beta", "yaw_rate")
# Bit i of the validity mask: bits 0-6 on CAN (``CE_Status.ValidFlags``), all of them in the CSV ``valid`` column
# (per-wheel forces and frictions from bit 7, as the per-wheel ``..Valid`` signals on CAN).
VALID_BITS = ("vx", "vy", "beta", "yaw_rate", "forces", "friction", "friction_observable",
              *(f"fy_{w}" for w in WHEELS), *(f"mu_{w}" for w in WHEELS))
CAN_VALID_BITS = 7  # how many of them CE_Status.ValidFlags carries
MODES = ("initializing", "normal", "low_speed", "degraded", "no_input")
# Why a validity bit is clear (index = the code of CE_ValidityCause; README "How far to trust the output").
CAUSES = ("valid", "no_input", "initializing", "low_speed", "inconsistent", "saturated", "after_reset",
          "not_excited", "at_bound", "uncertain", "model_regime")
CAUSE_GROUPS = ("vx", "yaw_rate", "beta", "forces", "friction")  # the states and groups whose cause is published


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
    causes: dict = field(default_factory=dict)  # state or group -> why its bit is clear ("valid" when set)
    calibration: Mapping = field(default_factory=dict)  # the online learner's report() (read-only), empty when off

    @property
    def valid_flags(self) -> int:
        """The validity mask over :data:`VALID_BITS`."""
        return sum(1 << i for i, name in enumerate(VALID_BITS) if self.valid.get(name, False))

    def cause_code(self, group: str) -> int:
        """The published code of why ``group``'s bit is clear (no_input for a group the model does not estimate)."""
        return CAUSES.index(self.causes.get(group, "no_input"))

    @property
    def missing_mask(self) -> int:
        return sum(1 << i for i, name in enumerate(INPUT_GROUPS) if name in self.missing)
