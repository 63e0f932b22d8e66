"""Weight ratios inside coupled parts, and whether their intervals cover known costs.

Two LQR operators (:mod:`workbench.sim.operators`) with known diagonal costs and zero-mean, AR(1), state-dependent
variability: B weights the attitude 46× and the horizontal and vertical positions 4× and 2× more than A.
The gain is estimated by instrumental variables (least squares is biased in closed loop), its covariance by
resampling each operator's trials with its own seed, and each ratio's factor B/A gets a 95 % profile interval
(:mod:`workbench.method.ratio_profile`).
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from workbench.defaults import OBJECTIVE_RESAMPLES
from workbench.errors import DataError, ModelError
from workbench.method import ratio_profile
from workbench.method.objective import forward_gain
from workbench.method.resampling import bootstrap_gain
from workbench.method.structured import decoupled_parts
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import LQROperator, lqr_operator_demos
from workbench.study.weights import (
    NOT_EXPLAINED,
    NOT_IDENTIFIABLE,
    RatioInterval,
    compare_strategies,
    format_interval,
    weight_ratios,
)

OP_A = LQROperator(q=(1.0, 1.0, 1.0, 0.3, 0.3, 0.01), r=(10.0, 10.0))
OP_B = LQROperator(q=(4.0, 2.0, 46.0, 0.3, 0.3, 0.01), r=(10.0, 10.0))


# A second pair never used to choose the method: other costs, a less persistent hand (ρ = 0.85)
OP_C = LQROperator(q=(2.0, 0.5, 5.0, 0.1, 0.6, 0.05), r=(5.0, 20.0), rho=0.85)
OP_D = LQROperator(q=(0.5, 3.0, 0.5, 0.1, 0.6, 0.05), r=(5.0, 10.0), rho=0.85)


def true_ratios(plant, op: LQROperator) -> dict[str, float]:
    """Every ratio Q_ii / R_kk inside a part, from an operator's cost."""
    out = {}
    for states, inputs in decoupled_parts(plant.A, plant.B):
        k = inputs[0]
        for i in states:
            out[f"Q_{plant.state_names[i]} / R_{plant.input_names[k]}"] = op.q[i] / op.r[k]
    return out


def true_factors(plant, a: LQROperator = OP_A, b: LQROperator = OP_B) -> dict[str, float]:
    """Factor b/a of every ratio Q_ii / R_kk inside a part, from the operators' costs."""
    ra, rb = true_ratios(plant, a), true_ratios(plant, b)
    return {name: rb[name] / ra[name] for name in ra}


def coverage(seeds, n_boot: int, n_demos: int = 30, a: LQROperator = OP_A, b: LQROperator = OP_B,
             own: list | None = None) -> pd.DataFrame:
    """Per seed and ratio, whether the factor's interval covers the truth; with ``own`` a list, each operator's
    own ratio intervals are recorded there too (``finite``: an interval that reaches neither 0 nor ∞)."""
    plant = planar_quadrotor()
    truth = true_factors(plant, a, b)
    rows = []
    for seed in seeds:
        ratios = {
            "A": weight_ratios(bootstrap_gain(lqr_operator_demos(a, n_demos, seed=1000 + seed, plant=plant),
                                              plant, n_boot=n_boot, method="iv", seed=seed), plant),
            "B": weight_ratios(bootstrap_gain(lqr_operator_demos(b, n_demos, seed=2000 + seed, plant=plant),
                                              plant, n_boot=n_boot, method="iv", seed=50000 + seed), plant),
        }
        if own is not None:
            for lb, op in (("A", a), ("B", b)):
                t = true_ratios(plant, op)
                for iv in ratios[lb].intervals:
                    own.append({"seed": seed, "operator": lb, "ratio": iv.name, "covered": iv.lo <= t[iv.name] <= iv.hi,
                                "finite": bool(np.isfinite(iv.span)), "of_form": iv.explained})
        table = compare_strategies(ratios)
        for r in table[table["strategy"] == "B"].itertuples():
            t = truth[r.ratio]
            rows.append({"seed": seed, "ratio": r.ratio, "truth": t, "factor": r.factor, "lo": r.factor_lo,
                         "hi": r.factor_hi, "covered": r.factor_lo <= t <= r.factor_hi,
                         "identifiable": r.factor_identifiable, "explained": not str(r.factor_note).startswith(
                             NOT_EXPLAINED)})
    return pd.DataFrame(rows)


def own_summary(own: list) -> pd.DataFrame:
    """Coverage of each operator's ratio intervals where they are finite, and how often they are."""
    df = pd.DataFrame(own)
    finite = df[df["finite"]]
    s = finite.groupby(["operator", "ratio"]).agg(coverage=("covered", "mean"), finite=("covered", "size"))
    s["seeds"] = df.groupby(["operator", "ratio"]).size()
    s["of_form"] = df.groupby(["operator", "ratio"])["of_form"].mean()
    print(s.to_string())
    return s


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    s = df.groupby("ratio").agg(coverage=("covered", "mean"), identifiable=("identifiable", "mean"),
                                explained=("explained", "mean"), median_factor=("factor", "median"),
                                truth=("truth", "first"))
    print(s.to_string())
    return s


