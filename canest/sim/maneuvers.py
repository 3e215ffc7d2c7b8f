"""Test maneuvers and the driver that performs them.

Path maneuvers (``dlc``, ``slalom``) give a reference path y(X) that a
pure-pursuit driver with preview follows; open-loop maneuvers (``sine``,
``step``) give the steering wheel angle as a function of time. A PI speed
controller holds the target speed with the four motor torques; ``launch``
drives straight and asks for an acceleration ramping up to ``amplitude`` m/s^2
(default 6) over 3 s, then coasts, with a traction control that takes torque
off a wheel whose slip ratio passes ``TRACTION_SLIP``: on a low-friction road the
driven tires reach their limit (the longitudinal excitation friction needs).
``country`` is a minute of country road drawn from its seed (:func:`country_road`):
the road's curvature and a target speed as functions of time, the driver steering
the curvature with the single-track feedforward at the speed it actually drives.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from canest.params import VehicleParams
from canest.models.wheels import GRAVITY
from canest.sim.plant import AIR_DENSITY, DRAG_AREA
from canest.sim.tire import TireParams

# ISO 3888-1 double lane change: entry 15 m, offset transition 30 m, offset lane
# 25 m, return 25 m, exit 30 m; lateral offset of the lane centres 3.5 m.
DLC_OFFSET = 3.5
DLC_SECTIONS = (15.0, 30.0, 25.0, 25.0, 30.0)
LEAD_TIME = 1.0  # s of straight driving before every maneuver


def _smoothstep(x: float, start: float, length: float) -> float:
    s = min(max((x - start) / length, 0.0), 1.0)
    return 0.5 - 0.5 * math.cos(math.pi * s)


def iso3888_path(x: float) -> float:
    entry, change, offset_lane, back, _ = DLC_SECTIONS
    out = _smoothstep(x, entry, change)
    ret = _smoothstep(x, entry + change + offset_lane, back)
    return DLC_OFFSET * (out - ret)


@dataclass(frozen=True)
class Maneuver:
    name: str
    duration: float
    path: Optional[Callable[[float], float]] = None  # y_ref(X), m
    steering_wheel: Optional[Callable[[float], float]] = None  # swa(t), rad
    acceleration: Optional[Callable[[float], float]] = None  # open-loop acceleration demand(t), m/s^2
    start_x: float = 0.0
    curvature: Optional[Callable[[float], float]] = None  # road curvature(t), 1/m (positive: a left bend)
    speed: Optional[Callable[[float], float]] = None  # target speed(t), m/s; None: the constant target speed


# country: segments of straight and bend, each bend's curvature giving a lateral acceleration in COUNTRY_AY at the
# segment's target speed, drawn in COUNTRY_SPEEDS; the speed changes over the straight before (braking, accelerating)
COUNTRY_SPEEDS = (50.0 / 3.6, 100.0 / 3.6)  # m/s
COUNTRY_AY = (1.0, 3.5)  # m/s^2: within the linear tire range, where the single-track model holds
COUNTRY_STRAIGHT = (2.0, 5.0)  # s
COUNTRY_BEND = (3.0, 7.0)  # s
COUNTRY_TRANSITION = 1.2  # s of clothoid into and out of a bend
COUNTRY_AX = 1.5  # m/s^2: the peak braking or acceleration of a speed change
COUNTRY_DURATION = 60.0  # s


def _profile(times, values, ramps) -> Callable[[float], float]:
    """A function of time that holds ``values[i]`` from ``times[i]`` on, with a smooth ramp of ``ramps[i]`` s
    from the value before."""
    def at(t: float) -> float:
        level = values[0]
        for start, previous, value, ramp in zip(times[1:], values, values[1:], ramps[1:]):
            level += (value - previous) * _smoothstep(t, start, ramp)
        return level
    return at


def _speed_ramp(change: float) -> float:
    """Seconds of a smooth speed change of ``change`` m/s whose peak acceleration is ``COUNTRY_AX``."""
    return max(math.pi / 2.0 * abs(change) / COUNTRY_AX, 1.0)


def country_road(seed: int, start_speed: float, duration: float) -> tuple:
    """(curvature(t), target speed(t)) of a country road drawn from ``seed``: straights and bends of both directions.

    Bends alternate in direction but for a random repeat; each straight carries a new target speed (braking or
    accelerating into the next bend)."""
    rng = np.random.default_rng(seed)
    low, high = COUNTRY_SPEEDS
    times, curvatures, speed_times, speeds = [0.0], [0.0], [0.0], [min(max(start_speed, low), high)]
    t, direction = LEAD_TIME, float(rng.choice((-1.0, 1.0)))
    while t < duration:
        speed = float(rng.uniform(low, high))
        speed_times.append(t)
        speeds.append(speed)
        t += float(rng.uniform(*COUNTRY_STRAIGHT)) + _speed_ramp(speed - speeds[-2])
        direction = -direction if rng.random() < 0.8 else direction
        times.append(t)
        curvatures.append(direction * float(rng.uniform(*COUNTRY_AY)) / speed**2)
        t += float(rng.uniform(*COUNTRY_BEND))
        times.append(t)
        curvatures.append(0.0)
    speed_ramps = [0.0, *(_speed_ramp(b - a) for a, b in zip(speeds, speeds[1:]))]
    return _profile(times, curvatures, [COUNTRY_TRANSITION] * len(times)), _profile(speed_times, speeds, speed_ramps)


def make_maneuver(name: str, speed: float, amplitude_deg: Optional[float] = None, duration: Optional[float] = None,
                  seed: int = 0) -> Maneuver:
    """Build a maneuver for a target speed (m/s). ``amplitude_deg`` is the steering wheel amplitude of sine/step;
    ``seed`` draws the country road (its start speed is ``speed``, within 50-100 km/h)."""
    lead = LEAD_TIME * speed
    if name == "country":
        curvature, target = country_road(seed, speed, duration or COUNTRY_DURATION)
        return Maneuver(name, duration or COUNTRY_DURATION, curvature=curvature, speed=target)
    if name == "dlc":
        length = sum(DLC_SECTIONS)
        return Maneuver(name, duration or LEAD_TIME + length / max(speed, 1.0) + 1.5, path=iso3888_path, start_x=-lead)
    if name == "slalom":
        spacing, amplitude, first = 36.0, 1.2, 10.0

        def slalom(x: float) -> float:
            return amplitude * math.sin(math.pi * (x - first) / spacing) if x > first else 0.0

        return Maneuver(name, duration or 15.0, path=slalom, start_x=-lead)
    if name == "sine":
        amp = math.radians(60.0 if amplitude_deg is None else amplitude_deg)
        return Maneuver(name, duration or 13.0,
                        steering_wheel=lambda t: amp * math.sin(2 * math.pi * (t - LEAD_TIME) / 4.0) if t > LEAD_TIME else 0.0)
    if name == "step":
        amp = math.radians(45.0 if amplitude_deg is None else amplitude_deg)
        return Maneuver(name, duration or 8.0,
                        steering_wheel=lambda t: amp * min(max((t - LEAD_TIME) / 0.2, 0.0), 1.0))
    if name == "launch":
        peak = 6.0 if amplitude_deg is None else amplitude_deg
        ramp = 3.0
        return Maneuver(name, duration or LEAD_TIME + ramp + 2.0, steering_wheel=lambda t: 0.0,
                        acceleration=lambda t: peak * (t - LEAD_TIME) / ramp if LEAD_TIME < t <= LEAD_TIME + ramp else 0.0)
    raise ValueError(f"unknown maneuver '{name}'; choose one of {', '.join(MANEUVERS)}")


MANEUVERS = ("dlc", "slalom", "sine", "step", "launch", "country")


class Driver:
    """Pure-pursuit path follower with preview, a first-order steering lag, and a PI speed controller."""

    PREVIEW_TIME = 0.6  # s
    MIN_PREVIEW = 6.0  # m
    STEER_LAG = 0.08  # s
    SPEED_GAIN = 0.8  # 1/s, P gain on speed error as acceleration demand
    SPEED_INTEGRAL = 0.2  # 1/s^2
    MAX_TORQUE = 1200.0  # N m per motor
    TRACTION_SLIP = 0.1  # slip ratio where traction control starts to take torque off
    TRACTION_BAND = 0.05  # slip ratio over which it takes all of it

    def __init__(self, vehicle: VehicleParams, maneuver: Maneuver, target_speed: float):
        self.p = vehicle
        self.maneuver = maneuver
        self.target_speed = target_speed
        self.delta = 0.0
        self.speed_integral = 0.0

    def steering_wheel_angle(self, t: float, x: float, y: float, psi: float, vx: float, dt: float) -> float:
        """Steering wheel angle (rad) to apply now; updates the driver's lag state."""
        m = self.maneuver
        if m.steering_wheel is not None:
            return m.steering_wheel(t)
        if m.curvature is not None:  # single-track feedforward: road wheel angle = kappa (L + K_us v^2)
            command = m.curvature(t) * (self.p.wheelbase + self.p.understeer_gradient * vx**2)
        else:
            preview = max(self.MIN_PREVIEW, self.PREVIEW_TIME * vx)
            target_x = x + preview * math.cos(psi)
            dx, dy = target_x - x, m.path(target_x) - y
            lateral = -dx * math.sin(psi) + dy * math.cos(psi)
            command = math.atan(2.0 * self.p.wheelbase * lateral / preview**2)
        self.delta += (command - self.delta) * min(dt / self.STEER_LAG, 1.0)
        return self.delta * self.p.steering_ratio

    def motor_torques(self, t: float, vx: float, wheel_speeds: np.ndarray, dt: float) -> np.ndarray:
        """Equal torque on the four motors (PI speed control, or the maneuver's acceleration), less traction control."""
        drag = 0.5 * AIR_DENSITY * DRAG_AREA * vx * abs(vx) + TireParams().rolling_resistance * self.p.mass * GRAVITY
        if self.maneuver.acceleration is not None:
            demand = self.maneuver.acceleration(t)
            drag = 0.0 if demand == 0.0 else drag
        else:
            error = (self.target_speed if self.maneuver.speed is None else self.maneuver.speed(t)) - vx
            self.speed_integral += error * dt
            demand = self.SPEED_GAIN * error + self.SPEED_INTEGRAL * self.speed_integral
        total = self.p.mass * demand * self.p.wheel_radius + drag * self.p.wheel_radius
        slip = (wheel_speeds * self.p.wheel_radius - vx) / max(vx, 1.0)
        traction = np.clip(1.0 - (slip - self.TRACTION_SLIP) / self.TRACTION_BAND, 0.0, 1.0)
        return np.clip(total / 4.0, -self.MAX_TORQUE, self.MAX_TORQUE) * traction
