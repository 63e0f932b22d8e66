"""How a leave-one-out study's folds are made and which were left out.

:func:`split_in_time` cuts a log's one manual segment into contiguous pieces, so that leave-one-segment-out
(:func:`workbench.study.pipeline.run_loso`) has something to train on. A fold whose training part cannot be fitted
(the plant's identification refuses, say, because an input never moves in the other trials) is a
:class:`LeftOutFold`: named with its cause, while the other folds are scored; so is a fold whose test trial never
moves (:func:`still_test_trial`), whose scores would compare nothing. :func:`too_few_folds` says in words where too
few folds remain for the methods' comparison to have an interval.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError
from workbench.study.method_level import MIN_SPLITS
from workbench.study.paired import ALL_LABELS, min_units

__all__ = ["TIME_SPLIT_PIECES", "split_in_time", "LeftOutFold", "still_test_trial", "too_few_folds"]

#: Contiguous pieces one long segment is cut into when it is all a log gives (:func:`split_in_time`).
TIME_SPLIT_PIECES = 3


def split_in_time(demos: DemonstrationSet, n_steps: int, pieces: int = TIME_SPLIT_PIECES) -> DemonstrationSet:
    """One segment cut into up to ``pieces`` contiguous pieces, each longer than the ``n_steps`` horizon, so that
    leave-one-segment-out has something to train on when a log holds a single manual segment. The pieces are
    parts of one flight, not independent trials: a score over them says how the models do later in the same
    flight.

    Raises
    ------
    DataError
        More than one segment, or one too short for two pieces longer than the horizon.
    """
    if len(demos) != 1:
        raise DataError(f"a time split is for a single segment; these demonstrations have {len(demos)}")
    d = demos[0]
    n = len(d.t)
    k = min(int(pieces), n // (n_steps + 2))
    if k < 2:
        raise DataError(
            f"one manual segment of {d.t[-1] - d.t[0]:.1f} s ({n} samples): too short to split into two pieces "
            f"longer than the {n_steps * demos.dt:g} s horizon, so no held-out evaluation is possible; fly longer or "
            "shorten --horizon"
        )
    bounds = np.linspace(0, n, k + 1).round().astype(int)
    t0 = float(d.meta.get("t0", 0.0))
    parts = [
        type(d)(d.t[a:b] - d.t[a], d.x[a:b], d.u[a:b],
                {**d.meta, "id": f"{d.id}.t{i + 1}", "t0": t0 + float(d.t[a] - d.t[0]), "time_split": f"{i + 1}/{k}"})
        for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True))
    ]
    return demos.with_demos(parts)


def still_test_trial(demos: DemonstrationSet, index: int) -> str:
    """Why trial ``index`` says nothing as a fold's test trial, in words; ``""`` where it can be scored.

    A trial whose position and velocity states (the set's roles) each hold one value throughout did not move as
    far as the log tells (an estimator without a position yet reports 0): persistence predicts it exactly (a
    position RMSE of 0) and any model is scored against a flight that did not happen. A trial none of whose sticks
    moves shows no pilot acting. Exact constancy is the rule, so no threshold decides which flights count.
    """
    d = demos[index]
    moving = [*demos.roles.position, *demos.roles.velocity]
    idx = [demos.state_names.index(n) for n in moving if n in demos.state_names]
    if idx and not np.ptp(d.x[:, idx], axis=0).any():
        values = sorted({float(v) for v in d.x[0, idx]})
        held = f"at {values[0]:g}" if len(values) == 1 else "each at one value"
        return (f"its {', '.join(demos.state_names[i] for i in idx)} stay {held} in all {len(d.t)} samples: the log "
                "shows no motion there (an estimator without a position reports 0), so persistence scores 0 and no "
                "comparison of models is made on it")
    if d.u.size and not np.ptp(d.u, axis=0).any():
        return (f"none of its inputs {', '.join(demos.input_names)} moves in its {len(d.t)} samples: no pilot acts "
                "there to be predicted")
    return ""


@dataclass(frozen=True)
class LeftOutFold:
    """A fold of :func:`workbench.study.pipeline.run_loso` that was not scored: its training part could not be fitted
    (``part`` ``"training"``), or its test trial never moves (``"test"``, :func:`still_test_trial`).

    Attributes
    ----------
    index, total : int
        The fold's place among all folds (1-based) and how many there were.
    trial : str
        The trial the fold would have tested.
    label : str
        That trial's strategy (``"all"``, :data:`~workbench.study.paired.ALL_LABELS`, where the trials carry
        none).
    reason : str
        The refusal of its training part, one line (a :class:`~workbench.errors.DataError` or
        :class:`~workbench.errors.ModelError`: e.g. an input that never moves in the other trials), or what its test
        trial does not do.
    part : str
        ``"training"`` or ``"test"``: the part of the fold that left it out.
    """

    index: int
    total: int
    trial: str
    label: str
    reason: str
    part: str = "training"

    def sentence(self) -> str:
        """"Fold 2 of 5 (testing seg3) left out: …" — which fold, and why: its training trials could not be fitted,
        or its test trial says nothing."""
        why = ("its test trial says nothing about the pilot" if self.part == "test"
               else "its training trials could not be fitted")
        return f"Fold {self.index} of {self.total} (testing {self.trial}) left out: {why} — {self.reason}"

    @classmethod
    def still(cls, demos: DemonstrationSet, index: int, unlabeled: str) -> LeftOutFold | None:
        """Trial ``index``'s fold left out before any fit where its test trial never moves
        (:func:`still_test_trial`), with ``unlabeled`` as the label of a trial that has none; else ``None``."""
        reason = still_test_trial(demos, index)
        d = demos[index]
        label = unlabeled if d.label is None else str(d.label)
        return cls(index + 1, len(demos), d.id, label, reason, part="test") if reason else None

    @staticmethod
    def none_scored(left_out: Sequence[LeftOutFold]) -> str:
        """Why a leave-one-out study has no fold to score, each fold named with its cause, in one line: "could be
        fitted" where every training part was refused, "could be scored" where a still test trial was left out."""
        what = "fitted" if all(f.part == "training" for f in left_out) else "scored"  # a still test is never fitted
        return (f"no fold of the {len(left_out)} could be {what}: "
                + "; ".join(f"fold {f.index} (testing {f.trial}): {f.reason}" for f in left_out))


