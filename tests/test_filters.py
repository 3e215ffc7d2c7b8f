"""Cubature filter: linear-Gaussian equivalence with the Kalman filter, SPD covariance."""
import numpy as np
import pytest

from canest.filters import FACTORIZATIONS, FILTERS


def kalman_step(x, P, F, Q, H, R, z):
    x = F @ x
    P = F @ P @ F.T + Q
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    return x + K @ (z - H @ x), (np.eye(len(x)) - K @ H) @ P


@pytest.mark.parametrize("name", sorted(FILTERS))
@pytest.mark.parametrize("factorization", FACTORIZATIONS)
def test_reproduces_linear_kalman_filter(name, factorization):
    rng = np.random.default_rng(0)
    n, m = 4, 2
    F = np.eye(n) + 0.05 * rng.standard_normal((n, n))
    H = rng.standard_normal((m, n))
    Q = np.diag(rng.uniform(0.01, 0.1, n))
    R = np.diag(rng.uniform(0.1, 0.5, m))
    x_ref, P_ref = np.zeros(n), np.eye(n)
    filt = FILTERS[name](x_ref, P_ref, factorization=factorization)
    for _ in range(50):
        z = rng.standard_normal(m)
        x_ref, P_ref = kalman_step(x_ref, P_ref, F, Q, H, R, z)
        filt.predict(lambda X, u, dt: X @ F.T, None, 0.01, Q)
        filt.update(z, lambda X, u: X @ H.T, None, R)
        np.testing.assert_allclose(filt.x, x_ref, atol=1e-10)
        np.testing.assert_allclose(filt.P, P_ref, atol=1e-10)


@pytest.mark.parametrize("factorization", FACTORIZATIONS)
def test_covariance_stays_symmetric_positive_definite_with_precise_measurements(factorization):
    """Nearly noiseless measurements of a nonlinear system are where P - K S K^T loses definiteness."""
    rng = np.random.default_rng(1)
    filt = FILTERS["ckf"](np.array([1.0, 0.5, -0.3]), np.eye(3), factorization=factorization)

    def f(X, u, dt):
        return np.column_stack([X[:, 0] + dt * np.sin(X[:, 1]), X[:, 1] + dt * X[:, 2] * X[:, 0], 0.99 * X[:, 2]])

    def h(X, u):
        return np.column_stack([X[:, 0] ** 2, np.arctan(X[:, 1])])

    for _ in range(5000):
        filt.predict(f, None, 0.01, 1e-9 * np.eye(3))
        filt.update(np.array([1.0, 0.4]) + 1e-6 * rng.standard_normal(2), h, None, 1e-10 * np.eye(2))
        assert np.array_equal(filt.P, filt.P.T)
        assert np.linalg.eigvalsh(filt.P).min() > 0.0
    assert np.all(np.isfinite(filt.x))


def test_repairs_a_covariance_that_is_not_positive_definite():
    filt = FILTERS["ckf"](np.zeros(2), np.eye(2))
    filt.P = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3 and -1
    filt.predict(lambda X, u, dt: X, None, 0.01, 1e-6 * np.eye(2))
    assert filt.repairs == 1
    assert np.linalg.eigvalsh(filt.P).min() > 0.0
