"""Which states each input's timed gain acts on: all of them, or its own decoupled part of the plant, chosen by
held-out prediction of the pilot's input (issue 41 §4; ``bench/gain_coverage.md``, rounds 8 and 9).

On 30 rest-start trials the trials' starts move the attitude least, and LIML's entries of an input on the *other*
part of the plant (the thrust on the roll angle of the planar quadrotor: 0 for a pilot whose cost has no weight
across the parts) spread by ±0.5 — the largest error of the gain on 11 of 14 failing seeds. Holding them at 0
always would be a decision about every pilot (a pilot who flies the landing cascade couples the parts); testing
whether they are 0 would be a pretest. Instead the structure is chosen as any model setting is, by its predictive
risk on trials it was not fitted on:

- **Candidates, per input ``i``.** Row ``i`` of ``K`` on all states, or on the states of its own decoupled part
  (:func:`workbench.method.structured.decoupled_parts` of the plant's ``A``, ``B``: what the vehicle connects, no
  index written down), the entries across the parts held at 0. An input whose part holds every state has nothing
  to choose.
- **Score: the pilot's input one step ahead.** Eq. (T1) predicts ``u[k] = a u[k−1] + (1 − a) K_i x̃_k``; its error
  is ``(1 − a)(c_i − K_i x̃_k)``, so at one timing the held-out sum of squares
  ``SSE_i(K_i) = H_cc − 2 K_i H_xc + K_i H_xx K_iᵀ`` (the held-out trials' raw moments) ranks the candidates as the
  input's one-step error does (the ``input_step`` score of :mod:`workbench.study.input_prediction`). The mean
  rollout from a trial's start would not do: it moves only where the starts move the states, the direction LIML
  already fits; one step ahead sees the states as they were flown.
- **Cross-validation over whole trials** (:data:`workbench.defaults.STRUCTURE_FOLDS` folds, a fixed permutation):
  on each fold's training trials the timing ``(d̂, τ̂)`` and the full LIML gain (:func:`fit_timing`), and at that
  timing the own-part gain; both scored on the fold's held-out trials. A fold whose fit fails is not scored.
- **Decision, per input:** its own part where the held-out SSE summed over the folds is ≤ the full row's (the
  smaller model at a tie), else all states; with no fold scored, all states.

Measured before it was adopted (``bench/timing_structure_cv.py``, choosing seeds only): on the timed pilots'
seeds 12000-12039 ‖K̂ − K‖/‖K‖ ≤ 0.2 on 40/40 against LIML's 26/40. The decision is made once, on all trials;
every resample and every leave-one-out set fits the gain with the structure so decided (as the timing rule,
:func:`workbench.method.timing.identify_timing`), so K̂'s interval is conditional on it, and an entry held at 0 has
no interval: it is printed as held, in words (:meth:`GainParts.held_text`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.defaults import STRUCTURE_FOLDS
from workbench.errors import ModelError

__all__ = ["GainParts", "choose_parts", "own_states"]


def own_states(A: Any, B: Any) -> list[tuple[int, ...] | None]:
    """Per input, the states of its decoupled part of the plant; None where that part holds every state (nothing
    to choose) or the input belongs to no part with states."""
    from workbench.method.structured import decoupled_parts

    n = np.asarray(A).shape[0]
    parts = decoupled_parts(A, B)
    out: list[tuple[int, ...] | None] = []
    for i in range(np.asarray(B).shape[1]):
        states = next((s for s, inputs in parts if i in inputs), None)
        out.append(states if states is not None and len(states) < n else None)
    return out


@dataclass(frozen=True)
class GainParts:
    """The states each input's row of ``K̂`` acts on (:func:`choose_parts`).

    Attributes
    ----------
    columns : tuple of tuple of int
        Per input, the states its row acts on (all of them where not restricted).
    own : tuple of bool
        Per input, whether its own part was chosen (its entries on the other parts held at 0).
    ratio : tuple of float
        Per input, the held-out SSE of its own-part row over the full row's (NaN: nothing to choose or no fold).
    state_names, input_names : tuple of str
    n_folds : int
    """

    columns: tuple[tuple[int, ...], ...]
    own: tuple[bool, ...]
    ratio: tuple[float, ...]
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    n_folds: int

    @property
    def restricted(self) -> bool:
        return any(self.own)

    def held(self) -> np.ndarray:
        """(m, n) bool: the entries held at 0 by the chosen structure."""
        H = np.ones((len(self.columns), len(self.state_names)), dtype=bool)
        for i, cols in enumerate(self.columns):
            H[i, list(cols)] = False
        return H

    def held_text(self, i: int) -> str:
        """What an entry of input ``i`` held at 0 says instead of an interval."""
        return f"held at 0: not in {self.input_names[i]}'s part of the plant"

    def describe(self) -> str:
        """One clause: which rows act on their own part, and by how much the held-out prediction chose it."""
        parts = []
        for i, (own, r) in enumerate(zip(self.own, self.ratio, strict=True)):
            if not np.isfinite(r):
                continue
            states = ", ".join(self.state_names[j] for j in self.columns[i])
            where = f"its own part ({states})" if own else "all states"
            parts.append(f"{self.input_names[i]} on {where}, held-out one-step error × {r:.3g} on its own part")
        if not parts:
            return ""
        return f"gain structure by {self.n_folds}-fold held-out prediction of the pilot's input: " + "; ".join(parts)

    def to_dict(self) -> dict[str, Any]:
        return {
            "columns": [list(c) for c in self.columns],
            "own": list(self.own),
            "ratio": [float(r) if np.isfinite(r) else None for r in self.ratio],
            "n_folds": self.n_folds,
        }


def choose_parts(
    data: Any,
    plant: Any,
    delay_s: float | None = None,
    lag_s: float | None = None,
    n_folds: int = STRUCTURE_FOLDS,
    seed: int = 0,
) -> GainParts:
    """The structure of the timed LIML gain by held-out prediction of the pilot's input (module docstring).

    Parameters
    ----------
    data : workbench.method.timing.TimingData
    plant : LinearSystem
        With ``A``, ``B`` (the plant the gain acts on) and, where it has them, ``state_names``, ``input_names``.
    delay_s, lag_s : float, optional
        A given timing (else searched on each fold's training trials).
    n_folds : int
        Folds of whole trials (at most one per trial).
    seed : int
        The folds' permutation.
    """
    from workbench.method.timing import fit_timing

    A, B = np.asarray(plant.A, dtype=float), np.asarray(plant.B, dtype=float)
    n, m = B.shape
    own = own_states(A, B)
    names = tuple(getattr(plant, "state_names", None) or (f"x{j + 1}" for j in range(n)))
    inputs = tuple(getattr(plant, "input_names", None) or (f"u{i + 1}" for i in range(m)))
    every = tuple(range(n))
    ratio = [float("nan")] * m
    J = data.n_trials
    k = min(int(n_folds), J)
    if all(o is None for o in own) or k < 2:
        return GainParts(tuple(every for _ in range(m)), (False,) * m, tuple(ratio), names, inputs, k)
    given = {"delay_s": delay_s, "lag_s": lag_s}
    restricted = [o if o is not None else every for o in own]
    order = np.random.default_rng(seed).permutation(J)
    sse = np.zeros((2, m))
    scored = False
    for f in range(k):
        test = np.zeros(J, dtype=bool)
        test[order[f::k]] = True
        try:
            fit = fit_timing(data, "liml", counts=(~test).astype(float), **given)
            K_own = data.metric((~test).astype(float)).gain_on(fit.delay_s, fit.lag_s, restricted)
        except (ModelError, np.linalg.LinAlgError):
            continue
        held_out = data.metric(test.astype(float), instruments=False)
        H_xx, H_xc, H_cc = (h[0] for h in held_out.blocks("VV", np.array([fit.delay_s]), np.array([fit.lag_s])))
        for row, K in enumerate((fit.K, K_own)):
            sse[row] += [H_cc[i] - 2 * K[i] @ H_xc[:, i] + K[i] @ H_xx @ K[i] for i in range(m)]
        scored = True
    chosen, columns = [], []
    for i in range(m):
        pick = scored and own[i] is not None and sse[1, i] <= sse[0, i]
        if scored and own[i] is not None and sse[0, i] > 0:
            ratio[i] = float(sse[1, i] / sse[0, i])
        chosen.append(bool(pick))
        columns.append(restricted[i] if pick else every)
    return GainParts(tuple(columns), tuple(chosen), tuple(ratio), names, inputs, k)
