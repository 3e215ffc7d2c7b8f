"""erfcx without scipy (canest/filters/special.py) against scipy's, and the truncated Gaussian built on it."""
import numpy as np
import pytest
from scipy import special, stats

from canest.filters.parameters import truncated
from canest.filters.special import OVERFLOW, TAIL, erfcx


def test_erfcx_matches_scipy_over_a_wide_range():
    x = np.concatenate([np.linspace(-5.0, 40.0, 200001), np.geomspace(TAIL, 1e300, 2001),
                        np.geomspace(1e-300, 1e-3, 301), -np.geomspace(1e-300, 1e-3, 301), [0.0]])
    np.testing.assert_allclose(erfcx(x), special.erfcx(x), rtol=1e-14, atol=0)


def test_erfcx_for_large_negative_arguments_within_scipys_rounding_of_x_squared():
    """scipy forms exp(x*x) with x*x rounded (relative error up to x^2 eps, 6e-14 at x = -26.6; against 40-digit
    mpmath it is off by that much, canest's split x^2 by 4e-16): the tolerance is that rounding."""
    x = np.linspace(-26.6, -5.0, 20001)
    np.testing.assert_allclose(erfcx(x), special.erfcx(x), rtol=1e-14 + 2.0 * 26.6**2 * np.finfo(float).eps, atol=0)


def test_erfcx_at_the_ends():
    x = np.array([-np.inf, -1e10, OVERFLOW - 1.0, np.inf, np.nan])
    with np.errstate(all="raise"):
        values = erfcx(x)
    np.testing.assert_array_equal(values, special.erfcx(x))
    assert erfcx(np.array([])).shape == (0,)


@pytest.mark.parametrize("mean,std,bound,side", [(0.05, 0.1, 0.1, 1.0), (-0.9, 0.2, 0.1, 1.0), (1.5, 0.05, 1.3, -1.0),
                                                 (4.3, 0.3, 1.3, -1.0)])
def test_truncated_mean_and_std_match_scipys_truncated_normal(mean, std, bound, side):
    """Up to 10 std outside the bound (the variance factor 1 + a l - l^2 cancels further out: 2e-6 at 60 std)."""
    low, high = (bound, np.inf) if side > 0 else (-np.inf, bound)
    reference = stats.truncnorm((low - mean) / std, (high - mean) / std, loc=mean, scale=std)
    new_mean, new_std = truncated(np.array([mean]), np.array([std]), bound, side)
    np.testing.assert_allclose(new_mean, reference.mean(), rtol=1e-12)
    np.testing.assert_allclose(new_std, reference.std(), rtol=1e-9)
