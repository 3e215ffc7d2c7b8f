"""What every filter shares: the model interfaces and covariance hygiene.

Filters never see a vehicle. They get a :class:`Transition` and a
:class:`Measurement` (in the manner of Stone Soup: models apart from the
predictor and updater), both vectorized over points: ``f(X, u, dt)`` maps
points of shape (N, n) to (N, n); ``h(X, u)`` maps them to (N, m). Filters that
linearize use the optional Jacobians; adaptive filters key their noise
statistics by ``channels`` (which measurements of the model these m are, as
channels arrive at different rates).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

EIGEN_FLOOR = 1e-12


@dataclass(frozen=True)
class Transition:
    f: Callable  # (X (N, n), u, dt) -> (N, n)
    jacobian: Optional[Callable] = None  # (x (n,), u, dt) -> (n, n)


@dataclass(frozen=True)
class Measurement:
    h: Callable  # (X (N, n), u) -> (N, m)
    jacobian: Optional[Callable] = None  # (x (n,), u) -> (m, n)
    channels: tuple = ()  # model measurement channel of each of the m rows
    parameter_jacobian: Optional[Callable] = None  # (x, u) -> (m,): d h / d(model parameter), for dual filters


def central_difference_jacobian(fun: Callable, x: np.ndarray, relative_step: float = 1e-6) -> np.ndarray:
    """``d fun / d x`` at ``x`` by central differences, all 2n points in one vectorized call.

    The fallback for models without an analytic Jacobian, so the linearizing
    filters run on every model. Step ``relative_step * max(1, |x_i|)``: second
    order, error ``O(h^2)`` (the states span rad/s to kN).
    """
    x = np.asarray(x, dtype=float)
    steps = relative_step * np.maximum(1.0, np.abs(x))
    offsets = np.diag(steps)
    values = fun(np.vstack([x + offsets, x - offsets]))
    n = x.size
    return ((values[:n] - values[n:]) / (2.0 * steps[:, None])).T


def symmetrize(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + P.T)


def svd_root(P: np.ndarray) -> np.ndarray:
    """``U diag(sqrt(s))`` from ``P = U diag(s) U^T``: a square root of any symmetric PSD matrix (DCKF eqs 16-19)."""
    U, s, _ = np.linalg.svd(symmetrize(P), hermitian=True)
    return U * np.sqrt(np.maximum(s, 0.0))


class GaussianFilter:
    """State ``x``, covariance ``P``; after an update the innovation ``y``, its covariance ``S``,
    the gain ``K`` and the normalized innovation squared ``nis``; ``repairs`` counts covariance repairs."""

    name = "gaussian"
    # What the filter needs of the model beyond f and h (the model catalog matches these):
    # "jacobian", "input_parameter" (a scalar parameter in u with d h / d parameter),
    # "state_parameters" (trailing states that are bounded parameters), "sensor_sets" (channels per sensor).
    needs: frozenset = frozenset()
    # Whether the filter takes square roots of P (so ``factorization`` applies); the EKFs propagate P itself.
    factorizes: bool = True

    def __init__(self, x0, P0):
        self.repairs = 0
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float)
        self.y = self.S = self.K = self.H = None
        self.nis = 0.0

    @property
    def covariance(self) -> np.ndarray:
        """The covariance the estimator publishes and judges with (P; an adaptive filter keeps its own)."""
        return self.P

    def noise_taken(self, channel: int, configured: float) -> float:
        """The noise variance of measurement ``channel`` that :attr:`covariance` took at its last update as the
        sensor's: the ``configured`` one here; an adaptive filter's learned R (:mod:`canest.filters.adaptive`).
        mcsckf answers the configured too: its reweighted R is an outlier's down-weighting, not the sensor's noise
        (taken as the noise, its yaw rate on the drawn cars with a vibrating IMU went 98.8 -> 98.5 % within 2 std,
        valid but wrong 0.05 -> 0.06 %, next to the wrong-sign edge it is nearest to)."""
        return configured

    def repair(self, P: np.ndarray) -> np.ndarray:
        """Nearest symmetric matrix with eigenvalues >= EIGEN_FLOOR * max(1, largest); counted."""
        self.repairs += 1
        P = np.nan_to_num(symmetrize(P), nan=0.0, posinf=0.0, neginf=0.0)
        values, vectors = np.linalg.eigh(P)
        floor = EIGEN_FLOOR * max(float(values.max()), 1.0)
        return symmetrize((vectors * np.maximum(values, floor)) @ vectors.T)

    def cholesky(self, P: np.ndarray) -> np.ndarray:
        """Lower Cholesky factor of P; a P that is not positive definite is repaired first."""
        try:
            return np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            self.P = self.repair(P)
            return np.linalg.cholesky(self.P)

    def apply_gain(self, y: np.ndarray, S: np.ndarray, K: np.ndarray, H: np.ndarray, R: np.ndarray) -> None:
        """x += K y and the Joseph-form covariance update ``(I - K H) P (I - K H)^T + K R K^T``.

        A congruence of a positive definite matrix plus a positive semidefinite
        one: symmetric positive definite by construction (then symmetrized).
        """
        A = np.eye(self.x.size) - K @ H
        self.y, self.S, self.K, self.H = y, S, K, H
        self.nis = float(y @ np.linalg.solve(S, y))
        self.x = self.x + K @ y
        self.P = symmetrize(A @ self.P @ A.T + K @ R @ K.T)
