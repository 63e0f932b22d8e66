"""Reading what a command is given: its logs and demonstrations (standard input included), its model files, and
the plant and the pilot's segments it works on.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from workbench.cli.options import DEFAULT_MAPPING
from workbench.cli.stdio import STDIN_NAME, is_stdio
from workbench.errors import DataError, ModelError, UsageError, WorkbenchError

if TYPE_CHECKING:
    from workbench.cli.context import Context

__all__ = ["input_stem", "existing_path", "is_demo_file", "load_one", "join_sets_named", "load_demos", "system_for",
           "study_plant", "pilot_only", "require_proposed", "load_model_file", "demos_at_model_dt"]


def input_stem(name: str) -> str:
    """A default output name's stem from an input's name (``stdin`` for ``-``)."""
    return "stdin" if is_stdio(name) else Path(name).stem


def existing_path(path: str | os.PathLike, what: str = "file") -> Path:
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such {what}")
    return p


def is_demo_file(path: Path) -> bool:
    if path.suffix.lower() in (".parquet", ".pq"):
        return True
    if not path.is_dir():
        return False  # a log: telling so must not import the dataset module, and pandas behind it (0.25 s)
    from workbench.data.dataset import is_dataset

    return is_dataset(path)


def load_one(path: Path, mapping: str | None, format: str | None = None, allow_still: bool = False) -> Any:
    from workbench.data.dataset import load_demonstrations

    if is_demo_file(path):
        return load_demonstrations(path)
    import adapters

    return adapters.load(path, mapping=mapping or DEFAULT_MAPPING,
                         format=None if format in (None, "parquet") else format, allow_still=allow_still)


def join_sets_named(sets: Sequence[Any], names: Sequence[str]) -> Any:
    """One set from several files; a trial id seen twice is prefixed with its file's name."""
    from workbench.data.dataset import join_sets

    return join_sets(sets, names)


def load_demos(ctx: Context, paths: Sequence[str], mapping: str | None, labels: Sequence[str] | None = None,
               allow_still: bool = False):
    """The demonstrations of ``paths``; ``allow_still`` (a viewer) shows a log whose position never moves, with a
    warning naming it, where the other commands stop with that cause."""
    if sum(is_stdio(p) for p in paths) > 1:
        raise UsageError("- (standard input) given twice: it can be read once")
    files = [ctx.input_path(p, "the demonstrations") for p in paths]
    sets = []
    with ctx.progress() as progress:
        task = progress.add_task("reading logs", total=len(files))
        for f in files:
            stdin = f == ctx.stdio.stdin_path
            chosen = mapping
            if mapping is None and not is_demo_file(f):
                import adapters

                chosen, why = adapters.choose_mapping(f, format=None if ctx.stdio.format == "parquet"
                                                      else ctx.stdio.format)
                # above the bar while it is drawn (printed beside it, the line ran on from the bar's, past 80 columns)
                say = progress.console.print if progress.live.is_started else ctx.say
                say(f"{ctx.shown(f)}: mapping {chosen} ({why}; --mapping chooses another)")
            ds = load_one(f, chosen, ctx.stdio.format, allow_still)
            if len(ds) and ds[0].meta.get("sticks"):  # the channels the log's RC map gave the sticks, and the check
                (progress.console.print if progress.live.is_started else ctx.say)(
                    f"{ctx.shown(f)}: {ds[0].meta['sticks']}")
            if len(ds) and ds[0].meta.get("still"):
                print(f"warning: {ds[0].meta['still']}", file=sys.stderr)
            if len(ds) and ds[0].meta.get("flipped"):  # the segments cut where the vehicle turned upside down
                print(f"warning: {ctx.shown(f)}: {ds[0].meta['flipped']}", file=sys.stderr)
            if stdin:  # the temporary file is gone once the command ends: the trials come from <stdin>
                ds = ds.with_demos([d.with_meta(source=STDIN_NAME) for d in ds])
            skipped = {k: v for k, v in dict(ds[0].meta.get("skipped") or {}).items() if v} if len(ds) else {}
            if skipped:  # a damaged or partly unmapped file still gave data: say what was left out
                what = ", ".join(f"{k.replace('_', ' ')}: {v}" for k, v in skipped.items())
                print(f"warning: {ctx.shown(f)}: skipped {what}", file=sys.stderr)
            sets.append(ds)
            progress.advance(task)
    ds = join_sets_named(sets, [ctx.shown(f) for f in files])
    if labels:
        parts = [ds.by_label(label) for label in labels]
        ds = parts[0]
        for p in parts[1:]:
            ds = ds + p
    if not len(ds):
        raise DataError(f"{', '.join(paths)}: no demonstrations")
    return ds


