"""The timed gain with each input's entries on the *other* decoupled parts of the plant taken as exogenous (issue 41
§4, round 9): a measurement, not the default.

In a plant with decoupled parts (:func:`workbench.method.structured.decoupled_parts`) the states of the other parts
are moved only by the other inputs. Where the pilot's variability in input ``i`` is uncorrelated with the other
inputs' variability, those states are uncorrelated with input ``i``'s residual of eq. (T1): they are exogenous for
row ``i`` and instrument themselves. Row ``i`` is then LIML with included exogenous regressors: its own part's seen
states instrumented by the trials' starts (and the other parts' states), the other parts' entries estimated with the
precision of least squares, from every excursion the other loops make — not only from what the starts move, which
is the direction round 8 found weak. The assumption (no correlation of the pilot's variability across sticks) is
stronger than none and weaker than "no coupling"; it keeps a real coupling.

Moments (at LIML's timing ``(d̂, τ̂)``, from the same blocks as the fit): with ``W`` the other parts' seen states,
``P_[Z,W] = P_Z + P_{M_Z W}`` and ``a'M_Z b = a'b − a'P_Z b``; Frisch-Waugh partials ``W`` out of
``Y = [c_i, x̃_own]`` in both the raw and the projected moments, LIML on the partialled ``Y`` gives the own entries,
and least squares of the residual on ``W`` the others.

    nice -n 10 .venv/bin/python bench/timing_gain_exogenous.py --seeds 12000 40
    nice -n 10 .venv/bin/python bench/timing_gain_exogenous.py --seeds 13000 20 --plain
    nice -n 10 .venv/bin/python bench/timing_gain_exogenous.py --seeds 12000 20 --coupling 0.2
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from timing_structure_cv import choose, flown, own_columns, share  # noqa: E402

from workbench.method.timing import _joint  # noqa: E402
from workbench.plant.system import planar_quadrotor  # noqa: E402


def exogenous_cross(metric, d: float, tau: float, own: list[list[int]]) -> np.ndarray:
    """Per input, LIML on its own part's states with the other parts' seen states as included exogenous regressors."""
    Hp = metric.blocks("MP", np.array([d]), np.array([tau]))
    Hr = metric.blocks("VV", np.array([d]), np.array([tau]))
    m, n = Hr[1].shape[2], Hr[0].shape[1]
    K = np.zeros((m, n))
    for i in range(m):
        Gp, Gr = _joint(Hp, i)[0], _joint(Hr, i)[0]  # moments of [c_i, x̃]
        y = [0] + [c + 1 for c in own[i]]
        w = [c + 1 for c in range(n) if c not in own[i]]
        if not w:
            sel = np.ix_(y, y)
            Li = np.linalg.inv(np.linalg.cholesky(Gr[sel]))
            lam = float(np.linalg.eigvalsh(Li @ Gp[sel] @ Li.T)[0])
            M = Gp[sel] - lam * Gr[sel]
            K[i, own[i]] = np.linalg.solve(M[1:, 1:], M[1:, 0])
            continue
        R = Gr - Gp  # a'M_Z b
        Rww_inv = np.linalg.inv(R[np.ix_(w, w)])
        G_full = Gp + R[:, w] @ Rww_inv @ R[w, :]  # a'P_[Z,W] b
        Vww_inv = np.linalg.inv(Gr[np.ix_(w, w)])
        PW = Gr[:, w] @ Vww_inv @ Gr[w, :]  # a'P_W b
        sel = np.ix_(y, y)
        Rt, Pt = (Gr - PW)[sel], (G_full - PW)[sel]  # partialled: a'M_W b, a'(P_[Z,W] − P_W) b
        Li = np.linalg.inv(np.linalg.cholesky(Rt))
        lam = float(np.linalg.eigvalsh(Li @ Pt @ Li.T)[0])
        M = Pt - lam * Rt
        g = np.linalg.solve(M[1:, 1:], M[1:, 0])
        K[i, own[i]] = g
        # the others: least squares of c_i − x̃_own g on W (raw moments)
        yw = Gr[w, 0] - Gr[np.ix_(w, y[1:])] @ g
        K[i, [c - 1 for c in w]] = Vww_inv @ yw
    return K


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", nargs=2, type=int, default=(12000, 40), metavar=("FIRST", "COUNT"))
    ap.add_argument("--plain", action="store_true")
    ap.add_argument("--coupling", type=float, default=0.0)
    ap.add_argument("--trials", type=int, default=30)
    args = ap.parse_args()
    quad = planar_quadrotor()
    own = own_columns(quad)
    first, count = args.seeds
    rows = []
    for k in range(count):
        K, data = flown(first + k, args, quad)
        _, _, _, Kcv, full = choose(data, quad)
        Kx = exogenous_cross(data.metric(), full.delay_s, full.lag_s, own)
        nK = np.linalg.norm(K)
        r = [float(np.linalg.norm(G - K) / nK) for G in (full.K, Kcv, Kx)]
        rows.append((*r, float(Kx[0, 2] / K[0, 2])))
        print(
            f"seed {first + k}: ‖K̂ − K‖/‖K‖ LIML {r[0]:.3f}, CV-chosen {r[1]:.3f}, exogenous cross {r[2]:.3f}; "
            f"K[u2, φ] true {K[1, 2]:+.3f}: LIML {full.K[1, 2]:+.3f}, CV {Kcv[1, 2]:+.3f}, exogenous {Kx[1, 2]:+.3f}; "
            f"K[u1, y] LIML {full.K[0, 1]:+.3f}, exogenous {Kx[0, 1]:+.3f}",
            flush=True,
        )
    a = np.array(rows)
    for j, name in enumerate(("LIML", "CV-chosen", "exogenous cross")):
        print(f"{name:16s} ≤ 0.2 on {share(a[:, j] <= 0.2)}, median {np.median(a[:, j]):.3f}")
    print(f"exogenous cross: K̂[u1, φ] within 20 % on {share(np.abs(a[:, 3] - 1) <= 0.2)}")


if __name__ == "__main__":
    main()
