"""Expected improvement (eqs. 38-39) against scipy.stats.norm, and DIRECT on known maxima."""

import math

import numpy as np
import pytest
from scipy.stats import norm

from handle_drake.learning.acquisition import (
    default_xi,
    expected_improvement,
    expected_improvement_point,
    maximize_acquisition,
)


def ei_reference(mu, var, best, xi):
    sigma = math.sqrt(var)
    z = (mu - best - xi) / sigma
    return (mu - best - xi) * norm.cdf(z) + sigma * norm.pdf(z)


CASES = [
    # mu, var, best, xi
    (0.0, 1.0, 0.0, 0.0),
    (1.3, 0.25, 1.0, 0.0),
    (0.2, 0.04, 1.0, 0.1),
    (-3.0, 2.0, 0.5, 0.01),
    (5.0, 1e-6, 4.0, 0.0),
    (0.0, 1e-4, 0.3, 0.0),  # far below f_best: tiny but positive
]


@pytest.mark.parametrize("mu, var, best, xi", CASES)
def test_ei_equals_formula(mu, var, best, xi):
    expected = ei_reference(mu, var, best, xi)
    # rel 1e-8: at z = -30 both sides lose digits to the cancellation of the two terms
    assert expected_improvement(mu, var, best, xi) == pytest.approx(expected, rel=1e-8, abs=1e-300)
    assert expected_improvement_point(mu, var, best, xi) == pytest.approx(
        expected, rel=1e-8, abs=1e-300
    )


def test_ei_vectorised_matches_elementwise():
    mu = np.array([c[0] for c in CASES])
    var = np.array([c[1] for c in CASES])
    got = expected_improvement(mu, var, 0.5, 0.05)
    expected = [ei_reference(m, v, 0.5, 0.05) for m, v in zip(mu, var, strict=True)]
    np.testing.assert_allclose(got, expected, rtol=1e-10)


@pytest.mark.parametrize(
    "mu, best, xi, expected", [(2.0, 1.0, 0.25, 0.75), (1.0, 1.0, 0.0, 0.0), (0.5, 1.0, 0.1, 0.0)]
)
def test_zero_variance_is_the_plain_improvement(mu, best, xi, expected):
    assert expected_improvement(mu, 0.0, best, xi) == expected
    assert expected_improvement_point(mu, 0.0, best, xi) == expected
    # and it is the limit of the formula as the variance vanishes
    assert ei_reference(mu, 1e-16, best, xi) == pytest.approx(expected, abs=1e-7)


def test_ei_grows_with_uncertainty_and_mean():
    var = np.linspace(0.01, 4.0, 50)
    assert np.all(np.diff(expected_improvement(0.0, var, 1.0)) > 0)
    mu = np.linspace(-1.0, 3.0, 50)
    assert np.all(np.diff(expected_improvement(mu, 0.3, 1.0)) > 0)


def test_xi_reduces_ei():
    values = [expected_improvement(1.0, 0.5, 1.0, xi) for xi in (0.0, 0.1, 0.5)]
    assert values[0] > values[1] > values[2] > 0


def test_default_xi_is_report_value_on_unit_scale_and_scale_free():
    assert default_xi(2.0) == pytest.approx(0.02)  # eq. (40) when the metric has unit scale
    # scaling the metric by 10 scales sigma_f^2 by 100 and y_scale by 10: xi scales by 10
    assert default_xi(200.0, 10.0) == pytest.approx(10 * default_xi(2.0, 1.0))


def test_bad_ei_input():
    with pytest.raises(ValueError, match="variance"):
        expected_improvement(0.0, -1.0, 0.0)
    with pytest.raises(ValueError, match="xi"):
        expected_improvement(0.0, 1.0, 0.0, -0.1)
    with pytest.raises(ValueError, match="positive"):
        default_xi(0.0)


def test_direct_finds_known_maximum_in_unit_cube():
    peak = np.array([0.731, 0.204])

    def bump(u):  # two bumps, the global one at `peak`
        return math.exp(-40 * np.sum((u - peak) ** 2)) + 0.6 * math.exp(
            -40 * np.sum((u - 0.25) ** 2)
        )

    x, value = maximize_acquisition(bump, 2, maxfun=1500)
    np.testing.assert_allclose(x, peak, atol=5e-3)
    assert value == pytest.approx(bump(peak), abs=1e-3)


def test_direct_rejects_bad_sizes():
    with pytest.raises(ValueError, match="dim"):
        maximize_acquisition(lambda u: 0.0, 0)
    with pytest.raises(ValueError, match="maxfun"):
        maximize_acquisition(lambda u: 0.0, 2, maxfun=0)


@pytest.mark.parametrize("dim, maxfun", [(1, 50), (2, 300), (6, 1000)])
def test_direct_respects_its_evaluation_budget(dim, maxfun):
    calls = []

    def acquisition(u):
        calls.append(u)
        return -float(np.sum((u - 0.3) ** 2))

    x, value = maximize_acquisition(acquisition, dim, maxfun=maxfun)
    assert len(calls) == maxfun
    assert value == max(acquisition(u) for u in calls[:maxfun])
    assert np.all(np.abs(x - 0.3) < 0.2)
