"""Sigma-point and cubature Kalman filters with a pluggable rule and factorization.

Time update (Arasaratnam & Haykin 2009; MCSCKF paper eqs 11-16; SVD-FCKF eqs 15-18;
DICI-GFCKF eqs 28-31):

    X_i = x + S xi_i,  S S^T = P
    x- = sum wm_i f(X_i),   P- = sum wc_i (f(X_i) - x-)(f(X_i) - x-)^T + Q

Measurement update (MCSCKF eqs 17-22; SVD-FCKF eqs 19-26), points regenerated from P-:

    Z_i = h(X_i),  z^ = sum wm_i Z_i
    Pzz = sum wc_i (Z_i - z^)(Z_i - z^)^T + R,   Pxz = sum wc_i (X_i - x-)(Z_i - z^)^T
    K = Pxz Pzz^-1,  x = x- + K (z - z^)

The covariance update is written in Joseph form with the statistically
linearized ``H = Pxz^T P-^-1`` (:meth:`GaussianFilter.apply_gain`); for a
linear h it equals ``P- - K Pzz K^T``. Square root ``S``: the lower Cholesky
factor, or from the SVD ``P = U diag(s) U^T`` the factor ``U diag(sqrt(s))``
(DCKF paper eqs 16-19, SVD-FCKF eq 19), which exists for any symmetric
positive semidefinite P. Rules with negative weights (fifth-degree for n > 4,
the UKF for n > 3) can make P- indefinite; the next factorization then repairs
it by clipping eigenvalues and counts it in ``repairs``.
"""
from __future__ import annotations

import numpy as np

from canest.filters import rules
from canest.filters.base import GaussianFilter, Measurement, Transition, svd_root, symmetrize

FACTORIZATIONS = ("cholesky", "svd")


class SigmaPointFilter(GaussianFilter):
    def __init__(self, x0, P0, xi: np.ndarray, w_mean: np.ndarray, w_cov=None, factorization: str = "cholesky"):
        super().__init__(x0, P0)
        if factorization not in FACTORIZATIONS:
            raise ValueError(f"factorization must be one of {FACTORIZATIONS}, got {factorization!r}")
        self.xi = xi
        self.wm = w_mean
        self.wc = w_mean if w_cov is None else w_cov
        self.factorization = factorization

    def square_root(self, P: np.ndarray) -> np.ndarray:
        return svd_root(P) if self.factorization == "svd" else self.cholesky(P)

    def points(self) -> np.ndarray:
        return self.x + self.xi @ self.square_root(self.P).T

    def _cov(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        return (A * self.wc[:, None]).T @ B

    def predict(self, transition: Transition, u, dt: float, Q: np.ndarray) -> None:
        """Time update (DICI-GFCKF eqs 28-31): :meth:`points` through ``f``, then :meth:`predict_from`."""
        self.predict_from(transition.f(self.points(), u, dt), Q)

    def predict_from(self, X: np.ndarray, Q: np.ndarray) -> None:
        """The time update's moments from the propagated points ``X = f(X_i)`` (the mean and covariance of
        DICI-GFCKF eqs 28-31): ``x- = sum wm_i X_i``, ``P- = sum wc_i (X_i - x-)(X_i - x-)^T + Q``, symmetrized.
        With nonnegative weights and Q positive definite, P- is positive definite by construction; a rule with
        negative weights (the generalized fifth-degree rule's 2n axis points for n = 7) can make it indefinite,
        and the next factorization repairs it and counts it (module docstring)."""
        self.x = self.wm @ X
        dX = X - self.x
        self.P = symmetrize(self._cov(dX, dX) + Q)

    def predicted_measurement(self, measurement: Measurement, u):
        """Predicted measurement z^, its covariance without R, and the cross covariance Pxz."""
        X = self.points()
        Z = measurement.h(X, u)
        z_hat = self.wm @ Z
        dX, dZ = X - self.x, Z - z_hat
        return z_hat, self._cov(dZ, dZ), self._cov(dX, dZ)

    def update(self, z: np.ndarray, measurement: Measurement, u, R: np.ndarray) -> None:
        z_hat, Pzz, Pxz = self.predicted_measurement(measurement, u)
        self.correct(z - z_hat, Pzz, Pxz, R)

    def correct(self, y, Pzz, Pxz, R, gain_mask=None) -> None:
        """Kalman gain and Joseph update; states outside ``gain_mask(K y)`` (a function of the unconstrained step)
        keep their value (their gain rows are 0).

        The Joseph form stays the true posterior covariance for any gain, so a
        masked (suboptimal) gain leaves P consistent.
        """
        S = symmetrize(Pzz + R)
        K = np.linalg.solve(S, Pxz.T).T
        if gain_mask is not None:
            K[~gain_mask(K @ y)] = 0.0
        H = np.linalg.solve(self.P, Pxz).T
        self.apply_gain(y, S, K, H, R)


def predict_together(filters, transition: Transition, u, dt: float, Qs) -> None:
    """The time update of several sigma-point filters with one evaluation of ``f`` (DICI-GFCKF eqs 28-31 for each
    local filter j): every filter's points ``X_j,i = x_j + S_j xi_i`` (``S_j S_j^T = P_j``) are stacked and
    propagated together, ``f(X_j,i)``, and each filter takes its mean and covariance from its own rows
    (:meth:`SigmaPointFilter.predict_from` with ``Qs[j]``).

    The same result as ``filters[j].predict(transition, u, dt, Qs[j])`` for each j, to rounding, where ``f`` maps
    each point on its own (as the vectorized models do), for less than the separate calls cost: numpy's per-call
    overhead dominates a model evaluation (one RK4 step of the tire-force model on 198 points 426 us, on 99 points
    321 us, measured). Only for filters whose time update is
    :meth:`SigmaPointFilter.predict` itself (a subclass that overrides it would silently lose its own).
    """
    for filt in filters:
        if type(filt).predict is not SigmaPointFilter.predict:
            raise TypeError(f"{type(filt).__name__} has its own time update; predict it on its own")
    points = [filt.points() for filt in filters]
    X = transition.f(np.concatenate(points), u, dt)
    start = 0
    for filt, own, Q in zip(filters, points, Qs):
        filt.predict_from(X[start:start + len(own)], Q)
        start += len(own)


class RuleFilter(SigmaPointFilter):
    """A sigma-point filter defined by its point rule alone (``rule(n) -> (xi, w_mean[, w_cov])``)."""

    rule = None

    def __init__(self, x0, P0, factorization: str = "cholesky"):
        super().__init__(x0, P0, *type(self).rule(len(x0)), factorization=factorization)


class CubatureKalmanFilter(RuleFilter):
    """``ckf``: third-degree cubature Kalman filter (Arasaratnam & Haykin 2009), 2n points."""

    name = "ckf"
    rule = staticmethod(rules.third_degree_cubature)


class UnscentedKalmanFilter(RuleFilter):
    """``ukf``: scaled unscented Kalman filter, 2n + 1 points (alpha 1, beta 2, kappa 3 - n)."""

    name = "ukf"
    rule = staticmethod(rules.unscented)


class FifthDegreeCubatureKalmanFilter(RuleFilter):
    """``fckf``: fifth-degree spherical-radial CKF, 2n^2 + 1 points (SVD-FCKF paper eqs 10-18)."""

    name = "fckf"
    rule = staticmethod(rules.fifth_degree_cubature)


class GeneralizedFifthDegreeCKF(RuleFilter):
    """``gfckf``: generalized fifth-degree CKF (DICI-GFCKF paper eqs 22-31)."""

    name = "gfckf"
    rule = staticmethod(rules.generalized_fifth_degree)
