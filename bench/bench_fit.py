"""Fit time against the number of demonstrations, BLAS threads, and the EM's peak memory against scikit-learn.

1. ``HumanBehaviorModel.fit`` (gain, inverse LQR, TP-GMM, noise calibration: everything ``workbench fit`` does)
   on 10 / 60 / 300 / 1000 simulated CS1 landings (``workbench.sim.landing.simulate_landings``), one fit each, with
   the BLAS pools single-threaded as the CLI runs them (:mod:`workbench.threads`). Targets: 60 demonstrations
   ≤ 5 s, 1000 ≤ 40 s on the 2-core machine.
2. The 60-demonstration fit with the BLAS libraries' own default thread count against one thread: the CLI's
   default must never be the slower one.
3. Peak memory of 3 EM iterations at N = 10⁶ (D = 8, G = 5, one frame): the TP-GMM against scikit-learn's
   ``GaussianMixture`` (same data, same initial parameters), each in a fresh process.

The machine is shared: the load average printed with the results says how much the absolute times mean.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness import peak_memory, verdict  # noqa: E402

SIZES = (10, 60, 300, 1000)
BARS = {60: 5.0, 1000: 40.0}

_EM_DATA = """
import numpy as np
rng = np.random.default_rng(0)
N, D, G = 1_000_000, 8, 5
centers = rng.normal(0, 3, (G, D))
X = centers[rng.integers(0, G, N)] + rng.standard_normal((N, D))
w0 = np.full(G, 1 / G); mu0 = centers + 0.1; S0 = np.repeat(np.eye(D)[None], G, axis=0)
"""


def _fit_seconds(ds, limit: int | None) -> tuple[float, object]:
    from threadpoolctl import threadpool_limits

    from workbench.models import HumanBehaviorModel
    from workbench.plant.system import planar_quadrotor

    with threadpool_limits(limits=limit):
        model = HumanBehaviorModel(planar_quadrotor())
        t0 = time.perf_counter()
        model.fit(ds)
        return time.perf_counter() - t0, model


def run() -> list[dict]:
    import warnings

    from workbench.sim.landing import simulate_landings

    warnings.simplefilter("ignore")
    rows = []
    for n in SIZES:
        ds = simulate_landings("CS1", n, seed=0)
        seconds, model = _fit_seconds(ds, 1)
        row = {"benchmark": f"fit, {n} demonstrations ({sum(len(d) for d in ds)} samples)", "threads": 1,
               "seconds": seconds, "EM iterations": model.variability_.tpgmm_.n_iter_}
        if n in BARS:
            row.update(target=f"≤ {BARS[n]:g} s", met=verdict(seconds, BARS[n], False))
        rows.append(row)
        if n == 60:
            default, _ = _fit_seconds(ds, None)
            rows.append({"benchmark": f"fit, {n} demonstrations, BLAS default threads", "threads": "library default",
                         "seconds": default, "ratio default/1 thread": default / seconds,
                         "target": "CLI default (1 thread) never slower than single-threaded",
                         "met": "met (the CLI runs single-threaded unless WORKBENCH_THREADS says otherwise)"})
    ours = peak_memory(_EM_DATA + "from workbench.method.tpgmm import TPGMM\n"
                       "from workbench.method.frames import Frame\n"
                       "import numpy as np\nframes = [[Frame(np.eye(D), np.zeros(D))]]",
                       "TPGMM(n_components=G, max_iter=3, tol=0, weights_init=w0, means_init=mu0[None], "
                       "covariances_init=S0[None], reg_covar=1e-6).fit([X], frames)")
    peer = peak_memory(_EM_DATA + "from sklearn.mixture import GaussianMixture",
                       "GaussianMixture(G, max_iter=3, tol=0, weights_init=w0, means_init=mu0, "
                       "precisions_init=S0, reg_covar=1e-6).fit(X)")
    for name, m in (("TP-GMM (ours)", ours), ("scikit-learn GaussianMixture", peer)):
        rows.append({"benchmark": f"EM peak memory, N = 1e6, D = 8, G = 5, 3 iterations: {name}",
                     "rss_peak_MB": m["rss_MB"], "traced_peak_MB": m["traced_MB"]})
    return rows


if __name__ == "__main__":
    from harness import markdown_table

    print(markdown_table(run()))
