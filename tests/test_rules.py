"""Every point rule integrates every Gaussian moment up to its degree exactly (n = 1..9)."""
import itertools

import numpy as np
import pytest

from canest.filters import rules


def gaussian_moment(powers) -> float:
    """E[prod x_i^p_i] for x ~ N(0, I): product of (p-1)!! for even p, 0 for odd."""
    result = 1.0
    for p in powers:
        if p % 2:
            return 0.0
        result *= np.prod(np.arange(p - 1, 0, -2)) if p else 1.0
    return result


def monomials(n, degree):
    for total in range(degree + 1):
        for combo in itertools.combinations_with_replacement(range(n), total):
            yield np.bincount(np.array(combo, dtype=int), minlength=n)


RULES = {
    "third_degree_cubature": (rules.third_degree_cubature, 3, lambda n: 2 * n),
    "fifth_degree_cubature": (rules.fifth_degree_cubature, 5, lambda n: 2 * n * n + 1),
    "generalized_fifth_degree": (rules.generalized_fifth_degree, 5, lambda n: 2 * n * n + 1),
    "unscented": (lambda n: rules.unscented(n)[:2], 3, lambda n: 2 * n + 1),
}


@pytest.mark.parametrize("name", RULES)
@pytest.mark.parametrize("n", range(1, 10))
def test_rule_integrates_all_monomials_up_to_its_degree(name, n):
    make, degree, count = RULES[name]
    xi, w = make(n)
    assert xi.shape == (count(n), n)
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    values = np.prod(xi[:, None, :] ** np.array(list(monomials(n, degree)))[None, :, :], axis=2)
    exact = np.array([gaussian_moment(p) for p in monomials(n, degree)])
    np.testing.assert_allclose(w @ values, exact, atol=1e-10)


@pytest.mark.parametrize("name, n, powers", [("third_degree_cubature", 2, (4, 0)),
                                             ("fifth_degree_cubature", 3, (6, 0, 0)),
                                             ("generalized_fifth_degree", 3, (2, 2, 2))])
def test_rule_is_not_exact_beyond_its_degree(name, n, powers):
    # Guards the test above against a moment function that every rule would pass trivially.
    xi, w = RULES[name][0](n)
    assert w @ np.prod(xi ** np.array(powers), axis=1) != pytest.approx(gaussian_moment(powers))


def test_negative_weights_where_the_papers_say():
    assert rules.fifth_degree_cubature(5)[1].min() < 0  # (4 - n) / (2 (n+2)^2)
    assert rules.generalized_fifth_degree(7)[1].min() < 0  # (4 - n) / 18
    assert rules.fifth_degree_cubature(4)[1].min() >= 0
