"""A rollout that diverges is not a prediction: it is said, not scored.

A model whose closed loop is *not distinguishable* from the unit circle is kept (:mod:`workbench.method.stability`),
and where its ρ̂ lies above 1, or a fold's refit lands further out, its mean rollout can grow without bound over a
study's horizon: on a real LOITER flight the proposed model's 3 s position RMSE came out at 9.99e+05 m beside
persistence's 0.906 m. Such an RMSE measures how fast the rollout blows up, not how well it predicts, and it is no
number to print as a comparison, nor to average into one.

The rule, decided in one place: :func:`workbench.study.evaluate.compare` asks :func:`diverged` of every window's
mean rollout and writes a ``diverged`` row (1 or 0) beside its scores, and the fitted loop's ρ̂ with its interval
(``loop_rho``, ``loop_rho_lo``, ``loop_rho_hi``, where the model has one) once per trial. A mean rollout
diverges where, on the scored blocks of states, a predicted state lies farther from the centre of the trial's
recorded states than ``factor`` times the farthest recorded state (:data:`~workbench.defaults.DIVERGED_FACTOR`, an
order of magnitude beyond anything flown), or is not finite. ρ̂ explains; it does not decide: a loop at 1.004 grows
by 27 % over 60 steps and still predicts.

Everything that summarizes a comparison reads the rows through :func:`notes` and :func:`scored`:

- a method that diverged in any window of a label shows ``diverges (ρ̂ 1.05 [0.999, 1.11])`` (or ``diverges on 1
  of 2 trials (…)``) in place of each of its horizon scores there — the state RMSEs, the Monte Carlo band, the
  input over the horizon — in the terminal, the report, the viewer and the bench table alike
  (:func:`workbench.study.scores.heldout_scores`); its one-step input score stands, as it never rolls out;
- and it is left out of that label's statistics of those scores, as a method that could not be fitted is: a mean
  over its other windows would flatter it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from workbench.defaults import DIVERGED_FACTOR

__all__ = ["DIVERGED", "LOOP_RHO", "MARKERS", "diverged", "is_rollout_metric", "loop_rows", "notes", "scored",
           "verdict_lines"]

#: The row beside a window's scores: 1 where the mean rollout diverged.
DIVERGED = "diverged"
#: The fitted loop's ρ̂ and its interval, one row each per trial and method (models with a gain).
LOOP_RHO = ("loop_rho", "loop_rho_lo", "loop_rho_hi")
#: The rows this module reads; not scores themselves.
MARKERS = (DIVERGED, *LOOP_RHO)
#: The scores that come from a rollout (every ``rmse_*`` and ``band_*``, and the input along the rollout).
_ROLLOUT_PREFIXES = ("rmse_", "band_", "input_horizon")


def is_rollout_metric(metric: str) -> bool:
    """Whether ``metric`` is scored along a model's rollout (and so means nothing where the rollout diverged)."""
    return str(metric).startswith(_ROLLOUT_PREFIXES)


def diverged(x_pred: np.ndarray, x_rec: np.ndarray, idx: Any = None, factor: float = DIVERGED_FACTOR) -> bool:
    """Whether the mean rollout ``x_pred`` (H+1, n) left the range of the recorded states ``x_rec`` (N, n).

    On the states ``idx`` (all without): some predicted state lies farther from the centre of the recorded box than
    ``factor`` times the farthest recorded state, or is not finite. Recorded states that do not move (no range)
    give no verdict but the non-finite one.
    """
    xp = np.asarray(x_pred, dtype=float)
    xr = np.asarray(x_rec, dtype=float)
    if idx is not None:
        cols = np.asarray(idx, dtype=int).reshape(-1)
        xp, xr = xp[:, cols], xr[:, cols]
    if not np.isfinite(xp).all():
        return True
    xr = xr[np.isfinite(xr).all(axis=1)]
    if not len(xr):
        return False
    centre = 0.5 * (xr.max(axis=0) + xr.min(axis=0))
    reach = float(np.linalg.norm(xr - centre, axis=1).max())
    if not reach > 0.0:
        return False
    return bool(np.linalg.norm(xp - centre, axis=1).max() > float(factor) * reach)


def loop_rows(model: Any) -> list[tuple[str, float]]:
    """``(metric, value)`` of the model's fitted loop: ρ̂ and its interval bounds (NaN without one); none for a
    model without a judged loop (GMR-only, persistence)."""
    s = getattr(model, "stability_", None)
    if s is None:
        return []
    return [(LOOP_RHO[0], float(s.rho)), (LOOP_RHO[1], float(s.lo)), (LOOP_RHO[2], float(s.hi))]


