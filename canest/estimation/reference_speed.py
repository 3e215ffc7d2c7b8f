"""A vehicle reference speed that does not follow spinning or locking wheels.

Wheel speeds measure the vehicle's speed only while the tires do not slip,
and friction estimation needs the slip exactly when the tires do. As the
reference speed of ABS and traction control does, :class:`ReferenceSpeed`
trusts the wheels only while they roll freely, and integrates the IMU's
longitudinal acceleration in between:

* free rolling: every wheel transmits little longitudinal force
  (``|T| / (R Fz) < FREE_ROLLING_USAGE``, from the motor torque and the load;
  a tire needs slip to transmit force, and on ice (mu 0.1) half its friction
  already takes ~2 % slip) and every wheel's circumferential acceleration
  ``R dw/dt`` agrees with the measured ``ax`` within ``WHEEL_ACCELERATION_TOLERANCE`` plus ``NOISE_STDS``
  of the accelerometer's configured noise, in quadrature (a wheel spinning up
  or locking does not), and the car does not slide: the lateral velocity's
  rate ``ay - r vx`` stays within ``SLIDE_TOLERANCE`` (plus the noise term of
  ay); a sliding car's steered front wheels roll along their own heading, not
  the body's. All three use accelerations averaged over the wheel
  acceleration's window (:data:`canest.models.wheel_force.WINDOW` samples, the
  same 20 ms lag), whose noise is the configured one over the square root of
  the window. An IMU vibrating as on a real car (1.4 m/s^2) failed the
  single-sample test with the fixed tolerance on 95-97 % of the simulator's
  ticks, so vx integrated ax nearly all the time: within 2 std on 28-69 % of
  a launch's ticks, NEES up to 58. The reference is then the mean wheel-centre
  speed ``R mean(w)``, standard deviation ``ANCHORED_STD``.
* otherwise: ``v += ax dt`` from the last free-rolling tick, variance growing
  by ``(DRIFT t)^2`` (IMU bias; the simulator's is 0.02 m/s^2, a 3 % grade adds
  0.3 m/s^2 and is not modelled) plus the configured noise integrated as white
  noise, ``sigma_ax^2 dt`` per step.

Measured on the simulator's launch on friction 0.35 (README "Tire forces and
road friction"): the reference stays within 0.1 m/s of the true speed while
the wheels run 1-2 m/s ahead. On the honesty grid with a vibrating IMU whose
noise is configured (README "How far to trust the output") the noise terms
took ckf's vx from RMSE 0.153 to 0.095 m/s, within 2 std 83 -> 95 %. Without
motor torques the usage test is blind: a launch whose wheels spin at a steady
slip accelerates with the car and passes the acceleration test once its
tolerance admits the vibration (vx valid but wrong on 24-30 % of those
launches' ticks, was 7-24 %); open.
"""
from __future__ import annotations

import math
from collections import deque

from canest.models.wheel_force import WINDOW

FREE_ROLLING_USAGE = 0.1  # |Fx| / Fz below which a tire is in its linear range
WHEEL_ACCELERATION_TOLERANCE = 0.5  # m/s^2 between R dw/dt and the measured ax, beside the accelerometer's noise
SLIDE_TOLERANCE = 3.0  # m/s^2 of ay - r vx (the lateral velocity's rate) above which the car slides
NOISE_STDS = 2.0  # standard deviations of the accelerometer's configured noise the test tolerates
DRIFT = 0.1  # m/s per s of integration
MAX_GAP = 0.1  # s without inputs after which the wheels are taken again


class ReferenceSpeed:
    def __init__(self, wheel_radius: float, slip_stiffness: float, anchored_std: float,
                 acceleration_noise: float = 0.0, lateral_noise: float = 0.0):
        """``acceleration_noise``, ``lateral_noise``: the accelerometer's configured standard deviations (m/s^2)."""
        self.wheel_radius = wheel_radius
        self.slip_stiffness = slip_stiffness
        self.anchored_std = anchored_std
        self.acceleration_noise = acceleration_noise
        self.tolerance = math.hypot(WHEEL_ACCELERATION_TOLERANCE, NOISE_STDS * acceleration_noise / math.sqrt(WINDOW))
        self.lateral_tolerance = math.hypot(SLIDE_TOLERANCE, NOISE_STDS * lateral_noise / math.sqrt(WINDOW))
        self.recent = deque(maxlen=WINDOW)  # accelerations of the last ticks, for the comparison
        self.recent_lateral = deque(maxlen=WINDOW)
        self.reset()

    def reset(self) -> None:
        self.speed = None
        self.last_t = None
        self.anchored_at = None
        self.integrated_variance = 0.0  # of the accelerometer's noise since the last anchoring
        self.recent.clear()
        self.recent_lateral.clear()

    def update(self, t: float, acceleration: float, wheel_speeds, wheel_accelerations, usage,
               sliding: float = 0.0) -> tuple[float, float]:
        """The reference speed (m/s) at tick ``t`` and its standard deviation.

        ``acceleration`` is ``ax + r vy`` (m/s^2); ``wheel_speeds`` (rad/s),
        ``wheel_accelerations`` (rad/s^2) and ``usage`` (``T / (R Fz)``, signed) per wheel, as sequences of
        floats (four numbers: plain Python beats numpy here); ``sliding`` is ``ay - r vx`` (m/s^2).
        """
        radius = self.wheel_radius
        self.recent.append(acceleration)
        mean = sum(self.recent) / len(self.recent)
        self.recent_lateral.append(sliding)
        free = (all(abs(x) < FREE_ROLLING_USAGE for x in usage)
                and all(abs(radius * a - mean) < self.tolerance for a in wheel_accelerations)
                and abs(sum(self.recent_lateral) / len(self.recent_lateral)) < self.lateral_tolerance)
        if free or self.speed is None or t - self.last_t > MAX_GAP:
            self.speed = radius * sum(w / (1.0 + x / self.slip_stiffness) for w, x in zip(wheel_speeds, usage)) \
                / len(wheel_speeds)
            self.anchored_at = t
            self.integrated_variance = 0.0
        else:
            dt = t - self.last_t
            self.speed += acceleration * dt
            self.integrated_variance += (self.acceleration_noise * dt) ** 2  # one sample's noise, integrated
        self.last_t = t
        drift = DRIFT * (t - self.anchored_at)
        return self.speed, math.sqrt(self.anchored_std**2 + drift**2 + self.integrated_variance)
