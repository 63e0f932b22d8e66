"""The human behavior model end to end: fit time, Monte Carlo rate, online query, and the paper's figures.

Run ``python bench/bench_model.py`` (Markdown on stdout); ``run() -> list[dict]`` for ``bench/run_all.py``.
Timings use one BLAS thread (threadpoolctl), best of a few repeats; the machine is shared, so they drift.

Cases
-----
* Fit of the paper-size set (CS1 + CS2, 30 trials each = 60 trials, simulator seed 0) end to end: gain,
  inverse LQR (first solve, which compiles the SDP, and a cached re-solve), TP-GMM EM, Monte Carlo noise
  calibration (3 cross-fitted fold models + held-out band calibration). Target: well under 10 s.
* Monte Carlo rollout rate: 1000 trajectories × 60 steps from one start (trajectory-steps per second).
* One online variability query (one state, task conditional cached), µs per call; and one mean prediction of
  60 steps.
* The paper's figures (issue 3's acceptance, as in ``tests/test_paper_shape.py``) per strategy on the test
  seeds (train 0 / test 1) and, as a robustness check, on other seeds (train 4 / test 5).
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness import best_time, markdown_table  # noqa: E402

from workbench.method.gain import estimate_gain
from workbench.method.inverse_lqr_sdp import InverseLQR  # noqa: E402
from workbench.models import GMROnlyModel, HumanBehaviorModel, IOCOnlyModel  # noqa: E402
from workbench.plant.system import planar_quadrotor  # noqa: E402
from workbench.sim.landing import simulate_landings  # noqa: E402
from workbench.study import evaluate as ev  # noqa: E402


def _row(case: str, value: float, unit: str, note: str = "") -> dict:
    return {"benchmark": "model", "case": case, "value": float(value), "unit": unit, "note": note}


def _timings() -> list[dict]:
    plant = planar_quadrotor()
    demos = simulate_landings("CS1", 30, seed=0) + simulate_landings("CS2", 30, seed=0)
    rows = []
    note = f"{len(demos)} trials, {demos.n_samples} samples"
    rows.append(_row("fit, gain K̂ (direct)", best_time(lambda: estimate_gain(demos, plant)), "s", note))
    K = estimate_gain(demos, plant)
    rows.append(_row("fit, inverse LQR first solve (compile)",
                     best_time(lambda: InverseLQR(plant.A, plant.B).solve(K), 1), "s"))
    problem = InverseLQR(plant.A, plant.B)
    problem.solve(K)
    rows.append(_row("fit, inverse LQR re-solve (cached)", best_time(lambda: problem.solve(K)), "s"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t_gmm = best_time(lambda: HumanBehaviorModel(plant, fit_objective=False, noise="gmr").fit(demos))
        t_all = best_time(lambda: HumanBehaviorModel(plant).fit(demos), 2)
        model = HumanBehaviorModel(plant).fit(demos)
    tp = model.variability_.tpgmm_
    rows.append(_row("fit, gain + TP-GMM EM (no objective, no noise calibration)", t_gmm, "s",
                     f"EM {tp.n_iter_} iterations, converged {tp.converged_}"))
    rows.append(_row("fit, end to end (gain + objective + TP-GMM + noise calibration)", t_all, "s", note))
    rows.append(_row("noise calibration: held-out band coverage reached", model.noise_band_coverage_, "",
                     f"factor {model.noise_band_factor_:.3f}, ρ = {np.round(model.noise_rho_, 3).tolist()}"))

    d = simulate_landings("CS1", 1, seed=1)[0]
    x0, target = d.x[0], d.target
    S, H = 1000, 60
    t_mc = best_time(lambda: model.predict(x0, H, target, samples=S, seed=0))
    rows.append(_row("Monte Carlo rollout, 1000 × 60", S * H / t_mc, "trajectory-steps/s", f"{1e3 * t_mc:.1f} ms"))
    model.variability(x0[None], x0=x0, target=target)  # builds and caches the task conditional
    n_q = 2000
    t_q = best_time(lambda: [model.variability(x0[None], x0=x0, target=target) for _ in range(n_q)])
    rows.append(_row("online variability query (1 state, cached task)", 1e6 * t_q / n_q, "µs"))
    cond = model.variability_.conditional(x0, target)
    t_raw = best_time(lambda: [cond.predict(x0[None]) for _ in range(n_q)])
    rows.append(_row("online query, precomputed GMR only", 1e6 * t_raw / n_q, "µs"))
    t_new = best_time(lambda: [model.variability_.product(x0 + 1e-3 * i, target) for i in range(50)])
    rows.append(_row("new task: product of frames (eq. (30))", 1e6 * t_new / 50, "µs"))
    t_pred = best_time(lambda: [model.predict(x0, H, target) for _ in range(50)])
    rows.append(_row("mean prediction, 60 steps", 1e3 * t_pred / 50, "ms"))
    return rows


def _paper_figures(train_seed: int, test_seed: int) -> list[dict]:
    plant = planar_quadrotor()
    rows = []
    for strategy in ("CS1", "CS2"):
        train = simulate_landings(strategy, 30, seed=train_seed)
        test = simulate_landings(strategy, 20, seed=test_seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            models = {
                "proposed": HumanBehaviorModel(plant).fit(train),
                "ioc_only": IOCOnlyModel(plant).fit(train),
                "gmr_only": GMROnlyModel(plant).fit(train),
            }
            small = ev.data_efficiency(
                lambda: {"proposed": HumanBehaviorModel(plant, fit_objective=False), "gmr_only": GMROnlyModel(plant)},
                train, test, sizes=(5,), repeats=5, seed=0,
            )
        table = ev.compare(models, test, n_steps=60, samples=200, seed=0)
        s = ev.method_means(table)
        cov = ev.coverage_summary(ev.one_step_coverage(models["proposed"], test))
        cov3 = cov[cov.n_sigma == 3].set_index("input")["coverage"]
        band = table[(table.method == "proposed") & table.metric.isin(["band_position_x", "band_position_y"])]
        small_pos = small[small.metric == "rmse_position"].groupby("method")["value"].mean()
        tag = f"{strategy} (train seed {train_seed}, test seed {test_seed})"
        for block in ("position", "velocity"):
            r = s.loc[f"rmse_{block}"]
            rows.append(_row(
                f"{tag}: {block} RMSE, 3 s", r["proposed"], "m" if block == "position" else "m/s",
                f"IOC-only {r['ioc_only']:.4f}, GMR-only {r['gmr_only']:.4f}; proposed "
                f"{ev.improvement(table, f'rmse_{block}', 'proposed', 'ioc_only'):.1f} % / "
                f"{ev.improvement(table, f'rmse_{block}', 'proposed', 'gmr_only'):.1f} % lower",
            ))
        rows.append(_row(f"{tag}: one-step 3σ coverage of ŵ", float(cov3.min()), "",
                         ", ".join(f"{k} {100 * v:.1f} %" for k, v in cov3.items())))
        bx, by, bj = (100 * s.loc[f"band_position{k}", "proposed"] for k in ("_x", "_y", ""))
        rows.append(_row(f"{tag}: MC 90 % band coverage of position (per axis)", float(band["value"].mean()), "",
                         f"x {bx:.1f} %, y {by:.1f} %, joint {bj:.1f} %"))
        p_small, g_small = small_pos["proposed"], small_pos["gmr_only"]
        rows.append(_row(f"{tag}: 5 training trials, GMR-only / proposed position RMSE", g_small / p_small, "ratio",
                         f"proposed {p_small:.4f}, GMR-only {g_small:.4f} (5 subsets)"))
    return rows


def run() -> list[dict]:
    with threadpool_limits(limits=1):
        return _timings() + _paper_figures(0, 1) + _paper_figures(4, 5)


def main() -> None:
    print(markdown_table(run()))


if __name__ == "__main__":
    main()
