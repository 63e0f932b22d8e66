"""Acceptance (slow) of the pilot's timing, issue 41 §4: on simulated pilots with a 0.15-0.25 s reaction delay and a
0.05-0.1 s neuromuscular lag (drawn per seed; the rest start of the collect page: the sticks let go until the pilot
reacts), and on pilots with neither, the gain comes out within 20 % of the truth (‖K̂ − K‖/‖K‖, the median over
seeds), its attitude entry K[u1, φ] within 20 % on ≥ 90 % of seeds, and the delay's 95 % interval holds the true
delay on ≥ 90 % of seeds.

Seeds start at 7000: no default of the workbench was chosen on them (the timing's search grid and its refusal rules
were looked at on seeds 100-103, 5000-5007 and 9000-9019). Said plainly: two earlier runs of this test (percentile
intervals of the delay, searched to 0.7 ms and then 0.08 ms) held the delay 16 and 17 times in 20; the interval was
then chosen again on seeds 9000-9019 (percentile 15/20, estimate ± t SD 19/20) and this test run once more. The
figures are printed (``pytest -s``) for the issue's note and ``bench/gain_coverage.md``.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from workbench.method.timing import identify_timing
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import SLOW_PILOT, LQROperator, lqr_operator_demos

pytestmark = pytest.mark.slow

SEED0 = 7000
N_TRIALS, N_BOOT = 30, 100
TIMED_SEEDS, PLAIN_SEEDS = 20, 10


def timed_pilot(k: int) -> LQROperator:
    rng = np.random.default_rng([SEED0 + k, 41])
    return LQROperator(**SLOW_PILOT, delay_s=float(rng.uniform(0.15, 0.25)), lag_s=float(rng.uniform(0.05, 0.1)),
                       start="rest")


@pytest.fixture(scope="module")
def runs():
    quad = planar_quadrotor()
    out = {"timed": [], "plain": []}
    for family, seeds, make in (("timed", TIMED_SEEDS, timed_pilot), ("plain", PLAIN_SEEDS, lambda k: LQROperator())):
        for k in range(seeds):
            op = make(k)
            seed = SEED0 + (0 if family == "timed" else 1000) + k
            t = identify_timing(lqr_operator_demos(op, N_TRIALS, seed=seed, plant=quad), quad, n_boot=N_BOOT, seed=k)
            K = op.gain(quad)
            out[family].append({"delay": op.delay_s, "lag": op.lag_s, "t": t, "K": K,
                                "rel": float(np.linalg.norm(t.K - K) / np.linalg.norm(K)),
                                "attitude": float(t.K[0, 2] / K[0, 2])})
            print(f"{family} {k}: delay {op.delay_s:.3f} in [{t.delay_lo:.3f}, {t.delay_hi:.3f}], lag {op.lag_s:.3f} "
                  f"in [{t.lag_lo:.3f}, {t.lag_hi:.3f}]; ‖K̂ − K‖/‖K‖ {out[family][-1]['rel']:.3f}, "
                  f"K̂[u1, φ]/K[u1, φ] {out[family][-1]['attitude']:.3f}")
    return out


def _share(flags) -> str:
    flags = np.asarray(flags, dtype=bool)
    ci = stats.binomtest(int(flags.sum()), len(flags)).proportion_ci(0.95)
    return f"{flags.sum()}/{len(flags)} (95 % CI {ci.low:.2f}-{ci.high:.2f})"


def test_the_delays_interval_covers_the_true_delay(runs):
    covered = [r["t"].delay_lo <= r["delay"] <= r["t"].delay_hi for r in runs["timed"]]
    lag = [r["t"].lag_lo <= r["lag"] <= r["t"].lag_hi for r in runs["timed"]]
    print(f"delay covered {_share(covered)}, lag covered {_share(lag)}")
    assert np.mean(covered) >= 0.9


def test_the_gain_of_a_slow_pilot_and_of_one_without_timing_is_within_20_percent(runs):
    for family, rs in runs.items():
        rel = np.array([r["rel"] for r in rs])
        attitude = np.array([r["attitude"] for r in rs])
        print(f"{family}: ‖K̂ − K‖/‖K‖ median {np.median(rel):.3f} (max {rel.max():.3f}), ≤ 0.2 on "
              f"{_share(rel <= 0.2)}; K̂[u1, φ] within 20 % on {_share(np.abs(attitude - 1) <= 0.2)}")
        # the gain's error as the issue states it, ≤ 0.2, for the pilot (the median over seeds; a single seed's is
        # printed: the thrust row's roll-angle entry, weakly instrumented, spreads it), and the attitude entry on
        # ≥ 90 % of seeds
        assert np.median(rel) <= 0.2
        assert np.mean(np.abs(attitude - 1) <= 0.2) >= 0.9
    # pilots without timing: none found
    assert all(r["t"].delay_s < 0.05 and r["t"].lag_s < 0.05 for r in runs["plain"])
