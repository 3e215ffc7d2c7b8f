"""The cubature rule integrates every Gaussian moment up to its degree exactly."""
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


@pytest.mark.parametrize("n", range(1, 10))
def test_third_degree_rule_integrates_all_monomials_up_to_degree_3(n):
    xi, w = rules.third_degree_cubature(n)
    assert xi.shape == (2 * n, n)
    assert w.sum() == pytest.approx(1.0)
    for powers in monomials(n, 3):
        approx = w @ np.prod(xi ** powers, axis=1)
        assert approx == pytest.approx(gaussian_moment(powers), abs=1e-12), powers


def test_third_degree_rule_is_not_exact_for_fourth_moments():
    # The test above could not fail if every rule were trivially exact: the rule misses E[x^4] = 3 for n = 2.
    xi, w = rules.third_degree_cubature(2)
    assert w @ xi[:, 0] ** 4 == pytest.approx(2.0)
