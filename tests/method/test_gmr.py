"""Tests of workbench.method.gmr: GMR (eqs. (24)-(27) of the method paper) against independent references."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import multivariate_normal

from workbench.errors import ModelError
from workbench.method.gmr import ConditionalGMM, GaussianMixture, GMRModel, GMRResult, gmr


def random_gmm(rng: np.random.Generator, G: int, D: int, jitter: float = 0.2):
    weights = rng.dirichlet(np.ones(G))
    means = rng.normal(scale=2.0, size=(G, D))
    A = rng.normal(size=(G, D, D))
    covs = A @ np.swapaxes(A, -1, -2) / D + jitter * np.eye(D)
    return weights, means, covs


def reference_gmr(weights, means, covs, x, in_idx, out_idx):
    """Eqs. (24)-(27) written out per point and per component, with scipy's multivariate normal."""
    in_idx, out_idx = list(in_idx), list(out_idx)
    G = len(weights)
    mus, Sigmas = [], []
    for xk in x:
        numer, mu_c, S_c = [], [], []
        for i in range(G):
            mu_I, mu_O = means[i][in_idx], means[i][out_idx]
            S_I = covs[i][np.ix_(in_idx, in_idx)]
            S_OI = covs[i][np.ix_(out_idx, in_idx)]
            S_O = covs[i][np.ix_(out_idx, out_idx)]
            numer.append(weights[i] * multivariate_normal(mu_I, S_I).pdf(xk))
            mu_c.append(mu_O + S_OI @ np.linalg.inv(S_I) @ (xk - mu_I))
            S_c.append(S_O - S_OI @ np.linalg.inv(S_I) @ S_OI.T)
        h = np.array(numer) / np.sum(numer)
        mu = sum(h[i] * mu_c[i] for i in range(G))
        Sigma = sum(h[i] * (S_c[i] + np.outer(mu_c[i], mu_c[i])) for i in range(G)) - np.outer(mu, mu)
        mus.append(mu)
        Sigmas.append(Sigma)
    return np.array(mus), np.array(Sigmas)


def test_matches_plain_loop_over_eqs_24_27():
    rng = np.random.default_rng(0)
    G, d, m = 4, 4, 2
    w, mu, S = random_gmm(rng, G, d + m)
    x = rng.normal(scale=2.0, size=(40, d))
    in_idx, out_idx = [0, 2, 4, 5], [1, 3]  # interleaved on purpose
    mu_ref, S_ref = reference_gmr(w, mu, S, x, in_idx, out_idx)
    mu_hat, S_hat = gmr(w, mu, S, x, in_idx, out_idx)
    err_mu = np.abs(mu_hat - mu_ref).max()
    err_S = np.abs(S_hat - S_ref).max()
    print(f"GMR vs per-point loop: max |mu| err {err_mu:.2e}, max |Sigma| err {err_S:.2e}")
    assert mu_hat.shape == (40, m) and S_hat.shape == (40, m, m)
    assert err_mu <= 1e-10 and err_S <= 1e-10


def test_matches_gmr_package():
    from gmr import GMM

    rng = np.random.default_rng(1)
    G, d, m = 5, 6, 2
    w, mu, S = random_gmm(rng, G, d + m)
    in_idx = np.arange(d)
    x = rng.normal(scale=2.0, size=(60, d))
    model = ConditionalGMM(w, mu, S, in_idx, np.arange(d, d + m))
    mu_hat, S_hat = model.predict(x)
    ref = GMM(n_components=G, priors=w, means=mu, covariances=S)
    err_mu = err_S = 0.0
    for k in range(len(x)):
        mvn = ref.condition(in_idx, x[k]).to_mvn()
        err_mu = max(err_mu, np.abs(mvn.mean - mu_hat[k]).max())
        err_S = max(err_S, np.abs(mvn.covariance - S_hat[k]).max())
    err_pred = np.abs(ref.predict(in_idx, x) - model.predict_mean(x)).max()
    print(f"GMR vs gmr package: mean {err_mu:.2e}, covariance {err_S:.2e}, batched predict {err_pred:.2e}")
    assert err_mu <= 1e-9 and err_S <= 1e-9 and err_pred <= 1e-9


