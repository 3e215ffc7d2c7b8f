"""Accelerometers fixed to a body that rolls and pitches read part of gravity.

A body rolled by ``phi`` (right side down, as a left bend rolls it) puts its
lateral accelerometer's axis ``phi`` above the horizontal: it reads
``ay cos(phi) + g sin(phi)``; pitched nose-up by ``theta`` (accelerating) the
longitudinal one reads ``ax cos(theta) + g sin(theta)``. A car's body rolls
and pitches in proportion to its accelerations: ``phi = k_roll ay``,
``theta = k_pitch ax`` with the roll and pitch gradients (deg/g in a config:
3-6 and 1-3 for a passenger car). An ESC may publish ax and ay compensated
(level) or as its sensors read them.
"""
from __future__ import annotations

import math

import numpy as np

from canest.models.wheels import GRAVITY

LEVEL_ITERATIONS = 6  # fixed-point steps of level_reading: each shrinks the error by k g (0.07 at 4 deg/g, 0.27 at 15)


def per_si(deg_per_g: float) -> float:
    """A gradient in deg/g as rad per m/s^2."""
    return math.radians(deg_per_g) / GRAVITY


def tilted_reading(acceleration, gradient: float):
    """What an accelerometer tilted by ``gradient * acceleration`` (rad; gradient in rad per m/s^2) reads."""
    angle = gradient * acceleration
    return acceleration * np.cos(angle) + GRAVITY * np.sin(angle)


def level_reading(reading, gradient: float):
    """The acceleration a tilted accelerometer's ``reading`` means: :func:`tilted_reading` inverted by fixed-point
    iteration (a contraction: its slope is ``gradient g``, 0.27 at 15 deg/g)."""
    acceleration = reading
    for _ in range(LEVEL_ITERATIONS):
        angle = gradient * acceleration
        acceleration = (reading - GRAVITY * np.sin(angle)) / np.cos(angle)
    return acceleration
