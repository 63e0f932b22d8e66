"""Held-out scores of a session recording: which trials a model has not seen, its (and its baselines' and
persistence's) prediction error on them, and the sentence that says where the numbers come from.

:func:`workbench.viewer.session.log_session` calls :func:`heldout_table` where no study passed its own table, and
logs :func:`scores_of` it under ``scores`` (:meth:`~workbench.viewer.session.SessionLogger.log_scores`).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.defaults import N_STEPS
from workbench.study.pipeline import StudyResult
from workbench.viewer.entities import SCORES, label_scores_path
from workbench.viewer.entities import model_for as _model_for

__all__ = ["SCORE_STRIDE_S", "heldout_table", "log_scores", "score_units", "scores_of", "study_note", "study_notes"]


def scores_of(table: Any) -> Any:
    """The held-out scores of a comparison table: the states' and the pilot's own input's."""
    from workbench.study.input_prediction import INPUT_METRICS
    from workbench.study.scores import SCORE_METRICS, heldout_scores

    return None if table is None or not len(table) else heldout_scores(table, (*SCORE_METRICS, *INPUT_METRICS))


def score_units(models: Any) -> dict[str, str]:
    """The unit of each RMSE metric from a model's plant roles (``rmse_position`` → "m")."""
    from workbench.study.evaluate import metric_blocks
    from workbench.study.pipeline import metric_unit

    first = next(iter(models.values()), None) if isinstance(models, Mapping) else models
    plant = getattr(first, "plant", None)
    if plant is None:
        return {}
    return {f"rmse_{b}": metric_unit(plant, f"rmse_{b}") for b in metric_blocks(plant)}


#: Windows of a view's held-out scores start every this many seconds of a trial (as ``evaluate``'s default).
SCORE_STRIDE_S = 1.0


def heldout_table(demos: DemonstrationSet, models: Any, baselines: Mapping[str, Mapping[str, Any]] | None = None,
                  *, n_steps: int = N_STEPS, samples: int = 0, seed: int | None = 0) -> tuple[Any, str]:
    """Score each model, its baselines and persistence on the trials it was not fitted on.

    Returns the :func:`workbench.study.evaluate.compare` table (None where no trial is held out) and a sentence
    stating the split: which trials are held out by the model's record of its training trials, the horizon and
    the windows; or why nothing is scored.
    """
    import pandas as pd

    from workbench.models.factory import make_model
    from workbench.models.training import held_out, training_known
    from workbench.study.evaluate import compare

    groups: dict[int, tuple[Any, list[Demonstration]]] = {}
    for d in demos:
        m = _model_for(models, d)
        if m is not None:
            groups.setdefault(id(m), (m, []))[1].append(d)
    parts, n_held, n_all, unknown = [], 0, 0, False
    stride = max(1, int(round(SCORE_STRIDE_S / demos.dt)))
    for model, trials in groups.values():
        n_all += len(trials)
        unknown |= not training_known(model)
        keep = set(held_out(model, trials))
        held = [d for d in trials if d.id in keep]
        if not held:
            continue
        n_held += len(held)
        label = held[0].label
        methods = {"proposed": model, **((baselines or {}).get(label) or (baselines or {}).get(None) or {})}
        if "persistence" not in methods:
            with warnings.catch_warnings():  # it learns nothing from them: no "too few trials" warning
                warnings.simplefilter("ignore")
                methods["persistence"] = make_model("persistence", model.plant).fit(held)
        parts.append(compare(methods, held, n_steps=n_steps, starts=stride, samples=samples, seed=seed))
    horizon = f"{n_steps * demos.dt:g} s horizon, windows every {SCORE_STRIDE_S:g} s"
    if not n_held:
        return None, (f"none: every one of the {n_all} trial(s) shown was used to fit the model (in-sample); "
                      "score it with `workbench evaluate` or on a log it has not seen")
    if unknown:
        what = f"{n_held} trial(s), the model file does not record its training trials (they may be in-sample)"
    else:
        what = f"{n_held} of {n_all} trial(s) held out (not among the trials the model file records)"
    return pd.concat(parts, ignore_index=True), f"{what}; {horizon}"



def study_note(result: StudyResult, label: str | None = None) -> str:
    """Where a study's held-out scores come from: its test trials (of ``label`` only, where given), the horizon,
    the windows."""
    n = sum(len(te) for lb, te in result.test.items() if label is None or str(lb) == str(label))
    stride = ("each trial's first state" if result.stride_steps is None
              else f"windows every {result.stride_steps * result.demos.dt:g} s")
    split = "leave-one-segment-out" if result.plants else "trials the models were not fitted on"
    return f"{n} test trial{'s' if n != 1 else ''}, {split}; {result.n_steps * result.demos.dt:g} s horizon, {stride}"


def study_notes(result: StudyResult) -> dict[str, str]:
    """:func:`study_note` of the whole study (key ``""``) and of each label: a label's table counts its own trials."""
    return {"": study_note(result), **{str(lb): study_note(result, lb) for lb in result.test}}


def log_scores(logger: Any, scores: Any, note: str | Mapping[str, str],
               units: Mapping[str, str] | None = None) -> None:
    """The held-out scores (:func:`workbench.study.scores.heldout_scores` rows) as a text under ``scores``
    (every label) and ``label_scores/<label>`` (one label, for its prediction tabs); ``note`` says where they come
    from, or why there are none: one sentence, or one per label (:func:`study_notes`, key ``""`` the whole)."""
    import rerun as rr

    from workbench.study.input_prediction import input_lines
    from workbench.study.scores import score_lines

    notes = {"": note} if isinstance(note, str) else dict(note)
    note = notes[""]
    s = logger.session
    s.scores, s.score_note = scores, note
    labels = [] if scores is None else list(dict.fromkeys(scores["label"]))
    lines = ["**held-out prediction error** (mean of trials [95 % interval]; MC band nominal 90 %; the pilot's "
             "input: RMS error one step ahead and over the horizon, against models with no pilot) — " + note]
    for label in labels:
        # the states' scores, then the pilot's own input's (each method's and the no-pilot models')
        part = score_lines(scores, label, dict(units or {}))
        inputs = input_lines(scores, label)
        part = [*part, *([""] + inputs if inputs else [])]
        head = [f"**{label}**"] if len(labels) > 1 or label not in ("", "all") else []
        lines += ["", *head, *part]
        logger._static(label_scores_path(label), rr.TextDocument(
            "\n".join([f"**held-out prediction error, {label}** (mean of trials [95 % interval]; MC band "
                       f"nominal 90 %) — {notes.get(str(label), note)}", "", *part]),
            media_type=rr.MediaType.MARKDOWN))
    logger._static(SCORES, rr.TextDocument("\n".join(lines), media_type=rr.MediaType.MARKDOWN))
