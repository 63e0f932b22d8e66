"""Tests of workbench.method.tpgmm and workbench.method.frames: TP-GMM EM (eq. (28)) and the product of frames
(eq. (30))."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.linalg import block_diag
from scipy.special import logsumexp
from scipy.stats import multivariate_normal
from sklearn.mixture import GaussianMixture as SkGaussianMixture

from workbench.errors import ConvergenceWarning, ModelError
from workbench.method.tpgmm import (
    TPGMM,
    Frame,
    FrameSpec,
    GaussianMixture,
    frames_for_demo,
    frames_for_task,
    goal_frame,
    identity_frame,
    select_components,
    start_frame,
)


def landing_demos(rng: np.random.Generator, M: int = 12, N: int = 60, noise: float = 0.02):
    """Synthetic point-to-point demonstrations: xi = [px, py, vx, vy, w1, w2] (n = 4, m = 2).

    Starts are spread over [-2, 2] x [2.5, 3], goals over [-1, 1] x [0, 0.3]; the path shape is the same in
    every demonstration, so it is regular in the start and goal frames but not globally.
    """
    tau = np.linspace(0.0, 1.0, N)
    s, ds = 3 * tau**2 - 2 * tau**3, 6 * tau - 6 * tau**2
    xi_list, frames_list, starts, goals = [], [], [], []
    for _ in range(M):
        start = np.array([rng.uniform(-2, 2), rng.uniform(2.5, 3.0)])
        goal = np.array([rng.uniform(-1, 1), rng.uniform(0.0, 0.3)])
        pos = start + np.outer(s, goal - start) + rng.normal(scale=noise, size=(N, 2))
        vel = np.outer(ds, goal - start) + rng.normal(scale=noise, size=(N, 2))
        w = np.column_stack([0.3 * np.sin(np.pi * tau), -0.2 * tau]) + rng.normal(scale=noise, size=(N, 2))
        x = np.column_stack([pos, vel])
        xi_list.append(np.column_stack([x, w]))
        target = np.concatenate([goal, [0.0, 0.0]])
        frames_list.append(frames_for_demo(("start", "goal"), x, n_inputs=2, target=target))
        starts.append(x[0])
        goals.append(target)
    return xi_list, frames_list, starts, goals


# -- frames ------------------------------------------------------------------------------------------------------
def test_frame_builders():
    x0 = np.array([1.0, 2.0, 0.1, 0.0, 0.0, 0.0])
    f = start_frame(x0, 2)
    np.testing.assert_array_equal(f.T, np.eye(8))
    np.testing.assert_array_equal(f.b, np.r_[x0, 0.0, 0.0])
    g = goal_frame(x0, 2, phi=0.3, position_idx=(0, 1))
    R = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    np.testing.assert_allclose(g.T[:2, :2], R)
    np.testing.assert_array_equal(g.T[2:, 2:], np.eye(6))
    np.testing.assert_array_equal(goal_frame(x0, 2).T, np.eye(8))
    np.testing.assert_array_equal(identity_frame(8).b, np.zeros(8))
    # The quadrotor convention: goal angle phi_N is the 3rd state entry.
    spec = FrameSpec(("start", "goal"), angle_index=2, position_idx=(0, 1))
    x = np.cumsum(np.ones((5, 6)), axis=0)
    target = np.array([0.5, 0.0, 0.2, 0, 0, 0])
    fs = frames_for_demo(spec, x, 2, target=target)
    np.testing.assert_array_equal(fs[0].b[:6], x[0])
    np.testing.assert_array_equal(fs[1].b[:6], target)
    np.testing.assert_allclose(fs[1].T[:2, :2], goal_frame(target, 2, phi=0.2, position_idx=(0, 1)).T[:2, :2])
    no_target = frames_for_demo(spec, x, 2)
    np.testing.assert_array_equal(no_target[1].b[:6], x[-1])
    task = frames_for_task(spec, x[0], target, 2)
    np.testing.assert_array_equal(task[1].T, fs[1].T)
    assert FrameSpec.coerce("goal").kinds == ("goal",)


def test_projection_is_exact_for_non_orthogonal_T():
    rng = np.random.default_rng(0)
    T = np.array([[2.0, 0.7, 0.0], [0.0, 0.5, 0.0], [0.3, 0.0, 1.5]])  # scaling + shear, not a rotation
    f = Frame(T, np.array([1.0, -2.0, 0.5]))
    xi = rng.normal(size=(10, 3))
    Z = f.to_local(xi)
    np.testing.assert_allclose(Z, (np.linalg.inv(T) @ (xi - f.b).T).T, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(f.to_global(Z), xi, rtol=1e-12, atol=1e-12)
    assert not np.allclose(Z, (xi - f.b) @ T)  # T^T would be wrong here


@pytest.mark.parametrize(
    "T, b, message",
    [
        (np.eye(3), np.zeros(2), "shape"),
        (np.diag([1.0, 1.0, 0.0]), np.zeros(3), "singular"),
        (np.eye(3), np.array([0.0, np.nan, 0.0]), "non-finite"),
        (np.full((3, 3), np.inf), np.zeros(3), "non-finite"),
        (np.eye(2), np.zeros((2, 1)), "1-D"),
    ],
)
def test_invalid_frames_raise_model_error(T, b, message):
    with pytest.raises(ModelError, match=message):
        Frame(T, b)


def test_invalid_frame_usage_raises_model_error():
    rng = np.random.default_rng(1)
    xi = [rng.normal(size=(30, 3)), rng.normal(size=(30, 3))]
    with pytest.raises(ModelError, match="frames, expected P"):
        TPGMM(2).fit(xi, [[identity_frame(3)], [identity_frame(3), identity_frame(3)]])
    with pytest.raises(ModelError, match="acts on dimension"):
        TPGMM(2).fit(xi, [[identity_frame(4)], [identity_frame(4)]])
    with pytest.raises(ModelError, match="frame lists"):
        TPGMM(2).fit(xi, [[identity_frame(3)]])
    with pytest.raises(ModelError, match="not a Frame"):
        TPGMM(2).fit(xi, [[np.eye(3)], [np.eye(3)]])
    model = TPGMM(2, random_state=0).fit(xi, [[identity_frame(3)]] * 2)
    with pytest.raises(ModelError, match="has 1 frames"):
        model.product([identity_frame(3), identity_frame(3)])
    with pytest.raises(ModelError, match="unknown frame kind"):
        FrameSpec(("start", "elbow"))
    with pytest.raises(ModelError, match="goal state"):
        frames_for_task(("start", "goal"), np.zeros(2), None, 1)
    with pytest.raises(ModelError, match="not fitted"):
        TPGMM(2).product([identity_frame(3)])


# -- EM ----------------------------------------------------------------------------------------------------------
def test_tp_likelihood_equals_block_diagonal_stacked_gmm():
    rng = np.random.default_rng(2)
    xi_list, frames_list, _, _ = landing_demos(rng, M=6, N=40)
    # Rotate the goal frames too, so T is not the identity.
    frames_list = [[f[0], Frame(goal_frame(f[1].b[:4], 2, phi=0.4, position_idx=(0, 1)).T, f[1].b)]
                   for f in frames_list]
    model = TPGMM(n_components=3, random_state=0).fit(xi_list, frames_list)
    ll_tp = model.score_samples(xi_list, frames_list)

    # Independent evaluation: stack [Z^1; Z^2] (with explicit inverses) and use one dense Gaussian per component
    # whose covariance is block-diagonal over the frames.
    ll_dense = []
    for xi, frames in zip(xi_list, frames_list, strict=True):
        Zs = np.hstack([(np.linalg.inv(f.T) @ (xi - f.b).T).T for f in frames])
        comp = [
            np.log(model.weights_[i])
            + multivariate_normal(
                np.concatenate([model.means_[p, i] for p in range(2)]),
                block_diag(*[model.covariances_[p, i] for p in range(2)]),
            ).logpdf(Zs)
            for i in range(3)
        ]
        ll_dense.append(logsumexp(np.array(comp), axis=0))
    ll_dense = np.concatenate(ll_dense)
    err = np.abs(ll_tp - ll_dense).max()
    print(f"TP E-step vs dense block-diagonal stacked GMM: max |log-lik diff| {err:.2e} "
          f"(mean log-lik {ll_tp.mean():.4f})")
    assert err <= 1e-8 * max(1.0, np.abs(ll_dense).max())
    assert model.means_.shape == (2, 3, 6) and model.covariances_.shape == (2, 3, 6, 6)
    assert model.weights_.shape == (3,)
    np.testing.assert_allclose(model.weights_.sum(), 1.0)
    np.testing.assert_allclose(model.predict_proba(xi_list, frames_list).sum(axis=1), 1.0)


def test_non_orthogonal_frames_and_constant_coordinate_fit_without_nan():
    rng = np.random.default_rng(3)
    xi_list, frames_list = [], []
    shear = np.array([[1.5, 0.8, 0, 0], [0, 0.4, 0, 0], [0, 0, 2.0, 0.3], [0, 0, 0, 1.0]])
    for _ in range(5):
        xi = rng.normal(size=(80, 4))
        xi[:, 3] = 0.7  # a constant coordinate: zero variance in every frame
        xi_list.append(xi)
        frames_list.append([Frame(shear, rng.normal(size=4)), Frame(np.diag([3.0, 0.1, 1.0, 1.0]), np.zeros(4))])
    model = TPGMM(n_components=3, random_state=0).fit(xi_list, frames_list)
    for name in ("weights_", "means_", "covariances_"):
        assert np.all(np.isfinite(getattr(model, name))), name
    lam_min = np.linalg.eigvalsh(model.covariances_).min()
    print(f"constant coordinate: smallest covariance eigenvalue {lam_min:.2e} (reg_covar {model.reg_covar:g})")
    assert lam_min > 0
    assert np.isfinite(model.score(xi_list, frames_list))
    gm = model.product(frames_list[0])
    assert np.all(np.isfinite(gm.means)) and np.all(np.isfinite(gm.covariances))


def test_identity_frame_matches_sklearn_from_same_init():
    rng = np.random.default_rng(4)
    D, G = 4, 3
    centers = rng.normal(scale=2.5, size=(G, D))
    X = np.concatenate([rng.normal(size=(300, D)) @ rng.normal(scale=0.6, size=(D, D)) + c for c in centers])
    rng.shuffle(X)
    xi_list = [X[:500], X[500:]]
    frames = [[identity_frame(D)], [identity_frame(D)]]
    ours = TPGMM(n_components=G, reg_covar=1e-6, tol=1e-8, max_iter=500, random_state=0).fit(xi_list, frames)
    sk = SkGaussianMixture(
        n_components=G,
        covariance_type="full",
        reg_covar=1e-6,
        tol=1e-8,
        max_iter=500,
        weights_init=ours.init_weights_,
        means_init=ours.init_means_[0],
        precisions_init=np.linalg.inv(ours.init_covariances_[0]),
        init_params="random_from_data",  # overridden by the *_init arguments
    ).fit(X)
    ll_ours, ll_sk = ours.score(xi_list, frames), sk.score(X)
    rel = abs(ll_ours - ll_sk) / abs(ll_sk)
    print(f"identity frame vs sklearn: log-lik {ll_ours:.10f} vs {ll_sk:.10f} (rel {rel:.1e}), "
          f"iterations {ours.n_iter_} vs {sk.n_iter_}, lower bounds {ours.lower_bound_:.10f} vs {sk.lower_bound_:.10f}")
    assert ours.converged_ and sk.converged_
    assert rel <= 1e-6
    assert abs(ours.lower_bound_ - sk.lower_bound_) <= 1e-6 * abs(sk.lower_bound_)
    np.testing.assert_allclose(ours.weights_, sk.weights_, atol=1e-6)
    np.testing.assert_allclose(ours.means_[0], sk.means_, atol=1e-5)


def test_product_single_identity_frame_returns_frame_model():
    rng = np.random.default_rng(5)
    xi = [np.concatenate([rng.normal(size=(100, 3)), rng.normal(loc=5.0, size=(100, 3))])]
    model = TPGMM(n_components=2, random_state=0).fit(xi, [[identity_frame(3)]])
    gm = model.product([identity_frame(3)])
    assert isinstance(gm, GaussianMixture)
    np.testing.assert_allclose(gm.means, model.means_[0], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(gm.covariances, model.covariances_[0], rtol=1e-10, atol=1e-12)


def test_product_matches_textbook_formula_eq_30():
    rng = np.random.default_rng(6)
    xi_list, frames_list, starts, goals = landing_demos(rng, M=6, N=40)
    model = TPGMM(n_components=3, random_state=0).fit(xi_list, frames_list)
    frames = [Frame(np.array(f.T) @ np.diag([1.2, 0.8, 1, 1, 1, 1]) + 0.1 * np.triu(np.ones((6, 6)), 1), f.b)
              for f in frames_for_task(("start", "goal"), starts[0], goals[1], 2)]
    gm = model.product(frames)
    for i in range(3):
        lam = sum(np.linalg.inv(f.T @ model.covariances_[p, i] @ f.T.T) for p, f in enumerate(frames))
        S = np.linalg.inv(lam)
        mu = S @ sum(
            np.linalg.inv(f.T @ model.covariances_[p, i] @ f.T.T) @ (f.T @ model.means_[p, i] + f.b)
            for p, f in enumerate(frames)
        )
        np.testing.assert_allclose(gm.means[i], mu, rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(gm.covariances[i], S, rtol=1e-7, atol=1e-12)
    assert np.array_equal(gm.covariances, np.swapaxes(gm.covariances, -1, -2))
    assert np.linalg.eigvalsh(gm.covariances).min() > 0
    gmr_model = gm.condition(range(4), [4, 5])
    mu_w, S_w = gmr_model.predict(np.array(starts[0]))
    assert mu_w.shape == (1, 2) and S_w.shape == (1, 2, 2)


def test_shifted_target_moves_means_near_goal():
    rng = np.random.default_rng(7)
    xi_list, frames_list, starts, goals = landing_demos(rng, M=14, N=60)
    model = TPGMM(n_components=5, n_init=3, random_state=0, frames=("start", "goal"))
    model.fit(xi_list, frames_list)
    x0 = np.array([-1.0, 2.8, 0.0, 0.0])
    goal = np.array([0.2, 0.1, 0.0, 0.0])
    delta = np.array([0.4, 0.15, 0.0, 0.0])
    base = model.product_for_task(x0, goal, 2)
    moved = model.product_for_task(x0, goal + delta, 2)
    pos_base, pos_moved = base.means[:, :2], moved.means[:, :2]
    near_goal = int(np.argmin(np.linalg.norm(pos_base - goal[:2], axis=1)))
    near_start = int(np.argmin(np.linalg.norm(pos_base - x0[:2], axis=1)))
    shift_goal = pos_moved[near_goal] - pos_base[near_goal]
    shift_start = pos_moved[near_start] - pos_base[near_start]
    print(f"target shifted by {delta[:2]}: component near goal moved {shift_goal}, near start moved {shift_start}")
    assert np.linalg.norm(shift_goal - delta[:2]) <= 0.15 * np.linalg.norm(delta[:2])
    assert np.linalg.norm(shift_start) <= 0.3 * np.linalg.norm(delta[:2])


def test_bic_picks_true_number_of_components():
    rng = np.random.default_rng(8)
    D, G_true = 3, 3
    centers = np.array([[0.0, 0.0, 0.0], [6.0, 0.0, 0.0], [0.0, 6.0, 3.0]])
    xi_list = [
        np.concatenate([c + rng.normal(scale=0.5, size=(80, D)) for c in centers]) for _ in range(3)
    ]
    frames_list = [[identity_frame(D)] for _ in xi_list]
    sel = select_components(xi_list, frames_list, candidates=range(1, 7), criterion="bic", random_state=0, n_init=3)
    print("BIC table:", [(r["n_components"], round(r["bic"], 1)) for r in sel.as_rows()])
    assert sel.n_components == G_true
    held = select_components(xi_list, frames_list, candidates=[1, 3], criterion="heldout", random_state=0)
    print("held-out table:", [(r["n_components"], round(r["heldout"], 3)) for r in held.as_rows()])
    assert held.n_components == G_true


def test_convergence_warning_on_max_iter():
    rng = np.random.default_rng(9)
    xi = [rng.normal(size=(200, 3))]
    with pytest.warns(ConvergenceWarning, match="max_iter=1"):
        model = TPGMM(n_components=3, max_iter=1, random_state=0).fit(xi, [[identity_frame(3)]])
    assert model.n_iter_ == 1 and not model.converged_
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConvergenceWarning)
        TPGMM(n_components=2, random_state=0).fit(xi, [[identity_frame(3)]])


def test_bic_parameter_count():
    rng = np.random.default_rng(10)
    xi = [rng.normal(size=(100, 3))]
    model = TPGMM(n_components=2, random_state=0).fit(xi, [[identity_frame(3), start_frame(np.ones(2), 1)]])
    G, P, D = 2, 2, 3
    k = (G - 1) + P * G * (D + D * (D + 1) // 2)
    assert model.n_parameters() == k
    ll = model.score_samples(xi, [[identity_frame(3), start_frame(np.ones(2), 1)]])
    assert np.isclose(model.bic(xi, [[identity_frame(3), start_frame(np.ones(2), 1)]]),
                      -2 * ll.sum() + k * np.log(100))


def test_bad_settings_and_data_raise_model_error():
    rng = np.random.default_rng(11)
    xi = [rng.normal(size=(5, 3))]
    with pytest.raises(ModelError, match="fewer than n_components"):
        TPGMM(n_components=6).fit(xi, [[identity_frame(3)]])
    with pytest.raises(ModelError, match="n_components"):
        TPGMM(n_components=0).fit(xi, [[identity_frame(3)]])
    bad = [np.array([[0.0, np.nan, 1.0]] * 5)]
    with pytest.raises(ModelError, match="non-finite value in row 0"):
        TPGMM(n_components=1).fit(bad, [[identity_frame(3)]])
    with pytest.raises(ModelError, match="frames setting"):
        TPGMM(n_components=1, frames=("start", "goal")).fit(xi, [[identity_frame(3)]])


def test_from_parameters_round_trip():
    rng = np.random.default_rng(12)
    xi_list, frames_list, starts, goals = landing_demos(rng, M=4, N=30)
    model = TPGMM(n_components=2, random_state=0).fit(xi_list, frames_list)
    back = TPGMM.from_parameters(model.weights_, model.means_, model.covariances_, reg_covar=model.reg_covar)
    np.testing.assert_allclose(back.score_samples(xi_list, frames_list), model.score_samples(xi_list, frames_list))
    task = frames_for_task(("start", "goal"), starts[0], goals[0], 2)
    np.testing.assert_allclose(back.product(task).means, model.product(task).means)
    with pytest.raises(ModelError, match="shapes"):
        TPGMM.from_parameters(model.weights_, model.means_[:, :1], model.covariances_)
