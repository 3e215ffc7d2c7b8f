"""Sigma-point / cubature Kalman filter with a pluggable point rule and factorization.

The filter knows nothing of vehicles: ``predict`` takes a vectorized transition
``f(X, u, dt)`` and ``update`` a vectorized measurement ``h(X, u)``, both
mapping points of shape (N, n) to (N, n) and (N, m).

Time update (Arasaratnam & Haykin 2009; MCSCKF paper eqs 11-16):

    X_i = x + S xi_i,  S S^T = P            (cubature points)
    X*_i = f(X_i, u, dt)
    x- = sum w_i X*_i
    P- = sum w_i (X*_i - x-)(X*_i - x-)^T + Q

Measurement update (eqs 17-22), points regenerated from the predicted P-:

    Z_i = h(X_i, u),  z^ = sum w_i Z_i
    Pzz = sum w_i (Z_i - z^)(Z_i - z^)^T + R,   Pxz = sum w_i (X_i - x-)(Z_i - z^)^T
    K = Pxz Pzz^-1,   x = x- + K (z - z^)

Covariance kept symmetric positive definite by construction: the update is
written in Joseph form with the statistically linearized measurement matrix
``H = Pxz^T P-^-1`` (for a linear h this is exactly H, and the result equals
``P- - K Pzz K^T``):

    P = (I - K H) P- (I - K H)^T + K R K^T

a congruence of a positive definite matrix plus a positive semidefinite one,
then averaged with its transpose. If the factorization of P still fails (e.g.
after a non-finite input), P is repaired by clipping its eigenvalues to
``EIGEN_FLOOR`` times its largest, and ``repairs`` counts it.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg

from canest.filters import rules

FACTORIZATIONS = ("cholesky", "svd")
EIGEN_FLOOR = 1e-12


def _symmetrize(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + P.T)


class SigmaPointFilter:
    """Gaussian filter that propagates a deterministic point set.

    Attributes readable after each step: ``x``, ``P``, and after an update the
    innovation ``y``, its covariance ``S``, the gain ``K`` and the normalized
    innovation squared ``nis``; ``repairs`` counts covariance repairs.
    """

    name = "sigma-point"

    def __init__(self, x0, P0, xi: np.ndarray, weights: np.ndarray, factorization: str = "cholesky"):
        if factorization not in FACTORIZATIONS:
            raise ValueError(f"factorization must be one of {FACTORIZATIONS}, got {factorization!r}")
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float)
        self.xi = xi
        self.w = weights
        self.factorization = factorization
        self.repairs = 0
        self.y = self.S = self.K = None
        self.nis = 0.0

    def _square_root(self, P: np.ndarray) -> np.ndarray:
        """A matrix S with S S^T = P: lower Cholesky factor, or U sqrt(s) from the SVD (DCKF paper eqs 16-19)."""
        if self.factorization == "svd":
            U, s, _ = np.linalg.svd(P, hermitian=True)
            return U * np.sqrt(s)
        try:
            return np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            self.P = self._repair(P)
            return np.linalg.cholesky(self.P)

    def _repair(self, P: np.ndarray) -> np.ndarray:
        self.repairs += 1
        P = np.nan_to_num(_symmetrize(P), nan=0.0, posinf=0.0, neginf=0.0)
        values, vectors = np.linalg.eigh(P)
        floor = EIGEN_FLOOR * max(float(values.max()), 1.0)
        return _symmetrize((vectors * np.maximum(values, floor)) @ vectors.T)

    def points(self) -> np.ndarray:
        return self.x + self.xi @ self._square_root(self.P).T

    def _weighted_cov(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        return (A * self.w[:, None]).T @ B

    def predict(self, f, u, dt: float, Q: np.ndarray) -> None:
        X = f(self.points(), u, dt)
        self.x = self.w @ X
        dX = X - self.x
        self.P = _symmetrize(self._weighted_cov(dX, dX) + Q)

    def update(self, z: np.ndarray, h, u, R: np.ndarray) -> None:
        X = self.points()
        Z = h(X, u)
        z_hat = self.w @ Z
        dX = X - self.x
        dZ = Z - z_hat
        Pzz = _symmetrize(self._weighted_cov(dZ, dZ) + R)
        Pxz = self._weighted_cov(dX, dZ)
        factor = scipy.linalg.cho_factor(Pzz)
        K = scipy.linalg.cho_solve(factor, Pxz.T).T
        H = scipy.linalg.solve(self.P, Pxz, assume_a="pos").T
        A = np.eye(self.x.size) - K @ H
        self.y = z - z_hat
        self.S = Pzz
        self.K = K
        self.nis = float(self.y @ scipy.linalg.cho_solve(factor, self.y))
        self.x = self.x + K @ self.y
        self.P = _symmetrize(A @ self.P @ A.T + K @ R @ K.T)


class CubatureKalmanFilter(SigmaPointFilter):
    """Third-degree cubature Kalman filter (Arasaratnam & Haykin 2009), 2n points."""

    name = "ckf"

    def __init__(self, x0, P0, factorization: str = "cholesky"):
        xi, w = rules.third_degree_cubature(len(x0))
        super().__init__(x0, P0, xi, w, factorization)
