"""Assumption 3 judged with its uncertainty (issue 41 §3): ρ(A + BK̂) on the regulated states, with its interval.

Questions answered: does a free flight (no goal) become a model of the loops its pilot closes, where the paper's
refusal stopped it on ρ = 1.0000x (previous main refused the first data set below)? Does a ρ whose interval holds 1
give a model, its margin said, without a task objective where ρ̂ ≥ 1? Does a loop clearly outside the unit circle
stop, naming the states of its slow mode and its interval? Does the interval cover the true ρ of an operator whose
gain is known? Does the judgement survive a model file?
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.errors import ModelError
from workbench.method.objective import forward_gain
from workbench.method.stability import Stability, judge_stability
from workbench.models import HumanBehaviorModel, IOCOnlyModel
from workbench.plant.system import planar_quadrotor

INNER = [2, 3, 4, 5]  # phi, xdot, ydot, phidot of the planar quadrotor


def free_flight(seed: int, n_trials: int = 8, duration_s: float = 20.0, targets: bool = False):
    """A pilot who flies the inner loops only (attitude, velocities: an LQR of them) and lets the position wander:
    nobody steers back to an absolute x, y. Stick noise AR(1), ρ = 0.9 per step."""
    p = planar_quadrotor()
    A, B = p.A[np.ix_(INNER, INNER)], p.B[INNER]
    K = np.zeros((2, 6))
    K[:, INNER] = forward_gain(A, B, np.diag([1.0, 0.5, 0.5, 0.01]), np.diag([10.0, 10.0]))[0]
    rng = np.random.default_rng(seed)
    N = int(round(duration_s / p.dt))
    demos = []
    for j in range(n_trials):
        x = np.zeros(6)
        x[:2] = rng.uniform(-20, 20, 2)
        x[INNER] = rng.normal(0, [0.1, 1.0, 0.5, 0.2])
        e = np.zeros(2)
        xs, us = np.empty((N, 6)), np.empty((N, 2))
        for k in range(N):
            e = 0.9 * e + np.sqrt(1 - 0.81) * rng.standard_normal(2)
            u = K @ x + np.array([0.02, 0.05]) * e
            xs[k], us[k] = x, u
            x = p.A @ x + p.B @ u
        meta = {"id": f"f{j}", **({"target": [0.0] * 6} if targets else {})}
        demos.append(Demonstration(p.dt * np.arange(N), xs, us, meta))
    return p, DemonstrationSet(demos, p.state_names, p.input_names, p.dt, roles=p.roles), K


def test_a_free_flight_models_the_inner_loops_its_pilot_closes():
    # previous main: "the gain is not stabilizing: ρ(A + B K) = 1.00008 ≥ 1" (the positions' integrators at 1 ± ε)
    p, ds, K = free_flight(seed=0)
    # the regulator's ρ(A + BK̂) with its interval: the paper's instantaneous gain (a model that identifies the
    # pilot's timing judges the pilot's delayed loop instead, below)
    model = IOCOnlyModel(p, noise_folds=0, timing="none").fit(ds)
    assert model.task_.relative_to == "zero"
    assert model.task_.regulated == tuple(p.state_names[i] for i in INNER)
    assert np.all(model.K_[:, :2] == 0)  # no gain on the absolute positions
    assert model.stability_.states == model.task_.regulated
    assert model.stability_.verdict != "unstable" and model.stability_.lo < model.stability_.rho < 1.0
    # the one line fit prints says which states, relative to what, and why
    line = model.task_.describe(p.state_names)
    assert "phi, xdot, ydot, phidot relative to zero" in line and "no goal" in line
    # the model predicts the whole state: the positions move on with the predicted velocities
    pred = model.predict(ds[0].x[0], 20)
    assert np.allclose(pred.x[1:, 0] - pred.x[:-1, 0], p.dt * pred.x[:-1, 3])
    # the default model identifies the pilot's timing and judges the loop it flew, on the same inner loops
    timed = IOCOnlyModel(p, noise_folds=0).fit(ds)
    assert timed.task_.regulated == model.task_.regulated and np.all(timed.K_[:, :2] == 0)
    assert timed.stability_.verdict == "stable" and timed.stability_.rho < 1.0
    assert (timed.timing_ is None) == (timed.stability_.loop == "A + BK̂")


@pytest.mark.parametrize("seed", [0, 2, 3])
def test_a_rho_within_its_interval_of_one_is_a_model_with_its_margin_said(seed):
    # the same pilot with a goal declared: the task regulates the positions too, which this pilot never brings back,
    # so ρ̂ sits at 1 ± 1e-4 — previous main refused these three seeds ("ρ = 1.00006 ≥ 1" …)
    p, ds, _ = free_flight(seed, duration_s=10.0, targets=True)
    model = IOCOnlyModel(p, fit_objective=True, noise_folds=0).fit(ds)
    s = model.stability_
    assert s.verdict == "not distinguishable" and s.lo <= 1.0 <= s.hi
    assert set(s.slow_states) & {"x", "y"}
    assert "not distinguishable from the unit circle" in s.describe() and "margin" in s.describe()
    if s.rho >= 1.0:  # no cost has a gain with ρ ≥ 1: the objective is not found, and the model says why
        assert model.objective_ is None and "Assumption 3" in model.objective_error_


def test_a_loop_clearly_outside_the_unit_circle_is_refused_naming_its_slow_states():
    p = planar_quadrotor()
    rng = np.random.default_rng(4)
    K = np.zeros((2, 6))
    K[1, 4] = 0.05  # the throttle pushes the climb rate on: the vertical speed runs away
    K[0, [2, 5]] = [-1.0, -0.05]
    demos = []
    for j in range(12):
        x = np.zeros(6)
        x[:2] = rng.uniform(-2, 2, 2)
        x[INNER] = rng.normal(0, [0.05, 0.3, 0.3, 0.1])
        xs, us = np.empty((60, 6)), np.empty((60, 2))
        for k in range(60):
            u = K @ x + 0.02 * rng.standard_normal(2)
            xs[k], us[k] = x, u
            x = p.A @ x + p.B @ u
        demos.append(Demonstration(p.dt * np.arange(60), xs, us, {"id": f"u{j}", "target": [0.0] * 6}))
    ds = DemonstrationSet(demos, p.state_names, p.input_names, p.dt, roles=p.roles)
    with pytest.raises(ModelError, match=r"not stabilizing: closed loop on x, y, phi, xdot, ydot, phidot: "
                                         r"ρ\(A \+ BK̂\) = 1\.\d+, 95 % interval \[1\.\d+, 1\.\d+\].*unstable; "
                                         r"the slow mode lies on y\b") as exc:
        HumanBehaviorModel(p, gain_method="direct", noise_folds=0).fit(ds)
    assert "autopilot" not in str(exc.value)  # no mode was flown: none is named


def test_the_interval_covers_the_true_rho_of_a_known_gain():
    """Does the resampled interval cover ρ of the gain the operator used? A smoke check on 6 seeds (the coverage
    proper, 40 seeds at 95 % nominal, is ``bench/bench_stability.py``)."""
    from workbench.data.pilot_task import PilotTask
    from workbench.method.gain import choose_gain
    from workbench.models.regulator import pilot_view
    from workbench.sim.operators import LQROperator, lqr_operator_demos

    p, op = planar_quadrotor(), LQROperator()
    rho_true = float(np.abs(np.linalg.eigvals(p.A + p.B @ op.gain(p))).max())
    hits = 0
    for seed in range(500, 504):
        views = pilot_view(p, PilotTask(), list(lqr_operator_demos(op, 10, seed=seed)))
        K, choice = choose_gain(views, p, check=False)
        s = judge_stability(p.A, p.B, K, views, choice.method, p.dt, p.state_names, seed=seed)
        assert s.verdict == "stable" and s.n_resamples == 200
        hits += s.lo <= rho_true <= s.hi
    assert hits >= 3  # P(≥ 3 of 4 | coverage 0.95) = 0.99


def test_the_judgement_round_trips_through_a_model_file(tmp_path):
    from workbench.models.storage import load_model

    p, ds, _ = free_flight(seed=0, n_trials=4, duration_s=8.0)
    model = IOCOnlyModel(p, noise_folds=0).fit(ds)
    back = load_model(model.save(tmp_path / "m.npz"))
    assert back.task_ == model.task_ and back.regulated_ == model.regulated_
    assert back.stability_ == model.stability_ and isinstance(back.stability_, Stability)
    x0 = ds[1].x[0]
    assert np.allclose(back.predict(x0, 30).x, model.predict(x0, 30).x)


def test_the_pilots_timed_loop_gets_its_interval_from_the_timing_resamples():
    # the fit judges the timed loop at its point alone; the bootstrap's resampled (K, delay, lag) give ρ's interval
    # by the rule of the untimed loop (the union of the percentile and the basic interval), and the verdict follows
    from types import SimpleNamespace

    from workbench.method.stability import with_timing_resamples
    from workbench.method.timing import timed_spectral_radius

    quad = planar_quadrotor()
    K = forward_gain(quad.A, quad.B, np.diag([0.1, 1.0, 1.0, 0.1, 0.3, 0.01]), np.diag([40.0, 10.0]))[0]
    rho = timed_spectral_radius(quad.A, quad.B, K, 0.2, 0.08, quad.dt)
    point = Stability(rho=rho, lo=np.nan, hi=np.nan, verdict="stable", loop="the pilot's loop", n_units=20)
    assert "no interval here" in point.describe()
    rng = np.random.default_rng(0)

    def timing(spread: float) -> SimpleNamespace:
        return SimpleNamespace(method="liml", n_trials=20, K_samples=K * (1 + spread * rng.normal(size=(40, 1, 1))),
                               delay_samples=0.2 + 0.01 * rng.normal(size=40),
                               lag_samples=np.abs(0.08 + 0.01 * rng.normal(size=40)))

    t = timing(0.05)
    judged = with_timing_resamples(point, quad.A, quad.B, quad.dt, t)
    rhos = [timed_spectral_radius(quad.A, quad.B, k, d, g, quad.dt)
            for k, d, g in zip(t.K_samples, t.delay_samples, t.lag_samples, strict=True)]
    q_lo, q_hi = np.percentile(rhos, [2.5, 97.5])
    assert judged.lo == pytest.approx(min(q_lo, 2 * rho - q_hi, rho))
    assert judged.hi == pytest.approx(max(q_hi, 2 * rho - q_lo, rho))
    assert judged.n_resamples == 40 and judged.unit == "trials"
    assert "over 40 resamples of 20 trials" in judged.describe()
    assert judged.verdict == ("stable" if judged.hi < 1 else "not distinguishable")
    # resampled gains twice as stiff reach the unit circle: the verdict says so
    wide = with_timing_resamples(point, quad.A, quad.B, quad.dt, timing(1.5))
    assert wide.hi > 1 and wide.verdict == "not distinguishable"
    # no timed resamples (a refused timing): the point's judgement as it was
    assert with_timing_resamples(point, quad.A, quad.B, quad.dt, SimpleNamespace(method="none")) is point


def test_without_an_interval_a_loop_outside_the_unit_circle_is_not_refused():
    """One short demonstration is one 2 s block: nothing to resample, so no interval. ρ̂ ≥ 1 is then not
    distinguishable from the unit circle — no refusal decided by a point estimate whose uncertainty is unknown (a
    real log's 5 s time-split piece was refused at ρ̂ 1.2238, "no interval") — and ρ̂ < 1 stays stable."""
    p = planar_quadrotor()
    K_lqr = forward_gain(p.A, p.B, np.eye(6), np.eye(2))[0]
    rng = np.random.default_rng(0)
    view = Demonstration(p.dt * np.arange(15), rng.normal(size=(15, 6)), rng.normal(size=(15, 2)), {"id": "short"})
    for K in (K_lqr, -0.3 * K_lqr):
        rho = float(np.abs(np.linalg.eigvals(p.A + p.B @ K)).max())
        s = judge_stability(p.A, p.B, K, [view], "direct", p.dt, p.state_names)
        assert not s.has_interval and s.rho == pytest.approx(rho)
        assert s.verdict == ("stable" if rho < 1.0 else "not distinguishable") and not s.refused
    assert float(np.abs(np.linalg.eigvals(p.A + p.B @ (-0.3 * K_lqr))).max()) > 1.0  # the second gain is outside
