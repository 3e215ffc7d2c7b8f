"""Every filter: linear-Gaussian equivalence with the Kalman filter, SPD covariance, the adaptive
and robust mechanisms doing what their papers claim on the data they were designed for."""
import numpy as np
import pytest

from canest.filters import FACTORIZATIONS, FILTERS, Measurement, Transition
from canest.filters.sqrt import tria

# Options that switch adaptation and robustness off, so the filter must equal the Kalman filter.
REDUCE_TO_KF = {"lmrwekf": {"window": 10_000}, "svd-fckf": {"window": 10_000}, "mcsckf": {"kernel_width": 1e9,
                                                                                          "min_kernel_width": 1e9}}


def kalman_step(x, P, F, Q, H, R, z):
    x = F @ x
    P = F @ P @ F.T + Q
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    return x + K @ (z - H @ x), (np.eye(len(x)) - K @ H) @ P


def linear_models(F, H):
    return (Transition(lambda X, u, dt: X @ F.T, lambda x, u, dt: F),
            Measurement(lambda X, u: X @ H.T, lambda x, u: H, channels=tuple(range(H.shape[0])),
                        parameter_jacobian=lambda x, u: np.zeros(H.shape[0])))


@pytest.mark.parametrize("name", sorted(set(FILTERS) - {"dckf", "jckf"}))  # parameter filters: test_dici_dual.py
@pytest.mark.parametrize("factorization", FACTORIZATIONS)
def test_reproduces_linear_kalman_filter(name, factorization):
    rng = np.random.default_rng(0)
    n, m = 4, 2
    F = np.eye(n) + 0.05 * rng.standard_normal((n, n))
    H = rng.standard_normal((m, n))
    Q = np.diag(rng.uniform(0.01, 0.1, n))
    R = np.diag(rng.uniform(0.1, 0.5, m))
    transition, measurement = linear_models(F, H)
    x_ref, P_ref = np.zeros(n), np.eye(n)
    filt = FILTERS[name](x_ref, P_ref, factorization=factorization, **REDUCE_TO_KF.get(name, {}))
    u = np.array([0.0, 0.0, 1.0])
    for _ in range(50):
        z = rng.standard_normal(m)
        x_ref, P_ref = kalman_step(x_ref, P_ref, F, Q, H, R, z)
        filt.predict(transition, u, 0.01, Q)
        filt.update(z, measurement, u, R)
        np.testing.assert_allclose(filt.x, x_ref, atol=1e-9)
        np.testing.assert_allclose(filt.P, P_ref, atol=1e-9)
    assert filt.repairs == 0


def nonlinear_models(n):
    def f(X, u, dt):
        out = 0.995 * X
        out[:, 0] += dt * np.sin(X[:, 1]) * X[:, -1]
        out[:, 1:] += dt * np.tanh(X[:, :-1])
        return out

    def h(X, u):
        return np.column_stack([X[:, 0] ** 2, np.arctan(X[:, 1]), X[:, -1] * X[:, 2]])

    return Transition(f), Measurement(h, channels=(0, 1, 2))


@pytest.mark.parametrize("name", ["ckf", "sckf", "mcsckf", "fckf", "svd-fckf", "gfckf", "ukf"])
@pytest.mark.parametrize("n", [3, 7])
def test_covariance_stays_spd_over_a_long_run_or_is_repaired_and_counted(name, n):
    """n = 7 gives the fifth-degree rules and the UKF negative weights; measurements are nearly exact."""
    rng = np.random.default_rng(1)
    transition, measurement = nonlinear_models(n)
    filt = FILTERS[name](np.linspace(0.5, -0.5, n), np.eye(n))
    truth = np.linspace(0.4, -0.4, n)
    u = np.array([0.0, 0.0, 1.0])
    for _ in range(2000):
        truth = transition.f(truth[None, :], u, 0.01)[0] + 1e-4 * rng.standard_normal(n)
        filt.predict(transition, u, 0.01, 1e-8 * np.eye(n))
        filt.update(measurement.h(truth[None, :], u)[0] + 1e-5 * rng.standard_normal(3), measurement, u,
                    1e-10 * np.eye(3))
        P = filt.P
        assert np.array_equal(P, P.T)
        assert np.all(np.isfinite(filt.x))
    assert np.linalg.eigvalsh(filt.P).min() > 0.0
    if filt.repairs:
        print(f"{name} n={n}: {filt.repairs} covariance repairs")


