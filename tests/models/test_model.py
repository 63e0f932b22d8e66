"""The behavior models: fit, variability, predictions, Monte Carlo bands, clipping, shifted targets, model files."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.errors import FormatError, ModelError
from workbench.models import GMROnlyModel, HumanBehaviorModel, IOCOnlyModel, load_model
from workbench.models.files import FORMAT_VERSION, ModelFileError
from workbench.models.prediction import Prediction, fit_noise
from workbench.sim.landing import simulate_landings

H = 40


@pytest.fixture(scope="module")
def train():
    return simulate_landings("CS1", n_trials=12, seed=5)


@pytest.fixture(scope="module")
def test_demo():
    return simulate_landings("CS1", n_trials=1, seed=6)[0]


@pytest.fixture(scope="module")
def hbm(quadrotor, train):
    return HumanBehaviorModel(quadrotor, n_components=3).fit(train)


@pytest.fixture(scope="module")
def ioc(quadrotor, train):
    return IOCOnlyModel(quadrotor).fit(train)


@pytest.fixture(scope="module")
def gmr_only(quadrotor, train):
    return GMROnlyModel(quadrotor, n_components=3).fit(train)


@pytest.fixture(scope="module")
def models(hbm, ioc, gmr_only):
    return {"proposed": hbm, "ioc_only": ioc, "gmr_only": gmr_only}


# ------------------------------------------------------------------------------------------------ fitting


def test_fit_sets_learned_attributes(hbm, train, quadrotor):
    n, m = quadrotor.n, quadrotor.m
    assert hbm.K_.shape == (m, n)
    assert hbm.objective_ is not None and hbm.objective_.forward_gain_error <= 1e-6
    assert hbm.n_features_in_ == n and hbm.n_outputs_ == m
    assert hbm.n_demos_ == len(train) and hbm.n_samples_ == train.n_samples
    assert hbm.variability_.tpgmm_.means_.shape == (2, 3, n + m)
    assert hbm.goal_relative_
    np.testing.assert_allclose(hbm.target_, np.mean([d.target for d in train], axis=0))
    assert hbm.noise_scale_.shape == (m,) and np.all((hbm.noise_rho_ >= 0) & (hbm.noise_rho_ < 1))
    # the residuals of eq. (20) are what the TP-GMM saw (in its standardized coordinates)
    d = train[0]
    np.testing.assert_allclose(hbm.residuals(d), d.u - d.x @ hbm.K_.T, atol=1e-15)


def test_unfitted_and_bad_input_raise(quadrotor, hbm):
    with pytest.raises(ModelError, match="not fitted"):
        HumanBehaviorModel(quadrotor).predict(np.zeros(6), 5)
    with pytest.raises(ModelError, match="horizon"):
        hbm.predict(np.zeros(6), 0)
    with pytest.raises(ModelError, match="start state"):
        hbm.predict(np.zeros(5), 5)
    with pytest.raises(ModelError, match="non-finite"):
        hbm.variability(np.full((2, 6), np.nan), x0=np.zeros(6))
    with pytest.raises(ModelError, match="samples"):
        hbm.predict(np.zeros(6), 5, samples=-1)
    with pytest.raises(ModelError, match="n_components"):
        HumanBehaviorModel(quadrotor, n_components=0).fit(simulate_landings("CS1", 2, seed=1))


def test_fit_rejects_mismatched_data(quadrotor, train):
    wrong_dt = DemonstrationSet(
        [Demonstration(d.t * 2, d.x, d.u, d.meta) for d in train], train.state_names, train.input_names, 0.1
    )
    with pytest.raises(ModelError, match="dt=0.1"):
        IOCOnlyModel(quadrotor).fit(wrong_dt)
    few = DemonstrationSet(
        [Demonstration(d.t, d.x[:, :4], d.u, {"id": d.id}) for d in train], train.state_names[:4],
        train.input_names, train.dt,
    )
    with pytest.raises(ModelError, match="4 states"):
        HumanBehaviorModel(quadrotor).fit(few)


# --------------------------------------------------------------------------------------------- predictions


@pytest.mark.parametrize("name", ["proposed", "ioc_only", "gmr_only"])
def test_prediction_shapes(models, test_demo, name):
    model = models[name]
    x0 = test_demo.x[0]
    p = model.predict(x0, H)
    assert isinstance(p, Prediction)
    assert p.x.shape == (H + 1, 6) and p.u.shape == (H, 2) and p.Sigma_u.shape == (H, 2, 2)
    assert p.x_bands is None and p.x_lower is None and p.band_level is None and p.n_samples == 0
    np.testing.assert_array_equal(p.x[0], x0)
    assert p.t[-1] == pytest.approx(H * 0.05)
    assert not p.x.flags.writeable
    # covariances are symmetric PSD at every step
    np.testing.assert_allclose(p.Sigma_u, np.swapaxes(p.Sigma_u, 1, 2), atol=1e-15)
    assert np.linalg.eigvalsh(p.Sigma_u).min() >= -1e-15
    s = model.predict(x0, H, samples=64, seed=1, percentiles=(5, 50, 95), return_samples=True)
    assert s.x_bands.shape == (3, H + 1, 6) and s.u_bands.shape == (3, H, 2)
    assert s.x_samples.shape == (64, H + 1, 6) and s.u_samples.shape == (64, H, 2)
    assert s.band_level == pytest.approx(0.9)
    np.testing.assert_array_equal(s.band(50), s.x_bands[1])
    assert np.all(s.x_lower <= s.x_upper)
    np.testing.assert_allclose(s.x_bands, np.percentile(s.x_samples, (5, 50, 95), axis=0))
    # the mean rollout does not depend on the sampling
    np.testing.assert_array_equal(s.x, p.x)
    with pytest.raises(ModelError, match="percentile 25"):
        s.band(25)


def test_ioc_only_is_the_pure_linear_rollout(ioc, quadrotor, test_demo):
    x0 = test_demo.x[0]
    A_cl = quadrotor.A + quadrotor.B @ ioc.K_
    x = [x0]
    for _ in range(H):
        x.append(A_cl @ x[-1])
    p = ioc.predict(x0, H)
    np.testing.assert_allclose(p.x, np.array(x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(p.u, p.x[:-1] @ ioc.K_.T, atol=1e-14)
    np.testing.assert_allclose(p.Sigma_u, np.broadcast_to(ioc.residual_cov_, (H, 2, 2)))


def test_proposed_mean_rollout_follows_eq20_and_gmr(hbm, quadrotor, test_demo):
    """û = K̂x̂ + μ̂(x̂), x̂⁺ = A x̂ + B û, step by step with the public variability()."""
    x0, target = test_demo.x[0], test_demo.target
    x = x0.copy()
    xs, us, sig = [x0], [], []
    for _ in range(H):
        mu, Sigma = hbm.variability(x[None], x0=x0, target=target)
        u = hbm.K_ @ x + mu[0]
        us.append(u)
        sig.append(Sigma[0])
        x = quadrotor.A @ x + quadrotor.B @ u
        xs.append(x)
    p = hbm.predict(x0, H, target)
    np.testing.assert_allclose(p.x, np.array(xs), rtol=0, atol=1e-12)
    np.testing.assert_allclose(p.u, np.array(us), rtol=0, atol=1e-12)
    np.testing.assert_allclose(p.Sigma_u, np.array(sig), rtol=0, atol=1e-15)


def test_predict_many_matches_predict(hbm, test_demo):
    starts = test_demo.x[[0, 10, 20]]
    many = hbm.predict_many(starts, H, test_demo.target, task_x0s=test_demo.x[0])
    for s, p in zip(starts, many, strict=True):
        single = hbm.predict(s, H, test_demo.target, task_x0=test_demo.x[0])
        np.testing.assert_allclose(p.x, single.x, rtol=0, atol=1e-12)


def test_monte_carlo_is_seeded_and_its_mean_tracks_the_mean_rollout(hbm, test_demo):
    x0 = test_demo.x[0]
    a = hbm.predict(x0, H, samples=200, seed=3, return_samples=True)
    b = hbm.predict(x0, H, samples=200, seed=3)
    np.testing.assert_array_equal(a.x_bands, b.x_bands)
    spread = a.x_samples[:, -1, :2].std(axis=0)
    assert np.all(spread > 0)
    # the sample mean of the final position lies within a few standard errors + the nonlinearity's bias
    gap = np.abs(a.x_samples[:, -1, :2].mean(axis=0) - a.x[-1, :2])
    assert np.all(gap < 5 * spread / np.sqrt(200) + 0.5 * spread)


def test_gmr_noise_draws_match_the_gmr_gaussian(quadrotor, train, test_demo):
    """With noise='gmr' every one-step draw is N(K̂x + μ̂, Σ̂): check the first step's sample moments."""
    model = HumanBehaviorModel(quadrotor, n_components=3, noise="gmr", fit_objective=False).fit(train)
    x0 = test_demo.x[0]
    p = model.predict(x0, 1, samples=20000, seed=0, return_samples=True)
    mean, Sigma = model.input_distribution(x0[None], x0)
    u0 = p.u_samples[:, 0]
    assert np.all(np.abs(u0.mean(axis=0) - mean[0]) < 5 * np.sqrt(np.diag(Sigma[0]) / 20000))
    sd = np.sqrt(np.diag(Sigma[0]))
    assert np.all(np.abs(np.cov(u0.T) - Sigma[0]) <= 0.05 * np.outer(sd, sd))


