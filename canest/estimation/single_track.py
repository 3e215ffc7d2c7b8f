"""Binding of the 3-DOF single-track model (:mod:`canest.models.single_track`) to the tick core.

Measurements ay, yaw rate and the wheel-speed mean ``vx_wheel``; input
``u = (road wheel angle, ax, cornering stiffness scale 1)`` (a dual filter
replaces the scale with its own estimate).
"""
from __future__ import annotations

import numpy as np

from canest.estimation import channels as ch
from canest.estimation.core import Estimator
from canest.estimation.inputs import TickInputs
from canest.estimation.stiffness_window import BEND_AY
from canest.models.single_track import SingleTrackModel


class SingleTrackEstimator(Estimator):
    def __init__(self, config):
        super().__init__(config, SingleTrackModel(config.vehicle))

    def _control(self, inputs: TickInputs, t: float) -> np.ndarray:
        return np.array([self._road_wheel_angle(inputs), inputs.current("ax"), 1.0])

    def _update(self, channels: ch.Channels, inputs: TickInputs, u: np.ndarray, lateral_ok: bool, t: float) -> bool:
        """A dual filter learns its stiffness scale only while the car turns (``|vx r|`` from the gyro at least
        ``BEND_AY``, the window fit's bend): on a straight its ``dh/dtheta`` is the prior's noise."""
        if hasattr(self.filter, "learning"):
            turning = inputs.has("yaw_rate") and abs(self.filter.x[self.vx] * inputs.values["yaw_rate"]) >= BEND_AY
            self.filter.learning = lateral_ok and turning
        return super()._update(channels, inputs, u, lateral_ok, t)
