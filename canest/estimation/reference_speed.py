"""A vehicle reference speed that does not follow spinning or locking wheels.

Wheel speeds measure the vehicle's speed only while the tires do not slip,
and friction estimation needs the slip exactly when the tires do. As the
reference speed of ABS and traction control does, :class:`ReferenceSpeed`
trusts the wheels only while they roll freely, and integrates the IMU's
longitudinal acceleration in between:

* free rolling: a wheel transmits little longitudinal force
  (``|Fx| / Fz < FREE_ROLLING_USAGE``; a tire needs slip to transmit force,
  and on ice (mu 0.1) half its friction already takes ~2 % slip) and its
  circumferential acceleration ``R dw/dt`` (a slope over the last ``WINDOW``
  samples) agrees with ax less its offset (a road's grade:
  :mod:`canest.estimation.longitudinal_offset`), ax's mean over the same
  samples where motor torques give the usage, within
  ``WHEEL_ACCELERATION_TOLERANCE`` and, in quadrature, ``IN_STEP_STDS``
  standard deviations of that mean's noise (``sqrt(q / T)``, ``q`` ax's
  measured density, ``T`` the window's samples times their period): a wheel
  spinning up or locking does not. Against the raw ax sample, an IMU vibrating
  as the simulator's ``vibration 1`` (1.4 m/s^2) let the wheels anchor the
  speed on 30 of the 1300 ticks of the 80 km/h sine (the reference integrated
  ax for up to 2.2 s); against the window's mean, on 476 (vibrating honesty
  grid: vx RMSE 0.17 -> 0.10 m/s for the ax-integrating filters). Where the
  usage itself comes from ax (no motor torques, below), the wheels are held to
  the 0.5 m/s^2 of this tick's ax sample, the one their usage was taken from: a
  vibrating ax dips below the free-rolling usage on a slipping launch, and the
  window's tolerance then let the spinning wheels anchor the speed 2.8-3.2 m/s
  high (``configs/hard_drive.yaml``, ckf, vibrating launch and sine: vx RMSE
  0.18 -> 0.54 m/s, valid but wrong 0 -> 3.6 %). ``Fx`` is the motor
  torque's where all four are in, else the share of ``m ax`` the drive
  layout (or the brake balance) gives the wheel
  (:func:`tick_usage`): a car that sends no torques still has driven wheels.
  With all four free the reference is their mean wheel-centre speed
  ``R mean(w)`` (less the slip their forces need), standard deviation the
  wheels' noise. Else the undriven axle's pair of a front- or rear-driven
  car (``vehicle.drive``) measures it alone while it transmits no more than
  rolling resistance (``UNDRIVEN_USAGE``) and is not braked, brought to the four wheels'
  mean by the steered front wheels' geometry, its noise ``sqrt(2)`` times
  the four wheels', once it has transmitted no more for ``PAIR_SETTLE`` s: as a launch
  ends on four motors, the torques are cut while the wheels still spin, and
  a pair whose deceleration matched ax for a sample anchored the reference
  3.5 m/s high (ckf's vx RMSE over the simulator's launches 0.022 -> 0.19
  m/s, a divergence reset).
* otherwise: ``v += (ax - offset) dt`` from the last free-rolling tick, the offset a road's grade and what
  is left of ax's bias (:mod:`canest.estimation.longitudinal_offset`), standard deviation
  growing per second since it by the std the wheels last measured that offset with (its prior, a 5 % grade,
  before they did), never by less than ``DRIFT`` (a bias's drift and a grade's change meanwhile; the
  simulator's ax bias is 0.02 m/s^2: growing by the offset's random walk too, the reference's std took
  jckf's sideslip RMSE on the honesty grid from 0.36 to 0.44 deg and dckf's vx up by 17 %) and, in
  quadrature, by the random walk of the ax noise's measured density ``q``:
  ``sqrt(q T)`` after ``T`` s (:mod:`canest.estimation.measured_noise`). An
  IMU vibrating as the simulator's ``vibration 1`` integrates to 0.24
  m/s/sqrt(s): 0.08 m/s within 0.1 s, where ``DRIFT`` alone had said 0.01.
  A filter takes the integrating reference every tick as a new measurement,
  yet its random walk is one error shared by all of them
  (:meth:`ReferenceSpeed.integration_std`): the estimator's published vx std
  carries it, and a model that integrates the same ax holds it in its prior
  instead of in this channel's std (:mod:`canest.estimation.core`).

Measured on the simulator's launch on friction 0.35 (README "Tire forces and
road friction"): the reference stays within 0.1 m/s of the true speed while
the wheels run 1-2 m/s ahead.
"""
from __future__ import annotations