def test_clip_keeps_inputs_in_bounds(hbm, quadrotor):
    # far from the pad, banked, rolling and falling fast: the unclipped model asks for more than full stick
    x0 = np.array([2.5, 3.0, 0.6, 2.0, -3.0, 12.0])
    free = hbm.predict(x0, H)
    assert np.abs(free.u).max() > 1.0
    clipped = hbm.predict(x0, H, clip=True, samples=50, seed=0, return_samples=True)
    assert clipped.clipped
    assert np.all(clipped.u <= quadrotor.u_max) and np.all(clipped.u >= quadrotor.u_min)
    assert np.all(clipped.u_samples <= 1.0) and np.all(clipped.u_samples >= -1.0)
    # the clipped mean rollout is the rollout of the clipped inputs
    x = x0.copy()
    for k in range(H):
        mu, _ = hbm.variability(x[None], x0=x0)
        x = quadrotor.A @ x + quadrotor.B @ np.clip(hbm.K_ @ x + mu[0], -1.0, 1.0)
        np.testing.assert_allclose(clipped.x[k + 1], x, atol=1e-12)


# ------------------------------------------------------------------------------------------ task frames


def test_shifted_target_moves_the_gmm_means_and_the_prediction(hbm, test_demo):
    """Start/goal frames: moving the pad by Δ moves every component mean of eq. (30) toward Δ and the
    predicted path toward the new pad."""
    x0 = test_demo.x[0]
    shift = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    _, means0, _ = hbm.task_gmm(x0, np.zeros(6))
    _, means1, _ = hbm.task_gmm(x0, shift)
    moved = means1[:, 0] - means0[:, 0]
    print(f"\nshift of the task GMM means along x for a pad moved by 1 m: {np.round(moved, 3)}")
    assert np.all(moved > 0.05) and np.all(moved <= 1.0 + 1e-9)
    p0 = hbm.predict(x0, 120, np.zeros(6))
    p1 = hbm.predict(x0, 120, shift)
    print(f"predicted x after 6 s: pad at 0 → {p0.x[-1, 0]:.3f}, pad at +1 → {p1.x[-1, 0]:.3f}")
    assert p1.x[-1, 0] - p0.x[-1, 0] > 0.5


