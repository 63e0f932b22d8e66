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

Both are computed and recorded for every candidate (:class:`AutoSettings`), whichever decides.

The fallback. The task objective's ``K̂x`` alone (the IOC-only prediction, each fold's own gain) is scored on the
same held-out rollouts, and the chosen candidate is kept only where it beats ``K̂x`` by more than one standard error
of the paired per-trial difference (Breiman's one-standard-error rule, a convention, not tuned here): the best of six
candidates is chosen on the same folds that score it, so its cross-validated error is optimistic, and a variability
model that wins by less than the folds' noise is as likely to lose on new trials (issue 40: on one of 8 seeds of a
non-LQR pilot a G = 5 model whose true error was 28 % above ``K̂x``'s won the plain comparison). Otherwise the model
predicts with ``K̂x`` (``AutoSettings.fallback``).

Speed. The candidates of one fold share its gain (estimated once, :func:`workbench.models.fitting.shared_gains`) and
skip the Monte Carlo noise (the held-out scores use mean rollouts only). Starting each regularizer's EM from the
previous one's fit on the same fold (a warm start) was tried and saved no iterations (G = 5 on the simulator's CS1:
339 iterations warm, 342 cold, over three folds), so every candidate starts from k-means.

Measured on 30
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
from workbench.models.fitting import shared_gains
from workbench.models.regulator import settle_task

__all__ = ["AutoSettings", "choose_settings", "COMPONENT_GRID", "REG_COVAR_GRID", "CRITERIA",
           "DEFAULT_COMPONENT_GRID", "DEFAULT_REG_COVAR_GRID", "NoCandidateFitted", "FALLBACK_SE"]

