"""``sckf``: square-root cubature Kalman filter (Arasaratnam & Haykin 2009; MCSCKF paper eqs 11-22).

The filter propagates a lower-triangular factor ``root`` (the papers' S) with ``P = root root^T`` and
never forms P in its recursion. ``Tria(A)`` is the lower-triangular ``T`` with
``T T^T = A A^T``, from the QR decomposition of ``A^T`` (eq 14):

    time update:  S- = Tria([Xc*, chol(Q)])             Xc* = (f(X_i) - x-) sqrt(w_i), columns
    measurement:  Szz = Tria([Zc, chol(R)]),   Pxz = Xc Zc^T
                  K = (Pxz / Szz^T) / Szz                (two triangular solves, eq 20)
                  S = Tria([Xc - K Zc, K chol(R)])        (eq 22)

The last line is the square root of the Joseph form, so P = S S^T is
symmetric positive semidefinite by construction, whatever rounding does.
"""
from __future__ import annotations

import numpy as np

from canest.filters import rules
from canest.filters.base import GaussianFilter, Measurement, Transition, svd_root
from canest.filters.sigma import FACTORIZATIONS


def tria(A: np.ndarray) -> np.ndarray:
    """Lower-triangular T with T T^T = A A^T (QR of A^T; the signs make T's diagonal non-negative)."""
    R = np.linalg.qr(A.T, mode="r")
    T = R[: A.shape[0]].T
    return T * np.where(np.diag(T) < 0, -1.0, 1.0)


class SquareRootCubatureKalmanFilter(GaussianFilter):
    name = "sckf"

    def __init__(self, x0, P0, factorization: str = "cholesky"):
        if factorization not in FACTORIZATIONS:
            raise ValueError(f"factorization must be one of {FACTORIZATIONS}, got {factorization!r}")
        self.factorization = factorization
        super().__init__(x0, P0)
        self.xi, w = rules.third_degree_cubature(len(x0))
        self.w = w
        self.sqrt_w = np.sqrt(w)

    @property
    def P(self) -> np.ndarray:
        """Formed only for readers (output, tests); the recursion uses ``root``."""
        return self.root @ self.root.T

    @P.setter
    def P(self, value: np.ndarray) -> None:
        self.root = self.cholesky(np.asarray(value, dtype=float))

    def cholesky(self, P):
        """A square root of P, Q or R: Cholesky, or triangularized U sqrt(s) from the SVD."""
        if self.factorization == "svd":
            return tria(svd_root(P))
        try:
            return np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            return np.linalg.cholesky(self.repair(P))

    def points(self) -> np.ndarray:
        return self.x + self.xi @ self.root.T

    def predict(self, transition: Transition, u, dt: float, Q: np.ndarray) -> None:
        X = transition.f(self.points(), u, dt)
        self.x = self.w @ X
        centred = ((X - self.x) * self.sqrt_w[:, None]).T
        self.root = tria(np.hstack([centred, self.cholesky(Q)]))

    def _moments(self, measurement: Measurement, u):
        X = self.points()
        Z = measurement.h(X, u)
        z_hat = self.w @ Z
        Xc = ((X - self.x) * self.sqrt_w[:, None]).T
        Zc = ((Z - z_hat) * self.sqrt_w[:, None]).T
        return z_hat, Xc, Zc

    @staticmethod
    def _innovation_root(Zc, sqrt_R) -> np.ndarray:
        return tria(np.hstack([Zc, sqrt_R]))

    @staticmethod
    def _gain(Szz, Pxz) -> np.ndarray:
        """K = Pxz (Szz Szz^T)^-1 by two solves with the triangular factor (eq 20).

        numpy's general solver: for m <= 3 it is four times faster than scipy's
        triangular one, whose call overhead dominates at this size.
        """
        return np.linalg.solve(Szz.T, np.linalg.solve(Szz, Pxz.T)).T

    def _correct(self, y, Xc, Zc, sqrt_R) -> None:
        Szz = self._innovation_root(Zc, sqrt_R)
        K = self._gain(Szz, Xc @ Zc.T)
        whitened = np.linalg.solve(Szz, y)
        self.y, self.S, self.K = y, Szz @ Szz.T, K
        self.nis = float(whitened @ whitened)
        self.x = self.x + K @ y
        self.root = tria(np.hstack([Xc - K @ Zc, K @ sqrt_R]))

    def update(self, z: np.ndarray, measurement: Measurement, u, R: np.ndarray) -> None:
        z_hat, Xc, Zc = self._moments(measurement, u)
        self._correct(z - z_hat, Xc, Zc, self.cholesky(R))