@pytest.mark.filterwarnings("ignore::workbench.errors.ConvergenceWarning")
def test_goal_frame_model_is_equivariant_to_shifting_the_task(quadrotor, train, test_demo):
    """With only the goal frame and a goal-relative gain, shifting start and pad by Δ shifts the prediction."""
    model = GMROnlyModel(quadrotor, n_components=3, frames=("goal",)).fit(train)
    hbm_goal = HumanBehaviorModel(quadrotor, n_components=3, frames=("goal",), fit_objective=False).fit(train)
    x0 = test_demo.x[0]
    delta = np.array([0.7, -0.4, 0.0, 0.0, 0.0, 0.0])
    for m in (model, hbm_goal):
        a = m.predict(x0, H, np.zeros(6))
        b = m.predict(x0 + delta, H, delta)
        np.testing.assert_allclose(b.x, a.x + delta, atol=1e-9)
        np.testing.assert_allclose(b.u, a.u, atol=1e-9)


# ------------------------------------------------------------------------------------------- model files


@pytest.mark.parametrize("name", ["proposed", "ioc_only", "gmr_only"])
def test_save_load_round_trip_predicts_identically(models, test_demo, tmp_path, name):
    model = models[name]
    path = model.save(tmp_path / f"{name}.npz")
    back = load_model(path)
    assert type(back) is type(model)
    assert back.get_params() == model.get_params()
    x0, target = test_demo.x[0], test_demo.target
    a = model.predict(x0, H, target, samples=32, seed=7)
    b = back.predict(x0, H, target, samples=32, seed=7)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.Sigma_u, b.Sigma_u)
    np.testing.assert_array_equal(a.x_bands, b.x_bands)
    np.testing.assert_array_equal(model.target_, back.target_)
    if name != "gmr_only":
        np.testing.assert_array_equal(model.K_, back.K_)
    if name == "proposed":
        for f in ("Q", "R", "S", "M_normalized"):
            np.testing.assert_array_equal(getattr(model.objective_, f), getattr(back.objective_, f))
        assert back.objective_.alpha == model.objective_.alpha
    assert [p.name for p in tmp_path.iterdir()] == [f"{name}.npz"]  # atomic write leaves no temp file


def test_model_file_has_no_pickles_and_a_json_header(hbm, tmp_path):
    path = hbm.save(tmp_path / "m.npz")
    with np.load(path, allow_pickle=False) as npz:
        header = json.loads(npz["__header__"].tobytes())
        assert all(npz[k].dtype.kind in "fiu" for k in npz.files)
    assert header["format"] == "workbench.model" and header["version"] == FORMAT_VERSION
    assert header["model_class"] == "HumanBehaviorModel"
    assert header["settings"]["n_components"] == 3
    assert header["system"]["state_names"] == ["x", "y", "phi", "xdot", "ydot", "phidot"]


