"""Which trials a fitted model has seen: in-sample and held-out trials, from what the model recorded at fit time.

A model records its training trials' ids and content digests (``train_ids_``, ``train_digests_``, written to its
file). A trial is in-sample when its id *or* its samples' digest is among them: the id catches the same trial
resampled or re-read with other floating-point noise, the digest the same samples under another id. Doubt counts
as in-sample, because an in-sample score shown as held-out is the error this module exists to prevent.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from workbench.data.demonstrations import Demonstration
from workbench.data.digest import trial_digest

__all__ = ["training_known", "in_sample", "held_out", "split_words"]


def training_known(model: Any) -> bool:
    """Whether ``model`` recorded its training trials (files written before they were recorded did not)."""
    return getattr(model, "train_ids_", None) is not None


def in_sample(model: Any, demos: Iterable[Demonstration]) -> list[str]:
    """The ids of ``demos`` that ``model`` was fitted on (empty when the model does not know its training data)."""
    if not training_known(model):
        return []
    ids = set(model.train_ids_)
    digests = set(getattr(model, "train_digests_", None) or ())
    return [d.id for d in demos if d.id in ids or (digests and trial_digest(d) in digests)]


def held_out(model: Any, demos: Iterable[Demonstration]) -> list[str]:
    """The ids of ``demos`` the model was not fitted on (all of them when it does not know its training data)."""
    demos = list(demos)
    seen = set(in_sample(model, demos))
    return [d.id for d in demos if d.id not in seen]


def split_words(model: Any, demos: Iterable[Demonstration]) -> str:
    """One phrase for a title or a line: how many of ``demos`` are in-sample and how many held out."""
    demos = list(demos)
    if not training_known(model):
        return f"{len(demos)} trial(s), training trials unknown (model file predates their record)"
    n_in = len(in_sample(model, demos))
    if n_in == len(demos):
        return f"all {n_in} trial(s) IN-SAMPLE (the model was fitted on them)"
    if n_in == 0:
        return f"{len(demos)} held-out trial(s)"
    return f"{len(demos) - n_in} held-out, {n_in} in-sample trial(s)"
