"""Filters, chosen by name in the config (``estimator.filter``).

Each filter class takes ``(x0, P0, factorization=...)`` and offers
``predict(f, u, dt, Q)`` and ``update(z, h, u, R)``. Adding a filter is adding
a class and one line here.
"""
from canest.filters.sigma import FACTORIZATIONS, CubatureKalmanFilter

FILTERS = {
    "ckf": CubatureKalmanFilter,
}

__all__ = ["FILTERS", "FACTORIZATIONS"]