def ill_conditioned_gmm(rng: np.random.Generator, G: int = 4, d: int = 12, m: int = 2):
    """14-D covariances: input blocks with eigenvalues 1e-6 .. 1e4, outputs almost a linear function of the
    inputs (residual variance 1e-10), so the Schur complement of eq. (25) suffers heavy cancellation."""
    covs = []
    for _ in range(G):
        Q, _ = np.linalg.qr(rng.normal(size=(d, d)))
        C = (Q * np.logspace(-6, 4, d)) @ Q.T
        A = rng.normal(size=(m, d))
        S = np.block([[C, C @ A.T], [A @ C, A @ C @ A.T + 1e-10 * np.eye(m)]])
        covs.append(0.5 * (S + S.T))
    return rng.dirichlet(np.ones(G)), rng.normal(scale=10.0, size=(G, d + m)), np.array(covs)


def test_ill_conditioned_14d_covariances_are_symmetric_psd():
    rng = np.random.default_rng(2)
    w, mu, S = ill_conditioned_gmm(rng)
    in_idx, out_idx = np.arange(12), np.array([12, 13])
    print(f"condition numbers of the full covariances: {np.linalg.cond(S).min():.1e} .. {np.linalg.cond(S).max():.1e}")
    # How bad the textbook formula is here: Sigma^O - Sigma^OI inv(Sigma^I) Sigma^IO, eigenvalues.
    naive = [S[i][np.ix_(out_idx, out_idx)] - S[i][np.ix_(out_idx, in_idx)] @ np.linalg.inv(
        S[i][np.ix_(in_idx, in_idx)]) @ S[i][np.ix_(in_idx, out_idx)] for i in range(4)]
    print(f"textbook Schur complements: min eigenvalue {min(np.linalg.eigvals(c).real.min() for c in naive):.2e}")
    model = ConditionalGMM(w, mu, S, in_idx, out_idx)
    x = mu[rng.integers(0, 4, size=500), :12] + rng.normal(scale=3.0, size=(500, 12))
    res = model.predict_components(x)
    assert np.all(np.isfinite(res.mean)) and np.all(np.isfinite(res.covariance))
    assert np.array_equal(res.covariance, np.swapaxes(res.covariance, -1, -2))
    lam = np.linalg.eigvalsh(res.covariance)
    lam_c = np.linalg.eigvalsh(res.component_covariances)
    scale = np.abs(res.covariance).max()
    print(f"ill-conditioned 14-D: min eigenvalue of merged Sigma {lam.min():.2e} (scale {scale:.2e}), "
          f"of component Sigma^i {lam_c.min():.2e}")
    assert lam.min() >= -1e-12 * scale
    assert lam_c.min() >= 0.0
    np.testing.assert_allclose(res.activations.sum(axis=1), 1.0, rtol=0, atol=1e-12)