def plant_group_parts(ctx: Context, ds: Any, name: str | None) -> list[tuple[str | None, Any]]:
    """The demonstrations by plant group (:mod:`workbench.data.plant_groups`), each a plant and a model of its own:
    the group ``name`` alone (``--plant-group``), else every group in the data, said in one line."""
    from workbench.data.plant_groups import by_plant_group, describe_groups, select_plant_group

    if name:
        part = select_plant_group(ds, name)
        ctx.say(f"plant group {describe_groups(part)} (--plant-group)")
        return [(name, part)]
    parts = by_plant_group(ds)
    if len(parts) > 1:
        ctx.say(f"{len(parts)} plant groups, a plant and a model for each (--plant-group NAME takes one): "
                f"{describe_groups(ds)}")
    elif next(iter(parts)) is not None:
        ctx.say(f"plant group {describe_groups(ds)}")
    return list(parts.items())


def per_group_path(path: Path, group: str | None) -> Path:
    """``m.npz`` → ``m.angle+climb.npz``: where a command writes one plant group's output of several."""
    if group is None:
        return path
    return path.with_name(f"{path.stem}.{group.replace(' ', '-')}{path.suffix}")


def system_for(ds: Any, choice: str = "auto", horizon_s: float = 3.0):
    from workbench.plant.choice import choose_plant

    return choose_plant(ds, choice, horizon_s)


def study_plant(choice: str, horizon_s: float = 3.0) -> Callable[[Any], Any]:
    from workbench.plant.choice import plant_rule

    return plant_rule(choice, horizon_s)


def pilot_only(ctx: Context, ds: Any, keep_still: bool) -> Any:
    """The segments with pilot input (:mod:`workbench.data.excitation`); the others are named and left out
    unless ``--keep-still``, and an input no segment moves is named too."""
    from workbench.data.excitation import pilot_segments

    kept, report = pilot_segments(ds, keep_still=keep_still)
    for line in report.describe():
        print(f"warning: {line}", file=sys.stderr)
    if report.still_segments:
        ctx.say(f"{'kept (--keep-still)' if keep_still else 'left out of fitting'}: {len(report.still_segments)} "
                f"segment(s) without pilot input")
    return kept


def require_proposed(result: Any) -> None:
    """A report and the demo show the proposed model: say why it is missing instead of failing inside them."""
    for label in result.test:
        if label not in result.models:
            reason = result.failures.get(label, {}).get("proposed", "unknown cause")
            raise ModelError(f"the proposed model could not be fitted on {label!r} (so no report): {reason}; "
                             "`workbench evaluate` compares the methods that can be")


def load_model_file(path: str, ctx: Context | None = None):
    from workbench.models.factory import load_model

    return load_model(ctx.input_path(path, "the model", ".npz") if ctx is not None else existing_path(path))


def demos_at_model_dt(ctx: Context, ds: Any, models: Sequence[Any], resample: bool, source: str) -> Any:
    """``ds`` on the models' time step: refused when sampled at another (a model steps once per its own dt, so
    its predictions would be drawn against the wrong times), resampled with ``--resample``."""
    import math

    dt = float(models[0].system.dt)
    if any(not math.isclose(float(m.system.dt), dt, rel_tol=1e-6) for m in models[1:]):
        steps = ", ".join(sorted({f"{float(m.system.dt):g}" for m in models}))
        raise ModelError(f"the models step at different dt ({steps} s); show them one at a time")
    try:
        at_dt = models[0].demos_at_model_dt(ds, resample=resample)
    except WorkbenchError as exc:
        raise type(exc)(f"{source}: {exc}") from None
    if at_dt is not ds:
        ctx.say(f"resampled {source} from dt = {ds.dt:g} s to the model's dt = {dt:g} s (states linear, inputs held)")
    return at_dt
