"""``jckf``: one cubature filter over the joint state of vehicle states and parameters (augmented state).

The same third-degree cubature rule and SVD square root as ``dckf``
(:mod:`canest.filters.dual`), but one filter with one covariance over
``(x_s, x_p)``: the cross-covariance between states and parameters is kept.
The dual filter drops it, and with it the information that matters for road
friction: a tire model with too much friction explains a saturated tire's
measured force by a smaller slip angle, i.e. by a different sideslip. With
the cross-covariance the measurements move sideslip and friction together;
without it the state filter absorbs every force error into sideslip and the
parameter filter sees no innovation (measured on the simulator, 50 km/h sine,
friction 0.35: the joint filter within 0.1 after 0.4-0.8 s, the dual filter
never; README "Tire forces and road friction").

Bounds, freezing and the variance cap of the parameters:
:class:`canest.filters.parameters.ParameterBlock`.
"""
from __future__ import annotations

import numpy as np

from canest.filters.base import Measurement, Transition
from canest.filters.parameters import ParameterBlock
from canest.filters.sigma import CubatureKalmanFilter


class JointCubatureKalmanFilter(CubatureKalmanFilter):
    name = "jckf"
    needs = frozenset({"state_parameters"})
    parameters_valid = True  # the joint posterior covariance bounds the parameters' error (honesty grid NEES 1.8-2.0)

    def __init__(self, x0, P0, factorization: str = "svd", parameters: int = 4, parameter_bounds=(-np.inf, np.inf)):
        super().__init__(x0, P0, factorization)
        self.parameters = ParameterBlock(self.x.size, self.P, parameters, parameter_bounds)

    def predict(self, transition: Transition, u, dt: float, Q: np.ndarray) -> None:
        super().predict(transition, u, dt, Q)
        self.P = self.parameters.cap_variance(self.P)

    def update(self, z: np.ndarray, measurement: Measurement, u, R: np.ndarray) -> None:
        z_hat, Pzz, Pxz = self.predicted_measurement(measurement, u)
        block = self.parameters.index
        prior = self.x[block].copy()
        self.correct(z - z_hat, Pzz, Pxz, R, gain_mask=self.parameters.gain_mask)
        self.x[block], self.P = self.parameters.project(self.x[block], self.P, prior)
