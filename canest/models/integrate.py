"""Explicit integration of vectorized model derivatives."""
from __future__ import annotations


def rk4(derivatives, X, u, dt: float):
    """One classic fourth-order Runge-Kutta step of ``dX/dt = derivatives(X, u)`` with ``u`` held (zero-order hold)."""
    k1 = derivatives(X, u)
    k2 = derivatives(X + 0.5 * dt * k1, u)
    k3 = derivatives(X + 0.5 * dt * k2, u)
    k4 = derivatives(X + dt * k3, u)
    return X + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