def test_ratio_intervals_on_a_seed():
    # a smoke test of the whole chain on one seed (two operators); coverage proper is the slow tests' below
    own: list = []
    s = summarize(coverage(seeds=(20,), n_boot=40, own=own))
    # LQR operators: their parts are of the diagonal form (untested: no restrictions; no mismatch shown)
    assert (s["explained"] == 1.0).all()
    # the position ratios are identifiable (interval within 10×) and cover their factor
    for name in ("Q_x / R_u1", "Q_y / R_u2"):
        assert s.loc[name, "identifiable"] == 1.0 and s.loc[name, "coverage"] == 1.0
    o = own_summary(own)
    assert o.loc[("A", "Q_y / R_u2"), "coverage"] == 1.0 and o.loc[("B", "Q_y / R_u2"), "coverage"] == 1.0


@pytest.mark.slow
@pytest.mark.parametrize("n_demos", [30, 60])
def test_every_finite_ratio_interval_covers_in_ninety_percent_of_seeds(n_demos):
    # seeds 500-529, never used to choose the method (chosen on 0-199): each operator's own ratios and the factors
    # between them. ~7 min at 30 demonstrations, ~8 at 60, on a shared 2-core machine
    own: list = []
    s = summarize(coverage(seeds=range(500, 530), n_boot=100, n_demos=n_demos, own=own))
    o = own_summary(own)
    for name, row in s.iterrows():
        assert row["coverage"] >= 0.9, f"factor {name} at {n_demos}: coverage {row['coverage']:.2f} < 0.9"
    for (op, name), row in o.iterrows():
        assert row["coverage"] >= 0.9, f"{op} {name} at {n_demos}: coverage {row['coverage']:.2f} < 0.9"
        # the diagonal form is not rejected on operators whose cost is diagonal
        assert row["of_form"] >= 0.9, f"{op} {name}: not of the form in {1 - row['of_form']:.2f} of seeds"


@pytest.mark.slow
def test_ratio_intervals_cover_the_truth_in_ninety_percent_of_seeds():
    # 50 seeds × 2 operators × 100 resampled gains and the profile intervals: ~4 min on an idle 2-core machine.
    # The method was chosen on seeds 0-39 and 100-139; these seeds were not looked at before the measurement.
    s = summarize(coverage(seeds=range(300, 350), n_boot=100))
    for name, row in s.iterrows():
        assert row["coverage"] >= 0.9, f"{name}: coverage {row['coverage']:.2f} < 0.9"
        # the diagonal form is kept for true diagonal costs in at least 90 % of seeds
        assert row["explained"] >= 0.9, f"{name}: a diagonal cost explains only {row['explained']:.2f}"


@pytest.mark.slow
def test_ratio_intervals_cover_the_truth_on_another_operator_pair():
    # 40 seeds, ~3 min. At a true coverage of 95 %, 40 seeds fall below 0.85 with probability < 1 %: the bar is set
    # by that, not by the run (measured: 0.90-1.00)
    s = summarize(coverage(seeds=range(700, 740), n_boot=100, a=OP_C, b=OP_D))
    for name, row in s.iterrows():
        assert row["coverage"] >= 0.85, f"{name}: coverage {row['coverage']:.2f} < 0.85"


def scalar_plant(a: float = 1.0, b: float = 0.1):
    return SimpleNamespace(A=np.array([[a]]), B=np.array([[b]]), state_names=("p",), input_names=("u",))


def scalar_gain(plant, ratio: float) -> float:
    """The LQR gain (u = K x) of Q / R = ratio on a scalar plant."""
    return float(forward_gain(plant.A, plant.B, np.array([[ratio]]), np.array([[1.0]]))[0][0, 0])


def gains(plant, k_hat: float, sigma: float, n_trials: int = 30, seed: int = 0, n: int = 400):
    """A gain bootstrap whose resampled gains have standard deviation ``sigma`` exactly."""
    z = np.random.default_rng(seed).standard_normal(n)
    z = (z - z.mean()) / z.std(ddof=1)
    return SimpleNamespace(K=np.array([[k_hat]]), K_samples=(k_hat + sigma * z)[:, None, None], n_trials=n_trials,
                           seed=seed)


def test_scalar_interval_is_where_the_gain_is_within_t_sigma():
    plant = scalar_plant()
    k_true, sigma, n = scalar_gain(plant, 2.0), 0.02, 30
    wr = weight_ratios(gains(plant, k_true, sigma, n), plant)
    (iv,) = wr.intervals
    assert iv.estimate == pytest.approx(2.0, rel=1e-4)
    # independently: the ratios whose gain lies t·σ·sqrt(n / (n − 1)) from k̂ (the gain falls with the ratio)
    half = np.sqrt(ratio_profile.critical_value(95, n) * n / (n - 1)) * sigma
    import scipy.optimize

    ends = [scipy.optimize.brentq(lambda lr, k=k: scalar_gain(plant, np.exp(lr)) - k, -10, 10)
            for k in (k_true + half, k_true - half)]
    assert iv.lo == pytest.approx(np.exp(ends[0]), rel=2e-3) and iv.hi == pytest.approx(np.exp(ends[1]), rel=2e-3)
    assert iv.identifiable
    # a gain whose interval reaches 0 (the gain of a zero weight) does not bound the weight away from zero
    loose = weight_ratios(gains(plant, k_true, abs(k_true) / 2, n), plant).intervals[0]
    assert loose.lo < 1e-12 and not loose.identifiable and NOT_IDENTIFIABLE in loose.describe()


