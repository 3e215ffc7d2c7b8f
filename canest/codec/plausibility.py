"""Physical plausibility of input samples: a slew-rate limit per canonical input.

A frame can pass every integrity check and still carry nonsense (a CRC-8
accepts one random payload in 256). No real vehicle signal changes faster
than its physics allows, so a sample whose change from the last accepted
sample exceeds ``MAX_RATE`` times the time between them is rejected
(``rejected_implausible``). So that a real step (a sensor re-zeroing, a
restart after a gap) cannot lock an input out, ``RESYNC_AFTER`` rejections in
a row accept the next sample as the new reference.
"""
from __future__ import annotations

import math

from canest.signals import WHEELS

# Largest plausible rate of change per second, SI units.
MAX_RATE = {
    "steering_wheel_angle": math.radians(2000.0),  # fast steering robots stay below 1500 deg/s
    **{f"wheel_speed_{w}": 400.0 for w in WHEELS},  # rad/s^2: spin-up on ice, lock-up under ABS
    **{f"motor_torque_{w}": 50_000.0 for w in WHEELS},  # N m/s: torque steps within 20 ms
    "ax": 200.0, "ay": 200.0, "ax_2": 200.0, "ay_2": 200.0,  # m/s^3: kerb strikes, potholes
    "yaw_rate": 10.0, "yaw_rate_2": 10.0,  # rad/s^2: about ten times a spin's yaw acceleration
}
MIN_INTERVAL = 0.005  # s: a rate over a shorter interval is judged over this one
RESYNC_AFTER = 5


class SlewLimit:
    def __init__(self, names):
        self.limits = {name: MAX_RATE[name] for name in names}
        self.last = {}
        self.rejected_in_a_row = {name: 0 for name in names}

    def _too_fast(self, name: str, value: float, t: float) -> bool:
        previous = self.last.get(name)
        if previous is None or self.rejected_in_a_row[name] >= RESYNC_AFTER:
            return False
        last_value, last_t = previous
        return abs(value - last_value) > self.limits[name] * max(abs(t - last_t), MIN_INTERVAL)

    def accept(self, values, t: float) -> bool:
        """True if every (name, value) of one frame is plausible; only then do they become the reference."""
        too_fast = [name for name, value in values if self._too_fast(name, value, t)]
        for name in too_fast:
            self.rejected_in_a_row[name] += 1
        if too_fast:
            return False
        for name, value in values:
            self.rejected_in_a_row[name] = 0
            self.last[name] = (value, t)
        return True
