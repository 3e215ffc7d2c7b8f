"""ax's offset from the wheels' acceleration: a road's grade, and what is left of the accelerometer's bias.

The accelerometer reads the tires' force, ``ax = dvx/dt - r vy + g sin(grade)`` (positive uphill), so on a hill
a speed that integrates ax runs away from the car's at ``g sin(grade)``: 0.59 m/s^2 on a 6 % grade. The wheels,
while they roll freely, measure ``dvx/dt``, and their difference from ax is that offset (the road gradient an ESC's
reference speed estimates alike). :class:`LongitudinalOffset` is a scalar Kalman filter of it, a random walk of
``WALK`` (a road's grade changes by a few percent over a hundred metres). Its evidence: over a span of ``SETTLE``
s on a straight (``|vx r|`` below ``STRAIGHT``) in which all four wheels transmitted little and steady force
(``|Fx| / Fz`` below the free-rolling usage and changed by less than ``USAGE_CHANGE``) and their speeds changed
alike (within ``WHEEL_SPREAD``), the integral of ax less the change of the wheels' mean speed, over the span; an
innovation beyond ``GATE`` standard deviations is left out, and after ``RELEARN`` s of such spans on end the
offset is learned anew from its prior (a climb begun in a bend, where nothing is learned, shows as a step that
the walk would take 10 s to admit, the reference meanwhile integrating gravity). Why each gate, measured:

- a tire's slip follows its force: at a launch's start on friction 0.35 the wheels' slip grew under a usage still
  below 0.1 and read as an offset of -0.044 m/s^2 (true 0.02), which the reference then integrated;
- in a bend each wheel rolls at its own centre's speed, and in a slide ``r vy`` is the model's guess: learned
  there too, the offset moved jckf's sideslip on the grid's slides on 0.35 (RMSE 0.36 -> 0.42 deg over the grid);
- the wheels' slopes over a few samples, which the reference speed's free-rolling test takes, have a median biased
  towards zero on a wheel-speed signal's resolution (a car slowing at 0.80 m/s^2 read 0.51: 0.35 learned on a 6 %
  grade, 0.59 true); hence a speed change over half a second;
- that free-rolling test compares the wheels with ax less this offset, so as a gate it leaves out the very
  samples that show an offset not learned yet.

Its prior (``PRIOR_STD``, a 5 % grade) is what a speed integrating ax does not know before the wheels measured it.
Before it the reference speed's free-rolling test compared the wheels with ax itself: from a 5 % grade on no wheel
was ever in step, the reference integrated ax for the whole climb, and on a 40 s country road uphill at 6 % ckf's
vx was 3.6 m/s off with a std of 0.08, valid but wrong on 61 % of its valid ticks.
"""
from __future__ import annotations

import math
from collections import deque

PRIOR_STD = 0.5  # m/s^2: a 5 % grade, or an accelerometer's bias, before any wheel measured it
WALK = 0.05  # m/s^2 per sqrt(s): the gain's; a grade's step (a climb begun in a bend) is RELEARN's
SAMPLE_STD = 0.1  # m/s^2: one span's offset from the four wheels' speed noise (0.05 m/s each) over its 0.5 s
SETTLE = 0.5  # s the four wheels must have transmitted little force: the span their speed change is taken over
USAGE_CHANGE = 0.02  # |Fx| / Fz a wheel's usage may change by over the span: its slip, and so its speed, follows it
WHEEL_SPREAD = 0.5  # m/s^2 between the four wheels' speed changes over the span beyond which one slips
STRAIGHT = 2.0  # m/s^2 of vx r: in a bend the wheels roll at their own centres' speeds, and a slide's r vy is unknown
GATE = 3.0  # standard deviations of an update's innovation beyond which it is not evidence
GAP = 0.1  # s between ticks beyond which a span starts anew
RELEARN = 1.0  # s of spans on end beyond the gate after which the offset is learned anew from its prior
# variance of a span's ax integral per unit of ax's measured density over the span's time: a vibrating body's road
# spikes are decaying steps whose integral the density of 30 ms means under-reads (the first spans' offset on the
# vibrating grid was 0.40-0.44 m/s^2 off with a std of 0.22-0.23 at 1)
SPIKE_FACTOR = 4.0


class LongitudinalOffset:
    """``(ax + r vy) - dvx/dt`` (m/s^2), learned from freely rolling wheels (module docstring)."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self.value = 0.0
        self.variance = PRIOR_STD**2
        self.measured_std = PRIOR_STD  # the std the wheels last left it with (its walk since is a grade's change)
        self.last_t = None
        self.integral = 0.0  # of ax since the first tick, m/s
        self.span = deque()  # (t, integral, wheel speeds, usage) of the ticks the wheels have rolled freely on end
        self.rejected_since = None  # the first of the spans on end whose innovation was beyond the gate

    def update(self, t: float, acceleration: float, wheel_speeds, usage, free_usage: float,
               ax_density: float | None, turning: float = 0.0) -> None:
        """One tick: ax (``acceleration``, m/s^2) integrated, the walk since the last tick, then the wheels' evidence
        if all four have transmitted little and steady force (``usage``, ``|Fx| / Fz``, below ``free_usage``) for
        ``SETTLE`` s on a straight (``turning``, ``vx r`` in m/s^2, below ``STRAIGHT``). ``wheel_speeds``: the four
        wheel-centre speeds (m/s); ``ax_density``: ax's noise density as measured (m^2/s^3; None until it is: nothing
        is learned then, a vibrating ax's integral would count as a quiet one's). Consecutive spans
        share all but a tick: each tick's measurement counts as that share of an independent one."""
        if self.last_t is not None and t < self.last_t:  # time ran backwards: another log, another road
            self.reset()
        dt = t - self.last_t if self.last_t is not None else 0.0
        if dt > 0.0:
            self.integral += acceleration * dt
            self.variance = min(self.variance + WALK**2 * dt, PRIOR_STD**2)
        self.last_t = t
        if abs(turning) >= STRAIGHT or any(abs(x) >= free_usage for x in usage) or not 0.0 < dt <= GAP:
            self.span.clear()
            self.rejected_since = None  # gated spans must follow on end: one after a bend is not a new grade
        self.span.append((t, self.integral, list(wheel_speeds), list(usage)))
        while len(self.span) > 1 and t - self.span[1][0] >= SETTLE:
            self.span.popleft()
        then, integral_then, speeds_then, usage_then = self.span[0]
        duration = t - then
        if duration < SETTLE or ax_density is None:
            return
        changes = [(now - before) / duration for now, before in zip(wheel_speeds, speeds_then)]
        if max(changes) - min(changes) > WHEEL_SPREAD or any(abs(now - before) >= USAGE_CHANGE
                                                              for now, before in zip(usage, usage_then)):
            return
        noise = SAMPLE_STD**2 + SPIKE_FACTOR * ax_density / duration
        innovation = (self.integral - integral_then) / duration - sum(changes) / len(changes) - self.value
        if innovation**2 > GATE**2 * (self.variance + noise):
            self.rejected_since = t if self.rejected_since is None else self.rejected_since
            if t - self.rejected_since >= RELEARN:  # the road's grade changed beyond the walk: learn it anew
                self.variance, self.measured_std = PRIOR_STD**2, PRIOR_STD
            return
        self.rejected_since = None
        gain = self.variance / (self.variance + noise * duration / dt)
        self.value += gain * innovation
        self.variance *= 1.0 - gain
        self.measured_std = math.sqrt(self.variance)