def test_repair_rule_clips_negative_eigenvalues_and_counts():
    filt = FILTERS["ckf"](np.zeros(2), np.eye(2))
    filt.P = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3 and -1
    filt.predict(Transition(lambda X, u, dt: X), None, 0.01, 1e-6 * np.eye(2))
    assert filt.repairs == 1
    assert np.linalg.eigvalsh(filt.P).min() > 0.0


def test_tria_is_a_triangular_square_root():
    A = np.random.default_rng(2).standard_normal((3, 7))
    T = tria(A)
    np.testing.assert_allclose(T @ T.T, A @ A.T, atol=1e-12)
    assert np.allclose(T, np.tril(T)) and np.all(np.diag(T) > 0)


def run_scalar_random_walk(name, true_r, configured_r, steps=3000, outliers=None, seed=3, **options):
    """x_{k+1} = x_k + w, z = x + v: returns (filter, errors)."""
    rng = np.random.default_rng(seed)
    F, H = np.eye(1), np.eye(1)
    transition, measurement = linear_models(F, H)
    filt = FILTERS[name](np.zeros(1), np.eye(1), **options)
    x, errors, u = 0.0, [], np.array([0.0, 0.0, 1.0])
    for k in range(steps):
        x += 0.01 * rng.standard_normal()
        noise = np.sqrt(true_r) * rng.standard_normal()
        if outliers is not None and rng.random() < outliers:
            noise = 50.0 * np.sqrt(true_r) * rng.standard_t(2)
        filt.predict(transition, u, 0.01, np.array([[1e-4]]))
        filt.update(np.array([x + noise]), measurement, u, np.array([[configured_r]]))
        errors.append(filt.x[0] - x)
    return filt, np.array(errors[200:])


@pytest.mark.parametrize("name, options", [("lmrwekf", {}), ("svd-fckf", {"adapt_q": False})])
def test_adaptive_filters_learn_a_wrong_r(name, options):
    """Configured R is 25x too large: the windowed estimate finds the true R and the error shrinks."""
    adaptive, errors = run_scalar_random_walk(name, true_r=0.04, configured_r=1.0, window=50, **options)
    assert 0.01 < adaptive.R_estimate[0, 0] < 0.08
    baseline = "ekf" if name == "lmrwekf" else "fckf"
    _, baseline_errors = run_scalar_random_walk(baseline, true_r=0.04, configured_r=1.0)
    assert np.sqrt(np.mean(errors**2)) < 0.8 * np.sqrt(np.mean(baseline_errors**2))


@pytest.mark.parametrize("name, options", [("lmrwekf", {}), ("svd-fckf", {"adapt_q": False})])
def test_adaptive_filters_publish_a_covariance_with_at_least_the_configured_noise(name, options):
    """The gain uses the learned R (25x below the configured one); the published covariance assumes the
    configured R, the paper's P and the estimates stay as they were (cov_floor 0 publishes the paper's P)."""
    adaptive, errors = run_scalar_random_walk(name, true_r=0.04, configured_r=1.0, window=50, **options)
    paper, paper_errors = run_scalar_random_walk(name, true_r=0.04, configured_r=1.0, window=50, cov_floor=0.0,
                                                 **options)
    np.testing.assert_array_equal(errors, paper_errors)
    assert adaptive.R_estimate[0, 0] < 0.08
    assert adaptive.covariance[0, 0] > 3.0 * adaptive.P[0, 0]
    assert paper.covariance[0, 0] == pytest.approx(paper.P[0, 0])
    with pytest.raises(ValueError, match="cov_floor"):
        FILTERS[name](np.zeros(1), np.eye(1), cov_floor=-1.0)


