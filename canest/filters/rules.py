"""Point sets for Gaussian-weighted integration, in unit (standard normal) coordinates.

A rule is a pair ``(xi, w)``: ``xi`` of shape (points, n) and weights ``w``
with ``sum(w) == 1`` such that ``E[g(x)] ~= sum_i w_i g(mu + S xi_i)`` for
``x ~ N(mu, S S^T)``. A rule of degree d integrates every monomial of degree
<= d exactly (tests/test_rules.py checks all of them for n = 1..9).
"""
from __future__ import annotations

import numpy as np


def third_degree_cubature(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Spherical-radial rule of Arasaratnam & Haykin (2009): 2n points ``+-sqrt(n) e_i``, weights 1/(2n).

    This is the rule of the CKF baseline in all five papers (e.g. MCSCKF paper eqs 11-13).
    """
    eye = np.eye(n)
    xi = np.sqrt(n) * np.vstack([eye, -eye])
    w = np.full(2 * n, 1.0 / (2 * n))
    return xi, w


def _pair_directions(n: int) -> np.ndarray:
    """All e_p + e_q and e_p - e_q for p < q, shape (n(n-1), n)."""
    p, q = np.triu_indices(n, k=1)
    plus = np.zeros((p.size, n))
    minus = np.zeros((p.size, n))
    rows = np.arange(p.size)
    plus[rows, p] = minus[rows, p] = 1.0
    plus[rows, q] = 1.0
    minus[rows, q] = -1.0
    return np.vstack([plus, minus])


def fifth_degree_cubature(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Fifth-degree spherical-radial rule, 2n^2 + 1 points (SVD-FCKF paper eqs 11, 13, 14, 17).

    Points ``0``, ``+-sqrt(n+2) e_j`` and ``+-sqrt(n+2) (e_p +- e_q)/sqrt(2)``; weights
    ``2/(n+2)``, ``(4-n)/(2(n+2)^2)`` and ``1/(n+2)^2``. The axis weight is negative for
    n > 4. (The paper's eq 10 prints the weights in terms of a sphere surface A_n that
    is never defined; eq 11 is the consistent form and is what the tests verify.)
    """
    kappa = np.sqrt(n + 2.0)
    eye = np.eye(n)
    pairs = _pair_directions(n) / np.sqrt(2.0)
    xi = np.vstack([np.zeros((1, n)), kappa * eye, -kappa * eye, kappa * pairs, -kappa * pairs])
    w = np.concatenate([[2.0 / (n + 2)], np.full(2 * n, (4.0 - n) / (2.0 * (n + 2) ** 2)),
                        np.full(2 * pairs.shape[0], 1.0 / (n + 2) ** 2)])
    return xi, w


def generalized_fifth_degree(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Generalized (fully symmetric) fifth-degree rule of the DICI-GFCKF paper, eqs 22-27.

    Points ``0``, ``+-sqrt(3) e_i`` and ``sqrt(3) (+-e_i +- e_j)`` (i < j), weights
    ``1 - (7-n)n/18``, ``(4-n)/18``, ``1/36``. The paper solves its moment equations
    (23)-(24) for the weight ``exp(-x^T x)`` (generator ``tau = sqrt(3/2)``); in standard
    normal coordinates the generator is ``sqrt(2) tau = sqrt(3)``, as in its eq 26.
    """
    eye = np.eye(n)
    pairs = _pair_directions(n)
    root3 = np.sqrt(3.0)
    xi = np.vstack([np.zeros((1, n)), root3 * eye, -root3 * eye, root3 * pairs, -root3 * pairs])
    w = np.concatenate([[1.0 - (7.0 - n) * n / 18.0], np.full(2 * n, (4.0 - n) / 18.0),
                        np.full(2 * pairs.shape[0], 1.0 / 36.0)])
    return xi, w


def unscented(n: int, alpha: float = 1.0, beta: float = 2.0, kappa: float | None = None):
    """Scaled unscented transform (Julier 2002; Wan & van der Merwe 2000): 2n + 1 points.

    ``lambda = alpha^2 (n + kappa) - n``, points ``0, +-sqrt(n + lambda) e_i``, mean weights
    ``lambda/(n+lambda), 1/(2(n+lambda))``; the covariance weight of the centre adds
    ``1 - alpha^2 + beta``. Returns ``(xi, w_mean, w_cov)``. Default ``kappa = 3 - n``.
    """
    kappa = 3.0 - n if kappa is None else kappa
    lam = alpha**2 * (n + kappa) - n
    spread = np.sqrt(n + lam)
    eye = np.eye(n)
    xi = np.vstack([np.zeros((1, n)), spread * eye, -spread * eye])
    w_mean = np.concatenate([[lam / (n + lam)], np.full(2 * n, 1.0 / (2.0 * (n + lam)))])
    w_cov = w_mean.copy()
    w_cov[0] += 1.0 - alpha**2 + beta
    return xi, w_mean, w_cov
