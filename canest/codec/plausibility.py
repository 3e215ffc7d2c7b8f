"""Physical plausibility of input samples: a slew-rate limit per canonical input.

A frame can pass every integrity check and still carry nonsense (a CRC-8
accepts one random payload in 256). No real vehicle signal changes faster
than its physics allows, so a sample whose change from the last accepted
sample exceeds ``MAX_RATE`` times the time between them is dropped, for its
own input only: the other signals of the frame are used (``implausible_samples``;
a frame none of whose samples is plausible is ``rejected_implausible``). So
that a real step (a sensor re-zeroing, a restart after a gap) cannot lock an
input out, ``RESYNC_AFTER`` rejections in a row accept the next sample as the
new reference.

The limits are physics plus what a real sensor adds to it. An accelerometer
measures vibration and road input too: on a real drive ay jumped by more than
2 m/s^2 between 10 ms samples on 16 % of samples, so the limit is 5000 m/s^3
(a kerb strike), not the body's few tens; with 200 m/s^3 a real drive lost 15 %
of its IMU frames, the yaw rate in them with the ay.
"""
from __future__ import annotations

import math

from canest.signals import WHEELS

# Largest plausible rate of change per second, SI units.
MAX_RATE = {
    "steering_wheel_angle": math.radians(2000.0),  # fast steering robots stay below 1500 deg/s
    **{f"wheel_speed_{w}": 400.0 for w in WHEELS},  # rad/s^2: spin-up on ice, lock-up under ABS
    **{f"motor_torque_{w}": 50_000.0 for w in WHEELS},  # N m/s: torque steps within 20 ms
    "ax": 5000.0, "ay": 5000.0, "ax_2": 5000.0, "ay_2": 5000.0,  # m/s^3: vibration, kerb strikes, potholes
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

    def accept(self, values, t: float) -> list:
        """The plausible (name, value) pairs of one frame; each becomes its input's reference."""
        accepted = []
        for name, value in values:
            if self._too_fast(name, value, t):
                self.rejected_in_a_row[name] += 1
                continue
            self.rejected_in_a_row[name] = 0
            self.last[name] = (value, t)
            accepted.append((name, value))
        return accepted