@pytest.mark.parametrize("name, options", [("lmrwekf", {}), ("svd-fckf", {"adapt_q": False})])
def test_adaptive_filters_say_which_noise_their_published_covariance_took(name, options):
    """A sensor 2.5x louder than configured (a vibrating gyro): the published covariance took the learned R, which the
    estimator's yaw-rate std must not count a second time (``Estimator._gyro_noise``); a quieter one: the configured
    R. A filter that does not learn R took the configured one."""
    loud, _ = run_scalar_random_walk(name, true_r=0.25, configured_r=0.04, window=50, **options)
    assert loud.noise_taken(0, 0.04) == pytest.approx(loud.R_estimate[0, 0])
    assert 0.15 < loud.noise_taken(0, 0.04) < 0.4  # the learned R, below its ceiling (10x the configured)
    quiet, _ = run_scalar_random_walk(name, true_r=0.04, configured_r=1.0, window=50, **options)
    assert quiet.noise_taken(0, 1.0) == 1.0
    assert FILTERS["ckf"](np.zeros(1), np.eye(1)).noise_taken(0, 0.04) == 0.04


def test_svd_fckf_adaptive_q_of_eq_29_is_indeterminate():
    """Q = K E K^T with E = P- + R is exactly P- - P+ for every P-: it confirms whatever P- the filter
    has, so it cannot pull a mistuned filter back. Measured on the random walk above: RMSE 0.117 with
    eq 29 against 0.066 for fckf and 0.045 with R adaptation alone."""
    R = 0.04
    for P_prior in (1e-4, 1e-2, 1.0):
        K = P_prior / (P_prior + R)
        assert K * (P_prior + R) * K == pytest.approx(P_prior - P_prior * R / (P_prior + R))
    _, with_q = run_scalar_random_walk("svd-fckf", true_r=0.04, configured_r=1.0, window=50)
    _, plain = run_scalar_random_walk("fckf", true_r=0.04, configured_r=1.0)
    assert np.sqrt(np.mean(with_q**2)) > np.sqrt(np.mean(plain**2))


def test_lmrwekf_weights_are_the_papers_dirichlet_weights():
    filt = FILTERS["lmrwekf"](np.zeros(1), np.eye(1), window=5, forgetting=0.95)
    w = filt.windows.weights
    assert w.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(w[::-1], (1 - 0.95) / (1 - 0.95**5) * 0.95 ** np.arange(5))
    with pytest.raises(ValueError, match="0.95, 0.995"):
        FILTERS["lmrwekf"](np.zeros(1), np.eye(1), forgetting=0.9)


def test_maximum_correntropy_resists_heavy_tailed_outliers():
    _, robust = run_scalar_random_walk("mcsckf", true_r=0.01, configured_r=0.01, outliers=0.02)
    _, plain = run_scalar_random_walk("sckf", true_r=0.01, configured_r=0.01, outliers=0.02)
    assert np.sqrt(np.mean(robust**2)) < 0.5 * np.sqrt(np.mean(plain**2))


def test_maximum_correntropy_equals_sckf_without_outliers():
    _, robust = run_scalar_random_walk("mcsckf", true_r=0.01, configured_r=0.01)
    _, plain = run_scalar_random_walk("sckf", true_r=0.01, configured_r=0.01)
    assert np.sqrt(np.mean(robust**2)) < 1.15 * np.sqrt(np.mean(plain**2))


def test_dual_ekf_identifies_a_parameter():
    """z = theta * x with x known to move: the parameter filter converges to the true theta."""
    rng = np.random.default_rng(4)
    transition = Transition(lambda X, u, dt: X * 0 + np.sin(u[0]), lambda x, u, dt: np.zeros((1, 1)))
    measurement = Measurement(lambda X, u: X * u[2], lambda x, u: np.array([[u[2]]]), channels=(0,),
                              parameter_jacobian=lambda x, u: x.copy())
    filt = FILTERS["dekf"](np.zeros(1), np.eye(1), theta_std=0.3)
    for k in range(2000):
        u = np.array([0.01 * k, 0.0, 1.0])
        x = np.sin(u[0])
        filt.predict(transition, u, 0.01, np.array([[1e-6]]))
        filt.update(np.array([0.8 * x + 0.01 * rng.standard_normal()]), measurement, u, np.array([[1e-4]]))
    assert filt.theta == pytest.approx(0.8, abs=0.02)