def test_factor_interval_is_the_profile_of_the_difference():
    import scipy.optimize

    plant = scalar_plant()
    ka, kb, sa, sb, n = scalar_gain(plant, 1.0), scalar_gain(plant, 3.0), 0.03, 0.05, 30
    wa = weight_ratios(gains(plant, ka, sa, n, seed=1), plant)
    wb = weight_ratios(gains(plant, kb, sb, n, seed=2), plant)
    row = compare_strategies({"a": wa, "b": wb}).query("strategy == 'b'").iloc[0]
    assert row.factor == pytest.approx(3.0, rel=1e-3)
    # independently: min over log ratio t of a of the two operators' whitened distances with b's at t + log f
    c = n / (n - 1)

    def profile(log_f):
        dist = lambda t: ((scalar_gain(plant, np.exp(t)) - ka) ** 2 / (c * sa**2)  # noqa: E731
                          + (scalar_gain(plant, np.exp(t + log_f)) - kb) ** 2 / (c * sb**2))
        return scipy.optimize.minimize_scalar(dist, bounds=(-8, 8), method="bounded", options={"xatol": 1e-9}).fun

    crit = ratio_profile.critical_value(95, n)
    ends = [scipy.optimize.brentq(lambda lf: profile(lf) - crit, a, b) for a, b in ((-3, np.log(3)), (np.log(3), 5))]
    assert row.factor_lo == pytest.approx(np.exp(ends[0]), rel=3e-3)
    assert row.factor_hi == pytest.approx(np.exp(ends[1]), rel=3e-3)


@pytest.mark.slow
def test_factor_interval_covers_at_its_level_when_the_gain_is_gaussian():
    # k̂ ~ N(k, σ²) per operator and resampled gains with that σ: the factor's 95 % interval covers the truth
    # (calibration over 60 draws; the fast suite checks the interval's ends against the profile it is defined by,
    # test_factor_interval_is_the_profile_of_the_difference)
    plant = scalar_plant()
    truth, ka, kb, sigma = 2.0, scalar_gain(plant, 1.0), scalar_gain(plant, 2.0), 0.02
    rng = np.random.default_rng(5)
    covered = []
    for i in range(60):
        wa = weight_ratios(gains(plant, ka + sigma * rng.standard_normal(), sigma, seed=2 * i), plant)
        wb = weight_ratios(gains(plant, kb + sigma * rng.standard_normal(), sigma, seed=2 * i + 1), plant)
        row = compare_strategies({"a": wa, "b": wb}).query("strategy == 'b'").iloc[0]
        covered.append(row.factor_lo <= truth <= row.factor_hi)
    # nominal 95 %; 60 draws: below 0.88 has probability < 1 %
    assert np.mean(covered) >= 0.88


def test_a_gain_no_diagonal_cost_reaches_is_flagged_without_a_test():
    # scalar plant x+ = x + 0.1 u: LQR gains run from 0 (zero state weight) to -10 (deadbeat, infinite ratio); -15
    # still stabilizes but is the gain of no cost
    plant = scalar_plant()
    sigma, n = 0.5, 30
    wr = weight_ratios(gains(plant, -15.0, sigma, n), plant)
    (fit,), (iv,) = wr.fits, wr.intervals
    nearest = scalar_gain(plant, np.exp(ratio_profile.LOG_BOUND))
    assert fit.distance == pytest.approx((nearest + 15.0) ** 2 / (sigma**2 * n / (n - 1)), rel=1e-6)
    # one gain entry, one free ratio: no restriction, so the structure test is not run
    assert fit.restrictions == 0 and not fit.tested and fit.explained is None and np.isnan(fit.critical)
    assert "no restriction to test" in fit.describe()
    # ... but the gain departs from the closest diagonal cost's (the deadbeat gain) by more than its spread
    closest = fit.closest
    assert closest.k_closest[0] == pytest.approx(nearest, rel=1e-6)
    assert closest.mismatch[0] == pytest.approx(-15.0 - nearest, rel=1e-6)
    half = np.sqrt(ratio_profile.critical_value(95, n) * n / (n - 1)) * sigma  # one entry: no Bonferroni
    assert closest.mismatch_hi[0] == pytest.approx(-15.0 - nearest + half, rel=1e-3)
    assert not fit.of_form and not iv.explained and iv.note.startswith(NOT_EXPLAINED + ": mismatch u on p ")
    assert "stiffer than" in iv.note and "%" not in iv.note  # |−15| > |−10|, on the entry's own scale
    assert f"-15 [{closest.k_closest[0] + closest.mismatch_lo[0]:.3g}," in iv.note
    # inside the reachable range the same spread is an exact fit: of the form, with a profile interval
    inside = weight_ratios(gains(plant, scalar_gain(plant, 2.0), sigma, n), plant)
    assert inside.fits[0].of_form and inside.fits[0].closest is None and inside.fits[0].distance < 1e-12
    assert inside.intervals[0].explained


