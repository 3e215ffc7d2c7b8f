"""Extended Kalman filters: ``ekf`` and the dual ``dekf``.

``ekf`` (the baseline of the LMRWEKF and MCSCKF papers):

    x- = f(x, u, dt),  P- = F P F^T + Q,  F = df/dx at x      (exact Jacobian from the model)
    K = P- H^T (H P- H^T + R)^-1,  H = dh/dx at x-
    x = x- + K (z - h(x-)),  P = (I - K H) P- (I - K H)^T + K R K^T   (Joseph form)

``dekf`` (the comparison of the LMRWEKF paper, after Wenzel et al. 2006 and Wan
& Nelson's dual estimation): a state EKF and a parameter EKF run side by side
and exchange estimates each step. The parameter is a common scale ``theta`` of
both axles' cornering stiffnesses: the one vehicle parameter that changes in
service (tire wear, temperature, inflation, load) and that dominates the
lateral model's error; it rides in the model input ``u[2]``. The parameter
filter is a random walk ``theta+ = theta`` with ``q_theta`` per second,
updated with the state filter's own innovation (Wan & Nelson's dual EKF: the
parameter's measurement is ``z = h(x-, theta)``):

    y = z - h(x-, theta),  C = dh/dtheta at (x-, theta)
    S_theta = C P_theta C^T + H P- H^T + R,  k = P_theta S_theta^-1 C
    theta += k^T y,  P_theta (1 - k^T C)

in the decoupled form: C is the direct derivative, the prior's own
dependence on theta (through this and earlier predictions, Wan & Nelson's
``H dx-/dtheta``) is neglected, and the prior's spread ``H P- H^T`` is noise
to the parameter filter, as in the dual CKF (:mod:`canest.filters.dual`).
The estimator says when theta may learn (:attr:`learning`; the single-track
binding: with the lateral channels in use, once the accelerometers' noise is
measured): otherwise its gain is zero and its value held. Its variance grows
with the random walk but never beyond the initial ``theta_std^2``, the widest
its prior is (as a friction's, :mod:`canest.filters.parameters`): held over
600 s it grew to 0.24 (std 0.49), and the next vibrating bend swung theta
between 0.44 and 1.41. An earlier form took the residual and C at the state
filter's *posterior* with R alone: that posterior had just taken in the
measurement's noise, and on the vibrating honesty grid's drives on 0.85 theta
ran to 1.35-1.79 (per-drive medians; quiet 0.93-1.07), the sideslip outside
2 std on 8-67 % of single drives' valid ticks. theta is clipped to
``THETA_BOUNDS``. Which entry of ``u`` holds ``theta`` is the model's
business: ``parameter_index`` (default the last input).
"""
from __future__ import annotations

import numpy as np

from canest.filters.base import GaussianFilter, Measurement, Transition, symmetrize

THETA_BOUNDS = (0.3, 2.0)


class ExtendedKalmanFilter(GaussianFilter):
    name = "ekf"
    needs = frozenset({"jacobian"})
    factorizes = False  # ``factorization`` is accepted for a uniform constructor and unused

    def __init__(self, x0, P0, factorization: str = "cholesky"):
        super().__init__(x0, P0)

    def predict(self, transition: Transition, u, dt: float, Q: np.ndarray) -> None:
        F = transition.jacobian(self.x, u, dt)
        self.x = transition.f(self.x[None, :], u, dt)[0]
        self.P = symmetrize(F @ self.P @ F.T + Q)

    def innovation(self, z, measurement: Measurement, u, R):
        """Innovation y, its covariance S and the Jacobian H at the prior."""
        H = measurement.jacobian(self.x, u)
        y = z - measurement.h(self.x[None, :], u)[0]
        return y, symmetrize(H @ self.P @ H.T + R), H

    def update(self, z: np.ndarray, measurement: Measurement, u, R: np.ndarray) -> None:
        self.correct(*self.innovation(z, measurement, u, R), R)

    def correct(self, y, S, H, R) -> None:
        """The Kalman gain and Joseph update for innovation ``y`` of covariance ``S`` and Jacobian ``H``."""
        self.apply_gain(y, S, np.linalg.solve(S, H @ self.P).T, H, R)


class DualExtendedKalmanFilter(ExtendedKalmanFilter):
    name = "dekf"
    needs = frozenset({"jacobian", "input_parameter"})

    def __init__(self, x0, P0, factorization: str = "cholesky", theta0: float = 1.0, theta_std: float = 0.1,
                 theta_noise: float = 0.02, parameter_index: int = -1):
        super().__init__(x0, P0)
        self.parameter_index = parameter_index
        self.theta = float(theta0)
        self.theta_var = self.theta_cap = theta_std**2
        self.theta_q = theta_noise**2
        self.learning = True  # set by the estimator: False while theta may not learn

    def _with_theta(self, u):
        u = np.array(u, dtype=float)
        u[self.parameter_index] = self.theta
        return u

    def predict(self, transition: Transition, u, dt: float, Q: np.ndarray) -> None:
        super().predict(transition, self._with_theta(u), dt, Q)
        self.theta_var = min(self.theta_var + self.theta_q * dt, self.theta_cap)

    def update(self, z: np.ndarray, measurement: Measurement, u, R: np.ndarray) -> None:
        u = self._with_theta(u)
        y, S, H = self.innovation(z, measurement, u, R)
        C = measurement.parameter_jacobian(self.x, u)
        S_theta = self.theta_var * np.outer(C, C) + S
        gain = self.theta_var * np.linalg.solve(S_theta, C) if self.learning else np.zeros_like(C)
        self.correct(y, S, H, R)
        self.theta = float(np.clip(self.theta + gain @ y, *THETA_BOUNDS))
        self.theta_var = max(self.theta_var * (1.0 - gain @ C), 1e-12)