def _rewrite(src, dst, change):
    with np.load(src, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = json.loads(arrays["__header__"].tobytes())
    change(header, arrays)
    arrays["__header__"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    with open(dst, "wb") as fh:
        np.savez(fh, **arrays)
    return dst


def test_bad_model_files_are_clear_errors(hbm, tmp_path):
    good = hbm.save(tmp_path / "good.npz")
    cases = {
        "missing": (tmp_path / "nope.npz", "no such model file"),
        "text": (tmp_path / "text.npz", "not an .npz"),
        "truncated": (tmp_path / "trunc.npz", "not an .npz|damaged"),
        "foreign": (tmp_path / "foreign.npz", "not a workbench model file"),
    }
    (tmp_path / "text.npz").write_text("hello")
    (tmp_path / "trunc.npz").write_bytes(good.read_bytes()[: len(good.read_bytes()) // 2])
    np.savez(tmp_path / "foreign.npz", a=np.zeros(3))
    newer = _rewrite(good, tmp_path / "newer.npz", lambda h, a: h.update(version=FORMAT_VERSION + 1))
    cases["newer"] = (newer, "newer than this workbench")
    other = _rewrite(good, tmp_path / "other.npz", lambda h, a: h.update(format="something.else"))
    cases["other format"] = (other, "not 'workbench.model'")
    cls = _rewrite(good, tmp_path / "cls.npz", lambda h, a: h.update(model_class="os.system"))
    cases["unknown class"] = (cls, "unknown model class")

    def drop(h, a):
        del a["K"]

    cases["missing array"] = (_rewrite(good, tmp_path / "drop.npz", drop), "named in the header are missing")

    def reshape(h, a):
        a["K"] = a["K"][:, :3]
        h["arrays"]["K"]["shape"] = [2, 3]

    cases["bad shape"] = (_rewrite(good, tmp_path / "shape.npz", reshape), "array 'K' has shape")

    def nan(h, a):
        a["tpgmm/means"] = np.full_like(a["tpgmm/means"], np.nan)

    cases["nan"] = (_rewrite(good, tmp_path / "nan.npz", nan), "non-finite")
    cases["bad header"] = (_rewrite(good, tmp_path / "hdr.npz", lambda h, a: h.pop("model_class")), "lacks")
    for what, (path, message) in cases.items():
        with pytest.raises(ModelFileError, match=message) as info:
            load_model(path)
        assert str(path) in str(info.value), what
        assert isinstance(info.value, FormatError) and isinstance(info.value, ModelError)


def test_pickled_array_is_refused(hbm, tmp_path):
    good = hbm.save(tmp_path / "good.npz")
    bad = tmp_path / "pickled.npz"
    with zipfile.ZipFile(good) as zin, zipfile.ZipFile(bad, "w") as zout:
        for item in zin.namelist():
            zout.writestr(item, zin.read(item))
        buf = __import__("io").BytesIO()
        np.save(buf, np.array([{"evil": 1}], dtype=object), allow_pickle=True)
        zout.writestr("payload.npy", buf.getvalue())
    with pytest.raises(ModelFileError, match="damaged"):
        load_model(bad)


# ---------------------------------------------------------------------------------------------- noise fit


def test_fit_noise_recovers_an_ar1_process():
    rng = np.random.default_rng(0)
    rho, s = np.array([0.0, 0.8]), np.array([1.0, 2.0])
    E = []
    for _ in range(40):
        z = np.zeros((300, 2))
        z[0] = rng.standard_normal(2)
        for k in range(1, 300):
            z[k] = rho * z[k - 1] + np.sqrt(1 - rho**2) * rng.standard_normal(2)
        E.append(s * z)
    scale, rho_hat = fit_noise(E, window=20)
    print(f"\nAR(1) noise fit: scale {scale.round(3)} (true {s}), rho {rho_hat.round(3)} (true {rho})")
    np.testing.assert_allclose(scale, s, rtol=0.05)
    assert rho_hat[0] < 0.1 and abs(rho_hat[1] - 0.8) < 0.05


def test_a_model_header_that_is_not_utf8_is_named_by_its_byte(tmp_path):
    """A model file whose JSON header holds a byte that is not UTF-8: the message quoted Python's codec."""
    from workbench.models import load_model
    from workbench.models.files import ModelFileError

    header = b'{"format": "caf\xe9"}'
    path = tmp_path / "m.npz"
    np.savez(path, __header__=np.frombuffer(header, dtype=np.uint8))
    with pytest.raises(ModelFileError) as info:
        load_model(path)
    text = str(info.value)
    at = header.index(b"\xe9")
    assert f"not UTF-8 text at byte {at}" in text and "codec" not in text