def test_structure_test_runs_only_with_restrictions():
    # the planar quadrotor's parts have as many free ratios as gain entries: never tested
    plant = planar_quadrotor()
    demos = lqr_operator_demos(OP_A, 12, seed=901, plant=plant)
    wr = weight_ratios(bootstrap_gain(demos, plant, n_boot=30, method="iv", seed=1), plant)
    assert [f.restrictions for f in wr.fits] == [0, 0]
    assert all(f.explained is None and not f.tested for f in wr.fits)
    # a part driven by two inputs has restrictions (6 gain entries, 3 + 2 − 1 ratios): tested
    two_inputs = two_input_plant()
    gains = bootstrap_gain(lqr_operator_demos(TWO_INPUT_OP, 30, seed=902, plant=two_inputs), two_inputs, n_boot=60,
                           method="iv", seed=2)
    (fit,) = weight_ratios(gains, two_inputs).fits
    assert fit.restrictions == 2 and fit.tested and fit.explained is not None
    # its reference: Hotelling's with the degrees of freedom of the jackknife covariance (the part is the plant)
    loo = gains.K_loo.reshape(30, -1)
    nu = ratio_profile.effective_dof(loo - loo.mean(axis=0))
    assert fit.dof == pytest.approx(nu) and 2 < nu <= 29
    # ... with one restriction more per ratio fitted at a zero or infinite weight
    assert fit.critical == pytest.approx(ratio_profile.critical_value(95, 30, 2 + fit.edges, dof=nu))


def two_input_plant():
    from workbench.plant.system import LinearSystem

    dt = 0.05
    # position, velocity and a lagged actuator state; input b drives both the velocity and the lag
    return LinearSystem(A=np.array([[1.0, dt, 0.0], [0.0, 1.0, 0.3 * dt], [0.0, 0.0, 0.9]]),
                        B=np.array([[0.0, 0.0], [dt, 0.5 * dt], [0.0, dt]]), dt=dt,
                        state_names=("p", "v", "w"), input_names=("a", "b"))


TWO_INPUT_OP = LQROperator(q=(1.0, 0.3, 0.1), r=(10.0, 4.0), sigma_near=(0.01, 0.02), sigma_far=(0.04, 0.06),
                           x0_low=(-2.0, -0.5, -0.5), x0_high=(2.0, 0.5, 0.5), duration=6.0)


def structure_rejections(seeds, n_demos: int = 30, n_boot: int = OBJECTIVE_RESAMPLES,
                         operator: LQROperator = TWO_INPUT_OP) -> float:
    plant = two_input_plant()
    rejected = []
    for seed in seeds:
        demos = lqr_operator_demos(operator, n_demos, seed=3000 + seed, plant=plant)
        (fit,) = weight_ratios(bootstrap_gain(demos, plant, n_boot=n_boot, method="iv", seed=seed), plant).fits
        rejected.append(fit.explained is False)
    return float(np.mean(rejected))


@pytest.mark.slow
def test_structure_test_false_rejections_on_a_diagonal_cost():
    # Seeds 1000-1079, never used to choose anything (0-399 chose the method; 400-439 judged an earlier one, 12.5 %,
    # and have been looked at since). 80 seeds, ≤ 8 rejections for the 10 % bar: at a true level of 5 % the
    # bar fails with probability 1.8 %, at the 6.5 % measured on development seeds 0-199 with 7.5 %, at 10 % with
    # 41 %. Measured: 2.5 % (2 of 80; 5 % without counting ratios at an edge). 2.5 minutes.
    rate = structure_rejections(range(1000, 1080))
    print(f"false rejections of a true diagonal cost: {rate:.3f}")
    assert rate <= 0.10


@dataclass(frozen=True)
class CrossCostOperator(LQROperator):
    """An LQR operator whose cost couples its two inputs (``R_ab = rab √(R_aa R_bb)``): its gain is no diagonal
    cost's."""

    rab: float = 0.0

    def gain(self, plant) -> np.ndarray:
        R = np.diag(self.r)
        R[0, 1] = R[1, 0] = self.rab * np.sqrt(self.r[0] * self.r[1])
        return forward_gain(plant.A, plant.B, np.diag(self.q), R)[0]


def cross_cost_operator(rab: float) -> CrossCostOperator:
    return CrossCostOperator(**asdict(TWO_INPUT_OP), rab=rab)


def two_input_part(K: np.ndarray, sd: float = 0.01) -> ratio_profile.PartDistance:
    """The two-input plant as one part with estimate ``K`` and covariance ``sd² I`` (20 degrees of freedom)."""
    plant = two_input_plant()
    return ratio_profile.PartDistance(A=plant.A, B=plant.B, k_hat=np.ravel(K), W=np.eye(K.size) / sd, n_trials=30,
                                      dof=20.0)


def test_a_ratio_fitted_at_a_zero_weight_is_one_restriction_more():
    plant = two_input_plant()
    theta0 = np.log(np.r_[TWO_INPUT_OP.q, TWO_INPUT_OP.r[1]] / TWO_INPUT_OP.r[0])
    on_edge = []
    for q_w in (0.1, 0.0, -0.2):  # inside, at the edge (Q_w = 0), beyond it (the gain of a negative weight)
        K = forward_gain(plant.A, plant.B, np.diag([1.0, 0.3, q_w]), np.diag(TWO_INPUT_OP.r))[0]
        part = two_input_part(K)
        theta, d = ratio_profile.fit(part, theta0)
        on_edge.append(ratio_profile.at_edge(part, theta).tolist())
        assert ratio_profile.tested_restrictions(part, theta) == part.restrictions + (q_w <= 0)
        assert ratio_profile.explains(part, theta, d, 95)  # distance 0 or 0.95; Hotelling (3, ν = 20): 10.5
    assert on_edge == [[False] * 4] + [[False, False, True, False]] * 2


