"""A block's optional stopping rule on identification: the block ends once the objective's contrast it asks about
is identified by the subject's trials so far.

``stop = { identified = "Q_phi / R_u1", min_trials = 5 }``: after each landed trial of the block from
``min_trials`` on, :func:`check_identified` runs in a worker (:class:`~workbench.collect.fitting.Jobs`) while the
subject flies on. It estimates the gain from the block's landed, not excluded trials (the IOC-only model: the
ratios need only K̂) and the weight ratios' bootstrap over whole trials (:func:`workbench.study.weights.
ratio_bootstrap`, the machinery ``workbench fit`` prints its ratios and power with); the ratio is identified when
its interval is of the diagonal form and spans at most ×10 (:attr:`~workbench.study.weights.RatioInterval.
identifiable`) and rests on at least :func:`~workbench.study.paired.min_units` trials (6 at 95 %: from fewer, no
bootstrap of them holds the ratio at its level, so the record has no interval and says why). Each check's record
is ``DIR/_collect/stops/<subject>/<block key>-<n>.json`` (n the trials it used); once one says identified, the
block's remaining trials are skipped. Trials flown while a check ran are kept: the record says on how many trials
the decision was made. ``stop.landed`` still caps the block.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from workbench.collect.fitting import Jobs
from workbench.collect.subjects import now, read_json, write_json
from workbench.defaults import OBJECTIVE_RESAMPLES
from workbench.errors import DataError

__all__ = ["StopChecks", "check_identified"]


def _folder(out: Path, subject: str) -> Path:
    return Path(out) / "_collect" / "stops" / subject


def check_identified(task: tuple) -> dict[str, Any]:
    """One check, in a worker: ``(out, subject, group, ids, ratio, seed)`` → its record."""
    from workbench.data.dataset import load_dataset
    from workbench.models.factory import make_model
    from workbench.plant.system import planar_quadrotor
    from workbench.study.paired import min_units, too_few_words
    from workbench.study.weights import ratio_bootstrap

    out, subject, group, ids, ratio, seed = task
    wanted = set(ids)
    ds = load_dataset(out, subjects=[subject]).filter(lambda d: d.id in wanted)
    plant = planar_quadrotor()
    model = make_model("ioc_only", plant, random_state=seed).fit(ds)
    ratios, gain, note = ratio_bootstrap(model, ds, n_boot=OBJECTIVE_RESAMPLES, seed=seed)
    if ratios is None:
        raise DataError(f"subject {subject}: no weight ratios from {len(ds)} trials ({note})")
    match = [iv for iv in ratios.intervals if iv.name == ratio]
    if not match:
        raise DataError(f"stop.identified: {ratio!r} is not a weight ratio of this plant (its ratios: "
                        + ", ".join(iv.name for iv in ratios.intervals) + ")")
    iv = match[0]
    record = {"kind": "stop", "subject": subject, "group": group, "n": len(ds), "ids": ds.ids, "ratio": ratio,
              "identified": iv.identifiable, "interval": iv.describe(), "estimate": iv.estimate, "lo": iv.lo,
              "hi": iv.hi, "gain": gain, "at": now()}
    if len(ds) < min_units(iv.ci):  # too few trials for any interval: none, and not identified, however narrow
        record.update(identified=False, estimate=None, lo=None, hi=None,
                      interval=f"{ratio}: no interval ({too_few_words(len(ds), 'trials', iv.ci)})")
    write_json(_folder(Path(out), subject) / f"{group}-{len(ds)}.json", record)
    return record


class StopChecks:
    """The identification checks of a session's blocks, on :class:`~workbench.collect.fitting.Jobs`."""

    def __init__(self, out: Path, seed: int, jobs: Jobs) -> None:
        self.out, self.seed, self.jobs = Path(out), seed, jobs

    def records(self, subject: str, group: str) -> list[dict[str, Any]]:
        folder = _folder(self.out, subject)
        found = [read_json(p, "stopping check") for p in folder.glob(f"{group}-*.json")
                 if p.stem.rsplit("-", 1)[-1].isdigit()] if folder.is_dir() else []
        return sorted(found, key=lambda r: r.get("n", 0))

    def identified(self, subject: str, group: str) -> dict[str, Any] | None:
        """The first check that identified the block's ratio, or None."""
        return next((r for r in self.records(subject, group) if r.get("identified")), None)

    def poll(self, subject: str, group: str, ids: list[str], ratio: str, min_trials: int) -> None:
        """Start a check on ``ids`` (the block's landed, not excluded trials so far) when there are enough, none
        ran on as many, and none is running for this block."""
        if len(ids) < min_trials or self.identified(subject, group) is not None:
            return
        if (_folder(self.out, subject) / f"{group}-{len(ids)}.json").is_file():
            return
        failed = _folder(self.out, subject) / f"{group}-{len(ids)}.failed.json"
        if failed.is_file():
            return
        self.jobs.start(("stop", subject, group), check_identified,
                        (str(self.out), subject, group, list(ids), ratio, self.seed), failed,
                        {"kind": "stop", "subject": subject, "group": group, "n": len(ids), "ratio": ratio})