def test_batch_equals_per_point_and_single_point_input():
    rng = np.random.default_rng(3)
    w, mu, S = random_gmm(rng, 5, 8)
    model = GMRModel(w, mu, S, range(6), range(6, 8))
    x = rng.normal(scale=2.0, size=(25, 6))
    mu_b, S_b = model.predict(x)
    mu_p = np.concatenate([model.predict(x[k])[0] for k in range(len(x))])
    S_p = np.concatenate([model.predict(x[k : k + 1])[1] for k in range(len(x))])
    dev = max(np.abs(mu_b - mu_p).max(), np.abs(S_b - S_p).max())
    print(f"batch vs per-point max deviation {dev:.2e}")
    np.testing.assert_allclose(mu_b, mu_p, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(S_b, S_p, rtol=1e-12, atol=1e-13)
    one_mu, one_S = model.predict(x[0])
    assert one_mu.shape == (1, 2) and one_S.shape == (1, 2, 2)
    assert model.predict_mean(x[0]).shape == (1, 2)
    np.testing.assert_allclose(model.predict_mean(x), mu_b, rtol=1e-12, atol=1e-13)


def test_far_away_query_is_finite():
    rng = np.random.default_rng(4)
    w, mu, S = random_gmm(rng, 4, 5, jitter=0.01)
    S = S * 0.01
    in_idx, out_idx = [0, 1, 2], [3, 4]
    x = mu[:, in_idx].mean(axis=0) + 300.0
    linear = [w[i] * multivariate_normal(mu[i, in_idx], S[i][np.ix_(in_idx, in_idx)]).pdf(x) for i in range(4)]
    print(f"linear-space activation numerators at the far query: {linear}")
    assert sum(linear) == 0.0  # the naive formula would divide 0 by 0
    res = gmr(w, mu, S, x, in_idx, out_idx, return_components=True)
    assert isinstance(res, GMRResult)
    assert np.all(np.isfinite(res.mean)) and np.all(np.isfinite(res.covariance))
    np.testing.assert_allclose(res.activations.sum(), 1.0, atol=1e-12)
    # The winner is the component with the largest log-numerator (computed independently with logpdf).
    log_num = [np.log(w[i]) + multivariate_normal(mu[i, in_idx], S[i][np.ix_(in_idx, in_idx)]).logpdf(x)
               for i in range(4)]
    assert int(np.argmax(res.activations[0])) == int(np.argmax(log_num))


def test_components_are_consistent_with_merged_result():
    rng = np.random.default_rng(5)
    w, mu, S = random_gmm(rng, 3, 5)
    x = rng.normal(size=(10, 3))
    res = gmr(w, mu, S, x, [0, 1, 2], [3, 4], return_components=True)
    assert res.component_means.shape == (10, 3, 2)
    assert res.component_covariances.shape == (3, 2, 2)
    assert res.activations.shape == (10, 3)
    mean = np.einsum("ng,ngm->nm", res.activations, res.component_means)
    np.testing.assert_allclose(res.mean, mean, rtol=1e-12, atol=1e-13)
    # The between-component term is kept: merged covariance >= the activation-weighted within term.
    within = np.einsum("ng,gij->nij", res.activations, res.component_covariances)
    assert np.linalg.eigvalsh(res.covariance - within).min() >= -1e-12


def test_gaussian_mixture_condition_and_score():
    rng = np.random.default_rng(6)
    w, mu, S = random_gmm(rng, 3, 4)
    gm = GaussianMixture(w, mu, S)
    X = rng.normal(size=(7, 4))
    ref = np.log(sum(w[i] * multivariate_normal(mu[i], S[i]).pdf(X) for i in range(3)))
    np.testing.assert_allclose(gm.score_samples(X), ref, rtol=1e-12)
    cond = gm.condition([0, 1], [2, 3])
    mu_ref, S_ref = reference_gmr(w, mu, S, X[:, :2], [0, 1], [2, 3])
    mu_hat, S_hat = cond.predict(X[:, :2])
    np.testing.assert_allclose(mu_hat, mu_ref, atol=1e-10)
    np.testing.assert_allclose(S_hat, S_ref, atol=1e-10)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda w, mu, S: (w[:-1], mu, S), "weights"),
        (lambda w, mu, S: (w * 2, mu, S), "sum to 1"),
        (lambda w, mu, S: (w, mu, S[:, :-1]), "covariances"),
        (lambda w, mu, S: (w, np.where(mu > 0, np.nan, mu), S), "non-finite"),
        (lambda w, mu, S: (w, mu, S - 10 * np.eye(5)), "positive definite"),
    ],
)
def test_bad_mixture_raises_model_error(mutate, message):
    rng = np.random.default_rng(7)
    w, mu, S = random_gmm(rng, 3, 5)
    with pytest.raises(ModelError, match=message):
        ConditionalGMM(*mutate(w, mu, S), [0, 1, 2], [3, 4])


def test_bad_indices_and_queries_raise_model_error():
    rng = np.random.default_rng(8)
    w, mu, S = random_gmm(rng, 3, 5)
    with pytest.raises(ModelError, match="overlap"):
        ConditionalGMM(w, mu, S, [0, 1, 2], [2, 3])
    with pytest.raises(ModelError, match="outside"):
        ConditionalGMM(w, mu, S, [0, 1, 7], [3, 4])
    model = ConditionalGMM(w, mu, S, [0, 1, 2], [3, 4])
    with pytest.raises(ModelError, match="shape"):
        model.predict(np.zeros((4, 2)))
    with pytest.raises(ModelError, match="non-finite"):
        model.predict(np.array([0.0, np.inf, 0.0]))


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    G=st.integers(1, 6),
    d=st.integers(1, 5),
    m=st.integers(1, 3),
    spread=st.floats(0.1, 100.0),
)
def test_property_merged_covariance_psd_and_activations_normalized(seed, G, d, m, spread):
    rng = np.random.default_rng(seed)
    w, mu, S = random_gmm(rng, G, d + m, jitter=1e-3)
    x = rng.normal(scale=spread, size=(20, d))
    res = ConditionalGMM(w, mu, S, range(d), range(d, d + m)).predict_components(x)
    assert np.all(np.isfinite(res.covariance))
    assert np.array_equal(res.covariance, np.swapaxes(res.covariance, -1, -2))
    assert np.linalg.eigvalsh(res.covariance).min() >= -1e-10 * max(1.0, np.abs(res.covariance).max())
    np.testing.assert_allclose(res.activations.sum(axis=1), 1.0, atol=1e-12)
