"""Inverse LQR on the planar quadrotor: first solve (compile + solve) against re-solves with a new gain.

``InverseLQR`` keeps K as a ``cvxpy.Parameter``, so a re-solve (bootstrap resampling, a second strategy)
skips cvxpy's canonicalization. Gains are DARE gains of random diagonal costs, so every solve is feasible.

Usage: ``python bench/bench_ioc.py``; ``run() -> list[dict]`` for ``bench/run_all.py``.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness import markdown_table  # noqa: E402

from workbench.method.inverse_lqr_sdp import InverseLQR  # noqa: E402
from workbench.method.objective import forward_gain
from workbench.plant.system import planar_quadrotor  # noqa: E402

N_FIRST = 5
N_RESOLVE = 20


def _gains(n_gains: int, seed: int = 0) -> list[np.ndarray]:
    sys_ = planar_quadrotor()
    rng = np.random.default_rng(seed)
    return [
        forward_gain(sys_.A, sys_.B, np.diag(rng.uniform(0.1, 10.0, 6)), np.diag(rng.uniform(0.5, 2.0, 2)))[0]
        for _ in range(n_gains)
    ]


def _row(case: str, structure: str, times: list[float], errors: list[float]) -> dict:
    return {
        "benchmark": "ioc",
        "case": case,
        "structure": structure,
        "n": len(times),
        "median_ms": 1e3 * statistics.median(times),
        "min_ms": 1e3 * min(times),
        "max_forward_error": max(errors),
    }


def run() -> list[dict]:
    sys_ = planar_quadrotor()
    gains = _gains(N_FIRST + N_RESOLVE)
    rows = []
    for structure in ("full", "diagonal"):
        first, first_err = [], []
        for K in gains[:N_FIRST]:
            problem = InverseLQR(sys_.A, sys_.B, structure=structure)  # a fresh, uncompiled problem
            t0 = time.perf_counter()
            obj = problem.solve(K)
            first.append(time.perf_counter() - t0)
            first_err.append(obj.forward_gain_error)
        resolve, resolve_err = [], []
        for K in gains[N_FIRST:]:
            t0 = time.perf_counter()
            obj = problem.solve(K)
            resolve.append(time.perf_counter() - t0)
            resolve_err.append(obj.forward_gain_error)
        rows.append(_row("first solve (compile + solve)", structure, first, first_err))
        rows.append(_row("re-solve, new K (cached problem)", structure, resolve, resolve_err))
        rows.append(
            {
                "benchmark": "ioc",
                "case": "speed-up of re-solve (median ratio)",
                "structure": structure,
                "ratio": statistics.median(first) / statistics.median(resolve),
            }
        )
    return rows


def main() -> None:
    print(markdown_table(run()))


if __name__ == "__main__":
    main()