def too_few_folds(left_out: Sequence[LeftOutFold], test: Mapping[str, DemonstrationSet],
                  ci: float = 95.0) -> list[str]:
    """Per strategy that lost folds, where fewer remain scored than the methods' difference needs for its interval
    (:func:`~workbench.study.method_level.corrected_t`'s floor: :data:`~workbench.study.method_level.MIN_SPLITS`
    and :func:`~workbench.study.paired.min_units` of ``ci``, 6 at 95 %), said in words where a difference would
    stand: from fewer than ``MIN_SPLITS`` the methods are not compared, from fewer than ``min_units`` the difference
    has its mean but no interval."""
    need = max(MIN_SPLITS, min_units(ci))
    out = []
    for label in dict.fromkeys(f.label for f in left_out):
        scored_folds = len(test.get(label, ()))
        if scored_folds >= need:
            continue
        total = scored_folds + sum(f.label == label for f in left_out)
        where = f"On {label}, " if label not in ("", "None", ALL_LABELS) else ""
        if scored_folds >= MIN_SPLITS:
            what = (f"only {scored_folds} of the {total} folds were scored: the methods' difference has its mean but "
                    f"no interval (an interval at {ci:g} % needs at least {need} scored folds).")
        elif scored_folds:
            what = (f"only {scored_folds} of the {total} folds was scored: the methods are not compared (a "
                    f"difference needs at least {need} scored folds for its interval); the errors above are that "
                    "fold's test trial alone, without an interval.")
        else:
            what = f"none of the {total} folds was scored: nothing is compared."
        out.append((where + what)[0].upper() + (where + what)[1:])
    return out