#: A wider grid, for those who ask for it (``cv_components=COMPONENT_GRID``).
COMPONENT_GRID = (1, 2, 3, 5, 8)
REG_COVAR_GRID = (0.1, 0.3, 1.0)
#: The grid of the default model (``"cv"`` wherever no grid is given): one component included, so a variability
#: model that is little more than a linear correction can win, and two regularizers.
DEFAULT_COMPONENT_GRID = (1, 2, 5)
DEFAULT_REG_COVAR_GRID = (0.3, 1.0)
#: The chosen candidate must beat ``K̂x`` on the held-out rollouts by more than this many standard errors of the
#: paired per-trial difference, else the model falls back to ``K̂x`` (the one-standard-error rule).
FALLBACK_SE = 1.0
CRITERIA = ("prediction", "likelihood")
# EM of the candidate fits (and of the chosen one's final fit, so it is fitted as it was scored): at most 200
# iterations, and stopped once the mean log-likelihood gains less than 1e-4 per sample. Against the fits' own 1e-6,
# measured on four simulated pilots (CS1, erratic, delayed, near-LQR; 24 training trials, seeds 3101-3103 — seeds
# no acceptance test uses — scored on 80 fresh trials): the same G, regularizer and fallback in 12 of 12, the
# proposed/IOC-only error ratio within 0.007 (0.8973 -> 0.9044 the largest change), 1.6x less CPU (2.2 s -> 1.3 s
# per cross-validation).
_CV_MAX_ITER = 200
_CV_TOL = 1e-4
# Starts per held-out trial, spread evenly over it (evaluate scores rollouts from every second of a whole trial).
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
        True where the chosen candidate does not beat that by more than :data:`FALLBACK_SE` standard errors of the
        paired per-trial difference: the fitted model predicts with ``K̂x`` alone (``variability_mean_ = False``)
        and keeps the variability model for its input band only. Said wherever the model is described, never silent.
    gain, gain_se : float
        The chosen candidate's mean per-trial held-out RMSE below ``K̂x``'s (> 0: lower) and its standard error
        over the held-out trials; NaN where not scored (files written before they were recorded).
    fitted_rmse, fitted_ioc_rmse : float
        The chosen setting fitted on all trials: its mean rollouts' RMSE on those trials, and ``K̂x``'s
        (:func:`fitted_check`). Where the first is the higher, the choice did not carry over to the fit on all
        trials and ``fallback`` is True; NaN where not checked.
    """

    n_components: int
    reg_covar: float
    criterion: str
    folds: int
    scores: tuple[dict, ...]
    ioc_only_rmse: float = math.nan
    fallback: bool = False
    gain: float = math.nan
    gain_se: float = math.nan
    fitted_rmse: float = math.nan
    fitted_ioc_rmse: float = math.nan

    def as_json(self) -> dict:
        def num(v: float) -> float | None:
            return None if math.isnan(v) else v

        return {"n_components": self.n_components, "reg_covar": self.reg_covar, "criterion": self.criterion,
                # a candidate not fitted on every fold scores NaN, which a model file (strict JSON) writes as null
                "folds": self.folds, "scores": [{k: num(v) if isinstance(v, float) else v for k, v in r.items()}
                                                for r in self.scores],
                "ioc_only_rmse": num(self.ioc_only_rmse), "fallback": self.fallback, "gain": num(self.gain),
                "gain_se": num(self.gain_se), "fitted_rmse": num(self.fitted_rmse),
                "fitted_ioc_rmse": num(self.fitted_ioc_rmse)}

    @classmethod
    def from_json(cls, d: dict) -> AutoSettings:
        def num(key: str) -> float:  # files written before the fallback (or its standard error) have none
            v = d.get(key)
            return math.nan if v is None else float(v)

        return cls(int(d["n_components"]), float(d["reg_covar"]), str(d["criterion"]), int(d["folds"]),
                   tuple({k: math.nan if v is None else v for k, v in r.items()} for r in d["scores"]),
                   num("ioc_only_rmse"), bool(d.get("fallback", False)),
                   num("gain"), num("gain_se"), num("fitted_rmse"), num("fitted_ioc_rmse"))

    def fallback_reason(self) -> str:
        """Why the model fell back to ``K̂x``, as a clause (``""`` where it did not)."""
        if not self.fallback:
            return ""
        if self.fitted_rmse > self.fitted_ioc_rmse:
            return (f"fitted on all trials, its variability model predicted them worse than K̂x alone "
                    f"({self.fitted_rmse:.4g} against {self.fitted_ioc_rmse:.4g})")
        return (f"in cross-validation its variability model did not lower the held-out error by more than its "
                f"standard error ({self.folds}-fold)")

    def describe(self) -> str:
        """One line: what was chosen, from what, and — where it happened — the fallback to ``K̂x``."""
        best = next((r for r in self.scores if r.get("chosen")), None)
        chosen = (f"G = {self.n_components}, reg_covar = {self.reg_covar:g} by {self.folds}-fold cross-validation "
                  f"({self.criterion})")
        if best is None or not math.isfinite(self.ioc_only_rmse):
            return chosen
        margin = (f"; per held-out trial {_signed(self.gain)} ± {self.gain_se:.2g} (one standard error) below it"
                  if math.isfinite(self.gain) and math.isfinite(self.gain_se) else "")
        if self.fallback and self.fitted_rmse > self.fitted_ioc_rmse:
            return (f"{chosen}; fitted on all trials, its variability model predicted those very trials worse than "
                    f"the task objective's K̂x alone ({self.fitted_rmse:.4g} against {self.fitted_ioc_rmse:.4g}; "
                    f"held out, {best['heldout_rmse']:.4g} against {self.ioc_only_rmse:.4g}): the choice did not "
                    "carry over to the fit on all trials, so the model predicts with K̂x alone (as IOC-only) and "
                    "keeps the variability model for its input band")
        if self.fallback:
            return (f"{chosen}; its variability model did not lower the held-out rollout error by more than its "
                    f"standard error (IOC-only {self.ioc_only_rmse:.4g} against {best['heldout_rmse']:.4g}{margin}), "
                    "so the model predicts with the task objective's K̂x alone (as IOC-only) and keeps the "
                    "variability model for its input band")
        return (f"{chosen}; held-out rollout RMSE {best['heldout_rmse']:.4g} against IOC-only "
                f"{self.ioc_only_rmse:.4g}{margin}")


def _signed(v: float) -> str:
    """A difference to 2 significant figures, never "-0"."""
    text = f"{v:.2g}"
    return "0" if float(text) == 0 else text


def _folds(n_demos: int, k: int, seed: int | None) -> list[np.ndarray]:
    order = np.random.default_rng(seed).permutation(n_demos)
    return [order[i::k] for i in range(k)]


def _starts(length: int, H: int) -> list[int]:
    """At most :data:`_CV_STARTS` starts of ``H``-step rollouts, spread evenly from the trial's first state to its
    last full window: a held-out score of the trial as a whole, not of its first seconds (issue 40: the first
    four half-horizons, 4.5 s of a 12 s trial, chose a variability model 0.5 % better than ``K̂x`` there that was
    57 % worse over the whole test trials)."""
    last = max(length - H - 1, 0)
    return sorted({int(round(v)) for v in np.linspace(0, last, min(_CV_STARTS, last + 1))})


def _scored_states(plant, demos) -> tuple[list[int], np.ndarray]:
    """The states a rollout is scored on and their scale: the positions as they are, or every state divided by its
    spread over ``demos`` on a plant without position roles."""
    idx = list(plant.r.position) if plant.r.position else list(range(plant.n))
    if plant.r.position:
        return idx, np.ones(len(idx))
    xs = np.concatenate([d.x for d in demos])[:, idx]
    spread = xs.std(axis=0)  # of a constant state: rounding (1e-16), not 0, hence the relative tolerance
    return idx, np.where(spread > 1e-12 * np.maximum(1.0, np.abs(xs).max(axis=0)), spread, 1.0)


def fitted_check(model, demos: Sequence) -> tuple[float, float]:
    """The mean-rollout RMSE of a fitted model on its own training trials, with its variability mean and with
    ``K̂x`` alone, scored as the cross-validation scores its candidates.

    The candidates are scored on folds, each with its own gain; the chosen setting is then fitted on all trials,
    with another gain. Where that gain is weakly identified (a pilot the gain's instruments barely reach), the
    fold gains and the final one differ, and a variability mean that helped every fold can drive the final
    model's rollouts away (issue 40: 310 against 0.49 on its own training trials, an erratic pilot). A mean
    fitted to these trials that predicts them worse than ``K̂x`` does is not kept.
    """
    demos = list(demos)
    idx, spread = _scored_states(model.plant, demos)
    H = max(1, int(round(model.noise_horizon_s / model.plant.dt)))
    kept = model.variability_mean_
    try:
        model.variability_mean_ = True
        with_mean, _ = _rollout_rmse(model, demos, H, idx, spread)
        model.variability_mean_ = False
        alone, _ = _rollout_rmse(model, demos, H, idx, spread)
    finally:
        model.variability_mean_ = kept
    return with_mean, alone


def _rollout_rmse(model, demos, n_steps: int, idx: Sequence[int], spread: np.ndarray) -> tuple[float, np.ndarray]:
    """Mean over starts of the RMSE of a mean rollout of ``horizon`` steps on the states ``idx``, and the mean
    over each trial's own starts (NaN for a trial too short to score)."""
    # the trials of one horizon in one predict_many call: their tasks roll out as one batch (the same numbers)
    plan: dict[int, list[tuple[int, list[int]]]] = {}
    for j, d in enumerate(demos):
        H = min(n_steps, len(d) - 1)
        if H >= 1:
            plan.setdefault(H, []).append((j, _starts(len(d), H)))
    preds: dict[int, list] = {}
    for H, trials in plan.items():
        x0s, goals, task_x0s, steps, pasts = [], [], [], [], []
        for j, starts in trials:
            d = demos[j]
            x0s += [d.x[s] for s in starts]
            goals += [model._goal_for(d)] * len(starts)
            task_x0s += [d.x[0]] * len(starts)
            steps += starts
            past = model.pasts(d, starts)
            pasts = None if past is None else [*(pasts or []), *past]
        out = model.predict_many(np.array(x0s), H, np.array(goals), task_x0s=np.array(task_x0s), task_steps=steps,
                                 pasts=pasts)
        for j, starts in trials:
            preds[j], out = out[: len(starts)], out[len(starts) :]
    errs, per_trial = [], []
    for j, d in enumerate(demos):
        if j not in preds:
            per_trial.append(math.nan)
            continue
        H = min(n_steps, len(d) - 1)
        starts = next(st for jj, st in plan[H] if jj == j)
        mine = []
        for s, p in zip(starts, preds[j], strict=True):
            diff = (p.x[1:, idx] - d.x[s + 1 : s + H + 1, idx]) / spread
            mine.append(float(np.sqrt(np.mean(np.sum(diff**2, axis=1)))))
        errs += mine
        per_trial.append(float(np.mean(mine)))
    return (float(np.mean(errs)) if errs else math.nan), np.array(per_trial, dtype=float)


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
        Candidate grids (default the default model's :data:`DEFAULT_COMPONENT_GRID` /
        :data:`DEFAULT_REG_COVAR_GRID` where the setting is ``"cv"``).
    folds : int
        Folds of whole demonstrations (at most one per demonstration).
    criterion : {"prediction", "likelihood"}
    fallback : bool
        Also score the task-objective behavior alone (``K̂x``, each fold's gain) on the same held-out rollouts and,
        with the "prediction" criterion, choose it where the chosen candidate does not beat it by more than
        :data:`FALLBACK_SE` standard errors of the paired per-trial difference (``AutoSettings.fallback``).

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
    Gs = list(components or (DEFAULT_COMPONENT_GRID if model.n_components == "cv" else (int(model.n_components),)))
    regs = list(reg_covars or (DEFAULT_REG_COVAR_GRID if model.reg_covar == "cv" else (float(model.reg_covar),)))
    k = max(2, min(int(folds), len(demos)))
    parts = _folds(len(demos), k, model.random_state if isinstance(model.random_state, int) else 0)
    plant = model.plant
    idx = list(plant.r.position) if plant.r.position else list(range(plant.n))
    H = max(1, int(round(model.noise_horizon_s / plant.dt)))
    # mean rollouts and likelihoods never use the Monte Carlo noise: "gmr" skips its calibration
    settings = {**model.get_params(), "fit_objective": False, "noise_folds": 0, "noise": "gmr",
                "max_iter": min(int(model.max_iter), _CV_MAX_ITER), "tol": max(float(model.tol), _CV_TOL)}
    tally = _Tally({(G, r): [] for G in Gs for r in regs}, {(G, r): [] for G in Gs for r in regs},
                   {(G, r): np.full(len(demos), math.nan) for G in Gs for r in regs}, [],
                   np.full(len(demos), math.nan), {})
    with shared_gains():
        for fold, test_idx in enumerate(parts):
            _fold(model, demos, fold, test_idx, Gs, regs, settings, idx, H, fallback, tally)
    return _decide(Gs, regs, k, tally, criterion, fallback)


@dataclass
class _Tally:
    """The scores of every candidate over the folds: mean held-out RMSE and log-likelihood per fold, RMSE per
    held-out trial, the same for ``K̂x`` alone, and why a candidate could not be fitted (→ first fold, its trials)."""

    rmse: dict
    loglik: dict
    trial_rmse: dict
    ioc: list
    ioc_trials: np.ndarray
    causes: dict


def _fold(model, demos, fold, test_idx, Gs, regs, settings, idx, H, fallback, tally: _Tally) -> None:
    """Fit and score every candidate on one fold (its gain estimated once)."""
    plant = model.plant
    held = set(test_idx.tolist())
    train = [demos[j] for j in range(len(demos)) if j not in held]
    test = [demos[j] for j in test_idx]
    n_train = sum(len(d) for d in train)
    _, spread = _scored_states(plant, train)
    # the fold's task (a reference's speed fitted on its training trials) is settled once for its candidates
    try:
        fold_task = settle_task(model, train)
    except ModelError as exc:
        tally.causes.setdefault(str(exc), (fold + 1, len(train)))
        for key in tally.rmse:  # no candidate of this fold is scored
            tally.rmse[key].append(math.nan)
            tally.loglik[key].append(math.nan)
        if fallback:
            tally.ioc.append(math.nan)
        return
    for G in Gs:
        if G * _SAMPLES_PER_COMPONENT > n_train:
            continue
        for r in regs:
            candidate = type(model)(plant, **{**settings, "n_components": int(G), "reg_covar": float(r),
                                               "task": fold_task})
            fitted = False
            try:
                with warnings.catch_warnings():
                    # a fold may hold few trials and stop EM early; the held-out score judges the result
                    warnings.simplefilter("ignore", ConvergenceWarning)
                    warnings.simplefilter("ignore", DegenerateFitWarning)
                    candidate.fit(train)
                fitted = True
                score, per_trial = _rollout_rmse(candidate, test, H, idx, spread)
                tally.rmse[(G, r)].append(score)
                tally.trial_rmse[(G, r)][test_idx] = per_trial
                tally.loglik[(G, r)].append(float(candidate.score_samples(test).mean()))
                if fallback and len(tally.ioc) == fold:
                    # the fold's K̂x alone: every candidate of a fold shares its gain, so any one scores it
                    candidate.variability_mean_ = False
                    score, per_trial = _rollout_rmse(candidate, test, H, idx, spread)
                    tally.ioc.append(score)
                    tally.ioc_trials[test_idx] = per_trial
                    candidate.variability_mean_ = True
            except ModelError as exc:
                tally.rmse[(G, r)].append(math.nan)
                tally.loglik[(G, r)].append(math.nan)
                if not fitted:  # the fit's own reason (a scoring failure is not the fold's size)
                    tally.causes.setdefault(str(exc), (fold + 1, len(train)))


def _decide(Gs, regs, k, tally: _Tally, criterion, fallback) -> AutoSettings:
    """The candidate the criterion chooses, and whether it beats ``K̂x`` by more than its standard error."""
    rmse, loglik, ioc, causes = tally.rmse, tally.loglik, tally.ioc, tally.causes
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
                    f"{len(tally.ioc_trials)} demonstrations" + (f": {why}" if why else ""))
    if criterion == "prediction":
        best = min(valid, key=lambda row: (row["heldout_rmse"], row["n_components"]))
    else:
        best = max(valid, key=lambda row: (row["heldout_loglik"], -row["n_components"]))
    for row in rows:
        row["chosen"] = row is best
    ioc_rmse = float(np.mean(ioc)) if fallback and len(ioc) == k and np.all(np.isfinite(ioc)) else math.nan
    gain, se = _paired_gain(tally.ioc_trials, tally.trial_rmse[(best["n_components"], best["reg_covar"])])
    # ties and wins inside the folds' noise go to the simpler prediction: a variability model must lower the held-out
    # error by more than its standard error to be used for the mean
    fell_back = criterion == "prediction" and math.isfinite(ioc_rmse) and (
        ioc_rmse <= best["heldout_rmse"] or not (math.isfinite(gain) and gain > FALLBACK_SE * se))
    return AutoSettings(best["n_components"], best["reg_covar"], criterion, k, tuple(rows), ioc_rmse, fell_back,
                        gain, se)


def _paired_gain(baseline: np.ndarray, candidate: np.ndarray) -> tuple[float, float]:
    """Mean per-trial ``baseline − candidate`` over the trials both scored, and its standard error."""
    d = baseline - candidate
    d = d[np.isfinite(d)]
    if d.size < 2:
        return math.nan, math.nan
    return float(d.mean()), float(d.std(ddof=1) / math.sqrt(d.size))

