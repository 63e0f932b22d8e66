"""The instrumental-variable gain (``estimate_gain(..., method="iv")``) on operators whose gain is known.

The operators (:mod:`workbench.sim.operators`) fly LQR with zero-mean, AR(1) (ρ = 0.9), state-dependent variability:
the closed-loop case where least squares stays biased however many demonstrations there are. Figures are
printed for ``pytest -s``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.errors import DataError, ModelError
from workbench.method.gain import estimate_gain, gain_from_arrays, iv_instruments, stack_demonstrations
from workbench.method.resampling import bootstrap
from workbench.models import HumanBehaviorModel, IOCOnlyModel
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import LQROperator, lqr_operator_demos

REPO = Path(__file__).resolve().parents[2]


def rel_error(K_hat: np.ndarray, K: np.ndarray) -> float:
    return float(np.linalg.norm(K_hat - K) / np.linalg.norm(K))


@pytest.fixture(scope="module")
def quad():
    return planar_quadrotor()


def test_iv_error_shrinks_with_demonstrations_while_least_squares_plateaus(quad):
    op = LQROperator()
    K = op.gain(quad)
    errors: dict[tuple[str, int], list[float]] = {}
    for seed in (11, 12):
        for n_demos in (30, 300):
            ds = lqr_operator_demos(op, n_demos, seed=seed, plant=quad)
            for method in ("direct", "dmd", "iv"):
                errors.setdefault((method, n_demos), []).append(rel_error(estimate_gain(ds, quad, method), K))
    mean = {k: float(np.mean(v)) for k, v in errors.items()}
    for k, v in sorted(mean.items()):
        print(f"{k[0]:>6} {k[1]:>3} demos: relative gain error {v:.3f}")
    for ls in ("direct", "dmd"):
        # inconsistent: ten times the data leaves the error where it was
        assert mean[(ls, 300)] > 0.8 * mean[(ls, 30)]
        assert mean[(ls, 300)] > 5 * mean[("iv", 300)]
    # consistent: ten times the data, an error shrinking roughly like 1/sqrt(10)
    assert mean[("iv", 300)] < 0.6 * mean[("iv", 30)]
    assert mean[("iv", 30)] < mean[("direct", 30)]


def test_iv_is_exact_without_variability(quad):
    op = LQROperator(sigma_near=(0.0, 0.0), sigma_far=(0.0, 0.0))
    ds = lqr_operator_demos(op, 5, seed=0, plant=quad)
    assert rel_error(estimate_gain(ds, quad, "iv"), op.gain(quad)) < 1e-8


def test_instruments_are_the_first_state_times_decaying_exponentials():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(3, 7))
    Z = iv_instruments(X, [4, 3], n_basis=2)
    assert Z.shape == (6, 7)
    # at the first sample of each demonstration every exponential is 1: the instruments are x0 repeated
    np.testing.assert_allclose(Z[:, 0], np.tile(X[:, 0], 2))
    np.testing.assert_allclose(Z[:, 4], np.tile(X[:, 4], 2))
    # later samples of a demonstration decay but keep the direction of its x0
    assert np.allclose(Z[:3, 2] / X[:, 0], Z[0, 2] / X[0, 0])
    with pytest.raises(DataError, match="lengths"):
        iv_instruments(X, [4, 4])


def test_iv_refuses_demonstrations_whose_starts_leave_a_state_unexcited(quad):
    # every trial starts on the pad's height: the variability moves y, but nothing the instruments see does
    op = LQROperator(x0_low=(-1.0, 0, 0, 0, 0, 0), x0_high=(1.0, 0, 0, 0, 0, 0))
    ds = lqr_operator_demos(op, 6, seed=0, plant=quad)
    with pytest.raises(ModelError, match="unexcited"):
        estimate_gain(ds, quad, "iv")
    X, U, X_next = stack_demonstrations(ds, quad.n, quad.m)
    with pytest.raises(DataError, match="lengths"):
        gain_from_arrays(X, U, X_next, quad.A, quad.B, "iv")


def test_iv_reaches_models_and_bootstrap(quad):
    op = LQROperator()
    ds = lqr_operator_demos(op, 30, seed=3, plant=quad)
    K_iv = estimate_gain(ds, quad, "iv")
    # the instantaneous gain (timing "none"; with the pilot's timing the models' gain is the timing's, test_timing)
    ioc = IOCOnlyModel(quad, gain_method="iv", timing="none").fit(ds)
    np.testing.assert_allclose(ioc.K_, K_iv, atol=1e-10)
    hbm = HumanBehaviorModel(quad, gain_method="iv", timing="none", n_components=2, fit_objective=False,
                             noise_folds=0).fit(ds)
    np.testing.assert_allclose(hbm.K_, K_iv, atol=1e-10)
    boot = bootstrap(ds, quad, n_boot=4, method="iv", structure="diagonal", seed=0)
    assert boot.method == "iv" and boot.n_ok >= 1
    np.testing.assert_allclose(boot.K, K_iv, atol=1e-12)


def test_cli_fit_takes_gain_iv(tmp_path, quad):
    ds = lqr_operator_demos(LQROperator(), 12, seed=4, plant=quad)
    demos = tmp_path / "lqr.parquet"
    ds.save(demos)
    out = tmp_path / "m.npz"
    env = {**os.environ, "COLUMNS": "160", "PYTHONWARNINGS": "ignore"}
    r = subprocess.run(
        [sys.executable, "-m", "workbench", "fit", str(demos), "--method", "ioc-only", "--gain", "iv",
         "--timing", "none", "--bootstrap", "0", "-o", str(out)],
        capture_output=True, text=True, timeout=300, cwd=REPO, env=env,
    )
    assert r.returncode == 0, r.stderr
    from workbench.models import load_model

    np.testing.assert_allclose(load_model(out).K_, estimate_gain(ds, quad, "iv"), atol=1e-9)


def test_single_sample_demonstrations_are_skipped_by_iv(quad):
    ds = lqr_operator_demos(LQROperator(), 8, seed=5, plant=quad)
    # a DemonstrationSet refuses one-sample trials; estimate_gain also takes any objects with x and u
    padded = [*ds, SimpleNamespace(x=ds[0].x[:1], u=ds[0].u[:1], id="one")]
    np.testing.assert_allclose(estimate_gain(padded, quad, "iv"), estimate_gain(ds, quad, "iv"))


def test_a_gain_that_does_not_stabilize_names_the_states_its_slow_mode_lies_on():
    # a pilot who damps the velocity but never brings the position back: the closed loop keeps the integrator
    import numpy as np

    from workbench.errors import ModelError
    from workbench.method.gain import gain_from_arrays

    A, B = np.array([[1.0, 0.1], [0.0, 1.0]]), np.array([[0.0], [0.1]])
    rng = np.random.default_rng(0)
    X = rng.normal(size=(2, 200))
    U = np.array([[0.0, -1.0]]) @ X + 0.01 * rng.normal(size=(1, 200))
    with pytest.raises(ModelError, match=r"lies on x: in these demonstrations the pilot does not bring x back"):
        gain_from_arrays(X, U, A @ X + B @ U, A, B, "direct", state_names=("x", "xdot"))


def test_a_bootstrap_whose_first_resamples_mostly_fail_stops_early_and_says_why(monkeypatch):
    # 128 s of CPU for 17 fitted resamples of 100 on a real .bin: after the first look the rest are not fitted
    import workbench.method.resampling as rs
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.landing import simulate_landings

    demos = simulate_landings("CS1", 6, seed=1)
    calls = []
    original = rs._resample_fit

    def failing(blocks, idx, A, B, method, solver):
        calls.append(1)
        if len(calls) > 1 and len(calls) % 4 != 0:  # the point fit passes; 3 of 4 resamples fail
            raise rs.ModelError("the gain is not stabilizing: spectral radius ρ(A + B K) = 1.01 ≥ 1")
        return original(blocks, idx, A, B, method, solver)

    monkeypatch.setattr(rs, "_resample_fit", failing)
    result = rs.bootstrap_gain(demos, planar_quadrotor(), n_boot=100, seed=0)
    assert result.n_boot == rs.EARLY_LOOK < 100
    assert result.n_failed > rs.EARLY_STOP_FAILED * result.n_boot
    assert f"stopped after {rs.EARLY_LOOK} of 100 resamples: {result.n_failed} of them failed" in result.stopped
    assert "not stabilizing" in result.stopped
    calls.clear()
    monkeypatch.setattr(rs, "_resample_fit", original)
    assert rs.bootstrap_gain(demos, planar_quadrotor(), n_boot=30, seed=0).stopped == ""
