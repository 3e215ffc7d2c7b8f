"""``dckf``: the double cubature Kalman filter of the DCKF paper (section 3, steps 1-4).

Two third-degree cubature filters with SVD square roots (eqs 16-19, 23-26):
one for the vehicle states ``x_s`` and one for the parameters ``x_p`` (the
four friction coefficients), the last ``parameters`` entries of the joint
state. The transition and measurement models are the joint ones; each filter
sees them with the other filter's latest estimate held fixed:

1. time update of ``x_p`` (eqs 16-22; a random walk: ``x_p`` unchanged, ``P_p += Q_p``);
2. time update of ``x_s`` with ``x_p`` at its prediction (eqs 23-29);
3. measurement update of ``x_p`` with ``x_s`` at its prediction (eqs 30-37);
4. measurement update of ``x_s`` with ``x_p`` at its new estimate (eqs 38-45).

The joint covariance is block diagonal: the two filters ignore their
cross-covariance (the dual filter's approximation). Step 3 holds the states at
their prediction, so their uncertainty is part of what the parameter filter
cannot explain: its innovation covariance (eq 33) adds the spread of the
measurement over the state filter's cubature points to ``R_p``. Without it every
state error is blamed on the parameters (measured on the simulator: started at
the true friction 0.35, the four estimates climbed to about 0.85). Step 3's
innovation is taken against the measurement at the parameters' mean,
``z - h(x_s-, x_p-)``, not against the cubature mean of eq 32: friction enters
through a saturation, so points below the mean predict less force, their mean
lies below ``h`` at the mean (Jensen), and where the data only bound friction
from below that bias pushes the estimate up every tick (measured on the
80 km/h sine, mu 0.85, three seeds: final estimates 1.08-1.25 with the
cubature mean, 0.62-0.93 with the mean point; RMSE 0.19 -> 0.05). Gain and
covariance still come from the cubature points; for an h linear in the
parameters both innovations are equal. Eqs 36 and 44 print
``Z_k Z^_k/k-1`` where the innovation ``Z_k - Z^_k/k-1`` is meant; eqs 22, 29, 33,
34 use the raw second moment minus the mean's outer product, computed here in
the centered form (the same value without cancellation).

Bounds (after step 3), freezing and refused rises (a zero gain in step 3) and the variance cap
(after step 1) of the parameters: :class:`canest.filters.parameters.ParameterBlock`.

Published covariance (:attr:`covariance`, what the estimator reports and
judges with): not the block-diagonal P, which says each filter's error is
independent of the other's, but the covariance of the dual estimate's joint
error under the gains the two filters actually apply. Time update: the joint
cubature rule (eqs 16-22 over the joint state, P's cross-covariance
included). Measurement update: step 3 moves ``x_p`` by ``K_p y`` (``y`` the
innovation at the mean); step 4's innovation is then ``y - H_p K_p y`` to first
order, so the pair applies the joint gain ``K = [K_s (I - H_p K_p); K_p]`` with
the statistically linearized ``H = [H_s, H_p]`` of the two steps, and the
error covariance is the Joseph form ``(I - K H) P (I - K H)^T + K R K^T``
(true for any gain; symmetric positive definite by construction), its
parameters' variances capped as P_p's are. Without it
the friction filter's own P_p published a std 3-4 times smaller than its
errors (honesty grid, 80 km/h, friction 0.35 and 0.85: NEES 11-17, 34-61 %
within 2 std). With it the sideslip is honest (NEES 2.0 -> 1.16, valid but
wrong 3.4 % -> 0) but the frictions are not (NEES 8.6-14, 46-71 % within 2
std, wrong by more than 3 std on 13-32 % of their ticks): their error is the
bias of step 3's estimate conditioned on predicted states (a tire model with
the wrong friction explained by a wrong sideslip), which no first-order
covariance of the gains carries. So the parameters are published but never
valid (``parameters_valid``; the estimator's cause ``uncertain``).
"""
from __future__ import annotations

import numpy as np

