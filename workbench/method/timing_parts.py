"""The timed gain on a plant with decoupled parts: each input's entries on the *other* parts as exogenous regressors
(issue 41 §4; ``bench/gain_coverage.md``, round 9).

In a plant whose ``(A, B)`` fall into decoupled parts (:func:`workbench.method.structured.decoupled_parts`: the planar
quadrotor's lateral ``(x, φ, ẋ, φ̇; u1)`` and vertical ``(y, ẏ; u2)``), the states of the other parts are moved by the
other inputs only. Where the pilot's variability in input ``i`` is uncorrelated with the variability in the other
inputs, those states are uncorrelated with row ``i``'s residual of eq. (T1): exogenous for that row, their own
instruments. Row ``i`` is then LIML with included exogenous regressors (Anderson & Rubin 1949; Davidson & MacKinnon
2004, §8.5): the states of its own part instrumented by the trials' starts and the other parts' states, the entries
on the other parts estimated from every excursion the other loops make — not only from what the starts move.

Why: on 30 rest-start trials the starts move the attitude least, and LIML with every state instrumented spread the
thrust row's roll-angle entry by ±0.5 (round 8: the largest error on 11 of 14 failing seeds; ‖K̂ − K‖/‖K‖ ≤ 0.2 on
26/40 choosing seeds 12000-12039). With the other parts exogenous: 38/40 (``bench/timing_gain_exogenous.py``), and a
real coupling is kept (a pilot with ``K[u2, φ] = 0.2``: 20/20 within 0.2, the entry 0.07-0.34), where holding the
cross entries at 0 — always, or where held-out prediction chose it (``bench/timing_structure_cv.py``) — drops it.

What it assumes: no correlation of the pilot's variability across sticks of different parts. Where there is (a
pilot whose corrective bursts move both sticks at once), the entries across parts take up that correlation's
projection on the other parts' states (they are then the best linear predictor of the input given those states,
not the pilot's structural gain), and the own part's entries are instrumented as before.

Moments: with ``G_r`` the raw and ``G_p`` the instruments' projected moments of ``[c_i, x̃]``, ``W`` the other parts'
states: ``a'M_Z b = a'b − a'P_Z b``, ``P_[Z,W] = P_Z + P_{M_Z W}``; partialling ``W`` out of ``Y = [c_i, x̃_own]``
(Frisch-Waugh) in both gives LIML's generalized eigenproblem for the own entries, and least squares of the residual
on ``W`` the others.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["own_parts", "partial_liml"]

#: Below this share of their raw variance, the other parts' states are taken as spanned by the starts.
_SPAN_TOL = 1e-9


def own_parts(plant: Any) -> tuple[tuple[int, ...] | None, ...] | None:
    """Per input, the states of its decoupled part of ``plant`` (None where that part holds every state); None where
    no input has a part smaller than the plant (nothing is exogenous) or the plant has no ``A`` and ``B``."""
    if not (hasattr(plant, "A") and hasattr(plant, "B")):
        return None
    from workbench.method.structured import decoupled_parts

    A, B = np.asarray(plant.A, dtype=float), np.asarray(plant.B, dtype=float)
    parts = decoupled_parts(A, B)
    out = []
    for i in range(B.shape[1]):
        states = next((s for s, inputs in parts if i in inputs), None)
        out.append(states if states is not None and 0 < len(states) < A.shape[0] else None)
    return tuple(out) if any(o is not None for o in out) else None


def partial_liml(Gp: np.ndarray, Gr: np.ndarray, own: tuple[int, ...]) -> np.ndarray:
    """Row ``K_i`` of eq. (T1) with the states outside ``own`` exogenous (module docstring).

    Parameters
    ----------
    Gp, Gr : ndarray, shape (n+1, n+1)
        Projected (on the trials' starts) and raw moments of ``[c_i, x̃]``.
    own : tuple of int
        The states of input ``i``'s own part (instrumented).

    Returns
    -------
    ndarray, shape (n,)

    Raises
    ------
    numpy.linalg.LinAlgError
        Where the starts alone already span the other parts' states (no more distinct trials than instruments: the
        projection is the identity and nothing is left to partial); the caller keeps every state instrumented.
    """
    n = Gr.shape[0] - 1
    y = [0, *(int(c) + 1 for c in own)]
    w = [c + 1 for c in range(n) if c not in own]
    R = Gr - Gp  # a'M_Z b
    r_ww = np.linalg.eigvalsh(R[np.ix_(w, w)])
    if not r_ww[0] > _SPAN_TOL * np.linalg.eigvalsh(Gr[np.ix_(w, w)])[-1]:
        raise np.linalg.LinAlgError("the trials' starts span the other parts' states: nothing left to partial")
    G_zw = Gp + R[:, w] @ np.linalg.solve(R[np.ix_(w, w)], R[w, :])  # a'P_[Z,W] b
    P_w = Gr[:, w] @ np.linalg.solve(Gr[np.ix_(w, w)], Gr[w, :])  # a'P_W b
    sel = np.ix_(y, y)
    raw, proj = (Gr - P_w)[sel], (G_zw - P_w)[sel]  # W partialled out: a'M_W b and a'(P_[Z,W] − P_W) b
    Li = np.linalg.inv(np.linalg.cholesky(raw))
    lam = float(np.linalg.eigvalsh(Li @ proj @ Li.T)[0])  # LIML: the smallest share the instruments explain
    M = proj - lam * raw
    k = np.zeros(n)
    k[list(own)] = np.linalg.solve(M[1:, 1:], M[1:, 0])
    k[[c - 1 for c in w]] = np.linalg.solve(Gr[np.ix_(w, w)], Gr[w, 0] - Gr[np.ix_(w, y[1:])] @ k[list(own)])
    return k
