"""Coverage of the stability judgement's interval (issue 41 §3): does the resampled interval of ρ(A + BK̂) cover the
ρ of the gain the operator used, and how often does a pilot who keeps an integrator get refused?

Two questions, each on operators whose truth is known:

1. An LQR operator to the pad (:class:`workbench.sim.operators.LQROperator`, the known-gain operator): the 95 %
   interval's coverage of the true ρ over ``--seeds`` seeds, with whole demonstrations resampled (30 trials) and
   with blocks (8 trials, fewer than ``MIN_DEMOS``).
2. A free-flight pilot who flies only its inner loops (the one of ``tests/method/test_stability.py``), with a goal
   declared so that the positions are regulated: the true ρ is 1 (the positions' integrators), and every refusal is a
   refusal decided by a ρ within its own uncertainty of 1. Counted, against the paper's rule (refuse ρ̂ ≥ 1).

Usage: ``nice python bench/bench_stability.py [--seeds 40]``; prints a Markdown table (recorded in
``bench/results.md``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _coverage(n_trials: int, seeds: range) -> tuple[int, int, float]:
    from workbench.data.pilot_task import PilotTask
    from workbench.method.gain import choose_gain
    from workbench.method.stability import judge_stability
    from workbench.models.regulator import pilot_view
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.operators import LQROperator, lqr_operator_demos

    p, op = planar_quadrotor(), LQROperator()
    rho = float(np.abs(np.linalg.eigvals(p.A + p.B @ op.gain(p))).max())
    hits, widths = 0, []
    for seed in seeds:
        views = pilot_view(p, PilotTask(), list(lqr_operator_demos(op, n_trials, seed=seed)))
        K, choice = choose_gain(views, p, check=False)
        s = judge_stability(p.A, p.B, K, views, choice.method, p.dt, p.state_names, seed=seed)
        hits += s.lo <= rho <= s.hi
        widths.append(s.hi - s.lo)
    return hits, len(seeds), float(np.median(widths))


def _integrator(seeds: range) -> tuple[int, int, int]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "method"))
    from test_stability import free_flight  # the test's pilot, not a copy

    from workbench.errors import ModelError
    from workbench.models import IOCOnlyModel

    refused = paper = 0
    for seed in seeds:
        p, ds, _ = free_flight(seed, duration_s=10.0, targets=True)
        try:
            m = IOCOnlyModel(p, noise_folds=0).fit(ds)
            paper += m.stability_.rho >= 1.0
        except ModelError:
            refused += 1
            paper += 1
    return refused, paper, len(seeds)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=40)
    a = ap.parse_args()
    seeds = range(1000, 1000 + a.seeds)  # seeds no default was chosen on
    t0 = time.time()
    print("| question | seeds | result |")
    print("|---|---|---|")
    for n in (30, 8):
        hits, total, width = _coverage(n, seeds)
        unit = "demonstrations" if n >= 10 else "2 s blocks"
        print(f"| 95 % interval of ρ covers the LQR operator's true ρ ({n} trials, {unit} resampled) | {total} | "
              f"{hits}/{total} = {hits / total:.0%} (median width {width:.2g}) |")
    refused, paper, total = _integrator(seeds)
    print(f"| pilot keeping an integrator (true ρ = 1): refused | {total} | {refused}/{total} (the paper's rule, "
          f"ρ̂ ≥ 1: {paper}/{total}) |")
    print(f"\n{time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
