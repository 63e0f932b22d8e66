"""Reading what a command's :class:`~workbench.cli.inputs.Inputs` name: its logs and demonstrations, the trials a
study means among them, its model files, and the plant and the pilot's segments it works on.

Everything here follows the resolved inputs and returns values (and the lines a user should read); it never asks
the options or the run's context again, so a command's walk of its inputs goes down: the command, its inputs,
this module, the data.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from workbench.cli.inputs import Inputs, Source, input_stem, is_demo_file
from workbench.cli.options import DEFAULT_MAPPING
from workbench.cli.stdio import STDIN_NAME
from workbench.defaults import HORIZON_S
from workbench.errors import DataError, ModelError, WorkbenchError

__all__ = ["Read", "read_demos", "read_models", "load_one", "chosen_plant", "study_plant", "pilot_only",
           "require_proposed", "demos_at_model_dt", "input_stem", "is_demo_file", "plant_group_parts",
           "per_group_path"]


@dataclass(frozen=True)
class Read:
    """The demonstrations a command works on, with what choosing them left out.

    ``selected`` is :func:`workbench.data.selection.select_trials`'s record (None where nothing was chosen);
    ``notes`` the lines to print (the trials used, segments without pilot input).
    """

    demos: Any
    selected: Any = None
    notes: tuple[str, ...] = ()


def load_one(source: Source, allow_still: bool = False) -> Any:
    """One source's demonstrations: a demonstrations file or dataset as it is, a log through its mapping."""
    from workbench.data.dataset import load_demonstrations

    if source.demos:
        return load_demonstrations(source.path)
    import adapters

    return adapters.load(source.path, mapping=source.mapping or DEFAULT_MAPPING, format=source.format,
                         allow_still=allow_still)


def _warn_about(source: Source, ds: Any) -> None:
    """What a log's import noticed and kept going with: a still position, flips, damaged or unmapped data."""
    if not len(ds):
        return
    meta = ds[0].meta
    if meta.get("still"):
        print(f"warning: {meta['still']}", file=sys.stderr)
    if meta.get("flipped"):  # the segments cut where the vehicle turned upside down
        print(f"warning: {source.shown}: {meta['flipped']}", file=sys.stderr)
    if meta.get("damaged"):  # the segments a damaged file's lost data cut into pieces
        print(f"warning: {meta['damaged']}", file=sys.stderr)
    if meta.get("unfixed"):  # the segments flown without a GPS fix, on the estimator's dead reckoning
        print(f"warning: {meta['unfixed']}", file=sys.stderr)
    skipped = {k: v for k, v in dict(meta.get("skipped") or {}).items() if v}
    if skipped:  # a damaged or partly unmapped file still gave data: say what was left out
        what = ", ".join(f"{k.replace('_', ' ')}: {v}" for k, v in skipped.items())
        # a demonstrations file carries its import's counts: they are the log's, named as such
        origin = f" (its import from {meta['source']})" if source.demos and meta.get("source") else ""
        print(f"warning: {source.shown}{origin}: skipped {what}", file=sys.stderr)


def read_demos(inputs: Inputs, progress: Any, *, select: bool = True) -> Read:
    """The demonstrations of ``inputs``: every source read (``progress``: a rich ``Progress`` to advance), joined,
    kept to ``inputs.labels``, and (``select``) to the trials ``inputs.selection`` means for ``inputs.purpose``;
    then, for a fit or a study, the segments with pilot input (:func:`pilot_only`)."""
    from workbench.data.dataset import join_sets, refuse_copies

    sets = []
    notes: list[str] = []
    task = progress.add_task("reading logs", total=len(inputs.sources))
    for source in inputs.sources:
        ds = load_one(source, inputs.allow_still)
        if len(ds) and ds[0].meta.get("sticks"):  # the channels the log's RC map gave the sticks, and the check
            notes.append(f"{source.shown}: {ds[0].meta['sticks']}")
        _warn_about(source, ds)
        if source.stdin:  # the spooled file is gone once the command ends: the trials come from <stdin>
            ds = ds.with_demos([d.with_meta(source=STDIN_NAME) for d in ds])
        sets.append(ds)
        progress.advance(task)
    names = [s.shown for s in inputs.sources]
    if len(sets) > 1 or not (inputs.sources[0].demos and inputs.sources[0].path.is_dir()):  # a dataset checks itself
        refuse_copies(sets, names, "")
    ds = join_sets(sets, names)
    if inputs.labels:
        parts = [ds.by_label(label) for label in inputs.labels]
        ds = parts[0]
        for p in parts[1:]:
            ds = ds + p
    if not len(ds):
        raise DataError(f"{inputs.names}: no demonstrations")
    selected = None
    if select:
        from workbench.data.selection import select_trials

        selected = select_trials(ds, inputs.selection, inputs.purpose)
        ds = selected.demos
        if line := selected.describe():
            notes.append(line)
    if inputs.purpose != "look":
        ds, lines = pilot_only(ds, inputs.keep_still)
        notes += lines
    return Read(ds, selected, tuple(notes))