def test_a_gain_of_no_diagonal_cost_is_rejected():
    plant = two_input_plant()
    gains = bootstrap_gain(lqr_operator_demos(cross_cost_operator(0.8), 30, seed=903, plant=plant), plant,
                           n_boot=60, method="iv", seed=3)
    (fit,) = weight_ratios(gains, plant).fits
    assert fit.tested and fit.explained is False and fit.distance > fit.critical
    assert "does not explain" in fit.describe()
    # the same with a known covariance: the gain of the coupled cost is far from every diagonal cost's
    part = two_input_part(cross_cost_operator(0.8).gain(plant))
    theta, d = ratio_profile.fit(part, np.zeros(part.d))
    assert ratio_profile.explains(part, theta, d, 95) is False


@pytest.mark.slow
def test_structure_test_rejects_a_coupled_cost():
    # power against an operator whose inputs' costs are correlated 0.6: 73 % on seeds 0-99 (81 % before ratios at an
    # edge counted as restrictions, which made the test reject true diagonal costs in 8.5 %); on seeds 1000-1039
    # here 80 % (92.5 % before). One minute.
    rate = structure_rejections(range(1000, 1040), operator=cross_cost_operator(0.6))
    print(f"rejections of a coupled cost: {rate:.3f}")
    assert rate >= 0.5


def test_identifiability_of_an_interval():
    assert NOT_IDENTIFIABLE in RatioInterval("r", 1.0, 0.5, 6.0, 95).describe()
    assert NOT_IDENTIFIABLE not in RatioInterval("r", 1.0, 0.5, 4.9, 95).describe()
    # a weight at the bottom of the search (zero) is no finite ratio, however narrow its interval
    assert not RatioInterval("r", 1e-13, 1e-13, 2e-13, 95).identifiable
    assert not RatioInterval("r", 1e13, 1e13, 1e13, 95).identifiable  # ... or at its top (infinite)
    # the ends of the searched range are no numbers the data gave
    edge_lo, edge_hi = np.exp(-ratio_profile.LOG_BOUND), np.exp(ratio_profile.LOG_BOUND)
    assert format_interval(0.5, 0.25, 1.0) == "0.5 [0.25, 1]"
    # nothing identified: said in words, without an estimate and without 0 or ∞ as numbers (issue 40)
    for est, lo, hi in ((0.5, edge_lo, edge_hi), (7.84e7, edge_lo, edge_hi), (edge_hi, edge_lo, edge_hi),
                        (edge_lo, edge_lo, edge_lo), (edge_hi, edge_hi, edge_hi), (2.0, edge_lo, 5.0),
                        (2.0, 0.5, edge_hi), (2.0, 0.1, 40.0)):
        text = format_interval(est, lo, hi)
        assert text.startswith(NOT_IDENTIFIABLE), text
        assert "∞" not in text and "[0" not in text and f"{est:.3g}" not in text.replace(f"{hi:.3g}", ""), text


def test_factor_needs_independent_resamples():
    plant = scalar_plant()
    a = weight_ratios(gains(plant, scalar_gain(plant, 1.0), 0.02, seed=7), plant)
    b = weight_ratios(gains(plant, scalar_gain(plant, 2.0), 0.02, seed=7), plant)
    with pytest.raises(ModelError, match="same seed"):
        compare_strategies({"a": a, "b": b})
    c = weight_ratios(gains(plant, scalar_gain(plant, 2.0), 0.02, seed=8), plant)
    assert compare_strategies({"a": a, "c": c}).query("strategy == 'c'").factor.iloc[0] == pytest.approx(2.0, rel=1e-3)


def test_gains_that_do_not_vary_give_no_interval():
    plant = scalar_plant()
    k = scalar_gain(plant, 2.0)
    same = SimpleNamespace(K=np.array([[k]]), K_samples=np.full((50, 1, 1), k), n_trials=30, seed=0)
    with pytest.raises(ModelError, match="do not vary"):
        weight_ratios(same, plant)
    with pytest.raises(ModelError, match="two or more"):
        weight_ratios(gains(plant, k, 0.02, n_trials=1), plant)
    with pytest.raises(DataError, match="percentage"):
        weight_ratios(gains(plant, k, 0.02), plant, ci=120)


def continuation_end(joint, theta, value, excess, direction, step=0.25):
    """An interval end by small steps, each fit started from the previous one, then bisection: slow and plain."""
    inside, theta_in = value, theta
    while True:
        nxt = float(np.clip(inside + direction * step, -ratio_profile.LOG_BOUND, ratio_profile.LOG_BOUND))
        dist, th = joint.fit(nxt, theta_in)
        if excess(dist) > 0:
            break
        inside, theta_in = nxt, th
        if abs(nxt) >= ratio_profile.LOG_BOUND:
            return nxt
    outside = nxt
    while abs(outside - inside) > 1e-3:
        mid = 0.5 * (inside + outside)
        dist, th = joint.fit(mid, theta_in)
        inside, theta_in, outside = (inside, theta_in, mid) if excess(dist) > 0 else (mid, th, outside)
    return inside


