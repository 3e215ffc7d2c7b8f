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
  ``R dw/dt`` agrees with the measured ``ax`` within
  ``WHEEL_ACCELERATION_TOLERANCE`` (a wheel spinning up or locking does not).
  The reference is then the mean wheel-centre speed ``R mean(w)``, standard
  deviation ``ANCHORED_STD``.
* otherwise: ``v += ax dt`` from the last free-rolling tick, standard deviation
  growing by ``DRIFT`` per second since it (IMU bias; the simulator's is
  0.02 m/s^2, a 3 % grade adds 0.3 m/s^2 and is not modelled).

Measured on the simulator's launch on friction 0.35 (README "Tire forces and
road friction"): the reference stays within 0.1 m/s of the true speed while
the wheels run 1-2 m/s ahead.
"""
from __future__ import annotations

import math

from canest.signals import INPUT_GROUPS

TORQUES = INPUT_GROUPS["motor_torques"]
FREE_ROLLING_USAGE = 0.1  # |Fx| / Fz below which a tire is in its linear range
WHEEL_ACCELERATION_TOLERANCE = 0.5  # m/s^2 between R dw/dt and the measured ax
DRIFT = 0.1  # m/s per s of integration
MAX_GAP = 0.1  # s without inputs after which the wheels are taken again


def tire_usage(torques, loads, wheel_radius: float) -> list:
    """Per wheel ``T / (R Fz)``: the share of its load a wheel's motor torque asks of its tire (loads floored at
    1 N)."""
    return [torque / (wheel_radius * max(load, 1.0)) for torque, load in zip(torques, loads)]


def tick_usage(inputs, geometry, wheel_radius: float) -> list:
    """:func:`tire_usage` of one tick (:class:`canest.estimation.inputs.TickInputs`): its motor torques (0 where
    not mapped) at the loads of its ax and ay (``geometry``: a :class:`canest.models.wheels.WheelGeometry`)."""
    loads = geometry.loads(inputs.current("ax"), inputs.current("ay")).tolist()
    return tire_usage([inputs.values.get(torque, 0.0) for torque in TORQUES], loads, wheel_radius)


def slip_free_speed(wheel_speeds, usage, wheel_radius: float, slip_stiffness: float) -> float:
    """The mean wheel-centre speed without the slip the wheels' forces need: ``R mean(w / (1 + usage / k))``,
    ``k`` the tire's longitudinal slip stiffness per unit load (a linear tire: ``Fx / Fz = k s``,
    ``s = (R w - v) / v``)."""
    return wheel_radius * sum(w / (1.0 + x / slip_stiffness) for w, x in zip(wheel_speeds, usage)) / len(wheel_speeds)


class ReferenceSpeed:
    def __init__(self, wheel_radius: float, slip_stiffness: float, anchored_std: float):
        self.wheel_radius = wheel_radius
        self.slip_stiffness = slip_stiffness
        self.anchored_std = anchored_std
        self.reset()

    def reset(self) -> None:
        self.speed = None
        self.last_t = None
        self.anchored_at = None

    def update(self, t: float, acceleration: float, wheel_speeds, wheel_accelerations, usage) -> tuple[float, float]:
        """The reference speed (m/s) at tick ``t`` and its standard deviation.

        ``acceleration`` is ``ax + r vy`` (m/s^2); ``wheel_speeds`` (rad/s),
        ``wheel_accelerations`` (rad/s^2) and ``usage`` (``T / (R Fz)``,
        signed) per wheel, as sequences of floats (four numbers: plain Python beats numpy here).
        """
        radius = self.wheel_radius
        free = (all(abs(x) < FREE_ROLLING_USAGE for x in usage)
                and all(abs(radius * a - acceleration) < WHEEL_ACCELERATION_TOLERANCE for a in wheel_accelerations))
        if free or self.speed is None or t - self.last_t > MAX_GAP:
            self.speed = slip_free_speed(wheel_speeds, usage, radius, self.slip_stiffness)
            self.anchored_at = t
        else:
            self.speed += acceleration * (t - self.last_t)
        self.last_t = t
        return self.speed, math.hypot(self.anchored_std, DRIFT * (t - self.anchored_at))