import math
from collections import deque

from canest.estimation.longitudinal_offset import LongitudinalOffset
from canest.models.wheel_force import WINDOW
from canest.signals import INPUT_GROUPS

TORQUES = INPUT_GROUPS["motor_torques"]
FREE_ROLLING_USAGE = 0.1  # |Fx| / Fz below which a tire is in its linear range
UNDRIVEN_USAGE = 0.02  # |Fx| / Fz of a pair that measures the speed alone: an undriven axle's rolling resistance
PAIR_SETTLE = 0.5  # s a pair must have been undriven before it anchors the speed alone
BRAKING = 0.5  # m/s^2 of deceleration beyond what drag and rolling resistance give: the brakes are on
WHEEL_ACCELERATION_TOLERANCE = 0.5  # m/s^2 between R dw/dt and the measured ax
IN_STEP_STDS = 2.0  # standard deviations of ax's noise (its mean over the wheels' window) added to that tolerance
DRIFT = 0.1  # m/s per s of integration, at least
MAX_GAP = 0.1  # s without inputs after which the wheels are taken again


def tire_usage(torques, loads, wheel_radius: float, rolling_resistance: float) -> list:
    """Per wheel ``T / (R Fz) - f_r``: the share of its load a wheel's motor torque asks of its tire, less the
    rolling moment's share ``f_r`` (``vehicle.tire.rolling_resistance``), which turns no tire force and so makes no
    slip (a wheel rolling forward; loads floored at 1 N). Without it a cruising car's slip-free speed was its
    rolling resistance's slip too low: on the simulator's dry double lane change at 80 km/h dici-gfckf's reference
    speed was 0.026 m/s slow on average (RMSE 0.028); with it 0.007 (RMSE 0.014)."""
    return [torque / (wheel_radius * max(load, 1.0)) - rolling_resistance for torque, load in zip(torques, loads)]


def tick_usage(inputs, geometry, vehicle, layout=None, use_torques: bool = True) -> list:
    """Per wheel ``Fx / Fz`` of one tick (:class:`canest.estimation.inputs.TickInputs`) at the loads of its ax and
    ay (``geometry``: a :class:`canest.models.wheels.WheelGeometry`; ``vehicle``: its radius and tire):
    :func:`tire_usage` of its motor torques (0 where not mapped) or, where they are not all in (or not
    ``use_torques``) and a ``layout`` (:class:`canest.models.wheel_force.DriveLayout`) is given, the share of
    ``m ax`` the drive layout or the brake balance asks of each wheel (the drag that ax shows beside the tires'
    forces is not known: its slip is left in)."""
    ax = inputs.current("ax")
    loads = geometry.loads(ax, inputs.current("ay")).tolist()
    if layout is None or (use_torques and inputs.has(*TORQUES)):
        return tire_usage([inputs.values.get(torque, 0.0) for torque in TORQUES], loads, vehicle.wheel_radius,
                          vehicle.tire.rolling_resistance)
    force = layout.mass * ax
    shares = layout.drive if ax >= 0.0 else layout.brake
    return [share * force / max(load, 1.0) for share, load in zip(shares.tolist(), loads)]


def slip_free_speed(wheel_speeds, usage, wheel_radius: float, slip_stiffness: float) -> float:
    """The mean wheel-centre speed without the slip the wheels' forces need: ``R mean(w / (1 + usage / k))``,
    ``k`` the tire's longitudinal slip stiffness per unit load (a linear tire: ``Fx / Fz = k s``,
    ``s = (R w - v) / v``)."""
    return wheel_radius * sum(w / (1.0 + x / slip_stiffness) for w, x in zip(wheel_speeds, usage)) / len(wheel_speeds)