def test_an_interval_end_is_not_taken_from_one_fit_that_fell_into_another_minimum():
    # a fully coupled 3-state, 2-input plant with wide gain noise: a long, flat profile where a far-started fit
    # can land in another local minimum (found by review: R_v / R_u ended at log 14.0, where the profile was
    # still inside; followed in small steps it stays inside to log 26.6)
    rng = np.random.default_rng(3)
    M = rng.standard_normal((3, 3))
    plant = SimpleNamespace(A=0.9 * M / np.max(np.abs(np.linalg.eigvals(M))), B=rng.standard_normal((3, 2)),
                            state_names=("a", "b", "c"), input_names=("u", "v"))
    K = forward_gain(plant.A, plant.B, np.diag([1.0, 0.2, 5.0]), np.diag([2.0, 0.5]))[0]
    noise = np.random.default_rng(4).standard_normal((400, *K.shape)) * 0.1 * np.maximum(np.abs(K), 1e-3)
    samples = K + noise
    wr = weight_ratios(SimpleNamespace(K=samples[7], K_samples=samples, n_trials=30, seed=4), plant)
    iv = wr.intervals[-1]
    assert iv.name == "R_v / R_u"
    (part, theta, d_min), (_, j) = wr._parts[0], wr._index[-1]
    crit = ratio_profile.critical_value(95, 30, part.d)  # simultaneous over the part's 4 ratios
    reference = continuation_end(ratio_profile._Joint([part], {j: 1.0}), theta, theta[j],
                                 lambda dist: dist - d_min - crit, +1)
    assert np.log(iv.hi) == pytest.approx(reference, abs=0.05)


def test_too_few_resamples_for_the_covariance_is_an_error():
    plant = SimpleNamespace(A=np.eye(2), B=np.array([[0.1], [0.2]]), state_names=("p", "q"), input_names=("u",))
    few = SimpleNamespace(K=np.array([[-1.0, -1.0]]), K_samples=np.zeros((2, 1, 2)), n_trials=30, seed=0)
    with pytest.raises(ModelError, match="more bootstrap resamples"):
        weight_ratios(few, plant)


def test_critical_value_is_hotelling_with_the_given_degrees_of_freedom():
    import scipy.stats

    # ν = n − 1 by default; q = 1 is the squared two-sided Student quantile
    assert ratio_profile.critical_value(95, 30, 3) == pytest.approx(ratio_profile.critical_value(95, 30, 3, dof=29))
    assert ratio_profile.critical_value(95, 30, 1, dof=12.5) == pytest.approx(scipy.stats.t.ppf(0.975, 12.5) ** 2)
    # fewer degrees of freedom, a larger critical value; none left, no finite one
    assert ratio_profile.critical_value(95, 30, 4, dof=15) > ratio_profile.critical_value(95, 30, 4)
    assert ratio_profile.critical_value(95, 30, 4, dof=3) == np.inf


def test_effective_dof_counts_trials_by_their_share_of_the_covariance():
    rng = np.random.default_rng(11)
    n, p = 4000, 3
    z = rng.standard_normal((n, p))
    # equal contributions: every trial counts (the moment match recovers n − 1 up to its sampling noise)
    assert ratio_profile.effective_dof(z - z.mean(axis=0)) == pytest.approx(n - 1, rel=0.1)
    # contributions scaled by s: Satterthwaite's (Σ s²)² / Σ s⁴ of the shares
    s = rng.uniform(-2.0, 2.0, n)
    expected = (n - 1) * np.sum(s**2) ** 2 / (n * np.sum(s**4))
    assert ratio_profile.effective_dof(s[:, None] * z) == pytest.approx(expected, rel=0.1)
    assert expected < 0.6 * n  # uniform starts: barely more than half the trials' worth


def test_leave_one_out_gains_give_the_jackknife_estimate_and_covariance():
    plant = scalar_plant()
    n = 30
    rng = np.random.default_rng(12)
    k_hat = scalar_gain(plant, 2.0)
    loo = k_hat + 0.01 + 0.02 * rng.standard_normal(n)  # leave-one-out gains 0.01 above the estimate on average
    samples = (k_hat + 0.05 * rng.standard_normal(200))[:, None, None]
    part = ratio_profile.PartDistance.from_samples(plant.A, plant.B, np.array([[k_hat]]), samples, n,
                                                   loo[:, None, None])
    # Quenouille: n k̂ − (n − 1) mean k̂₍₋ⱼ₎, and the jackknife variance (n − 1)/n Σ (k̂₍₋ⱼ₎ − mean)²
    assert part.k_hat[0] == pytest.approx(n * k_hat - (n - 1) * loo.mean())
    var = (n - 1) / n * np.sum((loo - loo.mean()) ** 2)
    assert part.W[0, 0] == pytest.approx(1.0 / np.sqrt(var))
    assert part.nu == pytest.approx(ratio_profile.effective_dof((loo - loo.mean())[:, None]))
    # without them: the resamples' covariance times n / (n − 1), and n − 1 degrees of freedom
    plain = ratio_profile.PartDistance.from_samples(plant.A, plant.B, np.array([[k_hat]]), samples, n)
    assert plain.k_hat[0] == k_hat and plain.nu == n - 1
    assert plain.W[0, 0] == pytest.approx(1.0 / np.sqrt(np.var(samples, ddof=1) * n / (n - 1)))


