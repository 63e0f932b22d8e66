"""Do the trials' starts move every state direction? A sign-flip randomization test over trials (issue 40 §2).

The timed LIML gain (:mod:`workbench.method.timing`) stands on instruments: each trial's first state (and a
constant) at every sample time. Its relevance (:meth:`workbench.method.timing._Metric.relevance`) is the smallest
canonical correlation of the seen states ``x̃`` with them beyond each trial's own rows, i.e. the leave-own-out
(jackknife) statistic ``ρ(v) = Σ_{j≠l} Σ_t (x̃_jt v) h_t(j, l) (x̃_lt v) / Σ_j Σ_t (x̃_jt v)²``, ``h_t(j, l)`` the
instruments' projection between trials ``j`` and ``l`` at sample ``t``, minimized over directions ``v``. Where no
direction escapes chance, the Anderson-Rubin set for the gain is unbounded along it and any interval with valid
coverage must be too (Dufour 1997, Econometrica 65). Flipping the sign of whole trials (``ε_j = ±1``: the null
"the starts do not move ``x̃ v``", symmetric trial by trial) gives ``ε'B_v ε`` with ``B_v[j, l]`` the pair's term:
a randomization test over trials (Canay, Romano & Shaikh 2017, Econometrica 85) that needs neither many trials
nor a null distribution for thousands of instruments. Per seed: the relevance, its p-value in the weakest
direction ``v̂`` (plugged in) and ``v̂``.

    nice -n 10 .venv/bin/python bench/gain_weak_direction.py erratic 5000 5008
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import gain_coverage  # noqa: E402

from workbench.method.pilot_loop import seen_states  # noqa: E402
from workbench.method.timing import TimingData, fit_timing  # noqa: E402
from workbench.plant.system import planar_quadrotor  # noqa: E402


def weakest_direction(demos: list, delay_s: float, lag_s: float, dt: float, start: str, n_flip: int = 2000,
                      seed: int = 0) -> tuple[float, float, np.ndarray]:
    """``(relevance, p-value, v̂)``: the smallest leave-own-out canonical correlation of the seen states with the
    starts, the share of ``n_flip`` sign flips of whole trials that reach it in the direction ``v̂`` (with the
    observed one counted), and ``v̂`` scaled to a largest entry of 1."""
    X = [seen_states(d.x, delay_s, lag_s, dt, start) for d in demos]
    z = np.array([np.append(d.x[0], 1.0) for d in demos])
    J, n, T = len(demos), X[0].shape[1], max(len(x) for x in X)
    Xp, act = np.zeros((T, J, n)), np.zeros((T, J))
    for j, x in enumerate(X):
        Xp[: len(x), j], act[: len(x), j] = x, 1.0
    S = np.einsum("tj,ja,jb->tab", act, z, z)
    H = np.einsum("ja,tab,lb->tjl", z, np.linalg.pinv(S, rcond=1e-10, hermitian=True), z)
    B = np.einsum("tjl,tja,tlb->jlab", H * act[:, :, None] * act[:, None, :], Xp, Xp)
    B[np.arange(J), np.arange(J)] = 0.0  # leave each trial's own rows out (chance alone "explains" them)
    V = np.einsum("tja,tjb->ab", Xp, Xp)
    Li = np.linalg.inv(np.linalg.cholesky(V))
    W = Li @ B.sum(axis=(0, 1)) @ Li.T
    lam, U = np.linalg.eigh(0.5 * (W + W.T))
    v = Li.T @ U[:, 0]
    Bv = np.einsum("jlab,a,b->jl", B, v, v) / (v @ V @ v)
    eps = np.random.default_rng(seed).choice([-1.0, 1.0], size=(n_flip, J))
    null = np.einsum("kj,jl,kl->k", eps, Bv, eps)
    return float(lam[0]), float((1 + np.sum(null >= lam[0])) / (n_flip + 1)), v / np.abs(v).max()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("operator", help="an operator of bench/gain_coverage.py")
    p.add_argument("seed0", type=int)
    p.add_argument("seed1", type=int)
    a = p.parse_args()
    quad = planar_quadrotor()
    for s in range(a.seed0, a.seed1):
        sim, *_ = gain_coverage.operator(a.operator, s)
        demos = list(sim(gain_coverage.N_TRIALS, s))
        data = TimingData(demos, quad.n, quad.m, quad.dt)
        fit = fit_timing(data, "liml")
        r, pv, v = weakest_direction(demos, fit.delay_s, fit.lag_s, quad.dt, data.start)
        print(f"{a.operator} {s}: delay {fit.delay_s:.3f} s, lag {fit.lag_s:.3f} s, relevance {r:.4f} (the fit's "
              f"{fit.relevance:.4f}), p = {pv:.4f} by sign flips of trials, weakest direction "
              + ", ".join(f"{name} {x:+.2f}" for name, x in zip(quad.state_names, v, strict=True)), flush=True)


if __name__ == "__main__":
    main()
