"""The pilot's timing (:mod:`workbench.method.timing`): a reaction delay and a neuromuscular lag, identified with
intervals, on simulated pilots whose timing and gain are known (:class:`workbench.sim.operators.LQROperator` with
``delay_s``, ``lag_s``). The acceptance over many seeds is the slow test at the end; the rest are fast checks of
the pieces. Figures are printed for ``pytest -s``.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from workbench.errors import DataError
from workbench.method import timing as tm
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import SLOW_PILOT, LQROperator, lqr_operator_demos


@pytest.fixture(scope="module")
def quad():
    return planar_quadrotor()


def rel_error(K_hat: np.ndarray, K: np.ndarray) -> float:
    return float(np.linalg.norm(K_hat - K) / np.linalg.norm(K))


@pytest.mark.parametrize(("delay", "lag"), [(0.2, 0.08), (0.213, 0.091), (0.0, 0.05), (0.137, 0.3), (0.1, 0.0)])
def test_seen_weights_are_the_lag_integral_of_the_interpolated_state(delay, lag):
    # the closed form against the integral done by brute force on a fine grid of ages
    dt = 0.05
    l0, beta = tm.seen_weights(delay, lag, dt)
    age = np.linspace(0.0, dt, 200_001)
    if lag > 0:
        w = np.exp(-age / lag)
        w /= np.trapezoid(w, age)
        back = (delay + age) / dt  # samples back
        brute = [np.trapezoid(w * np.clip(1 - np.abs(back - (l0[0] + j)), 0, None), age) for j in range(3)]
    else:
        back = delay / dt
        brute = [max(0.0, 1 - abs(back - (l0[0] + j))) for j in range(3)]
    np.testing.assert_allclose(beta[0], brute, atol=1e-6)
    assert beta[0].sum() == pytest.approx(1.0)


def test_a_timed_pilot_without_noise_acts_on_the_state_it_saw(quad):
    # two samples of delay, no lag: every recorded input is the gain times the state two samples back
    op = LQROperator(delay_s=2 * quad.dt, sigma_near=(0, 0), sigma_far=(0, 0))
    d = lqr_operator_demos(op, 2, seed=1, plant=quad)[1]
    K = op.gain(quad)
    seen = np.concatenate([[d.x[0], d.x[0]], d.x[:-2]])
    np.testing.assert_allclose(d.u, seen @ K.T, atol=1e-12)
    # the timed operators record what the page records of a dead zone
    dz = lqr_operator_demos(LQROperator(delay_s=0.1, dead_zone=0.05), 1, seed=1, plant=quad)[0]
    assert dz.meta["calibration"]["deadzone"] == 0.05


@pytest.mark.parametrize("start", ["steady", "rest"])
def test_exact_timing_and_gain_without_noise(quad, start):
    # the estimator's model is the simulator's up to rounding: least squares recovers both without noise
    op = LQROperator(**SLOW_PILOT, delay_s=0.2127, lag_s=0.0908, start=start, sigma_near=(0, 0), sigma_far=(0, 0))
    ds = lqr_operator_demos(op, 6, seed=3, plant=quad)
    data = tm.TimingData(ds, quad.n, quad.m, quad.dt)
    assert data.start == start  # "auto": a rest start is every trial's first input exactly 0
    fit = tm.fit_timing(data, "direct")
    assert fit.delay_s == pytest.approx(0.2127, abs=5e-4)
    assert fit.lag_s == pytest.approx(0.0908, abs=5e-4)
    assert rel_error(fit.K, op.gain(quad)) < 1e-3


def test_a_slow_pilot_is_no_longer_fitted_soft(quad):
    # the failure: the instantaneous regression fits a pilot with a delay and a lag far too soft
    from workbench.method.gain import estimate_gain

    op = LQROperator(**SLOW_PILOT, delay_s=0.2, lag_s=0.08, start="rest")
    ds = lqr_operator_demos(op, 20, seed=4, plant=quad)
    K = op.gain(quad)
    timing = tm.identify_timing(ds, quad, n_boot=0)
    K_plain = estimate_gain(ds, quad, "direct")
    print(f"K[u1, phi]: true {K[0, 2]:.3f}, instantaneous {K_plain[0, 2]:.3f}, timed {timing.K[0, 2]:.3f}; "
          f"{timing.describe()}")
    assert abs(K_plain[0, 2] / K[0, 2]) < 0.5  # what main does: far too soft
    assert abs(timing.K[0, 2] / K[0, 2] - 1) < 0.2
    assert abs(timing.delay_s - 0.2) < 0.02 and abs(timing.lag_s - 0.08) < 0.02


def test_the_paper_pilot_is_found_without_timing(quad):
    # a pilot without either: the delay and the lag come out near 0, the gain as the instantaneous instruments give
    ds = lqr_operator_demos(LQROperator(), 20, seed=5, plant=quad)
    timing = tm.identify_timing(ds, quad, n_boot=0)
    assert timing.delay_s < 0.03 and timing.lag_s < 0.03
    assert rel_error(timing.K, LQROperator().gain(quad)) < 0.1


def test_intervals_fixed_values_and_bad_input(quad):
    ds = lqr_operator_demos(LQROperator(**SLOW_PILOT, delay_s=0.15, lag_s=0.05, start="rest"), 12, seed=6,
                            plant=quad)
    t = tm.identify_timing(ds, quad, n_boot=8, seed=1)
    assert t.delay_lo <= t.delay_s <= t.delay_hi and t.lag_lo <= t.lag_s <= t.lag_hi
    assert t.K_samples.shape == (8 - t.n_failed, 2, 6) and t.delay_samples.shape == (8 - t.n_failed,)
    assert "reaction delay" in t.describe() and "[" in t.describe()
    given = tm.identify_timing(ds, quad, delay_s=0.15, lag_s=0.05, n_boot=0)
    assert given.fixed == ("delay", "lag") and given.delay_s == 0.15 and "(given)" in given.describe()
    with pytest.raises(DataError, match="delay_s must lie"):
        tm.identify_timing(ds, quad, delay_s=2.0)
    with pytest.raises(DataError, match="start must be"):
        tm.TimingData(ds, quad.n, quad.m, quad.dt, start="sometimes")
    with pytest.raises(DataError, match="no demonstration has two"):
        tm.TimingData([SimpleNamespace(x=ds[0].x[:1], u=ds[0].u[:1])], 6, 2, quad.dt)


@pytest.mark.slow
def test_the_landing_simulators_cascade_is_refused(quad):
    # no delay, no lag, saturations: its best fit is the longest lag searched (30 trials; with 12 it is not)
    from workbench.errors import ModelError
    from workbench.sim.landing import simulate_landings

    with pytest.raises(ModelError, match="end of the range searched"):
        tm.identify_timing(simulate_landings("CS1", 30, seed=11), quad, n_boot=0)


def _counts(seed: int, n_trials: int, n_boot: int) -> list[np.ndarray]:
    # each resample's multiplicities, drawn as identify_timing draws them
    rng = np.random.default_rng(seed)
    return [np.bincount(rng.integers(0, n_trials, size=n_trials), minlength=n_trials) for _ in range(n_boot)]


def test_a_refused_timing_falls_back_to_the_rule_in_every_resample(quad):
    # four trials whose starts explain nothing beyond chance: no timing on all trials, so the default rule gives the
    # paper's gain there, and every resample fits that same gain (two-stage least squares, no relevance pretest),
    # even the resamples whose own trials would have identified a timing: they are counted, not mixed in
    from workbench.errors import ModelError
    from workbench.method.gain import choose_gain, demo_blocks
    from workbench.method.resampling import _rule_fit, bootstrap_gain

    ds = lqr_operator_demos(LQROperator(), 4, seed=20, plant=quad)
    with pytest.raises(ModelError, match="no better than chance"):
        tm.identify_timing(ds, quad, n_boot=0)
    g = bootstrap_gain(ds, quad, n_boot=2, method="iv", seed=0, jackknife=False, timing="identify-or-none")
    K, choice = choose_gain(ds, quad)
    np.testing.assert_allclose(g.K, K, atol=1e-10)
    assert g.timing.method == "none" and "pilot timing: none" in g.timing.describe()
    assert g.timing.n_timed == 0 and g.n_failed == 0 and g.timing.n_otherwise >= 1
    assert f"{g.timing.n_otherwise} of them would have identified a timing" in g.timing.describe()
    blocks = demo_blocks(list(ds), quad.n, quad.m)
    rule = [_rule_fit(blocks, np.repeat(np.arange(4), c), quad.A, quad.B, choice.method) for c in _counts(0, 4, 2)]
    np.testing.assert_allclose(g.K_samples, np.array(rule), atol=1e-9)


def test_an_identified_timing_is_kept_in_every_resample(quad):
    # four trials whose starts are relevant on all trials (the timing identified), though most resamples repeat a
    # trial and alone would refuse it: every resample still fits the timed gain, the estimator printed (on the
    # previous main those resamples took the paper's gain instead, and K̂'s interval mixed the two)
    from workbench.method.resampling import bootstrap_gain

    ds = lqr_operator_demos(LQROperator(), 4, seed=8, plant=quad)
    g = bootstrap_gain(ds, quad, n_boot=6, method="iv", seed=0, jackknife=False, timing="identify-or-none")
    assert g.timing.method == "liml" and g.timing.n_timed == 6 - g.n_failed and g.timing.n_otherwise >= 1
    assert f"{g.timing.n_otherwise} of them would have refused the timing" in g.timing.describe()
    data = tm.TimingData(ds, quad.n, quad.m, quad.dt)
    timed = [tm.fit_timing(data, "liml", counts=c).K for c in _counts(0, 4, 6)]
    np.testing.assert_allclose(g.K_samples, np.array(timed), atol=1e-9)


def test_the_gains_interval_is_the_estimate_plus_minus_t_standard_deviations():
    from scipy import stats

    from workbench.method.resampling import gain_interval

    rng = np.random.default_rng(3)
    K = rng.normal(size=(2, 3))
    samples = K + rng.normal(scale=0.1, size=(50, 2, 3))
    lo, hi = gain_interval(K, samples, n_trials=20, ci=95.0)
    half = stats.t.ppf(0.975, 19) * samples.std(axis=0, ddof=1)
    np.testing.assert_allclose(lo, K - half)
    np.testing.assert_allclose(hi, K + half)
