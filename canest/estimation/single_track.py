"""Binding of the 3-DOF single-track model (:mod:`canest.models.single_track`) to the tick core.

Measurements ay, yaw rate and the wheel-speed mean ``vx_wheel``; input
``u = (road wheel angle, ax, cornering stiffness scale 1)`` (a dual filter
replaces the scale with its own estimate), ax less its offset from the
wheels' acceleration (a road's grade: :mod:`canest.estimation.longitudinal_offset`):
the model's ax is ``dvx/dt - r vy`` (eq 3), the accelerometer's holds gravity's pull
down a hill.
"""
from __future__ import annotations

import numpy as np

from canest.estimation import channels as ch
from canest.estimation.core import Estimator
from canest.estimation.inputs import TickInputs
from canest.models.single_track import SingleTrackModel


class SingleTrackEstimator(Estimator):
    def __init__(self, config):
        super().__init__(config, SingleTrackModel(config.vehicle))

    def _control(self, inputs: TickInputs, t: float) -> np.ndarray:
        return np.array([self._road_wheel_angle(inputs), inputs.current("ax") - self.reference_speed.offset.value, 1.0])

    def _update(self, channels: ch.Channels, inputs: TickInputs, u: np.ndarray, lateral_ok: bool, t: float) -> bool:
        """A dual filter learns its stiffness scale only with the lateral channels in use and the accelerometers'
        noise measured (:mod:`canest.estimation.measured_noise`): until then the filter takes ay at its configured
        noise, 0.15 m/s^2 where a vibrating body shakes it by 1.4, and in the first 0.3 s of vibrating drives theta
        fell to 0.30-0.73 (its bound 0.3 on one launch of three; true 1) and stayed there."""
        if "input_parameter" in self.filter.needs:  # dekf: its parameter filter learns theta
            measured = all(noise.std is not None for _, noise in self.accelerometer_rows)
            self.filter.learning = lateral_ok and measured
        return super()._update(channels, inputs, u, lateral_ok, t)
