"""CI and ICI (DICI-GFCKF paper eqs 15-20): formulas, weights and consistency."""
import numpy as np
import pytest

from canest.filters.fusion import fuse, fuse_many, fuse_two


def random_spd(rng, n, scale=1.0):
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T + 0.1 * np.eye(n))


def common_information_sources(rng, n_sources, dim, samples):
    """Local estimates sharing a common prior plus private measurements (the correlation ICI is built for).

    Each local estimate fuses the same prior (information Pc^-1) with its own
    measurement (information A_j^-1): errors are correlated through the prior.
    Returns the covariances the locals report and error samples (samples, sources, dim).
    """
    Pc = random_spd(rng, dim)
    As = [random_spd(rng, dim, 0.5 + j) for j in range(n_sources)]
    Ps = [np.linalg.inv(np.linalg.inv(Pc) + np.linalg.inv(A)) for A in As]
    prior_error = rng.multivariate_normal(np.zeros(dim), Pc, size=samples)
    errors = np.empty((samples, n_sources, dim))
    for j, (A, P) in enumerate(zip(As, Ps)):
        measurement_error = rng.multivariate_normal(np.zeros(dim), A, size=samples)
        errors[:, j] = (P @ (np.linalg.solve(Pc, prior_error.T) + np.linalg.solve(A, measurement_error.T))).T
    return Ps, errors


def fused_errors(method, Ps, errors, weights):
    """The fused covariance and the fused estimate's error for every sample (linear fusion, truth 0).

    Each gain L_j of ``x = sum L_j x_j`` is recovered by fusing unit vectors.
    """
    n, dim = errors.shape[1], errors.shape[2]
    gains = []
    for j in range(n):
        columns = []
        for i in range(dim):
            xs = [np.zeros(dim) for _ in range(n)]
            xs[j][i] = 1.0
            columns.append(fuse(method, xs, Ps, weights).x)
        gains.append(np.column_stack(columns))
    P = fuse(method, [np.zeros(dim)] * n, Ps, weights).P
    return P, np.einsum("jab,sjb->sa", np.array(gains), errors)


@pytest.mark.parametrize("method", ["ici", "ci"])
def test_two_source_closed_form_equals_direct_formulas(method):
    rng = np.random.default_rng(1)
    P1, P2 = random_spd(rng, 5), random_spd(rng, 5, 3.0)
    x1, x2 = rng.standard_normal(5), rng.standard_normal(5)
    for w in (0.0, 0.3, 0.77, 1.0):
        fast = fuse_two(method, x1, P1, x2, P2, w)
        direct = fuse_many(method, [x1, x2], [P1, P2], [w, 1 - w])
        np.testing.assert_allclose(fast.P, direct.P, rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(fast.x, direct.x, rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("method", ["ici", "ci"])
def test_optimal_weight_minimizes_the_trace(method):
    rng = np.random.default_rng(2)
    P1, P2 = random_spd(rng, 7), random_spd(rng, 7, 2.0)
    best = fuse(method, [np.zeros(7)] * 2, [P1, P2])
    dense = [np.trace(fuse_two(method, np.zeros(7), P1, np.zeros(7), P2, w).P) for w in np.linspace(0, 1, 2001)]
    assert np.trace(best.P) <= min(dense) * (1 + 1e-6)
    assert abs(best.weights.sum() - 1.0) < 1e-12


def test_ici_is_less_conservative_than_ci_and_never_below_independent_fusion():
    rng = np.random.default_rng(3)
    P1, P2 = random_spd(rng, 4), random_spd(rng, 4)
    ici = fuse("ici", [np.zeros(4)] * 2, [P1, P2])
    ci = fuse("ci", [np.zeros(4)] * 2, [P1, P2])
    naive = np.linalg.inv(np.linalg.inv(P1) + np.linalg.inv(P2))
    assert np.trace(ici.P) < np.trace(ci.P)
    assert np.linalg.eigvalsh(ici.P - naive).min() > -1e-12  # ICI never claims more than independence would


def test_identical_estimates_fuse_to_themselves():
    rng = np.random.default_rng(4)
    P = random_spd(rng, 3)
    x = rng.standard_normal(3)
    for method in ("ici", "ci"):
        fused = fuse(method, [x, x, x], [P, P, P])
        np.testing.assert_allclose(fused.P, P, rtol=1e-6)
        np.testing.assert_allclose(fused.x, x, rtol=1e-6, atol=1e-9)


def test_paper_eq19_without_the_n_minus_1_factor_is_overconfident_for_three_sources():
    P = np.diag([1.0, 2.0])
    gamma_inv = np.linalg.inv(P)  # equal weights, identical sources
    literal = np.linalg.inv(3 * np.linalg.inv(P) - gamma_inv)
    np.testing.assert_allclose(literal, P / 2)  # the error covariance of identical estimates is P, not P/2
    np.testing.assert_allclose(fuse("ici", [np.zeros(2)] * 3, [P] * 3, [1 / 3] * 3).P, P)


@pytest.mark.parametrize("method,n_sources", [("ici", 2), ("ci", 2), ("ici", 3), ("ci", 3)])
def test_fused_covariance_is_consistent_in_monte_carlo(method, n_sources):
    rng = np.random.default_rng(10 + n_sources)
    Ps, errors = common_information_sources(rng, n_sources, 3, 20000)
    weights = fuse(method, [np.zeros(3)] * n_sources, Ps).weights
    P, fused = fused_errors(method, Ps, errors, weights)
    empirical = np.cov(fused.T)
    # consistent: the claimed covariance bounds the actual error covariance (5 % sampling margin)
    assert np.linalg.eigvalsh(1.05 * P - empirical).min() > 0
    # while naive independent fusion of the same correlated sources is overconfident
    naive = np.linalg.inv(sum(np.linalg.inv(Pj) for Pj in Ps))
    information_sum = sum(np.linalg.solve(Pj, errors[:, j].T) for j, Pj in enumerate(Ps))
    naive_errors = (naive @ information_sum).T
    assert np.linalg.eigvalsh(1.05 * naive - np.cov(naive_errors.T)).min() < 0


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="fusion must be one of"):
        fuse("mean", [np.zeros(1)] * 2, [np.eye(1)] * 2)
