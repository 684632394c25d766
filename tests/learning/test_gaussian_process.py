"""GP posterior against the closed form of eqs. (25), (31), (32), and against scikit-learn."""

import math

import numpy as np
import pytest

from handle_drake.learning.gp import GaussianProcess, Hyperparameters, matern, matern32


def matern32_by_hand(a, b, length_scale, signal_variance):
    """Eq. (25) with ARD, written out for one pair of points."""
    r = math.sqrt(sum(((ai - bi) / li) ** 2 for ai, bi, li in zip(a, b, length_scale, strict=True)))
    return signal_variance * (1 + math.sqrt(3) * r) * math.exp(-math.sqrt(3) * r)


def matern52_by_hand(a, b, length_scale, signal_variance):
    """The Matérn 5/2 covariance (Rasmussen & Williams eq. 4.17) with ARD, one pair."""
    r = math.sqrt(sum(((ai - bi) / li) ** 2 for ai, bi, li in zip(a, b, length_scale, strict=True)))
    s5r = math.sqrt(5) * r
    return signal_variance * (1 + s5r + 5 * r * r / 3) * math.exp(-s5r)


def posterior_by_hand(X, y, Xs, ls, sf2, sn2, prior, kernel=matern32_by_hand):
    """Eqs. (31)-(32) with explicit matrix inverse, no shared code with the module."""
    K = np.array([[kernel(a, b, ls, sf2) for b in X] for a in X])
    Ks = np.array([[kernel(a, b, ls, sf2) for b in X] for a in Xs])
    Kss = np.array([kernel(a, a, ls, sf2) for a in Xs])
    inverse = np.linalg.inv(K + sn2 * np.eye(len(X)))
    mean = np.array([prior(p) for p in Xs]) + Ks @ inverse @ (y - np.array([prior(p) for p in X]))
    var = Kss - np.einsum("ij,jk,ik->i", Ks, inverse, Ks)
    return mean, var


X = np.array([[0.1, 0.2], [0.4, 0.9], [0.8, 0.3], [0.55, 0.5]])
Y = np.array([1.0, -0.5, 2.0, 0.7])
QUERY = np.array([[0.0, 0.0], [0.3, 0.3], [0.55, 0.5], [1.0, 1.0], [0.6, 0.45]])
HYPER = Hyperparameters(length_scale=[0.3, 0.7], signal_variance=1.7, noise_variance=0.01)


def test_matern32_matrix_matches_formula():
    K = matern32(X, QUERY, HYPER.length_scale, 1.7)
    for i, a in enumerate(X):
        for j, b in enumerate(QUERY):
            assert K[i, j] == pytest.approx(matern32_by_hand(a, b, HYPER.length_scale, 1.7), 1e-13)


