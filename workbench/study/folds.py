"""How a leave-one-out study's folds are made and which were left out.

:func:`split_in_time` cuts a log's one manual segment into contiguous pieces, so that leave-one-segment-out
(:func:`workbench.study.pipeline.run_loso`) has something to train on. A fold whose training part cannot be fitted
(the plant's identification refuses, say, because an input never moves in the other trials) is a
:class:`LeftOutFold`: named with its cause, while the other folds are scored; :func:`too_few_folds` says in words
where too few folds remain for the methods' comparison to have an interval.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError
from workbench.study.method_level import MIN_SPLITS
from workbench.study.paired import ALL_LABELS

__all__ = ["TIME_SPLIT_PIECES", "split_in_time", "LeftOutFold", "too_few_folds"]

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


@dataclass(frozen=True)
class LeftOutFold:
    """A fold of :func:`workbench.study.pipeline.run_loso` that was not scored: its training part could not be fitted.

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
        :class:`~workbench.errors.ModelError`: e.g. an input that never moves in the other trials).
    """

    index: int
    total: int
    trial: str
    label: str
    reason: str

    def sentence(self) -> str:
        """"Fold 2 of 5 (testing seg3) left out: …" — which fold, and why its training trials could not be fitted."""
        return (f"Fold {self.index} of {self.total} (testing {self.trial}) left out: its training trials could not "
                f"be fitted — {self.reason}")


def too_few_folds(left_out: Sequence[LeftOutFold], test: Mapping[str, DemonstrationSet]) -> list[str]:
    """Per strategy that lost folds, where fewer than :data:`~workbench.study.method_level.MIN_SPLITS` remain
    scored: the methods are not compared there (the corrected resampled t has ``J − 1`` degrees of freedom, so one
    fold gives no interval), said in words where a difference would stand."""
    out = []
    for label in dict.fromkeys(f.label for f in left_out):
        scored_folds = len(test.get(label, ()))
        if scored_folds >= MIN_SPLITS:
            continue
        total = scored_folds + sum(f.label == label for f in left_out)
        where = f"On {label}, " if label not in ("", "None", ALL_LABELS) else ""
        if scored_folds:
            what = (f"only {scored_folds} of the {total} folds was scored: the methods are not compared (a "
                    f"difference needs at least {MIN_SPLITS} scored folds for its interval); the errors above are that "
                    "fold's test trial alone, without an interval.")
        else:
            what = f"none of the {total} folds was scored: nothing is compared."
        out.append((where + what)[0].upper() + (where + what)[1:])
    return out