from canest.filters.base import GaussianFilter, Measurement, Transition, symmetrize
from canest.filters.parameters import ParameterBlock
from canest.filters.sigma import CubatureKalmanFilter

IDENTITY = Transition(lambda X, u, dt: X)


class DoubleCubatureKalmanFilter(GaussianFilter):
    name = "dckf"
    needs = frozenset({"state_parameters"})
    parameters_valid = False  # no covariance bounds the parameters' error (see above)

    def __init__(self, x0, P0, factorization: str = "svd", parameters: int = 4, parameter_bounds=(-np.inf, np.inf)):
        super().__init__(x0, P0)
        self.parameters = ParameterBlock(self.x.size, self.P, parameters, parameter_bounds)
        p = self.parameters.index
        self.split = p.start
        s = slice(0, self.split)
        self.blocks = (s, p)
        self.states = CubatureKalmanFilter(self.x[s], self.P[s, s], factorization)
        self.params = CubatureKalmanFilter(self.x[p], self.P[p, p], factorization)
        self.error = CubatureKalmanFilter(self.x, self.P, factorization)  # the joint error covariance, published

    @property
    def covariance(self) -> np.ndarray:
        return self.error.P

    def _join(self) -> None:
        s, p = self.blocks
        self.x = np.concatenate([self.states.x, self.params.x])
        self.P = np.zeros((self.x.size, self.x.size))
        self.P[s, s], self.P[p, p] = self.states.P, self.params.P
        self.repairs = self.states.repairs + self.params.repairs

    def _with_params(self, Xs):
        return np.hstack([Xs, np.broadcast_to(self.params.x, (Xs.shape[0], self.params.x.size))])

    def _with_states(self, Xp):
        return np.hstack([np.broadcast_to(self.states.x, (Xp.shape[0], self.split)), Xp])

    def predict(self, transition: Transition, u, dt: float, Q: np.ndarray) -> None:
        s, p = self.blocks
        self.params.predict(IDENTITY, u, dt, Q[p, p])  # step 1
        self.params.P = self.parameters.cap_variance(self.params.P)
        state_transition = Transition(lambda Xs, u_, dt_: transition.f(self._with_params(Xs), u_, dt_)[:, s])
        self.states.predict(state_transition, u, dt, Q[s, s])  # step 2
        self.error.x = self.x
        self.error.predict(transition, u, dt, Q)
        self.error.P = self.parameters.cap_variance(self.error.P)
        self._join()

    def update(self, z, measurement: Measurement, u, R) -> None:
        states_view = Measurement(lambda Xs, u_: measurement.h(self._with_params(Xs), u_))
        _, state_spread, _ = self.states.predicted_measurement(states_view, u)
        params_view = Measurement(lambda Xp, u_: measurement.h(self._with_states(Xp), u_))
        _, Pzz, Pxz = self.params.predicted_measurement(params_view, u)  # step 3
        at_mean = params_view.h(self.params.x[None, :], u)[0]
        prior = self.params.x.copy()
        self.params.correct(z - at_mean, Pzz, Pxz, R + state_spread, gain_mask=self.parameters.gain_mask)
        K_p, H_p = self.params.K, self.params.H
        variance = np.diag(self.params.P).copy()
        self.params.x, self.params.P = self.parameters.project(self.params.x, self.params.P, prior)
        self.states.update(z, states_view, u, R)  # step 4
        self.y, self.S, self.K, self.nis = self.states.y, self.states.S, self.states.K, self.states.nis
        self._join()
        K = np.vstack([self.states.K @ (np.eye(z.size) - H_p @ K_p), K_p])
        A = np.eye(self.x.size) - K @ np.hstack([self.states.H, H_p])
        scale = np.ones(self.x.size)  # the parameters' truncation, as on P_p (a congruence)
        scale[self.split:] = np.sqrt(np.diag(self.params.P) / variance)
        self.error.P = self.parameters.cap_variance(symmetrize((A @ self.error.P @ A.T + K @ R @ K.T)
                                                               * np.outer(scale, scale)))
