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
