"""Benchmark of the TP-GMM (EM) and GMR against scikit-learn and the ``gmr`` package.

Run ``python bench/bench_gmm.py``; a driver can call :func:`run` for the rows. All timings are taken with BLAS
limited to one thread (threadpoolctl), best of several repeats, so that they are comparable on a shared machine.

Cases
-----
(a) EM: TPGMM with one identity frame vs scikit-learn ``GaussianMixture`` on the same 14 000 x 8 data, G = 5, the
    same initial parameters, ``tol = 0`` and the same fixed number of iterations (target: <= 1.5x sklearn's time).
(b) GMR mean + covariance for 100 000 queries, batched, vs ``gmr``'s ``GMM.condition(...).to_mvn()`` per query
    (timed on 2 000 queries and scaled per query; results equal to 1e-9 on those) (target: >= 100x faster).
(c) GMR mean only, batched, vs ``gmr``'s batched ``GMM.predict`` (target: >= 1.5x faster).
(d) One online query (a single 1-D state), microseconds per call.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np
from gmr import GMM
from sklearn.mixture import GaussianMixture
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from harness import best_time  # noqa: E402

from workbench.errors import ConvergenceWarning  # noqa: E402
from workbench.method.gmr import ConditionalGMM  # noqa: E402
from workbench.method.tpgmm import TPGMM, identity_frame, start_frame  # noqa: E402


def _em_data(rng: np.random.Generator, N: int = 14_000, D: int = 8, G: int = 5) -> np.ndarray:
    centers = rng.normal(scale=2.0, size=(G, D))  # overlapping, so EM keeps moving for many iterations
    X = np.concatenate([rng.normal(size=(N // G, D)) @ rng.normal(scale=0.7, size=(D, D)) + c for c in centers])
    rng.shuffle(X)
    return X


def bench_em(n_iter: int = 50, seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    G = 5
    X = _em_data(rng, G=G)
    D = X.shape[1]
    xi_list = [X[: len(X) // 2], X[len(X) // 2 :]]
    frames = [[identity_frame(D)], [identity_frame(D)]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        init = TPGMM(n_components=G, max_iter=1, random_state=seed).fit(xi_list, frames)
    w0, mu0, S0 = init.init_weights_, init.init_means_, init.init_covariances_

    def ours():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            return TPGMM(
                n_components=G, max_iter=n_iter, tol=0.0, weights_init=w0, means_init=mu0, covariances_init=S0
            ).fit(xi_list, frames)

    def sk():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return GaussianMixture(
                n_components=G,
                covariance_type="full",
                reg_covar=1e-6,
                max_iter=n_iter,
                tol=0.0,
                weights_init=w0,
                means_init=mu0[0],
                precisions_init=np.linalg.inv(S0[0]),
                init_params="random_from_data",  # its result is overridden by the *_init arguments
            ).fit(X)

    a, b = ours(), sk()
    if a.n_iter_ != b.n_iter_:
        raise AssertionError(f"iteration counts differ: {a.n_iter_} vs {b.n_iter_}")
    ll_a, ll_b = a.score(xi_list, frames), b.score(X)
    t_ours, t_sk = best_time(ours), best_time(sk)
    rows = [
        {
            "case": f"(a) EM, N={len(X)}, D={D}, G={G}, P=1, {a.n_iter_} iterations",
            "ours": f"{t_ours * 1e3:.0f} ms",
            "reference": f"{t_sk * 1e3:.0f} ms (sklearn GaussianMixture)",
            "ratio": t_ours / t_sk,
            "ratio_meaning": "ours / sklearn time",
            "target": "<= 1.5",
            "met": t_ours / t_sk <= 1.5,
            "check": f"mean log-lik {ll_a:.10f} vs {ll_b:.10f}",
        }
    ]
    # For scale: the same data seen from two frames (identity + a shifted start frame), P = 2.
    frames2 = [[identity_frame(D), start_frame(xi[0, :6], 2)] for xi in xi_list]

    def ours_p2():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            return TPGMM(n_components=G, max_iter=n_iter, tol=0.0, random_state=seed).fit(xi_list, frames2)

    t_p2 = best_time(ours_p2, repeats=2)
    rows.append(
        {
            "case": f"(a') TP-GMM EM incl. k-means init, P=2, {n_iter} iterations",
            "ours": f"{t_p2 * 1e3:.0f} ms",
            "reference": "-",
            "ratio": t_p2 / t_ours,
            "ratio_meaning": "P=2 / P=1 time",
            "target": "-",
            "met": True,
            "check": "",
        }
    )
    return rows


def _gmr_model(seed: int = 1, G: int = 5, d: int = 6, m: int = 2):
    rng = np.random.default_rng(seed)
    D = d + m
    w = rng.dirichlet(np.ones(G))
    mu = rng.normal(scale=2.0, size=(G, D))
    A = rng.normal(size=(G, D, D))
    S = A @ np.swapaxes(A, -1, -2) / D + 0.1 * np.eye(D)
    X = mu[rng.integers(0, G, size=100_000), :d] + rng.normal(size=(100_000, d))
    return w, mu, S, X


def bench_gmr(n_queries: int = 100_000, n_reference: int = 2_000) -> list[dict]:
    G, d, m = 5, 6, 2
    w, mu, S, X = _gmr_model(G=G, d=d, m=m)
    X = X[:n_queries]
    in_idx, out_idx = np.arange(d), np.arange(d, d + m)
    model = ConditionalGMM(w, mu, S, in_idx, out_idx)
    ref = GMM(n_components=G, priors=w, means=mu, covariances=S)
    rows = []

    # (b) mean + covariance
    t_batch = best_time(lambda: model.predict(X))
    sub = X[:n_reference]
    t0 = time.perf_counter()
    ref_out = [ref.condition(in_idx, x).to_mvn() for x in sub]
    t_ref = (time.perf_counter() - t0) / n_reference * n_queries
    mu_b, S_b = model.predict(sub)
    err = max(
        max(np.abs(r.mean - mu_b[k]).max() for k, r in enumerate(ref_out)),
        max(np.abs(r.covariance - S_b[k]).max() for k, r in enumerate(ref_out)),
    )
    if err > 1e-9:
        raise AssertionError(f"GMR differs from gmr's condition().to_mvn() by {err:.2e}")
    rows.append(
        {
            "case": f"(b) GMR mean+cov, {n_queries} queries, G={G}, d_in={d}, m={m}",
            "ours": f"{t_batch * 1e3:.1f} ms (batched)",
            "reference": f"{t_ref:.1f} s (gmr condition().to_mvn() per query, from {n_reference})",
            "ratio": t_ref / t_batch,
            "ratio_meaning": "batched ours vs gmr's per-query loop: NOT like for like (gmr has no batched "
            "covariance query); like for like see (c) batched mean and (d) vs (d') one query",
            "target": "-",
            "met": "-",
            "check": f"max abs diff {err:.1e} on {n_reference} queries",
        }
    )

    # (c) mean only, batched both
    t_mean = best_time(lambda: model.predict_mean(X), repeats=5)
    t_ref_mean = best_time(lambda: ref.predict(in_idx, X), repeats=5)
    err_mean = np.abs(model.predict_mean(X) - ref.predict(in_idx, X)).max()
    rows.append(
        {
            "case": f"(c) GMR mean only, {n_queries} queries, batched",
            "ours": f"{t_mean * 1e3:.1f} ms",
            "reference": f"{t_ref_mean * 1e3:.1f} ms (gmr GMM.predict)",
            "ratio": t_ref_mean / t_mean,
            "ratio_meaning": "speed-up",
            "target": ">= 1.5",
            "met": t_ref_mean / t_mean >= 1.5,
            "check": f"max abs diff {err_mean:.1e}",
        }
    )

    # (d) one online query
    x = X[0].copy()
    calls = 20_000
    for name, fn in (("predict (mean+cov)", model.predict), ("predict_mean", model.predict_mean)):
        fn(x)
        t = best_time(lambda fn=fn: [fn(x) for _ in range(calls)]) / calls
        rows.append(
            {
                "case": f"(d) one online query, {name}",
                "ours": f"{t * 1e6:.1f} us",
                "reference": "-",
                "ratio": t * 1e6,
                "ratio_meaning": "us per call",
                "target": "tens of us",
                "met": t * 1e6 < 100,
                "check": "",
            }
        )
    t0 = time.perf_counter()
    n_ref = 500
    for _ in range(n_ref):
        ref.condition(in_idx, x).to_mvn()
    t_ref1 = (time.perf_counter() - t0) / n_ref
    rows.append(
        {
            "case": "(d') one query with gmr condition().to_mvn()",
            "ours": "-",
            "reference": f"{t_ref1 * 1e6:.0f} us",
            "ratio": t_ref1 * 1e6,
            "ratio_meaning": "us per call",
            "target": "-",
            "met": True,
            "check": "",
        }
    )
    t_build = best_time(lambda: ConditionalGMM(w, mu, S, in_idx, out_idx), repeats=20)
    rows.append(
        {
            "case": "(d'') building the precomputed ConditionalGMM once",
            "ours": f"{t_build * 1e6:.0f} us",
            "reference": "-",
            "ratio": t_build * 1e6,
            "ratio_meaning": "us once",
            "target": "-",
            "met": True,
            "check": "",
        }
    )
    return rows


def run() -> list[dict]:
    """All benchmark rows (BLAS limited to one thread); each row starts with ``benchmark``."""
    with threadpool_limits(limits=1):
        rows = bench_em() + bench_gmr()
    return [{"benchmark": "gmm", **row} for row in rows]


def to_markdown(rows: list[dict]) -> str:
    lines = [
        "| case | ours | reference | ratio | target | met | check |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['ours']} | {r['reference']} | {r['ratio']:.2f} ({r['ratio_meaning']}) | "
            f"{r['target']} | {'yes' if r['met'] else 'NO'} | {r['check']} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    print(to_markdown(run()))
