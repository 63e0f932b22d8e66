"""Weight ratios inside coupled parts, and whether their bootstrap intervals cover known costs.

Two LQR operators (:mod:`workbench.operators`) with known diagonal costs and zero-mean, AR(1), state-dependent
variability: B weights the attitude 46× and the horizontal and vertical positions 4× and 2× more than A.
The gain is estimated by instrumental variables (least squares is biased in closed loop), the cost is the
closest diagonal one, and each ratio's factor B/A gets a 95 % percentile interval from 2 × n_boot resamples,
each operator's trials resampled with its own seed (independent resamples).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from workbench.errors import ModelError
from workbench.ioc import bootstrap, decoupled_parts
from workbench.operators import LQROperator, lqr_operator_demos
from workbench.system import planar_quadrotor
from workbench.weights import NOT_IDENTIFIABLE, RatioInterval, compare_strategies, weight_ratios

OP_A = LQROperator(q=(1.0, 1.0, 1.0, 0.3, 0.3, 0.01), r=(10.0, 10.0))
OP_B = LQROperator(q=(4.0, 2.0, 46.0, 0.3, 0.3, 0.01), r=(10.0, 10.0))


def true_factors(system) -> dict[str, float]:
    """Factor B/A of every ratio Q_ii / R_kk inside a part, from the operators' costs."""
    out = {}
    for states, inputs in decoupled_parts(system.A, system.B):
        k = inputs[0]
        for i in states:
            name = f"Q_{system.state_names[i]} / R_{system.input_names[k]}"
            out[name] = (OP_B.q[i] / OP_B.r[k]) / (OP_A.q[i] / OP_A.r[k])
    return out


def coverage(seeds, n_boot: int, n_demos: int = 30) -> pd.DataFrame:
    system = planar_quadrotor()
    truth = true_factors(system)
    rows = []
    for seed in seeds:
        boots = {
            "A": bootstrap(lqr_operator_demos(OP_A, n_demos, seed=1000 + seed, system=system), system,
                           n_boot=n_boot, method="iv", structure="diagonal", seed=seed),
            "B": bootstrap(lqr_operator_demos(OP_B, n_demos, seed=2000 + seed, system=system), system,
                           n_boot=n_boot, method="iv", structure="diagonal", seed=50000 + seed),
        }
        table = compare_strategies(boots, system.state_names, system.input_names)
        for r in table[table["strategy"] == "B"].itertuples():
            t = truth[r.ratio]
            rows.append({"seed": seed, "ratio": r.ratio, "truth": t, "factor": r.factor, "lo": r.factor_lo,
                         "hi": r.factor_hi, "covered": r.factor_lo <= t <= r.factor_hi,
                         "identifiable": r.factor_identifiable})
    return pd.DataFrame(rows)


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    s = df.groupby("ratio").agg(coverage=("covered", "mean"), identifiable=("identifiable", "mean"),
                                median_factor=("factor", "median"), truth=("truth", "first"))
    print(s.to_string())
    return s


def test_attitude_ratio_interval_covers_the_truth_on_a_few_seeds():
    s = summarize(coverage(seeds=(20, 21), n_boot=30))
    assert s.loc["Q_phi / R_u1", "coverage"] == 1.0
    # the position ratios are identifiable (interval within 10×)
    for name in ("Q_x / R_u1", "Q_y / R_u2"):
        assert s.loc[name, "identifiable"] == 1.0


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "issue 10's bar (every ratio covered in >= 90 % of seeds) is not met: with independent resamples the 95 % "
    "percentile intervals (100 resamples, 30 trials per operator) cover Q_x/R_u1 in 0.80 and Q_phidot/R_u1 in 0.76 "
    "of seeds 100-124 (seeds 20-44: all >= 0.92); the bootstrap spread of log Q_x/R_u1 (0.099) is below its spread "
    "across seeds (0.115), and neither BC/BCa or basic intervals on the log scale (Q_x 0.80-0.84) nor 400 "
    "resamples (Q_x 0.84, Q_phidot 0.76) fix it"))