def test_no_verdict_sentence_on_an_infinite_critical_value():
    # "a diagonal cost explains the gain (critical value inf)" was printed after 17 of 100 resamples fitted
    from workbench.study.weights import PartFit

    fit = PartFit(("x", "xdot"), ("u1",), distance=3.2, restrictions=1, critical=float("inf"), explained=True,
                  dof=2.0)
    text = fit.describe()
    assert "no verdict" in text and "explains" not in text and "critical value inf" not in text


def test_the_gain_with_the_pilots_timing_keeps_its_estimate_with_the_jackknifes_covariance():
    # the timed gain is LIML, whose leave-one-out gains each re-identify the timing on a grid: Quenouille's correction
    # (n − 1)(mean k̂₍₋ⱼ₎ − k̂) moved the virtual subjects' gains away from the truth (ratio_profile's docstring)
    plant = scalar_plant()
    n = 30
    rng = np.random.default_rng(13)
    k_hat = scalar_gain(plant, 2.0)
    loo = (k_hat + 0.002 + 0.004 * rng.standard_normal(n))[:, None, None]  # 0.002 above k̂ on average
    samples = (k_hat + 0.02 * rng.standard_normal(200))[:, None, None]
    common = dict(K=np.array([[k_hat]]), K_samples=samples, K_loo=loo, n_trials=n)
    timed = weight_ratios(SimpleNamespace(**common, timing=object()), plant)
    untimed = weight_ratios(SimpleNamespace(**common, timing=None), plant)
    assert timed.intervals[0].estimate == pytest.approx(2.0, rel=1e-4)  # the estimate's own cost
    corrected = n * k_hat - (n - 1) * loo.mean()
    assert untimed._parts[0][0].k_hat[0] == pytest.approx(corrected)
    assert abs(np.log(untimed.intervals[0].estimate / 2.0)) > 0.05  # … which the correction would have moved
    # the covariance and its degrees of freedom are the jackknife's either way
    assert timed._parts[0][0].W[0, 0] == pytest.approx(untimed._parts[0][0].W[0, 0])
    assert timed._parts[0][0].nu == pytest.approx(untimed._parts[0][0].nu)
    # and the words about its gain entries say corrected only where they are
    assert not timed.fits[0].bias_corrected and untimed.fits[0].bias_corrected


def _fieller_ends(ka: float, sa: float, kb: float, sb: float, nu: float) -> tuple[float, float]:
    """Independently: the θ where the pivot ``(k̂_b − θ k̂_a) / √(s_b² + θ² s_a²)`` reaches ``±t_ν``, by root finding
    on either side of ``k̂_b / k̂_a``."""
    import scipy.optimize
    import scipy.stats

    t = scipy.stats.t.ppf(0.975, nu)
    pivot = lambda th: (kb - th * ka) ** 2 - t**2 * (sb**2 + th**2 * sa**2)  # noqa: E731
    est = kb / ka
    return (scipy.optimize.brentq(pivot, est - 50 * abs(est), est),
            scipy.optimize.brentq(pivot, est, est + 50 * abs(est)))


def test_the_gain_entry_factor_is_fiellers_interval_and_the_report_prints_it_beside_the_ratio(capsys, monkeypatch):
    """Two strategies on a scalar plant whose weights differ 3× while their gains differ less: the gain entry's
    factor (second over first) with Fieller's interval from each gain's resampled standard deviation, rendered by the
    report's task-objective section and by the terminal's comparison, beside the weight ratio's factor."""
    import argparse

    from workbench.cli.context import Context
    from workbench.cli.study import _print_objective_comparison
    from workbench.report.markdown import _objective_interval_notes
    from workbench.study.weights import format_gain_factor, gain_contrasts

    plant = scalar_plant()
    ka, kb, sa, sb, n = scalar_gain(plant, 1.0), scalar_gain(plant, 3.0), 0.03, 0.05, 30
    wa = weight_ratios(gains(plant, ka, sa, n, seed=1), plant)
    wb = weight_ratios(gains(plant, kb, sb, n, seed=2), plant)
    table = compare_strategies({"a": wa, "b": wb})
    row = table.query("strategy == 'b'").iloc[0]
    assert row.gain == "K[u, p]" and row.gain_factor == pytest.approx(kb / ka)
    # no leave-one-out gains: each standard error the resampled gains' times √(n / (n − 1)), n − 1 degrees of freedom
    # each, Welch–Satterthwaite's for the pivot's variance at the estimate
    c, th = np.sqrt(n / (n - 1)), kb / ka
    var = (c * sb) ** 2 + (th * c * sa) ** 2
    lo, hi = _fieller_ends(ka, c * sa, kb, c * sb, var**2 / (((c * sb) ** 4 + (th * c * sa) ** 4) / (n - 1)))
    assert (row.gain_factor_lo, row.gain_factor_hi) == pytest.approx((lo, hi), rel=1e-9)
    assert 1.0 < lo < kb / ka < hi and row.gain_factor_identifiable
    shown = format_gain_factor(row.gain_factor, row.gain_factor_lo, row.gain_factor_hi)
    assert shown == f"{kb / ka:.3g} [{lo:.3g}, {hi:.3g}]"
    beside = format_interval(row.factor, row.factor_lo, row.factor_hi)
    want = {"gain entry": "K[u, p]", "strategies": "b / a", "gain factor [interval]": shown,
            "weight ratio": "Q_p / R_u", "its factor": beside}
    assert gain_contrasts(table) == [want]

    # the report: a table of its own, after what the data identify, the same cells; listed among what is identified
    boot = SimpleNamespace(ci=95.0, n_boot=len(wa.gains.K_samples))
    objectives = {lb: SimpleNamespace(boot=boot, ratios=w, ratio_gain="iv", power=None)
                  for lb, w in (("a", wa), ("b", wb))}
    md = "\n".join(_objective_interval_notes(objectives, ["a", "b"], plant.state_names, plant.input_names, table))
    section = md.split("### Gain entries compared between strategies")[1].split("\n### ")[0]
    assert f"| K[u, p] | b / a | {shown} | Q_p / R_u | {beside} |" in section
    assert f"- K[u, p] (beside Q_p / R_u): b / a = {shown}" in md.split("### Gain entries")[0]
    # the terminal (evaluate, report): the same row in its own table
    monkeypatch.setenv("COLUMNS", "200")
    ctx = Context(argparse.Namespace(quiet=False, format=None))
    _print_objective_comparison(ctx, SimpleNamespace(objectives=objectives, ratio_comparison=table))
    out = capsys.readouterr().out
    printed = out.split("gain K̂[u, s] between strategies beside Q_s / R_u")[1]
    cells = r"\s*[│|]?\s*".join(re.escape(c) for c in want.values())
    assert re.search(cells, printed), printed