def _labelled(table: pd.DataFrame) -> pd.DataFrame:
    label = table["label"].fillna("").astype(str) if "label" in table.columns else pd.Series("", index=table.index)
    return table.assign(label=label)


def _rho_words(table: pd.DataFrame, label: str, method: str, trials: set) -> tuple[str, bool]:
    """ρ̂ [lo, hi] of the loop behind the largest ρ̂ among ``trials`` (each fold's own model), or "", and whether
    that loop's whole interval lies inside the unit circle."""
    t = table[(table["label"] == label) & (table["method"] == method) & table["metric"].isin(LOOP_RHO)
              & table["trial"].isin(list(trials))]
    if t.empty:
        return "", False
    per = t.groupby(["trial", "metric"], sort=False)["value"].first().unstack("metric")
    if LOOP_RHO[0] not in per.columns:
        return "", False
    top = per.sort_values(LOOP_RHO[0], ascending=False).iloc[0]
    rho, lo, hi = (float(top.get(m, np.nan)) for m in LOOP_RHO)
    if np.isfinite(lo) and np.isfinite(hi):
        return f"ρ̂ {rho:.4g} [{lo:.3g}, {hi:.3g}]", hi < 1.0
    return f"ρ̂ {rho:.4g}, no interval", False


def notes(table: pd.DataFrame) -> dict[tuple[str, str], str]:
    """Per ``(label, method)`` whose mean rollout diverged in any window: the words shown in place of each of its
    horizon scores, e.g. ``"diverges (ρ̂ 1.052 [0.999, 1.1])"`` where it diverged on every test trial, ``"diverges
    on 1 of 2 trials (ρ̂ 1.052 [0.999, 1.1])"`` where not (the loop of the fold with the largest ρ̂ among the
    trials that diverged; no ρ̂ for a model without a judged loop), ``"diverges though its loop is stable (ρ̂ 0.986
    [0.981, 0.992])"`` where that loop's whole interval lies inside the unit circle. Empty for a table without
    ``diverged`` rows."""
    if table is None or not len(table) or DIVERGED not in set(table["metric"]):
        return {}
    t = _labelled(table)
    rows = t[t["metric"] == DIVERGED]
    per = rows.groupby(["label", "method", "trial"], sort=False)["value"].max()
    out: dict[tuple[str, str], str] = {}
    for (label, method), v in per.groupby(level=["label", "method"], sort=False):
        bad = v[v > 0]
        if bad.empty:
            continue
        rho, stable = _rho_words(t, str(label), str(method), set(bad.index.get_level_values("trial")))
        where = "" if len(bad) == len(v) else f" on {len(bad)} of {len(v)} trials"
        # a loop inside the unit circle beside "diverges" reads as a contradiction unless it is named: the rule is
        # the rollout's range, and what carries a stable loop's mean off is not its gain
        though = " though its loop is stable" if stable else ""
        out[(str(label), str(method))] = f"diverges{where}{though}" + (f" ({rho})" if rho else "")
    return out


def scored(table: pd.DataFrame) -> pd.DataFrame:
    """``table`` without the horizon scores of every ``(label, method)`` whose rollout diverged somewhere: the rows
    a study's statistics may average (the one-step scores, and every other method's, stay)."""
    said = notes(table)
    if not said:
        return table
    t = _labelled(table)
    pair = pd.Series(list(zip(t["label"], t["method"].astype(str), strict=True)), index=t.index)
    drop = pair.isin(list(said)) & t["metric"].map(is_rollout_metric)
    return table[~drop.to_numpy()]


def verdict_lines(table: pd.DataFrame, titles: dict[str, str] | None = None,
                  factor: float = DIVERGED_FACTOR) -> list[str]:
    """One plain sentence per ``(label, method)`` whose rollout diverged: what was seen and what it means."""
    out = []
    for (label, method), note in notes(table).items():
        name = (titles or {}).get(method, method)
        head = f"On {label}, {name}" if label not in ("", "None", "all") else name[:1].upper() + name[1:]
        out.append(f"{head}'s mean rollout {note}: it leaves the recorded states' range by more than ×{factor:g} "
                   "over the horizon, so its horizon errors are not numbers to compare; it is left out of the "
                   "statistics of those scores (its one-step input score stands).")
    return out