def test_ratio_intervals_cover_the_truth_in_ninety_percent_of_seeds():
    # 2 × 25 seeds × 2 operators × 100 resamples: ~12 min on an idle 2-core machine. The first 25 seeds are the
    # ones the intervals were examined on, the second 25 were not looked at before the measurement.
    s = summarize(coverage(seeds=[*range(20, 45), *range(100, 125)], n_boot=100))
    for name, row in s.iterrows():
        assert row["coverage"] >= 0.9, f"{name}: coverage {row['coverage']:.2f} < 0.9"


def fake_boot(q_samples, r_samples, q, r, parts, ci=95.0, structure="diagonal"):
    obj = SimpleNamespace(Q=np.diag(q), R=np.diag(r), parts=parts)
    return SimpleNamespace(objective=obj, Q_diag_samples=np.asarray(q_samples), R_diag_samples=np.asarray(r_samples),
                           ci=ci, structure=structure)


def test_factor_and_identifiability_are_computed_from_paired_resamples():
    parts = (((0, 1), (0,)),)
    rng = np.random.default_rng(0)
    qa = np.c_[np.exp(rng.normal(0, 0.05, 200)), np.exp(rng.normal(0, 2.0, 200))]
    ra = np.ones((200, 1))
    a = fake_boot(qa, ra, [1.0, 1.0], [1.0], parts)
    b = fake_boot(3 * qa, ra, [3.0, 3.0], [1.0], parts)
    table = compare_strategies({"a": a, "b": b}, ["p", "s"], ["u"])
    row_p = table[(table.strategy == "b") & (table.ratio == "Q_p / R_u")].iloc[0]
    # paired resamples: b's samples are exactly 3× a's, so the factor's interval collapses onto 3
    assert row_p.factor == pytest.approx(3.0) and row_p.factor_lo == pytest.approx(3.0)
    assert row_p.factor_hi == pytest.approx(3.0) and row_p.factor_identifiable
    row_s = table[(table.strategy == "a") & (table.ratio == "Q_s / R_u")].iloc[0]
    lo, hi = np.percentile(qa[:, 1], [2.5, 97.5])
    assert row_s.lo == pytest.approx(lo) and row_s.hi == pytest.approx(hi)
    assert (hi / lo > 10) == (row_s.note == NOT_IDENTIFIABLE)
    intervals = weight_ratios(a, ["p", "s"], ["u"])
    assert [iv.name for iv in intervals] == ["Q_p / R_u", "Q_s / R_u"]
    assert NOT_IDENTIFIABLE in RatioInterval("r", 1.0, 0.5, 6.0, 95).describe()
    assert NOT_IDENTIFIABLE not in RatioInterval("r", 1.0, 0.5, 4.9, 95).describe()
    # a weight at the bottom of the search (zero) is no finite ratio, however narrow its interval
    assert not RatioInterval("r", 1e-13, 1e-13, 2e-13, 95).identifiable


def test_factor_needs_independent_resamples():
    parts = (((0,), (0,)),)
    a = fake_boot(np.ones((3, 1)), np.ones((3, 1)), [1.0], [1.0], parts)
    b = fake_boot(np.ones((3, 1)), np.ones((3, 1)), [2.0], [1.0], parts)
    same = {"a": SimpleNamespace(**vars(a), seed=7), "b": SimpleNamespace(**vars(b), seed=7)}
    with pytest.raises(ModelError, match="same seed"):
        compare_strategies(same, ["p"], ["u"])
    apart = {"a": SimpleNamespace(**vars(a), seed=7), "b": SimpleNamespace(**vars(b), seed=8)}
    assert compare_strategies(apart, ["p"], ["u"]).query("strategy == 'b'").factor.iloc[0] == pytest.approx(2.0)


def test_ratios_need_the_diagonal_structure():
    boot = fake_boot(np.ones((3, 2)), np.ones((3, 1)), [1, 1], [1], (), structure="full")
    with pytest.raises(ModelError, match="diagonal"):
        weight_ratios(boot, ["p", "s"], ["u"])
