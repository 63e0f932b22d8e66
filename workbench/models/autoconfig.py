"""Settings chosen from the user's data: ``n_components="cv"`` and ``reg_covar="cv"`` by cross-validation.

The number of Gaussian components G and the covariance regularizer of the TP-GMM decide how much
state-dependent structure the variability model claims. Defaults tuned on one simulator do not carry over to
another operator, so :func:`choose_settings` picks them on the demonstrations at hand: whole demonstrations
are split into folds (samples inside one trial are strongly correlated), every candidate is fitted on the
other folds, and scored on the held-out ones by

* ``"prediction"`` (default): the RMSE of mean rollouts of ``noise_horizon_s`` seconds from several starts of each
  held-out trial, over the position states (all states, each divided by its training spread, on a plant
  without position roles) — the quantity the workbench's evaluations compare;
* ``"likelihood"``: the mean held-out log-likelihood of ``[x; ŵ]`` under the TP-GMM (eq. (29)).

Both are computed and recorded for every candidate (:class:`AutoSettings`), whichever decides. Measured on 30
training / 20 test trials (3 s position RMSE from every second), the prediction criterion chose better each time:
an erratic non-LQR operator (:func:`workbench.sim.operators.erratic_operator_demos`) 0.203 m against 0.233 m for the
likelihood's choice (IOC-only 0.236, the fixed G = 5, reg_covar = 0.5 0.244); the simulator's CS1 0.082 against
0.084 (IOC-only 0.167) and CS2 0.0425 against 0.0438 (IOC-only 0.0494). The likelihood keeps preferring the
smallest regularizer, which sharpens the density but not the mean that predictions follow.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from workbench.errors import ConvergenceWarning, DegenerateFitWarning, ModelError
from workbench.models.regulator import settle_task

__all__ = ["AutoSettings", "choose_settings", "COMPONENT_GRID", "REG_COVAR_GRID", "CRITERIA",
           "DEFAULT_COMPONENT_GRID", "DEFAULT_REG_COVAR_GRID", "NoCandidateFitted"]

COMPONENT_GRID = (1, 2, 3, 5, 8)
REG_COVAR_GRID = (0.1, 0.3, 1.0)
#: The small grid of the default model (``n_components="cv"`` in a study): one component included, so a
#: variability model that is little more than a linear correction can win, and two regularizers.
DEFAULT_COMPONENT_GRID = (1, 2, 5)
DEFAULT_REG_COVAR_GRID = (0.3, 1.0)
CRITERIA = ("prediction", "likelihood")
# EM iterations of the candidate fits: their likelihood has long flattened out by then (as for the noise folds).
_CV_MAX_ITER = 200
# Starts per held-out trial: every half horizon from the first state, at most this many.
_CV_STARTS = 4
# A candidate needs this many samples per free TP-GMM parameter per frame to be worth fitting.
_SAMPLES_PER_COMPONENT = 20


class NoCandidateFitted(ModelError):
    """No candidate setting could be fitted on every fold: there is nothing to choose between (each fold too small
    for the fit, say); the settings cannot be cross-validated on these demonstrations."""


@dataclass(frozen=True)
class AutoSettings:
    """What ``"cv"`` chose, and the cross-validation scores it chose from.

    Attributes
    ----------
    n_components : int
    reg_covar : float
    criterion : str
        ``"prediction"`` (lowest held-out rollout RMSE) or ``"likelihood"`` (highest held-out log-likelihood).
    folds : int
        Folds of whole demonstrations.
    scores : tuple of dict
        One row per candidate: ``n_components``, ``reg_covar``, ``heldout_rmse``, ``heldout_loglik`` (means over
        folds; NaN where a fold's fit failed), ``chosen``.
    ioc_only_rmse : float
        The held-out rollout RMSE of the task-objective behavior alone (``û = K̂x``, the IOC-only prediction)
        on the same folds; NaN where it was not scored.
    fallback : bool
        True where that beat every candidate: the variability model does not lower the held-out error, so the
        fitted model predicts with ``K̂x`` alone (``variability_mean_ = False``) and keeps the variability model
        for its input band only. Said wherever the model is described, never silent.
    """

    n_components: int
    reg_covar: float
    criterion: str
    folds: int
    scores: tuple[dict, ...]
    ioc_only_rmse: float = math.nan
    fallback: bool = False

    def as_json(self) -> dict:
        return {"n_components": self.n_components, "reg_covar": self.reg_covar, "criterion": self.criterion,
                "folds": self.folds, "scores": [dict(r) for r in self.scores],
                "ioc_only_rmse": None if math.isnan(self.ioc_only_rmse) else self.ioc_only_rmse,
                "fallback": self.fallback}

    @classmethod
    def from_json(cls, d: dict) -> AutoSettings:
        ioc = d.get("ioc_only_rmse")  # files written before the fallback existed have neither
        return cls(int(d["n_components"]), float(d["reg_covar"]), str(d["criterion"]), int(d["folds"]),
                   tuple(dict(r) for r in d["scores"]), math.nan if ioc is None else float(ioc),
                   bool(d.get("fallback", False)))

    def describe(self) -> str:
        """One line: what was chosen, from what, and — where it happened — the fallback to ``K̂x``."""
        best = next((r for r in self.scores if r.get("chosen")), None)
        chosen = (f"G = {self.n_components}, reg_covar = {self.reg_covar:g} by {self.folds}-fold cross-validation "
                  f"({self.criterion})")
        if best is None or not math.isfinite(self.ioc_only_rmse):
            return chosen
        if self.fallback:
            return (f"{chosen}; its variability model did not lower the held-out rollout error (IOC-only "
                    f"{self.ioc_only_rmse:.4g} against {best['heldout_rmse']:.4g}), so the model predicts with the "
                    "task objective's K̂x alone (as IOC-only) and keeps the variability model for its input band")
        return f"{chosen}; held-out rollout RMSE {best['heldout_rmse']:.4g} against IOC-only {self.ioc_only_rmse:.4g}"


def _folds(n_demos: int, k: int, seed: int | None) -> list[np.ndarray]:
    order = np.random.default_rng(seed).permutation(n_demos)
    return [order[i::k] for i in range(k)]


def _rollout_rmse(model, demos, n_steps: int, idx: Sequence[int], spread: np.ndarray) -> float:
    """Mean over starts of the RMSE of a mean rollout of ``horizon`` steps on the states ``idx``."""
    errs = []
    for d in demos:
        H = min(n_steps, len(d) - 1)
        if H < 1:
            continue
        starts = list(range(0, len(d) - H, max(1, H // 2)))[:_CV_STARTS] or [0]
        goal = model._goal_for(d)
        preds = model.predict_many(d.x[starts], H, [goal] * len(starts), task_x0s=[d.x[0]] * len(starts),
                                   task_steps=starts, pasts=model.pasts(d, starts))
        for s, p in zip(starts, preds, strict=True):
            diff = (p.x[1:, idx] - d.x[s + 1 : s + H + 1, idx]) / spread
            errs.append(float(np.sqrt(np.mean(np.sum(diff**2, axis=1)))))
    return float(np.mean(errs)) if errs else math.nan


def choose_settings(
    model,
    demos: Sequence,
    components: Sequence[int] | None = None,
    reg_covars: Sequence[float] | None = None,
    folds: int = 3,
    criterion: str = "prediction",
    fallback: bool = True,
) -> AutoSettings:
    """Cross-validate the TP-GMM settings of a :class:`~workbench.models.proposed.HumanBehaviorModel` over
    demonstrations.

    Parameters
    ----------
    model : HumanBehaviorModel
        Its other settings (frames, gain method, standardization, seed, …) are kept for every candidate; its
        ``n_components`` / ``reg_covar`` are the candidates' where they are not ``"cv"``.
    demos : sequence of Demonstration
    components, reg_covars : sequence, optional
        Candidate grids (default :data:`COMPONENT_GRID` / :data:`REG_COVAR_GRID` where the setting is
        ``"cv"``).
    folds : int
        Folds of whole demonstrations (at most one per demonstration).
    criterion : {"prediction", "likelihood"}
    fallback : bool
        Also score the task-objective behavior alone (``K̂x``, each fold's gain) on the same held-out rollouts and,
        with the "prediction" criterion, choose it where no candidate beats it (``AutoSettings.fallback``).

    Raises
    ------
    ModelError
        With fewer than 2 demonstrations, an unknown criterion, or when no candidate could be fitted.
    """
    if criterion not in CRITERIA:
        raise ModelError(f"auto settings: criterion must be one of {CRITERIA}, got {criterion!r}")
    demos = list(demos)
    if len(demos) < 2:
        raise ModelError(f"auto settings need at least 2 demonstrations to cross-validate, got {len(demos)}")
    Gs = list(components or (COMPONENT_GRID if model.n_components == "cv" else (int(model.n_components),)))
    regs = list(reg_covars or (REG_COVAR_GRID if model.reg_covar == "cv" else (float(model.reg_covar),)))
    k = max(2, min(int(folds), len(demos)))
    parts = _folds(len(demos), k, model.random_state if isinstance(model.random_state, int) else 0)
    system = model.system
    idx = list(system.r.position) if system.r.position else list(range(system.n))
    H = max(1, int(round(model.noise_horizon_s / system.dt)))
    settings = {**model.get_params(), "fit_objective": False, "noise_folds": 0,
                "max_iter": min(int(model.max_iter), _CV_MAX_ITER)}
    rmse = {(G, r): [] for G in Gs for r in regs}
    loglik = {(G, r): [] for G in Gs for r in regs}
    ioc: list[float] = []
    causes: dict[str, tuple[int, int]] = {}  # why a candidate could not be fitted → (first fold, its trials)
    for fold, test_idx in enumerate(parts):
        held = set(test_idx.tolist())
        train = [demos[j] for j in range(len(demos)) if j not in held]
        test = [demos[j] for j in test_idx]
        n_train = sum(len(d) for d in train)
        # the fold's task (a reference's speed fitted on its training trials) is settled once for its candidates
        try:
            fold_task = settle_task(model, train)
        except ModelError as exc:
            causes.setdefault(str(exc), (fold + 1, len(train)))
            continue
        if system.r.position:
            spread = np.ones(len(idx))
        else:
            xs = np.concatenate([d.x for d in train])[:, idx]
            spread = xs.std(axis=0)  # of a constant state: rounding (1e-16), not 0, hence the relative tolerance
            spread = np.where(spread > 1e-12 * np.maximum(1.0, np.abs(xs).max(axis=0)), spread, 1.0)
        for G in Gs:
            if G * _SAMPLES_PER_COMPONENT > n_train:
                continue
            for r in regs:
                candidate = type(model)(system, **{**settings, "n_components": int(G), "reg_covar": float(r),
                                                   "task": fold_task})
                fitted = False
                try:
                    with warnings.catch_warnings():
                        # a fold may hold few trials and stop EM early; the held-out score judges the result
                        warnings.simplefilter("ignore", ConvergenceWarning)
                        warnings.simplefilter("ignore", DegenerateFitWarning)
                        candidate.fit(train)
                    fitted = True
                    rmse[(G, r)].append(_rollout_rmse(candidate, test, H, idx, spread))
                    loglik[(G, r)].append(float(candidate.score_samples(test).mean()))
                    if fallback and len(ioc) == fold:
                        # the fold's K̂x alone: every candidate of a fold shares its gain, so any one scores it
                        candidate.variability_mean_ = False
                        ioc.append(_rollout_rmse(candidate, test, H, idx, spread))
                except ModelError as exc:
                    rmse[(G, r)].append(math.nan)
                    loglik[(G, r)].append(math.nan)
                    if not fitted:  # the fit's own reason (a scoring failure is not the fold's size)
                        causes.setdefault(str(exc), (fold + 1, len(train)))
    rows = []
    for (G, r), errs in rmse.items():
        complete = len(errs) == k and np.all(np.isfinite(errs)) and np.all(np.isfinite(loglik[(G, r)]))
        rows.append({"n_components": int(G), "reg_covar": float(r),
                     "heldout_rmse": float(np.mean(errs)) if complete else math.nan,
                     "heldout_loglik": float(np.mean(loglik[(G, r)])) if complete else math.nan})
    valid = [row for row in rows if math.isfinite(row["heldout_rmse"])]
    if not valid:
        # the fits' own reason, which the grid cannot change when it is the gain's (one trial per fold, say)
        why = "; ".join(f"fold {f} ({n} training trials): {c}" for c, (f, n) in list(causes.items())[:2])
        # only fits that failed (a fold too small for them) fall back to the defaults; a grid whose every candidate
        # was skipped for want of samples, or a scoring failure, stays an error
        error = NoCandidateFitted if causes else ModelError
        raise error(f"auto settings: no candidate of G {Gs} × reg_covar {regs} could be fitted on every fold of "
                    f"{len(demos)} demonstrations" + (f": {why}" if why else ""))
    if criterion == "prediction":
        best = min(valid, key=lambda row: (row["heldout_rmse"], row["n_components"]))
    else:
        best = max(valid, key=lambda row: (row["heldout_loglik"], -row["n_components"]))
    for row in rows:
        row["chosen"] = row is best
    ioc_rmse = float(np.mean(ioc)) if fallback and len(ioc) == k and np.all(np.isfinite(ioc)) else math.nan
    # ties go to the simpler prediction: a variability model must lower the held-out error to be used for the mean
    fell_back = criterion == "prediction" and math.isfinite(ioc_rmse) and ioc_rmse <= best["heldout_rmse"]
    return AutoSettings(best["n_components"], best["reg_covar"], criterion, k, tuple(rows), ioc_rmse, fell_back)
