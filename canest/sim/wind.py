"""Crosswind gusts: a lateral aerodynamic force on the simulated car that no estimator's model has.

The simulator's roads are otherwise calm: on a straight the car's sideslip is
exactly zero and every filter's sideslip is right to a hundredth of a degree,
far inside its published std (the launches of the honesty grid: ckf's NEES
0.23). A real car on a straight meets gusts. ``scale`` 1 is a gusty day's:
the crosswind's speed a first-order (Ornstein-Uhlenbeck) process of
``GUST_SPEED`` std and ``GUST_TIME`` correlation (44 m of road at 80 km/h,
about the size of a gust near the ground), zero mean (a steady wind is a
bank's cousin the online calibration sees as a lateral offset). The side force
is linear in the crosswind's angle ``w / v``: ``F = 1/2 rho A C_y' v w``
(``SIDE_FORCE_FACTOR``: frontal area 2.2 m^2 and a side-force slope of 3 per
rad, a passenger car's), 180 N in RMS at 80 km/h, acting ``PRESSURE_CENTRE`` m
ahead of the centre of gravity (the aerodynamic centre of a saloon lies
ahead of it: the yaw moment turns the car out of the wind). The accelerometer
measures it (a force on the body, unlike a bank's gravity), so a model that
explains ay by its tires alone reads it as a sideslip.

Drawn from its own random stream (seed and ``STREAM``): a drive without wind
is the drive it was before wind existed.
"""
from __future__ import annotations

import math

import numpy as np

from canest.sim.plant import AIR_DENSITY

GUST_SPEED = 2.0  # m/s, std of the lateral wind at scale 1
GUST_TIME = 2.0  # s, correlation time of the gusts
SIDE_FORCE_FACTOR = 0.5 * AIR_DENSITY * 2.2 * 3.0  # N per (m/s of travel x m/s of crosswind)
PRESSURE_CENTRE = 0.4  # m ahead of the centre of gravity, where the side force acts
STREAM = 2908  # the wind's random stream beside the drive's seed


class Crosswind:
    """The side force (N, ISO 8855: positive to the left) of gusts at ``scale`` times a gusty day's, one plant step
    ``dt`` at a time."""

    def __init__(self, seed: int, scale: float, dt: float):
        self.scale = scale
        self.rng = np.random.default_rng([seed, STREAM]) if scale > 0.0 else None
        self.keep = math.exp(-dt / GUST_TIME)
        self.speed = GUST_SPEED * scale * self.rng.standard_normal() if self.rng is not None else 0.0

    def side_force(self, vx: float) -> float:
        """This step's side force at the car's speed ``vx`` (m/s), then the gust moves on by one step."""
        if self.rng is None:
            return 0.0
        force = SIDE_FORCE_FACTOR * vx * self.speed
        innovation = GUST_SPEED * self.scale * math.sqrt(1.0 - self.keep ** 2)
        self.speed = self.keep * self.speed + innovation * self.rng.standard_normal()
        return force
