"""The longitudinal acceleration ``ax`` derived from the wheel speeds, for a car without an accelerometer on the bus.

When the config maps no ``ax`` but all four wheel speeds (opendbc's
``toyota_rav4_2017_pt_generated``), :class:`WheelAx` adds ``ax`` to each
tick's inputs, flagged derived (:attr:`TickInputs.derived`): the slope of the
reference speed ``v = R mean(w)`` (the wheel-centre speed of
:meth:`TickInputs.wheel_speed`), differentiated between wheel samples and
smoothed by a first-order low-pass of time constant ``TIME_CONSTANT``::

    a_raw[k] = (v[k] - v[k-1]) / dt_k,   ax[k] = ax[k-1] + alpha (a_raw[k] - ax[k-1]),   alpha = dt_k / (tau + dt_k)

It is ``dv/dt``: it lacks the accelerometer's ``-r vy`` and gravity on a grade
(a 3 % grade is 0.3 m/s^2), lags the true acceleration by about ``tau``, and
during wheel spin or lock it follows the wheels, not the car. It is stale
while a wheel speed is, and until two wheel samples have been seen.
"""
from __future__ import annotations

import math

from canest.estimation.inputs import WHEEL_SPEEDS, TickInputs

NAME = "ax"
SOURCES = WHEEL_SPEEDS
NOTE = "ax derived from wheel speeds"
TIME_CONSTANT = 0.1  # s: the low-pass tau (the lag it adds to ax)
MAX_GAP = 0.5  # s between wheel samples after which the derivative starts again


def derives_ax(mapped) -> bool:
    """True when ``ax`` is not mapped and every wheel speed is: the estimator derives it."""
    return NAME not in mapped and all(name in mapped for name in SOURCES)


def differentiation_std(wheel_radius: float, wheel_speed_std: float, dt: float,
                        time_constant: float = TIME_CONSTANT) -> float:
    """Standard deviation (m/s^2) of the derived ax from white noise on each wheel speed.

    With ``sigma_v = R sigma_w / 2`` the noise of the mean of four wheel speeds
    and ``a_raw`` the difference of white noise (an MA(1) process), the
    low-pass output has the variance::

        var(ax) = (alpha sigma_v / dt)^2 * 2 / (2 - alpha),   alpha = dt / (tau + dt)

    (``sum_k alpha^2 (1 - alpha)^(2k)`` over the differenced sequence), i.e.
    ``sigma_v / tau`` for ``tau >> dt``. ``dt`` is the estimator's tick, the
    shortest possible wheel sample interval, so this is an upper bound.
    """
    alpha = dt / (time_constant + dt)
    speed_std = wheel_radius * wheel_speed_std / math.sqrt(len(SOURCES))
    return alpha * speed_std / dt * math.sqrt(2.0 / (2.0 - alpha))


class MappedAx:
    """``ax`` comes from the bus (or nothing derives it): the inputs stay as they are."""

    noise: dict = {}

    def add_to(self, inputs: TickInputs) -> None:
        pass


class WheelAx:
    """``ax`` as the smoothed slope of the wheel-centre speed."""

    def __init__(self, wheel_radius: float, wheel_speed_std: float, dt: float):
        self.wheel_radius = wheel_radius
        self.noise = {NAME: differentiation_std(wheel_radius, wheel_speed_std, dt)}  # measurement noise of ax
        self.ax = None
        self.last = None  # (time, speed) of the last wheel sample

    def _differentiate(self, inputs: TickInputs) -> None:
        """Take this tick's wheel sample (time-stamped by the wheels' mean age) into the smoothed slope."""
        sampled = inputs.t - sum(inputs.ages[name] for name in SOURCES) / len(SOURCES)
        speed = inputs.wheel_speed(self.wheel_radius)
        if self.last is not None:
            dt = sampled - self.last[0]
            if dt > MAX_GAP:
                self.ax = None
            elif dt > 0.0:
                raw = (speed - self.last[1]) / dt
                self.ax = raw if self.ax is None else self.ax + dt / (TIME_CONSTANT + dt) * (raw - self.ax)
        self.last = (sampled, speed)

    def add_to(self, inputs: TickInputs) -> None:
        """Add the derived ``ax`` to this tick's inputs (fresh when a wheel sample came, stale while a wheel is)."""
        wheels = inputs.has(*SOURCES)
        fresh = wheels and inputs.any_fresh(*SOURCES)
        if fresh:
            self._differentiate(inputs)
        age = sum(inputs.ages[name] for name in SOURCES) / len(SOURCES) if wheels else math.inf
        known = wheels and self.ax is not None
        inputs.derive(NAME, self.ax if known else 0.0, stale=not known, fresh=fresh and known, age=age)


def derived_ax(config) -> MappedAx | WheelAx:
    """:class:`WheelAx` when the config maps wheel speeds but no ax, else :class:`MappedAx`."""
    if not derives_ax(config.signals):
        return MappedAx()
    return WheelAx(config.vehicle.wheel_radius, config.estimator.measurement_noise["wheel_speed"],
                   1.0 / config.estimator.rate_hz)