def test_a_gain_entry_factor_whose_first_entry_is_not_distinguishable_from_zero_is_words():
    # the first strategy's gain within t·s of zero: every factor fits in size (Fieller's set is unbounded), so the
    # report prints words and no estimate; a bounded set that includes 0 says the signs may differ
    from workbench.study.weights import format_gain_factor, gain_factor

    lo, hi = gain_factor(0.01, 0.03, 29, -0.5, 0.03, 29)
    assert (lo, hi) == (-np.inf, np.inf)
    words = format_gain_factor(-50.0, lo, hi)
    assert NOT_IDENTIFIABLE in words and "not distinguishable from 0" in words and "-50" not in words
    lo, hi = gain_factor(-0.5, 0.03, 29, 0.02, 0.03, 29)
    assert lo < 0 < hi and "signs may differ" in format_gain_factor(-0.04, lo, hi)
    # a narrow terminal's table shortens both verdicts and keeps every number
    from workbench.cli.context import shorter_words

    assert shorter_words(words) == "any (first ≈ 0)"
    assert shorter_words(format_gain_factor(-0.04, lo, hi)) == f"{lo:.3g} … {hi:.3g} (sign?)"


def test_a_gain_entrys_standard_error_is_the_jackknifes_where_every_leave_one_out_gain_is_there():
    # the covariance the weight ratios beside it use (ratio_profile.PartDistance.from_samples): CV3 with its
    # effective degrees of freedom, not the resamples' spread
    from workbench.method.ratio_profile import effective_dof
    from workbench.study.weights import entry_error

    n = 30
    rng = np.random.default_rng(3)
    loo = -0.8 + 0.004 * rng.standard_normal((n, 1, 2)) * np.linspace(0.2, 3, n)[:, None, None]
    g = SimpleNamespace(K=np.array([[-0.8, 0.1]]), K_samples=-0.8 + 0.05 * rng.standard_normal((200, 1, 2)),
                        K_loo=loo, n_trials=n)
    se, nu = entry_error(g, 0, 0)
    dev = loo[:, 0, 0] - loo[:, 0, 0].mean()
    assert se == pytest.approx(np.sqrt((n - 1) / n * np.sum(dev**2)))
    assert nu == pytest.approx(effective_dof(dev[:, None])) and nu < n - 1  # unequal trials: fewer than n − 1
    se, nu = entry_error(SimpleNamespace(**{**vars(g), "K_loo": None}), 0, 0)
    assert se == pytest.approx(g.K_samples[:, 0, 0].std(ddof=1) * np.sqrt(n / (n - 1))) and nu == n - 1


def test_a_cause_that_stops_both_gains_is_said_once(monkeypatch):
    """GPS_issues1's fit printed "weight ratios: none (weight ratios with gain 'iv' failed: <cause>. weight ratios
    with gain 'direct' failed: <the same cause>.)"; each cause is said once, naming the gains it stopped."""
    from types import SimpleNamespace

    from workbench.errors import ModelError
    from workbench.method import resampling
    from workbench.models import fitting
    from workbench.study import power
    from workbench.study.weights import ratio_bootstrap

    cause = "the 100 resampled gains do not vary in every direction of the part's 8 gain entries"
    monkeypatch.setattr(power, "as_fitted", lambda model, demos: demos)
    monkeypatch.setattr(power, "regulated_plant", lambda model: None)
    monkeypatch.setattr(fitting, "timing_setting", lambda model: None)

    def fails(*args, method, **kwargs):
        raise ModelError(cause if method == "iv" or same else f"{cause} ({method})")

    monkeypatch.setattr(resampling, "bootstrap_gain", fails)
    model = SimpleNamespace(gain_method_="direct")
    same = True
    ratios, _, note = ratio_bootstrap(model, [], n_boot=3)
    assert ratios is None and note.count(cause) == 1 and "'iv' and 'direct'" in note, note
    same = False  # two causes: each said, with its gain
    _, _, note = ratio_bootstrap(model, [], n_boot=3)
    assert note.count(cause) == 2 and "gain 'iv' failed" in note and "gain 'direct' failed" in note, note