def read_models(inputs: Inputs) -> dict[str, Any]:
    """The models ``inputs`` name, by label (``""`` for one given without ``LABEL=``)."""
    from workbench.models.factory import load_model

    return {m.label: load_model(m.path) for m in inputs.models}


def plant_group_parts(ds: Any, name: str | None) -> tuple[list[tuple[str | None, Any]], str | None]:
    """The demonstrations by plant group (:mod:`workbench.data.plant_groups`), each a plant and a model of its own:
    the group ``name`` alone (``--plant-group``), else every group in the data; and the one line that says so
    (``None`` for data without groups)."""
    from workbench.data.plant_groups import by_plant_group, describe_groups, select_plant_group

    if name:
        part = select_plant_group(ds, name)
        return [(name, part)], f"plant group {describe_groups(part)} (--plant-group)"
    parts = by_plant_group(ds)
    if len(parts) > 1:
        return list(parts.items()), (f"{len(parts)} plant groups, a plant and a model for each (--plant-group NAME "
                                     f"takes one): {describe_groups(ds)}")
    return list(parts.items()), (f"plant group {describe_groups(ds)}" if next(iter(parts)) is not None else None)


def per_group_path(path: Path, group: str | None) -> Path:
    """``m.npz`` → ``m.angle+climb.npz``: where a command writes one plant group's output of several."""
    if group is None:
        return path
    return path.with_name(f"{path.stem}.{group.replace(' ', '-')}{path.suffix}")


def chosen_plant(ds: Any, choice: str = "auto", horizon_s: float = HORIZON_S, where: str = ""):
    """The plant of ``ds`` (:func:`workbench.plant.choice.choose_plant`). A plant refused for its physics has its
    identification report printed to standard error first, the report its one-line refusal refers to, and the
    refusal begins with ``where`` (the file and plant group, for a command whose error line would name neither)."""
    from workbench.errors import PlantRefused
    from workbench.plant.choice import choose_plant

    try:
        return choose_plant(ds, choice, horizon_s)
    except PlantRefused as exc:
        if exc.report is not None:
            print(exc.report.describe(warning=False), file=sys.stderr)
        raise PlantRefused(f"{where}{exc}") from None  # still a refusal: a caller may name the file and group


def study_plant(choice: str, horizon_s: float = HORIZON_S) -> Callable[[Any], Any]:
    from workbench.plant.choice import plant_rule

    return plant_rule(choice, horizon_s)


def pilot_only(ds: Any, keep_still: bool) -> tuple[Any, list[str]]:
    """The segments with pilot input (:mod:`workbench.data.excitation`) and the line saying what was left out;
    the others are left out unless ``keep_still``. An input no segment moves is named on stderr, as a warning."""
    from workbench.data.excitation import pilot_segments

    kept, report = pilot_segments(ds, keep_still=keep_still)
    for line in report.describe():
        print(f"warning: {line}", file=sys.stderr)
    notes = []
    if report.still_segments:
        notes.append(f"{'kept (--keep-still)' if keep_still else 'left out of fitting'}: "
                     f"{len(report.still_segments)} segment(s) without pilot input")
    return kept, notes


def require_proposed(result: Any) -> None:
    """A report and the demo show the proposed model: say why it is missing instead of failing inside them."""
    for label in result.test:
        if label not in result.models:
            reason = result.failures.get(label, {}).get("proposed", "unknown cause")
            raise ModelError(f"the proposed model could not be fitted on {label!r} (so no report): {reason}; "
                             "`workbench evaluate` compares the methods that can be")


def demos_at_model_dt(ds: Any, models: Sequence[Any], resample: bool, source: str) -> tuple[Any, str]:
    """``ds`` on the models' time step, and the line saying it was resampled (empty if it was not): refused when
    sampled at another (a model steps once per its own dt, so its predictions would be drawn against the wrong
    times), resampled with ``--resample``."""
    import math

    dt = float(models[0].plant.dt)
    if any(not math.isclose(float(m.plant.dt), dt, rel_tol=1e-6) for m in models[1:]):
        steps = ", ".join(sorted({f"{float(m.plant.dt):g}" for m in models}))
        raise ModelError(f"the models step at different dt ({steps} s); show them one at a time")
    try:
        at_dt = models[0].demos_at_model_dt(ds, resample=resample)
    except WorkbenchError as exc:
        raise type(exc)(f"{source}: {exc}") from None
    if at_dt is ds:
        return ds, ""
    return at_dt, f"resampled {source} from dt = {ds.dt:g} s to the model's dt = {dt:g} s (states linear, inputs held)"


def default_output(name: str, suffix: str) -> Path:
    """Where a recording goes without ``--save`` and without a display: under ``out/``, never beside the input."""
    return Path("out") / (input_stem(name) + suffix)
