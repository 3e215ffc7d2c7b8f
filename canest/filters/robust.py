"""``mcsckf``: maximum-correntropy square-root cubature Kalman filter (MCSCKF paper, eqs 23-41).

The SCKF measurement update is re-derived under the maximum correntropy
criterion: instead of the quadratic cost, maximize the sum of Gaussian
kernels of the whitened residuals (eqs 30-32). Setting the derivative to zero
gives a fixed point in which each measurement's noise is inflated by the
inverse of its kernel weight (eqs 33-36; the state part keeps P, eq 35):

    e   = S_R^-1 (z - z^ - H (x_t - x-))          whitened residual at iterate x_t
    c_i = exp(-e_i^2 / (2 sigma^2))                kernel weights, C_y = diag(c)
    R~  = S_R C_y^-1 S_R^T                        (eq 36)
    x_{t+1} = x- + K(R~) (z - z^)

iterated from ``x_0 = x-`` until the step is below ``tol`` (at most
``max_iterations``), ``H = Pxz^T P-^-1`` (statistical linearization). The
covariance then follows the SCKF square-root update with ``chol(R~)``.

Adaptive kernel width (eqs 37-41). The normalized innovation squared
``eta = mu^T Pzz^-1 mu`` (eq 40) has expectation m when the model and R are
right. The paper's eq 41 is garbled in print; taken as ``sigma = eta exp(-eta/2)``
it sends sigma to zero as eta goes to zero, which discards perfect
measurements. We keep its intent, a width that narrows as the innovation
grows beyond what R explains:

    sigma_k = max(sigma_min, sigma_0 sqrt(m / max(eta_k, m)))

so consistent innovations see the wide kernel ``sigma_0`` (weight 0.95 at one
standard deviation for sigma_0 = 3, close to the Kalman filter) and an
outlier both a narrow kernel and a large residual.
"""
from __future__ import annotations

import numpy as np

from canest.filters.base import Measurement
from canest.filters.sqrt import SquareRootCubatureKalmanFilter

MIN_WEIGHT = 1e-8


class MaximumCorrentropySCKF(SquareRootCubatureKalmanFilter):
    name = "mcsckf"

    def __init__(self, x0, P0, factorization: str = "cholesky", kernel_width: float = 3.0,
                 min_kernel_width: float = 1.0, max_iterations: int = 5, tol: float = 1e-6):
        super().__init__(x0, P0)
        self.sigma0 = kernel_width
        self.sigma_min = min_kernel_width
        self.max_iterations = max_iterations
        self.tol = tol
        self.kernel_weights = None
        self.iterations = 0

    def kernel_width(self, eta: float, m: int) -> float:
        return max(self.sigma_min, self.sigma0 * np.sqrt(m / max(eta, m)))

    def update(self, z: np.ndarray, measurement: Measurement, u, R: np.ndarray) -> None:
        z_hat, Xc, Zc = self._moments(measurement, u)
        y = z - z_hat
        sqrt_R = self.cholesky(R)
        Pzz = Zc @ Zc.T + R
        eta = float(y @ np.linalg.solve(Pzz, y))
        sigma = self.kernel_width(eta, y.size)
        H = np.linalg.solve(self.P, Xc @ Zc.T).T
        prior = self.x
        x_t = prior
        for self.iterations in range(1, self.max_iterations + 1):
            e = np.linalg.solve(sqrt_R, y - H @ (x_t - prior))
            weights = np.maximum(np.exp(-e**2 / (2.0 * sigma**2)), MIN_WEIGHT)
            sqrt_R_tilde = sqrt_R / np.sqrt(weights)  # columns scaled: S_R C^-1/2
            Szz = self._innovation_root(Zc, sqrt_R_tilde)
            K = self._gain(Szz, Xc @ Zc.T)
            x_next = prior + K @ y
            converged = np.linalg.norm(x_next - x_t) <= self.tol * (np.linalg.norm(x_t) + self.tol)
            x_t = x_next
            if converged:
                break
        self.kernel_weights = weights
        self._correct(y, Xc, Zc, sqrt_R_tilde)