class ReferenceSpeed:
    def __init__(self, wheel_radius: float, slip_stiffness: float, anchored_std: float,
                 drive_front_share: float = 1.0):
        self.wheel_radius = wheel_radius
        self.slip_stiffness = slip_stiffness
        self.anchored_std = anchored_std
        # the undriven axle's wheels, and the share of front_excess that brings their pair to the four wheels' mean;
        # none where both axles drive (at a steady speed ax shows no drive force, but drag and rolling need some)
        self.undriven = {1.0: (slice(2, 4), 0.5), 0.0: (slice(0, 2), -0.5)}.get(drive_front_share)
        self.offset = LongitudinalOffset()  # kept over a restart: the road is the same
        self.reset()

    def reset(self) -> None:
        self.speed = None
        self.last_t = None
        self.wheels_t = None  # the last update with the wheels (:meth:`update`, not :meth:`coast`)
        self.usage = None  # per wheel Fx / Fz of that update
        self.anchored_at = None
        self.anchor_std = self.anchored_std
        self.settled_at = math.inf  # from when the undriven pair may anchor the speed alone
        self.ax_density = 0.0  # m^2/s^3, the latest update's
        self.recent = deque(maxlen=WINDOW)  # (t, acceleration) over the wheel accelerations' window

    def update(self, t: float, acceleration: float, wheel_speeds, wheel_accelerations, usage,
               front_excess: float = 0.0, ax_density: float | None = 0.0, usage_measured: bool = False,
               turning: float = 0.0) -> tuple[float, float]:
        """The reference speed (m/s) at tick ``t`` and its standard deviation.

        ``acceleration`` is ``ax + r vy`` (m/s^2); ``wheel_speeds`` (rad/s),
        ``wheel_accelerations`` (rad/s^2) and ``usage`` (``Fx / Fz``,
        signed) per wheel (fl, fr, rl, rr), as sequences of floats (four numbers: plain Python beats numpy here);
        ``front_excess``: how much faster the front wheels' centres roll than the rear's for the car's motion
        (m/s; steered: ``vx (cos delta - 1) + (vy + a r) sin delta``); ``ax_density``: the ax noise's measured
        density (m^2/s^3; None while not measured yet: taken as 0, and ax's offset is not learned meanwhile: in
        the first half second of a vibrating launch it learned -0.40 m/s^2, true 0.02, with a std of 0.22);
        ``usage_measured``: the usage is the motor torques' (False: the drive layout's share of
        this tick's ax, module docstring); ``turning``: ``vx r`` (m/s^2), the offset is learned on straights only.
        """
        radius = self.wheel_radius
        self.ax_density = ax_density or 0.0
        measured, tolerance = self._window_acceleration(t, acceleration)
        if not usage_measured:
            measured, tolerance = acceleration, WHEEL_ACCELERATION_TOLERANCE
        measured -= self.offset.value
        # the wheels' slopes span samples from before a gap until the window has refilled: none is in step then
        refilled = len(self.recent) == WINDOW
        in_step = [refilled and abs(radius * a - measured) < tolerance for a in wheel_accelerations]
        free = [step and abs(x) < FREE_ROLLING_USAGE for step, x in zip(in_step, usage)]
        self.offset.update(t, acceleration, [radius * w for w in wheel_speeds], usage, FREE_ROLLING_USAGE, ax_density,
                           turning)
        restart = self.speed is None or not 0.0 <= t - self.last_t <= MAX_GAP  # a gap, or time ran backwards
        if restart:  # nothing known of what the pair transmitted over the last PAIR_SETTLE s
            self.settled_at = t + PAIR_SETTLE
        if all(free) or restart:
            self._anchor(t, slip_free_speed(wheel_speeds, usage, radius, self.slip_stiffness), self.anchored_std)
        else:
            self.speed += (acceleration - self.offset.value) * (t - self.last_t)
        if self.undriven is not None:
            self._undriven_pair(t, acceleration, wheel_speeds, usage, in_step, front_excess)
        self.last_t = self.wheels_t = t
        self.usage = usage
        return self.speed, self._std(t)

    def coast(self, t: float, acceleration: float, ax_density: float = 0.0) -> None:
        """Integrate ``acceleration`` (``ax + r vy``, m/s^2) to tick ``t`` while the wheels are missing: the speed
        keeps its anchor, so its std grows with the time since, and the wheels, back, anchor it only if they roll
        freely, once their slopes span samples since the gap. Restarted on them after a gap instead, the
        reference took wheels that spun in a launch on 0.35 (their frames lost for 0.2 s) with the anchored
        std, and jckf's vx ran 2.3 m/s ahead, valid. No filter takes it meanwhile, but its walk is the error
        each took with it (``wheels_t``: the last update with the wheels). Nothing before the first anchor,
        after a gap of ``MAX_GAP`` or when time ran backwards (:meth:`update` starts again on the wheels); the
        undriven pair's transmission is unknown meanwhile."""
        if self.speed is None or not 0.0 < t - self.last_t <= MAX_GAP:
            return
        self.ax_density = ax_density
        self.speed += (acceleration - self.offset.value) * (t - self.last_t)
        self.settled_at = t + PAIR_SETTLE
        self.last_t = t

    def _window_acceleration(self, t: float, acceleration: float) -> tuple[float, float]:
        """The acceleration's mean over the wheel accelerations' window (their Theil-Sen slopes span the same
        ``WINDOW`` samples) and how far a wheel in step may differ from it: ``WHEEL_ACCELERATION_TOLERANCE`` and, in
        quadrature, ``IN_STEP_STDS`` std of the mean's noise, ``sqrt(q / T)``, ``T`` its samples times their period."""
        if self.recent and not 0.0 < t - self.recent[-1][0] <= MAX_GAP:
            self.recent.clear()
        self.recent.append((t, acceleration))
        mean = sum(a for _, a in self.recent) / len(self.recent)
        if len(self.recent) < 2:
            return mean, WHEEL_ACCELERATION_TOLERANCE
        span = (t - self.recent[0][0]) * len(self.recent) / (len(self.recent) - 1)
        return mean, math.hypot(WHEEL_ACCELERATION_TOLERANCE, IN_STEP_STDS * math.sqrt(self.ax_density / span))

    def _undriven_pair(self, t: float, acceleration: float, wheel_speeds, usage, in_step, front_excess: float) -> None:
        """Anchor on the pair of an undriven axle (``vehicle.drive``) that spins with ax and has transmitted no
        more than ``UNDRIVEN_USAGE`` for ``PAIR_SETTLE`` s, unless the four wheels anchored this tick; the pair's
        speed brought to the four wheels' mean by ``front_excess``. A driven axle's pair never measures it alone:
        at a steady speed ax shows no drive force, yet drag and rolling resistance need one (a rear-driven car at
        30 m/s: 0.14 m/s of slip). Braking harder than ``BRAKING`` no pair counts as undriven: friction brakes act
        on both axles, and motor torques do not show them."""
        wheels, excess = self.undriven
        if acceleration < -BRAKING or any(abs(x) >= UNDRIVEN_USAGE for x in usage[wheels]):
            self.settled_at = t + PAIR_SETTLE
        if self.anchored_at != t and t >= self.settled_at and all(in_step[wheels]):
            speed = slip_free_speed(wheel_speeds[wheels], usage[wheels], self.wheel_radius, self.slip_stiffness)
            self._anchor(t, speed + excess * front_excess, math.sqrt(2.0) * self.anchored_std)

    def _std(self, t: float) -> float:
        integrated = t - self.anchored_at
        return math.sqrt(self.anchor_std**2 + self._drift(integrated) ** 2 + self.ax_density * integrated)

    def _drift(self, integrated: float) -> float:
        """The error (m/s) ax's offset puts into ``integrated`` s of integration: the std the wheels last measured it
        with, never below ``DRIFT``, times the time."""
        return max(DRIFT, self.offset.measured_std) * integrated

    def disagreement(self, t: float, speed: float, beside: float = 0.0) -> float:
        """How far (m/s) an estimate ``speed`` of the same vx lies from the reference at tick ``t`` beyond the
        reference's std, ``beside`` (an error it shares with what it integrates, not in its own std) in quadrature:
        the least error the estimate has while the reference is within one std (0 within it, or without an update
        at ``t``)."""
        if self.last_t != t:
            return 0.0
        return max(0.0, abs(speed - self.speed) - math.hypot(self._std(t), beside))

    def integration_std(self, t: float, density: float | None = None) -> float:
        """The std (m/s) of the integration's error in the speed at tick ``t`` over the ``T`` s since the wheels last
        anchored it (0 while they anchor it, or without an update at ``t``): the ax noise's random walk ``sqrt(q T)``
        and ax's offset's error (:meth:`_drift`), in quadrature: what a filter that takes this reference every tick
        shares with all of them, and is never more certain than. ``q`` is the density of that update, or
        ``density`` where given (measured since: a walk begun before ax's noise was known is that noise's all the
        same). The offset's error counted as each tick's own, dckf's vx on a vibrating launch on 0.35 followed a
        reference integrating an offset learned 0.42 m/s^2 off (1.9 of its std) and was 1.6 m/s off with a std of
        0.27, the reference's own 0.45."""
        if self.last_t != t or self.anchored_at in (None, t):
            return 0.0
        integrated = t - self.anchored_at
        return math.hypot(math.sqrt((self.ax_density if density is None else density) * integrated),
                          self._drift(integrated))

    def _anchor(self, t: float, speed: float, std: float) -> None:
        self.speed, self.anchored_at, self.anchor_std = speed, t, std
