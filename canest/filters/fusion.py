"""Fusion of estimates whose cross-covariance is unknown: CI and ICI.

Covariance intersection (DICI-GFCKF paper eqs 15-16; Julier & Uhlmann 1997)::

    P_CI^-1 = sum w_j P_j^-1,   x_CI = P_CI sum w_j P_j^-1 x_j,   sum w_j = 1, w_j >= 0

Inverse covariance intersection (eqs 17-20; Noack et al., "Decentralized data
fusion with inverse covariance intersection", Automatica 2017)::

    Gamma = sum w_j P_j
    P_ICI^-1 = sum P_j^-1 - (n - 1) Gamma^-1
    L_j = P_ICI (P_j^-1 - (n - 1) w_j Gamma^-1),   x_ICI = sum L_j x_j

ICI bounds the information the sources may share by ``Gamma^-1``; each source
contains it once, so it is subtracted ``n - 1`` times. For two sources this is
exactly the paper's eqs 18-19. The paper writes the factor as 1 for every n:
then n identical, fully correlated sources would fuse to ``P / (n - 1)``, a
covariance smaller than the error's (tests/test_fusion.py shows it), so the
factor ``n - 1`` is used. The weights minimize the trace of the fused
covariance (eqs 16 and 20).

Two sources, the case of the dual-IMU filter, are solved in closed form per
weight: the generalized eigen-decomposition ``P2 v = lambda P1 v`` (``V^T P1 V = I``,
``V^T P2 V = diag(lambda)``, ``M = V^-T``) diagonalizes every matrix above, so

    P_ICI(w) = M diag(1 / d(w)) M^T,   d_i = 1 + 1/lambda_i - 1/(w + (1 - w) lambda_i)
    P_CI(w)  = M diag(1 / c(w)) M^T,   c_i = w + (1 - w)/lambda_i

and ``tr P(w) = sum ||M_:,i||^2 / d_i(w)`` is evaluated on a grid of weights at
once; the best grid weight is refined by one parabola through its neighbours.
A grid finds the global minimum (a local search may not). ``d_i >= (1 - w) + w / lambda_i > 0``
by the convexity of ``1/x``: the fused covariance is positive definite by
construction for every w. More than two sources: the weights are found over
the simplex by SLSQP on the direct formulas, rejecting weights whose fused
information is not positive definite (scipy's, from the ``calibrate`` extra:
the filters' two-source fusion does not need it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from canest.errors import DependencyError

GRID = np.linspace(0.0, 1.0, 101)
METHODS = ("ici", "ci")
INSTALL_SCIPY = "pip install 'canest[calibrate]'"


@dataclass
class Fused:
    x: np.ndarray
    P: np.ndarray
    weights: np.ndarray


def _parabola_vertex(values: np.ndarray, k: int) -> float:
    """The weight at the vertex of the parabola through grid points k-1, k, k+1 (k itself at the ends)."""
    if k == 0 or k == GRID.size - 1:
        return float(GRID[k])
    left, mid, right = values[k - 1], values[k], values[k + 1]
    curvature = left - 2.0 * mid + right
    step = GRID[1] - GRID[0]
    shift = 0.5 * (left - right) / curvature if curvature > 0 else 0.0
    return float(GRID[k] + np.clip(shift, -1.0, 1.0) * step)


def _diagonal_terms(method: str, lam: np.ndarray, w) -> np.ndarray:
    """d(w) (ICI) or c(w) (CI) of the module docstring; w of shape (...,1) or scalar."""
    if method == "ici":
        return 1.0 + 1.0 / lam - 1.0 / (w + (1.0 - w) * lam)
    return w + (1.0 - w) / lam


def fuse_two(method: str, x1, P1, x2, P2, weight: float | None = None) -> Fused:
    """CI or ICI of two estimates; the weight of source 1 minimizes the fused trace unless given."""
    # P1 = L L^T, L^-1 P2 L^-T = U diag(lambda) U^T  =>  V = L^-T U, M = V^-T = L U
    L = np.linalg.cholesky(P1)
    L_inv = np.linalg.inv(L)
    lam, U = np.linalg.eigh(L_inv @ P2 @ L_inv.T)
    lam = np.maximum(lam, 1e-300)
    M = L @ U
    V = L_inv.T @ U
    column_norms = np.einsum("ij,ij->j", M, M)
    if weight is None:
        traces = (column_norms / _diagonal_terms(method, lam, GRID[:, None])).sum(axis=1)
        k = int(np.argmin(traces))
        weight = _parabola_vertex(traces, k)
        refined = float(column_norms @ (1.0 / _diagonal_terms(method, lam, weight)))
        if refined > traces[k]:
            weight = float(GRID[k])
    d = _diagonal_terms(method, lam, weight)
    a1, a2 = V.T @ x1, V.T @ x2
    if method == "ici":
        gamma = weight + (1.0 - weight) * lam
        mixed = (1.0 - weight / gamma) * a1 + (1.0 / lam - (1.0 - weight) / gamma) * a2
    else:
        mixed = weight * a1 + (1.0 - weight) / lam * a2
    P = (M / d) @ M.T
    return Fused(M @ (mixed / d), 0.5 * (P + P.T), np.array([weight, 1.0 - weight]))


def _information(method: str, Ps: list, inverses: list, w: np.ndarray) -> np.ndarray:
    if method == "ci":
        return sum(wj * Pi for wj, Pi in zip(w, inverses))
    gamma = sum(wj * Pj for wj, Pj in zip(w, Ps))
    return sum(inverses) - (len(Ps) - 1) * np.linalg.inv(gamma)


def _gains(method: str, Ps: list, inverses: list, w: np.ndarray, P: np.ndarray) -> list:
    if method == "ci":
        return [wj * P @ Pi for wj, Pi in zip(w, inverses)]
    gamma_inv = np.linalg.inv(sum(wj * Pj for wj, Pj in zip(w, Ps)))
    return [P @ (Pi - (len(Ps) - 1) * wj * gamma_inv) for wj, Pi in zip(w, inverses)]


def fuse_many(method: str, xs: list, Ps: list, weights=None) -> Fused:
    """CI or ICI of any number of estimates by the direct formulas; weights over the simplex unless given."""
    inverses = [np.linalg.inv(P) for P in Ps]
    n = len(Ps)

    def trace(w):
        info = _information(method, Ps, inverses, w)
        values = np.linalg.eigvalsh(0.5 * (info + info.T))
        return float(np.sum(1.0 / values)) if values.min() > 0 else np.inf

    if weights is None:
        optimize = DependencyError.require("scipy.optimize", f"fusing {n} estimates", INSTALL_SCIPY)
        start = np.full(n, 1.0 / n)
        result = optimize.minimize(
            lambda w: min(trace(w), 1e300), start, method="SLSQP", bounds=[(0.0, 1.0)] * n,
            constraints=[{"type": "eq", "fun": lambda w: w.sum() - 1.0}])
        weights = result.x if np.isfinite(trace(result.x)) and trace(result.x) <= trace(start) else start
    weights = np.asarray(weights, dtype=float)
    P = np.linalg.inv(_information(method, Ps, inverses, weights))
    P = 0.5 * (P + P.T)
    x = sum(L @ xj for L, xj in zip(_gains(method, Ps, inverses, weights, P), xs))
    return Fused(x, P, weights)


def fuse(method: str, xs: list, Ps: list, weights=None) -> Fused:
    """Fuse estimates ``xs`` with covariances ``Ps`` by ``method`` ('ici' or 'ci')."""
    if method not in METHODS:
        raise ValueError(f"fusion must be one of {METHODS}, got {method!r}")
    if len(xs) == 1:
        return Fused(np.asarray(xs[0], dtype=float), np.asarray(Ps[0], dtype=float), np.ones(1))
    if len(xs) == 2:
        return fuse_two(method, xs[0], Ps[0], xs[1], Ps[1], None if weights is None else float(weights[0]))
    return fuse_many(method, xs, Ps, weights)
