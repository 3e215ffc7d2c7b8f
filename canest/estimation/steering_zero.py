"""The zero of a relative steering-wheel angle, learned while the car drives straight.

Some cars send only an angle relative to where the wheel was at power-up
(the Ford Fusion's ``StePinRelInit_An_Sns``); its zero is whatever the wheel
stood at then. ``zero: learn`` on ``steering_wheel_angle`` learns it:

- a sample is taken on every tick the car drives nearly straight and steadily
  (|yaw rate| below ``MAX_YAW_RATE``, |ay| below ``MAX_AY``, speed above
  ``MIN_SPEED``): the measured angle minus the steering-wheel angle the linear
  single-track model needs for the measured yaw rate, ``ratio r (L + K_us v^2) / v``
  (a fraction of a degree on a straight road, so the tolerances need not be tight);
- the zero is the mean of the samples, with the variance of that mean (ticks
  within ``CORRELATION_TIME`` are not independent), *learned* once
  ``LEARN_TIME`` s of samples give a standard deviation below ``LEARNED_STD``;
- afterwards it follows slowly (time constant ``FOLLOW_TIME``), each sample
  bounded to ``MAX_PULL`` from the zero, so a curve or a swerve cannot move it.

Until learned the angle is corrected by the running mean (or, before any
sample, taken as straight ahead), and the core reports sideslip as
``initializing``: a road wheel angle off by a degree is a sideslip off by as much.
"""
from __future__ import annotations

import math

from canest.estimation.inputs import WHEEL_SPEEDS, TickInputs
from canest.params import VehicleParams

MIN_SPEED = 5.0  # m/s
MAX_YAW_RATE = math.radians(3.0)  # rad/s
MAX_AY = 1.0  # m/s^2: well inside the linear tire range, and above a mounting bias or a road's bank
LEARN_TIME = 2.0  # s of straight driving before the zero counts as learned
LEARNED_STD = math.radians(1.0)  # rad at the steering wheel
CORRELATION_TIME = 0.5  # s: samples closer than this are one observation
FOLLOW_TIME = 60.0  # s: time constant of the learned zero
MAX_PULL = math.radians(5.0)  # rad: the most one sample may differ from a learned zero


class FixedZero:
    """An absolute steering angle: its zero is the DBC's."""

    learned = True

    def use_vehicle(self, vehicle: VehicleParams) -> None:
        """Nothing: the DBC's zero needs no vehicle."""

    def angle(self, inputs: TickInputs) -> float:
        return inputs.values.get("steering_wheel_angle", 0.0)


class SteeringZero:
    """The learned zero of a relative steering angle (rad at the steering wheel)."""

    def __init__(self, vehicle: VehicleParams, dt: float):
        self.vehicle = vehicle
        self.dt = dt
        self.zero = None
        self.time = 0.0  # s of straight driving seen
        self.mean = 0.0
        self.square_sum = 0.0  # sum of squared deviations from the mean (Welford)
        self.count = 0
        self.learned = False
        self.last_t = None

    def use_vehicle(self, vehicle: VehicleParams) -> None:
        """The steering a straight needs takes ``vehicle``'s understeer gradient (the learned stiffnesses)."""
        self.vehicle = vehicle

    @property
    def std(self) -> float:
        """Standard deviation of the zero: the samples' spread over the independent observations among them."""
        if self.count < 2:
            return math.inf
        spread = math.sqrt(self.square_sum / (self.count - 1))
        return spread / math.sqrt(max(self.time / CORRELATION_TIME, 1.0))

    def _sample(self, inputs: TickInputs):
        """The zero this tick suggests, or None unless the car drives straight and fast enough."""
        if not inputs.has("steering_wheel_angle", "yaw_rate", "ay", *WHEEL_SPEEDS):
            return None
        v, r = inputs.wheel_speed(self.vehicle.wheel_radius), inputs.values["yaw_rate"]
        if v < MIN_SPEED or abs(r) > MAX_YAW_RATE or abs(inputs.values["ay"]) > MAX_AY:
            return None
        v_ = self.vehicle
        needed = v_.steering_ratio * r * (v_.wheelbase + v_.understeer_gradient * v * v) / v
        return inputs.values["steering_wheel_angle"] - needed

    def _learn(self, sample: float) -> None:
        if self.learned:
            pull = max(-MAX_PULL, min(MAX_PULL, sample - self.zero))
            self.zero += pull * self.dt / FOLLOW_TIME
            return
        self.count += 1
        self.time += self.dt
        delta = sample - self.mean
        self.mean += delta / self.count
        self.square_sum += delta * (sample - self.mean)
        self.zero = self.mean
        self.learned = self.time >= LEARN_TIME and self.std <= LEARNED_STD

    def angle(self, inputs: TickInputs) -> float:
        """The steering-wheel angle from its learned zero (0, straight ahead, before any sample); learns once a tick."""
        if inputs.t != self.last_t:
            self.last_t = inputs.t
            sample = self._sample(inputs)
            if sample is not None:
                self._learn(sample)
        if self.zero is None:
            return 0.0
        return inputs.values.get("steering_wheel_angle", 0.0) - self.zero


def steering_zero(config) -> FixedZero | SteeringZero:
    """The zero the config asks for: learned for ``zero: learn``, else the DBC's."""
    spec = config.signals.get("steering_wheel_angle")
    if spec is not None and spec.learn_zero:
        return SteeringZero(config.vehicle, 1.0 / config.estimator.rate_hz)
    return FixedZero()
