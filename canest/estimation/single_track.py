"""Binding of the 3-DOF single-track model (:mod:`canest.models.single_track`) to the tick core.

Measurements ay, yaw rate and the wheel-speed mean ``vx_wheel``; input
``u = (road wheel angle, ax, cornering stiffness scale 1)`` (a dual filter
replaces the scale with its own estimate).
"""
from __future__ import annotations

import numpy as np

from canest.estimation.core import Estimator
from canest.estimation.inputs import TickInputs
from canest.models.single_track import SingleTrackModel


class SingleTrackEstimator(Estimator):
    def __init__(self, config):
        super().__init__(config, SingleTrackModel(config.vehicle))

    def _control(self, inputs: TickInputs, t: float) -> np.ndarray:
        return np.array([self._road_wheel_angle(inputs), inputs.current("ax"), 1.0])