def assert_posterior(gp, expected_mean, expected_var):
    """Both prediction paths (batch and one point) equal the expected posterior."""
    m, v = gp.predict(QUERY)
    np.testing.assert_allclose(m, expected_mean, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(v, expected_var, rtol=1e-7, atol=1e-9)
    predict_point = gp.point_predictor()
    for q, em, ev in zip(QUERY, expected_mean, expected_var, strict=True):
        pm, pv = predict_point(q)
        assert pm == pytest.approx(em, rel=1e-8, abs=1e-9)
        assert pv == pytest.approx(ev, rel=1e-7, abs=1e-9)


@pytest.mark.parametrize(
    "mean, prior",
    [
        ("zero", lambda p: 0.0),
        (0.4, lambda p: 0.4),
        (lambda P: P[:, 0] - P[:, 1], lambda p: p[0] - p[1]),
    ],
    ids=["zero", "number", "callable"],
)
def test_posterior_equals_closed_form(mean, prior):
    gp = GaussianProcess(mean=mean).fit(X, Y, hyperparameters=HYPER)
    assert_posterior(gp, *posterior_by_hand(X, Y, QUERY, [0.3, 0.7], 1.7, 0.01, prior))


def test_matern52_matrix_and_posterior_equal_closed_form():
    K = matern(X, QUERY, HYPER.length_scale, 1.7, nu=2.5)
    for i, a in enumerate(X):
        for j, b in enumerate(QUERY):
            assert K[i, j] == pytest.approx(matern52_by_hand(a, b, HYPER.length_scale, 1.7), 1e-13)
    gp = GaussianProcess(mean="zero", nu=2.5).fit(X, Y, hyperparameters=HYPER)
    assert_posterior(gp, *posterior_by_hand(X, Y, QUERY, [0.3, 0.7], 1.7, 0.01, lambda p: 0.0,
                                            kernel=matern52_by_hand))
    # The two kernels differ (same hyperparameters): the option is not ignored.
    assert not np.allclose(gp.predict(QUERY)[0], GaussianProcess(mean="zero").fit(
        X, Y, hyperparameters=HYPER).predict(QUERY)[0])


def test_constant_mean_is_the_sample_mean():
    gp = GaussianProcess(mean="constant").fit(X, Y, hyperparameters=HYPER)
    m, v = gp.predict(QUERY)
    em, ev = posterior_by_hand(X, Y, QUERY, [0.3, 0.7], 1.7, 0.01, lambda p: Y.mean())
    np.testing.assert_allclose(m, em, rtol=1e-8)
    np.testing.assert_allclose(v, ev, rtol=1e-7, atol=1e-12)
    # far from the data the posterior returns to the prior
    far_mean, far_var = gp.predict([[50.0, 50.0]])
    assert far_mean[0] == pytest.approx(Y.mean(), abs=1e-12)
    assert far_var[0] == pytest.approx(1.7, rel=1e-12)


def test_noise_free_gp_interpolates():
    hyper = Hyperparameters(length_scale=[0.3, 0.7], signal_variance=1.7, noise_variance=0.0)
    gp = GaussianProcess(mean="zero").fit(X, Y, hyperparameters=hyper)
    m, v = gp.predict(X)
    np.testing.assert_allclose(m, Y, atol=1e-7)
    np.testing.assert_allclose(v, 0.0, atol=1e-8)


@pytest.mark.parametrize("nu", [1.5, 2.5])
def test_fast_path_matches_sklearn_predict(nu):
    rng = np.random.default_rng(3)
    Xt = rng.random((30, 3))
    yt = np.sin(4 * Xt[:, 0]) + Xt[:, 1] ** 2 - Xt[:, 2] + 0.05 * rng.standard_normal(30)
    gp = GaussianProcess(mean="constant", seed=0, nu=nu).fit(Xt, yt)
    assert gp.sklearn_model.kernel_.k1.k2.nu == nu
    Xq = rng.random((7, 3))
    mean, var = gp.predict(Xq)
    sk_mean, sk_std = gp.sklearn_model.predict(Xq, return_std=True)
    # sklearn models (y - mean) / scale and its std includes the white noise
    np.testing.assert_allclose(mean, yt.mean() + gp.y_scale * sk_mean, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(
        var + gp.hyperparameters.noise_variance, (gp.y_scale * sk_std) ** 2, rtol=1e-5, atol=1e-9
    )


def test_marginal_likelihood_fit_recovers_noise_level():
    rng = np.random.default_rng(0)
    n, noise_std = 120, 0.1
    Xt = rng.random((n, 1))
    yt = np.sin(6 * Xt[:, 0]) + noise_std * rng.standard_normal(n)
    gp = GaussianProcess(seed=1).fit(Xt, yt)
    assert 0.5 * noise_std**2 < gp.hyperparameters.noise_variance < 2.0 * noise_std**2
    # and the posterior mean is close to the noise-free function
    grid = np.linspace(0.05, 0.95, 50)[:, None]
    np.testing.assert_allclose(
        gp.predict(grid, return_variance=False), np.sin(6 * grid[:, 0]), atol=0.08
    )


def test_fit_is_deterministic_for_a_seed():
    rng = np.random.default_rng(5)
    Xt, yt = rng.random((15, 2)), rng.standard_normal(15)
    a = GaussianProcess(seed=7).fit(Xt, yt).hyperparameters
    b = GaussianProcess(seed=7).fit(Xt, yt).hyperparameters
    np.testing.assert_array_equal(a.length_scale, b.length_scale)
    assert a.noise_variance == b.noise_variance


def test_log_marginal_likelihood_matches_formula():
    gp = GaussianProcess(mean="zero").fit(X, Y, hyperparameters=HYPER)
    C = matern32(X, X, HYPER.length_scale, 1.7) + 0.01 * np.eye(len(X))
    sign, logdet = np.linalg.slogdet(C)
    expected = (
        -0.5 * Y @ np.linalg.solve(C, Y) - 0.5 * logdet - 0.5 * len(Y) * math.log(2 * math.pi)
    )
    assert gp.log_marginal_likelihood() == pytest.approx(expected, rel=1e-7)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda gp: gp.fit(np.zeros((3, 2)), np.zeros(2)), "expected 3, got 2"),
        (lambda gp: gp.fit(np.zeros(3), np.zeros(3)), "2-D"),
        (lambda gp: gp.fit(np.zeros((0, 2)), np.zeros(0)), "0 observations"),
        (lambda gp: gp.fit([[0.0], [np.nan]], [1.0, 2.0]), "non-finite"),
        (lambda gp: gp.fit([[0.0], [1.0]], [1.0, np.inf]), "non-finite"),
        (lambda gp: gp.fit(X, Y).predict(np.zeros((2, 3))), "expected|columns"),
    ],
)
def test_bad_input_raises(call, message):
    with pytest.raises(ValueError, match=message):
        call(GaussianProcess())


def test_bad_options_and_unfitted_use():
    with pytest.raises(ValueError, match="'constant' or 'zero'"):
        GaussianProcess(mean="linear")
    with pytest.raises(ValueError, match="noise_variance_bounds"):
        GaussianProcess(noise_variance_bounds=(1.0, 0.1))
    with pytest.raises(ValueError, match="nu must be one of"):
        GaussianProcess(nu=0.5)
    with pytest.raises(ValueError, match="nu must be one of"):
        matern(X, X, [0.3, 0.7], nu=3.5)
    with pytest.raises(ValueError, match="length_scale must be positive"):
        Hyperparameters([0.1, -1.0], 1.0, 0.1)
    with pytest.raises(RuntimeError, match="not fitted"):
        GaussianProcess().predict([[0.0]])
