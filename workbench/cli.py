"""The ``workbench`` command: from flight logs to a model of how a human flies, its report and a rerun view.

Run ``workbench demo`` first: it imports the sample logs, fits one model per control strategy, compares it with
its two baselines, and writes a report and a rerun recording. Every command has ``--help`` with an example.

Bad input (a missing file, a corrupt log, a wrong mapping, a model file from a newer version) prints one line,
``error: <what>: <cause>``, and exits with status 1; ``--debug`` shows the traceback instead. Every output file
is written atomically (a temp file renamed into place), so a failed run never leaves half a file behind.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import traceback
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from workbench.atomic import atomic_write_table
from workbench.errors import DataError, ModelError, WorkbenchError
from workbench.threads import limit_threads

__all__ = ["main", "build_parser", "SAMPLE_LOGS"]

SAMPLE_LOGS = Path(__file__).resolve().parents[1] / "sample_logs"
DEFAULT_MAPPING = "planar_quadrotor"
EXIT_ERROR = 1
EXIT_INTERNAL = 3


class _Context:
    """What every command gets: parsed options, consoles and a progress factory."""

    def __init__(self, args: argparse.Namespace) -> None:
        from rich.console import Console

        self.args = args
        self.quiet = bool(getattr(args, "quiet", False))
        self.out = Console(highlight=False, quiet=self.quiet)
        if not self.out.is_terminal:  # piped or captured: wide tables instead of 80 columns
            self.out = Console(highlight=False, quiet=self.quiet, width=140)
        self.err = Console(stderr=True, highlight=False)

    def say(self, *parts: Any, markup: bool = False) -> None:
        self.out.print(*parts, soft_wrap=True, markup=markup)

    def progress(self):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        return Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=self.err,
            transient=True,
            disable=self.quiet or not self.err.is_terminal,  # no bars (or blank lines) in logs and pipes
        )

    def executor(self):
        """Serial by default; a Dask ``LocalCluster`` with ``--workers N``; the cluster at ``--scheduler``."""
        from workbench.executor import make_executor

        a = self.args
        ex = make_executor(getattr(a, "workers", None), getattr(a, "scheduler", None),
                           staging=getattr(a, "staging", None))
        if ex.parallel and not self.quiet:
            print(f"running tasks on {ex}", file=sys.stderr)
        return ex


# -- input helpers -----------------------------------------------------------------------------------------
def _existing(path: str | os.PathLike, what: str = "file") -> Path:
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such {what}")
    return p


def _is_demo_file(path: Path) -> bool:
    from workbench.dataset import is_dataset

    return path.suffix.lower() in (".parquet", ".pq") or is_dataset(path)


def _load_one(path: Path, mapping: str | None) -> Any:
    from workbench.demos import DemonstrationSet

    if _is_demo_file(path):
        return DemonstrationSet.load(path)
    import adapters

    return adapters.load(path, mapping=mapping or DEFAULT_MAPPING)


def _join(sets: Sequence[Any], names: Sequence[str]) -> Any:
    """One set from several files; a trial id seen twice is prefixed with its file's name."""
    from workbench.dataset import join_sets

    return join_sets(sets, names)


def _load_demos(ctx: _Context, paths: Sequence[str], mapping: str | None, labels: Sequence[str] | None = None):
    files = [_existing(p) for p in paths]
    sets = []
    with ctx.progress() as progress:
        task = progress.add_task("reading logs", total=len(files))
        for f in files:
            ds = _load_one(f, mapping)
            skipped = {k: v for k, v in dict(ds[0].meta.get("skipped") or {}).items() if v} if len(ds) else {}
            if skipped:  # a damaged or partly unmapped file still gave data: say what was left out
                what = ", ".join(f"{k.replace('_', ' ')}: {v}" for k, v in skipped.items())
                print(f"warning: {f}: skipped {what}", file=sys.stderr)
            sets.append(ds)
            progress.advance(task)
    ds = _join(sets, [str(f) for f in files])
    if labels:
        parts = [ds.by_label(label) for label in labels]
        ds = parts[0]
        for p in parts[1:]:
            ds = ds + p
    if not len(ds):
        raise DataError(f"{', '.join(paths)}: no demonstrations")
    return ds


def _system_for(ds: Any, choice: str = "auto", horizon: float = 3.0):
    """The plant (A, B): the paper's planar quadrotor, or identified from the data by least squares.

    ``auto`` takes the paper's model for data in its layout and at its step (the sample logs), and identifies
    (A, B) otherwise — a real vehicle is not the paper's linearized 0.25 kg quadrotor. Identification is
    kinematic (position rows fixed, :mod:`workbench.identification`) whenever the data's roles pair positions
    with velocities, and its report checks ``horizon`` seconds ahead.
    """
    from workbench.system import LinearSystem, planar_quadrotor

    paper = planar_quadrotor()
    layout = tuple(ds.state_names) == paper.state_names and len(ds.input_names) == paper.m
    if choice == "paper" or (choice == "auto" and layout and abs(ds.dt - paper.dt) < 1e-9):
        if not layout:
            raise DataError(
                f"--system paper needs states {list(paper.state_names)} and {paper.m} inputs; "
                f"the data have {list(ds.state_names)} and {list(ds.input_names)}"
            )
        return planar_quadrotor(dt=ds.dt)
    return LinearSystem.identify(ds, u_min=paper.u_min if layout else None, u_max=paper.u_max if layout else None,
                                 structure="auto", horizon=horizon)


def _plant(choice: str, horizon: float = 3.0) -> Callable[[Any], Any]:
    """The plant of a study as a function of its training trials (``_system_for`` on them), so that (A, B) is
    never identified from a trial the study then scores."""
    return lambda train: _system_for(train, choice, horizon)


def _require_proposed(result: Any) -> None:
    """A report and the demo show the proposed model: say why it is missing instead of failing inside them."""
    for label in result.test:
        if label not in result.models:
            reason = result.failures.get(label, {}).get("proposed", "unknown cause")
            raise ModelError(f"the proposed model could not be fitted on {label!r} (so no report): {reason}; "
                             "`workbench evaluate` compares the methods that can be")


def _print_plant(ctx: _Context, system: Any, note: str = "") -> None:
    """An identified plant's report (held-out errors vs persistence, ρ, conditioning, checks); its warning on
    stderr too, where a user looks for problems."""
    report = getattr(system, "identification", None)
    if report is None:
        return
    ctx.say(str(report) + (f"\n  {note}" if note else ""))
    if report.warning:
        print(f"warning: {report.warning}", file=sys.stderr)


def _load_model(path: str):
    from workbench.model import load_model

    return load_model(_existing(path))


def _demos_at_model_dt(ctx: _Context, ds: Any, models: Sequence[Any], resample: bool, source: str) -> Any:
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


def _components(value: str) -> int | str:
    if value == "auto":
        return "auto"
    try:
        g = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--components must be a positive integer or 'auto', got {value!r}") from None
    if g < 1:
        raise argparse.ArgumentTypeError(f"--components must be at least 1, got {g}")
    return g


def _fit_components(value: str) -> int | str:
    return "cv" if value == "cv" else _components(value)


def _positive_float(value: str) -> float:
    try:
        v = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {value!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {value!r}")
    return v


def _int_list(value: str) -> list[int]:
    try:
        out = [int(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {value!r}") from None
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"expected positive integers, got {value!r}")
    return out


def _steps(seconds: float, dt: float) -> int:
    return max(1, int(round(seconds / dt)))


# -- commands ----------------------------------------------------------------------------------------------
def cmd_simulate(ctx: _Context) -> int:
    a = ctx.args
    if a.sample_logs:
        from workbench.sample_logs import write_sample_logs

        written = write_sample_logs(a.sample_logs, seed=a.seed)
        files = list(written) if written is not None else sorted(Path(a.sample_logs).iterdir())
        ctx.say(f"wrote {len(files)} sample logs to {a.sample_logs}")
        return 0
    if not a.output:
        raise WorkbenchError("simulate needs -o FILE (.parquet, .csv, .tlog or .mcap) or --sample-logs DIR")
    from workbench.simulate import simulate_landings

    subjects = [None] if a.subjects == 0 else [f"s{i + 1:02d}" for i in range(a.subjects)]
    sets = []
    with ctx.progress() as progress:
        task = progress.add_task("simulating", total=len(a.strategy) * len(subjects))
        for strategy in a.strategy:
            for subject in subjects:
                sets.append(simulate_landings(strategy, a.trials, seed=a.seed, subject=subject))
                progress.advance(task)
    ds = sets[0]
    for s in sets[1:]:
        ds = ds + s
    out = Path(a.output)
    _write_demos(ds, out)
    ctx.say(f"wrote {len(ds)} demonstrations ({ds.n_samples} samples) to {out}")
    return 0


def _write_demos(ds: Any, out: Path, mapping: str | None = None) -> None:
    if out.suffix.lower() in (".parquet", ".pq"):
        ds.save(out)
        return
    import adapters

    adapters.write(ds, out, mapping or DEFAULT_MAPPING)


def cmd_inspect(ctx: _Context) -> int:
    from rich.markup import escape
    from rich.table import Table

    path = _existing(ctx.args.log)
    if _is_demo_file(path):
        from workbench.demos import DemonstrationSet

        ds = DemonstrationSet.load(path)
        ctx.say(f"[bold]{escape(str(path))}[/bold]: workbench demonstrations, {len(ds)} trials, "
                f"{ds.n_samples} samples, dt {ds.dt} s", markup=True)
        ctx.say(f"states {list(ds.state_names)}, inputs {list(ds.input_names)}")
        table = Table("id", "label", "subject", "samples", "duration [s]", "success", "source")
        for d in ds:
            table.add_row(d.id, str(d.label), str(d.meta.get("subject")), str(len(d)), f"{d.duration:.2f}",
                          str(d.meta.get("success")), Path(str(d.meta.get("source", ""))).name)
        ctx.say(table)
        return 0
    import adapters

    summary = adapters.inspect(path)
    t0 = summary.t_start
    ctx.say(
        f"[bold]{escape(str(summary.path))}[/bold]: {summary.format}, {summary.size_bytes} bytes, "
        f"{len(summary.streams)} streams, {summary.duration:.1f} s",
        markup=True,
    )
    table = Table("stream", "messages", "mean rate [Hz]", "from [s]", "to [s]", "fields")
    for st in summary.streams:
        fields = ", ".join(st.fields[:8]) + (f", … (+{len(st.fields) - 8})" if len(st.fields) > 8 else "")
        table.add_row(st.name, str(st.count), f"{st.rate_hz:.3g}", f"{st.t_start - t0:.2f}", f"{st.t_end - t0:.2f}",
                      fields)
    ctx.say(table)
    if summary.modes:
        ctx.say(f"flight modes{f' ({summary.vehicle})' if summary.vehicle else ''}: " + "; ".join(
            f"{m.mode} {m.start - t0:.1f}–{min(m.end, summary.t_end) - t0:.1f} s "
            f"({min(m.end, summary.t_end) - m.start:.1f} s)" for m in summary.modes))
    if summary.armed:
        ctx.say("armed: " + "; ".join(f"{a - t0:.1f}–{min(b, summary.t_end) - t0:.1f} s" for a, b in summary.armed))
    if summary.skipped:
        ctx.say("skipped: " + ", ".join(f"{k} {v}" for k, v in summary.skipped))
    return 0


def _is_dataset_output(output: str) -> bool:
    """``-o DIR/`` (or an existing directory, or a name without a suffix) asks for a partitioned dataset."""
    return output.endswith(("/", os.sep)) or Path(output).is_dir() or not Path(output).suffix


def _import_dataset(ctx: _Context) -> int:
    from adapters.batch import expand_logs, import_logs

    a = ctx.args
    files = expand_logs(a.logs)
    with ctx.executor() as ex, ctx.progress() as progress:
        task = progress.add_task(f"importing {len(files)} logs", total=len(files))
        report = import_logs(files, a.output, a.mapping, label=a.label, executor=ex,
                             progress=lambda done, total: progress.update(task, completed=done))
    for log in report.imported:
        if log.skipped:  # a damaged or partly unmapped file still gave data: say what was left out
            what = ", ".join(f"{k.replace('_', ' ')}: {v}" for k, v in log.skipped)
            print(f"warning: {log.source}: skipped {what}", file=sys.stderr)
    for source, cause in report.failures:
        print(f"error: {source}: not imported: {cause}", file=sys.stderr)
    subjects = {p.subject for log in report.imported for p in log.partitions if p.subject is not None}
    ctx.say(f"wrote {report.n_demos} demonstrations ({report.n_samples} samples, {len(subjects)} subjects) from "
            f"{len(report.imported)} of {len(files)} logs to the dataset {report.path}/")
    return EXIT_ERROR if report.failures else 0


def cmd_import(ctx: _Context) -> int:
    a = ctx.args
    if _is_dataset_output(a.output):
        return _import_dataset(ctx)
    if a.workers or a.scheduler:
        print(f"warning: --workers and --scheduler import in parallel into a dataset (-o DIR/); {a.output} is one "
              "file, so the logs are read here, one after another", file=sys.stderr)
    from adapters.batch import expand_logs

    ds = _load_demos(ctx, [str(f) for f in expand_logs(a.logs)], a.mapping)
    if a.label:
        ds = type(ds)([d.with_meta(label=a.label) for d in ds], ds.state_names, ds.input_names, ds.dt)
    out = Path(a.output)
    _write_demos(ds, out, a.mapping)
    ctx.say(f"wrote {len(ds)} demonstrations ({ds.n_samples} samples, labels {ds.labels}) to {out}")
    return 0


def _make_model(kind: str, system: Any, components: int | str, seed: int, gain: str = "direct"):
    from workbench import model as wm

    if kind == "ioc-only":
        return wm.IOCOnlyModel(system, gain_method=gain)
    if kind == "proposed":
        reg: float | str = "auto" if components == "cv" else 0.5
        return wm.HumanBehaviorModel(system, n_components="auto" if components == "cv" else components,
                                     reg_covar=reg, random_state=seed, gain_method=gain)
    return wm.GMROnlyModel(system, n_components=components, random_state=seed)


def cmd_fit(ctx: _Context) -> int:
    a = ctx.args
    ds = _load_demos(ctx, [a.demos], a.mapping, [a.label] if a.label else None)
    system = _system_for(ds, a.system)
    _print_plant(ctx, system)
    t0 = time.perf_counter()
    with ctx.progress() as progress:
        components = a.components
        if components == "cv" and a.method != "proposed":
            raise DataError("--components cv chooses the proposed model's settings; use a number or 'auto' with "
                            f"--method {a.method}")
        if components == "auto" and a.method != "ioc-only":
            from workbench.study import select_components

            progress.add_task("choosing the number of components by BIC", total=None)
            components = select_components(ds, system, seed=a.seed)
            ctx.say(f"chose {components} components by BIC")
        progress.add_task(f"fitting {a.method} model on {len(ds)} demonstrations", total=None)
        model = _make_model(a.method, system, components, a.seed, a.gain).fit(ds)
    model.save(a.output)
    ctx.say(f"fitted {type(model).__name__} on {len(ds)} demonstrations in {time.perf_counter() - t0:.1f} s")
    _print_model(ctx, model, ds)
    if a.bootstrap > 0 and getattr(model, "K_", None) is not None:
        _print_bootstrap(ctx, _as_fitted(ds, model), system, a.bootstrap, a.seed, a.gain)
        _print_ratios(ctx, model, ds, a.bootstrap, a.seed)
    elif getattr(model, "objective_", None) is not None:
        ctx.say("(no intervals: --bootstrap 0; the objective above is a point estimate)")
    ctx.say(f"wrote {a.output}")
    return 0


def _print_bootstrap(ctx: _Context, ds: Any, system: Any, n_boot: int, seed: int, gain: str = "direct") -> None:
    from workbench.ioc import bootstrap

    with ctx.executor() as ex, ctx.progress() as progress:
        task = progress.add_task(f"bootstrap: {n_boot} resamples of {len(ds)} trials", total=n_boot)
        result = bootstrap(ds, system, n_boot=n_boot, seed=seed, method=gain,
                           progress=lambda done, total: progress.update(task, completed=done), executor=ex)
    ctx.say(f"bootstrap ({result.n_boot - result.n_failed} of {result.n_boot} resamples fitted, "
            f"{result.ci:g} % percentile intervals):")
    for names, lo, hi, what in ((ds.state_names, result.Q_diag_lo, result.Q_diag_hi, "Q/λmax"),
                                (ds.input_names, result.R_diag_lo, result.R_diag_hi, "R/λmax")):
        ctx.say(f"  diag {what}: " + ", ".join(
            f"{s} [{a:.3g}, {b:.3g}]" for s, a, b in zip(names, lo, hi, strict=True)))
    for i, u in enumerate(ds.input_names):
        ctx.say(f"  K̂ row {u}: " + ", ".join(
            f"{s} [{a:.3g}, {b:.3g}]" for s, a, b in zip(ds.state_names, result.K_lo[i], result.K_hi[i], strict=True)))


def _as_fitted(ds: Any, model: Any) -> Any:
    """The trials as a goal-relative model fitted them (states minus their targets), so the bootstrap's point
    estimate is the model's own gain and objective; unchanged for a model of ``u = K̂x``."""
    from workbench.demos import Demonstration

    if not getattr(model, "goal_relative_", False):
        return ds
    return ds._like([Demonstration(d.t, d.x - d.target, d.u, d.meta) for d in ds])


def _print_ratios(ctx: _Context, model: Any, ds: Any, n_boot: int, seed: int) -> None:
    """Weight ratios inside each coupled part of the plant (minimum-distance diagonal cost), with intervals."""
    from workbench.weights import ratio_bootstrap

    with ctx.progress() as progress:
        task = progress.add_task(f"weight ratios: {n_boot} resampled gains", total=n_boot)
        ratios, gain, note = ratio_bootstrap(model, ds, n_boot=n_boot, seed=seed,
                                             progress=lambda done, total: progress.update(task, completed=done))
    if ratios is None:
        ctx.say(f"weight ratios: none ({note})")
        return
    g = ratios.gains
    ctx.say(f"weight ratios inside coupled parts (S = 0, diagonal cost closest to the {gain} gain in the metric of "
            f"its covariance over {g.n_ok} of {g.n_boot} resamples; {ratios.ci:g} % profile intervals; "
            f"forward-gain error {ratios.forward_gain_error:.2g}):")
    for r in ratios.intervals:
        ctx.say(f"  {r.describe()}")
    for f in ratios.fits:
        if not f.explained:
            ctx.say(f"  {f.describe()}: its ratios describe no objective the operator could have had")


def _print_model(ctx: _Context, model: Any, ds: Any) -> None:
    import numpy as np

    K = getattr(model, "K_", None)
    if K is not None:
        ctx.say("K̂ (u = K̂ x): " + np.array2string(np.asarray(K), precision=3, suppress_small=True))
    o = getattr(model, "objective_", None)
    if o is not None:
        n = ds.n_states
        q = np.diag(np.asarray(o.M_normalized)[:n, :n])
        r = np.diag(np.asarray(o.M_normalized)[n:, n:])
        ctx.say(f"α* = {o.alpha:.4g}, forward-gain error {o.forward_gain_error:.1e}")
        ctx.say("diag Q/λmax: " + ", ".join(f"{s} {v:.3g}" for s, v in zip(ds.state_names, q, strict=True)))
        ctx.say("diag R/λmax: " + ", ".join(f"{s} {v:.3g}" for s, v in zip(ds.input_names, r, strict=True)))
    g = getattr(model, "n_components_", None) or getattr(model, "n_components", None)
    if g is not None:
        ctx.say(f"GMM components: {g}")
    auto = getattr(model, "auto_", None)
    if auto is not None:
        ctx.say(f"chose G = {auto.n_components}, reg_covar = {auto.reg_covar:g} by {auto.folds}-fold cross-validation "
                f"over the trials ({auto.criterion}); held-out 3 s RMSE per candidate: " + ", ".join(
                    f"G{r['n_components']}/{r['reg_covar']:g} {r['heldout_rmse']:.3g}" for r in auto.scores))


def cmd_predict(ctx: _Context) -> int:
    import numpy as np
    import pandas as pd

    a = ctx.args
    model = _load_model(a.model)
    if a.x0 is not None:
        try:
            x0 = np.array([float(v) for v in a.x0.split(",")])
        except ValueError:
            raise DataError(f"--x0 must be comma-separated numbers, got {a.x0!r}") from None
        target, t0, demo_id, task_x0, start = None, 0.0, "x0", None, 0
        names, in_names = model.system.state_names, model.system.input_names
    else:
        if not a.demos:
            raise WorkbenchError("predict needs DEMOS (with --demo ID and --start K) or --x0 x,y,…")
        ds = _load_demos(ctx, [a.demos], a.mapping)
        ids = ds.ids
        if a.demo and a.demo not in ids:
            raise DataError(f"{a.demos}: no demonstration {a.demo!r}; ids present: {ids[:10]}")
        demo = ds[ids.index(a.demo)] if a.demo else ds[0]
        if not 0 <= a.start < len(demo):
            raise DataError(f"{a.demos}: --start {a.start} outside trial {demo.id!r} (0…{len(demo) - 1})")
        t0 = float(demo.t[a.start])
        at_dt = _demos_at_model_dt(ctx, ds, [model], a.resample, a.demos)
        if at_dt is not ds:
            # --start counts samples of the file; on the model's grid the start is the sample nearest its time
            demo = at_dt[ids.index(demo.id)]
            start = int(np.argmin(np.abs(demo.t - t0)))
            ctx.say(f"step {a.start} (t = {t0:.3f} s) of {demo.id} is step {start} on the model's grid")
            t0 = float(demo.t[start])
        else:
            start = a.start
        x0, target, demo_id, task_x0 = demo.x[start], demo.target, demo.id, demo.x[0]
        names, in_names = ds.state_names, ds.input_names
    dt = model.system.dt  # the model steps at its own dt, whatever the demonstrations' sampling
    horizon = _steps(a.horizon, dt)
    # from inside a trial, the task's start frame stays at the trial's first state
    kwargs: dict[str, Any] = {"target": target, "task_x0": task_x0}
    if a.samples:
        kwargs.update(samples=a.samples, seed=a.seed)
    pred = model.predict(x0, horizon, **kwargs)
    x, u = np.asarray(pred.x), np.asarray(pred.u)
    names = list(names or [f"x{i}" for i in range(x.shape[1])])
    in_names = list(in_names or [f"u{i}" for i in range(u.shape[1])])
    cols: dict[str, Any] = {"demo": demo_id, "step": np.arange(len(x)), "t": t0 + dt * np.arange(len(x))}
    cols.update({s: x[:, j] for j, s in enumerate(names)})
    u_full = np.vstack([u, np.full((1, u.shape[1]), np.nan)])  # the last state has no input yet
    cols.update({s: u_full[:, j] for j, s in enumerate(in_names)})
    if pred.x_lower is not None:
        cols.update({f"{s}_lower": pred.x_lower[:, j] for j, s in enumerate(names)})
        cols.update({f"{s}_upper": pred.x_upper[:, j] for j, s in enumerate(names)})
    out = atomic_write_table(pd.DataFrame(cols), a.output)
    # the end position where the plant declares positions, else the whole end state
    shown = model.system.r.position or range(len(names))
    ctx.say(
        f"predicted {horizon} steps ({horizon * dt:.2f} s) from {demo_id} step {start}: "
        "end " + ", ".join(f"{names[j]} = {x[-1, j]:.3f}" for j in shown)
    )
    ctx.say(f"wrote {out}")
    return 0


def cmd_evaluate(ctx: _Context) -> int:
    from workbench import study

    a = ctx.args
    ds = _load_demos(ctx, a.demos, a.mapping, a.label)
    if a.per_subject:
        return _evaluate_per_subject(ctx, ds)
    smallest = min(len(ds.by_label(lbl)) for lbl in ds.labels) if ds.labels else len(ds)
    loso = a.holdout == "loso" or (a.holdout == "auto" and smallest < study.LOSO_BELOW)
    with ctx.executor() as ex:
        if loso:
            ctx.say(f"leave-one-segment-out over {len(ds)} segments (each scored by models and a plant fitted on "
                    "the others)")
            result = study.run_loso(
                ds, _plant(a.system, a.horizon), horizon=_steps(a.horizon, ds.dt), components=a.components,
                samples=a.samples, seed=a.seed, progress=ctx.progress, executor=ex,
            )
        else:
            result = study.run_study(
                ds,
                _plant(a.system, a.horizon),
                test_size=a.test_size,
                horizon=_steps(a.horizon, ds.dt),
                components=a.components,
                samples=a.samples,
                efficiency=a.efficiency,
                repeats=a.repeats,
                seed=a.seed,
                progress=ctx.progress,
                executor=ex,
            )
    if loso and getattr(result.system, "identification", None) is not None:
        # the plant a user would fit on all segments (its report is itself leave-one-segment-out) and the
        # spread of the folds' plants, which the scores below used
        checks = [c for p in result.plants.values() for c in p.identification.checks]
        spread = (f"each fold's plant from its training segments: {checks[0].name} "
                  f"{min(c.value for c in checks):.4g}–{max(c.value for c in checks):.4g} over {len(checks)} folds"
                  if checks else "each fold's plant is identified from its training segments only")
        _print_plant(ctx, _system_for(ds, a.system, a.horizon), f"(plant from all {len(ds)} segments; {spread})")
    else:
        _print_plant(ctx, result.system, "(plant from the training trials)")
    _print_study(ctx, result)
    if a.output:
        result.save_tables(a.output)
        ctx.say(f"wrote {a.output}")
    return 0


def _evaluate_per_subject(ctx: _Context, ds: Any) -> int:
    from rich.markup import escape
    from rich.table import Table

    from workbench import evaluate
    from workbench.study import METHOD_TITLES, verdicts

    a = ctx.args
    components = 5 if a.components == "auto" else a.components
    plant = _plant(a.system)
    subjects = sorted({str(d.meta.get("subject")) for d in ds if d.meta.get("subject") is not None})
    seed = a.seed
    # a dataset is read where it lies, each subject's partition by its own task: nothing to stage for workers
    source = a.demos[0] if len(a.demos) == 1 and not a.label and _is_demo_file(Path(a.demos[0])) and Path(
        a.demos[0]).is_dir() else ds
    with ctx.executor() as ex, ctx.progress() as progress:
        task = progress.add_task(f"a model per subject ({len(subjects)} subjects)", total=len(subjects))
        res = evaluate.per_subject(
            # each subject's plant from its training trials only, never from the held-out ones
            lambda train: evaluate.default_models(plant(train), components, seed), source, n_test=a.n_test,
            horizon=_steps(a.horizon, ds.dt), seed=a.seed,
            progress=lambda done, total: progress.update(task, completed=done), executor=ex,
        )
    for failure in res.failures:
        print(f"warning: {failure}", file=sys.stderr)
    table = Table("subject", *[METHOD_TITLES.get(m, m) for m in res.groups],
                  title=f"per-subject {res.metric} ({a.n_test} held-out trial(s) each, {a.horizon:g} s horizon)")
    for i, subject in enumerate(res.subjects):
        table.add_row(subject, *[f"{g[i]:.4g}" for g in res.groups.values()])
    ctx.say(table)
    ctx.say(f"one-way ANOVA across methods: {res.anova}")
    for r in res.ttests.values():
        ctx.say(f"  {r}")
    for line in verdicts(res.table.assign(label=""), res.metric):
        ctx.say(f"[bold]{escape(line)}[/bold]", markup=True)
    if a.output:
        atomic_write_table(res.table, a.output)
        ctx.say(f"wrote {a.output}")
    return 0


def _viewer_command(path: str | os.PathLike) -> str:
    """How to open a recording, with the viewer this workbench would start (the venv's, found without PATH)."""
    import shlex

    from workbench.viewer.output import rerun_executable

    def short(p: str) -> str:  # .venv/bin/rerun when run from the project, the full path from anywhere else
        rel = os.path.relpath(p) if os.path.isabs(p) else p
        return p if rel.startswith("..") else rel

    return shlex.join([*(short(p) for p in rerun_executable()), str(path)])


def _print_study(ctx: _Context, result: Any) -> None:
    from rich.markup import escape
    from rich.table import Table

    summary = result.summary()
    table = Table(*[str(c) for c in summary.columns], title="mean horizon RMSE on the test trials")
    for row in summary.itertuples(index=False):
        table.add_row(*[f"{v:.4g}" if isinstance(v, float) else str(v) for v in row])
    ctx.say(table)
    if result.coverage is not None and len(result.coverage):
        cov = Table(*[str(c) for c in result.coverage.columns], title="one-step coverage of ŵ by GMR bands [%]")
        for row in result.coverage.itertuples(index=False):
            cov.add_row(*[f"{v:.1f}" if isinstance(v, float) else str(v) for v in row])
        ctx.say(cov)
    if result.stats_text:
        ctx.say(result.stats_text)
    _print_objective_comparison(ctx, result)
    for line in result.verdicts():
        ctx.say(f"[bold]{escape(line)}[/bold]", markup=True)


def _print_objective_comparison(ctx: _Context, result: Any) -> None:
    """Weight ratios inside coupled parts per strategy, and each one's factor against the first strategy."""
    from rich.table import Table

    from workbench.weights import NOT_EXPLAINED, NOT_IDENTIFIABLE, compare_strategies, format_interval

    ratios = {lb: oi.ratios for lb, oi in getattr(result, "objectives", {}).items() if oi.ratios is not None}
    if not ratios:
        return
    table = compare_strategies(ratios)
    first = next(iter(ratios))
    out = Table("ratio", "strategy", "estimate [95 % interval]", f"× vs {first}", "",
                title="task-objective weight ratios inside coupled parts (diagonal cost, profile intervals)")
    for r in table.itertuples():
        factor = getattr(r, "factor", float("nan"))
        note = r.note if r.strategy == first or factor != factor else (r.factor_note or r.note)
        out.add_row(r.ratio, str(r.strategy), format_interval(r.estimate, r.lo, r.hi),
                    "" if factor != factor else format_interval(factor, r.factor_lo, r.factor_hi),
                    note if note else "")
    ctx.say(out)
    notes = set(table["note"]) | (set(table["factor_note"].dropna()) if "factor_note" in table else set())
    if NOT_IDENTIFIABLE in notes:
        ctx.say(f"(\"{NOT_IDENTIFIABLE}\": the 95 % interval spans more than ×10)")
    if NOT_EXPLAINED in notes:
        ctx.say(f"(\"{NOT_EXPLAINED}\": the estimated gain is farther from every diagonal-cost LQR gain than its "
                "spread allows, so the operator's objective is not of that form and these ratios describe none)")


def _output_kwargs(a: argparse.Namespace, default: Path) -> dict[str, Any]:
    from workbench.viewer import has_display

    if a.spawn or a.serve or a.save:
        return {"save": a.save, "spawn": a.spawn, "serve": a.serve}
    # headless by default when nothing could show a window
    return {"save": str(default), "spawn": False, "serve": False} if not has_display() else {
        "save": None, "spawn": True, "serve": False}


def cmd_view(ctx: _Context) -> int:
    from workbench import viewer

    a = ctx.args
    ds = _load_demos(ctx, a.inputs, a.mapping, a.label)
    models, named = None, None
    if a.model:
        by_label: dict[str, Any] = {}
        for spec in a.model:
            label, _, path = spec.rpartition("=")
            by_label[label] = _load_model(path)
        if "" in by_label:
            if len(by_label) > 1:
                raise WorkbenchError("give every --model a LABEL= (e.g. --model CS1=cs1.npz) or pass only one")
            models = by_label[""]
            named = {Path(a.model[0]).stem: models}
        else:
            models = named = by_label
        ds = _demos_at_model_dt(ctx, ds, list(by_label.values()), a.resample, ", ".join(a.inputs))
    horizon = _steps(a.horizon, ds.dt)
    default = Path("out") / (Path(a.inputs[0]).stem + ".rrd")  # under out/, never beside the input
    out = _output_kwargs(a, default)
    rec = viewer.new_recording(viewer.APPLICATION_IDS["session" if models is not None else "log"])
    with ctx.progress() as progress:
        progress.add_task(f"logging {len(ds)} demonstrations", total=None)
        with viewer.open_output(rec, **out) as sink:
            session = viewer.log_session(
                rec, ds, models=models, named_models=named, focus=a.focus or None, horizon=horizon,
                samples=a.samples, starts=a.starts or (0,), seed=a.seed,
            )
            sink.blueprint = viewer.default_blueprint(session)
    _announce(ctx, out, sink, f"{len(ds)} demonstrations")
    return 0


def _announce(ctx: _Context, out: dict[str, Any], sink: Any, what: str) -> None:
    if out["save"]:
        ctx.say(f"wrote {out['save']} ({what}); open it with:  {_viewer_command(out['save'])}")
    elif out["spawn"]:
        ctx.say(f"sent {what} to the rerun viewer")
    else:
        ctx.say(f"serving {what} on 127.0.0.1 only: open {sink.url}  (Ctrl-C to stop)")
        sink.wait()


def cmd_replay(ctx: _Context) -> int:
    if getattr(ctx.args, "to", None):  # a stand-in vehicle: the log's raw MAVLink frames, no model
        return _replay_to(ctx)
    from workbench import viewer
    from workbench.viewer import replay, replay_blueprint

    a = ctx.args
    if not a.model:
        raise WorkbenchError("replay needs --model MODEL.npz (predictions) or --to CONNECTION (send the log to a link)")
    ds = _load_demos(ctx, [a.log], a.mapping)
    model = _load_model(a.model)
    ds = _demos_at_model_dt(ctx, ds, [model], a.resample, a.log)
    ids = ds.ids
    chosen = a.demo or [ids[0]]
    missing = [i for i in chosen if i not in ids]
    if missing:
        raise DataError(f"{a.log}: no demonstration {missing[0]!r}; ids present: {ids[:10]}")
    out = _output_kwargs(a, Path("out") / (Path(a.log).stem + ".replay.rrd"))
    rec = viewer.new_recording(viewer.APPLICATION_IDS["replay"])
    stats = []
    with viewer.open_output(rec, **out) as sink:
        sink.blueprint = replay_blueprint(chosen, ds.state_names, ds.input_names, roles=ds.roles,
                                          demos=[ds[ids.index(i)] for i in chosen])
        if not out["save"]:
            rec.send_blueprint(sink.blueprint)
        with ctx.progress() as progress:
            for demo_id in chosen:
                demo = ds[ids.index(demo_id)]
                task = progress.add_task(f"replaying {demo_id} at {a.speed:g}×", total=len(demo))
                stats.append(
                    replay(demo, model, rec, state_names=ds.state_names, input_names=ds.input_names, roles=ds.roles,
                           speed=a.speed, wait=not a.no_wait, horizon=_steps(a.horizon, ds.dt) if a.horizon else 0,
                           on_step=lambda k, task=task: progress.update(task, completed=k + 1))
                )
    for s in stats:
        cover = ", ".join(f"{n} {100 * c:.1f} %" for n, c in zip(ds.input_names, s.coverage_3sigma, strict=True))
        ctx.say(f"{s.demo_id}: {s.n_steps} steps, {s.sim_time:.1f} s of flight in {s.wall_time:.2f} s "
                f"({s.realtime_factor:.1f}× real time); actual input inside the online 3σ band: {cover}")
    _announce(ctx, out, sink, f"replay of {', '.join(chosen)}")
    return 0


def _replay_to(ctx: _Context) -> int:
    from adapters.mavlink_link import send_tlog

    a = ctx.args
    log = _existing(a.log)
    ctx.say(f"sending {log} to {a.to} at {a.speed:g}× real time (Ctrl-C to stop)")
    with ctx.progress() as progress:
        task = progress.add_task(f"replaying {log.name} to {a.to}", total=None)
        try:
            report = send_tlog(log, a.to, speed=a.speed,
                               on_frame=lambda n, t: progress.update(task, completed=n) if n % 200 == 0 else None)
        except KeyboardInterrupt:
            ctx.say("stopped")
            return 130
    ctx.say(f"sent {report.n_frames} MAVLink frames ({report.log_seconds:.1f} s of log) in {report.wall_seconds:.1f} s "
            f"({report.speed:.1f}× real time)")
    return 0


def cmd_live(ctx: _Context) -> int:
    import signal

    from adapters.mavlink_link import open_link
    from workbench import viewer
    from workbench.live import OnlinePredictor, listen
    from workbench.viewer.live import LIVE_APPLICATION_ID, LiveLogger, live_blueprint
    from workbench.viewer.scene import plane_of

    a = ctx.args
    model = _load_model(a.model)
    predictor = OnlinePredictor(model, a.mapping or DEFAULT_MAPPING, horizon=a.horizon, system=a.sysid,
                                clock=a.clock, silence=a.silence)
    m = predictor.mapping
    scene = plane_of(m.roles, m.state_names)  # the plane of flight the replay and the session draw
    plane = None if scene is None else (scene.across, scene.up, scene.heading)
    out = _output_kwargs(a, Path("out") / "live.rrd")
    rec = viewer.new_recording(LIVE_APPLICATION_ID)
    link = open_link(a.connection)
    logger: Any = None
    shown: list[str] = []

    def on_prediction(p: Any) -> None:
        logger.log(p)
        if not out["save"] and logger.demo_ids[-1:] != shown[-1:]:  # a new segment: show it in the viewer
            shown.append(p.demo_id)
            rec.send_blueprint(live_blueprint(logger.demo_ids, m.state_names, m.input_names, scene=plane is not None,
                                              bounds=logger.scene_bounds()))

    def on_event(ev: Any) -> None:
        logger.event(ev)
        print(f"{ev.kind}: {ev.text}", file=sys.stderr)

    with link, viewer.open_output(rec, **out) as sink:
        logger = LiveLogger(rec, m.state_names, m.input_names, plane=plane)
        if not out["save"]:
            rec.send_blueprint(live_blueprint([], m.state_names, m.input_names, scene=plane is not None))
        ctx.say(f"listening on {a.connection} (mapping {m.name}, dt {m.dt:g} s, rollout {a.horizon:g} s)"
                + (f" for {a.duration:g} s" if a.duration else "; Ctrl-C to stop"))
        def on_tick(stats: Any) -> None:  # the viewer gets the steps in batches, a few times a second
            logger.flush()
            logger.status(stats)

        def on_term(signum: int, frame: Any) -> None:  # a SIGTERM ends the session as cleanly as Ctrl-C
            raise KeyboardInterrupt

        previous = signal.signal(signal.SIGTERM, on_term)
        try:
            summary = listen(link, predictor, duration=a.duration, on_prediction=on_prediction, on_event=on_event,
                             on_tick=on_tick, tick=0.25)
        finally:
            signal.signal(signal.SIGTERM, previous)
        sink.blueprint = live_blueprint(logger.demo_ids, m.state_names, m.input_names, scene=plane is not None,
                                        bounds=logger.scene_bounds())
    c50, c99 = summary.percentiles("compute")
    l50, l99 = summary.percentiles("latency")
    ctx.say(f"{summary.n_steps} steps in {summary.n_segments} segment(s) over {summary.wall_seconds:.1f} s "
            f"({'interrupted' if summary.ended_by == 'interrupt' else 'duration reached'}); per step "
            f"p50 {c50:.2f} ms, p99 {c99:.2f} ms; message to prediction p50 {l50:.2f} ms, p99 {l99:.2f} ms")
    counts = summary.stats.counts
    ctx.say("link: " + (", ".join(f"{k} {v}" for k, v in sorted(counts.items()) if v) or "nothing received"))
    if summary.stats.waiting_for and not summary.n_steps:
        ctx.say(f"never received: {', '.join(summary.stats.waiting_for)}")
    if summary.ended_by == "interrupt" and out["serve"]:
        return 0
    _announce(ctx, out, sink, f"live session ({summary.n_steps} steps)")
    return 0


def cmd_report(ctx: _Context) -> int:
    from workbench import study
    from workbench.report import write_study_report

    a = ctx.args
    ds = _load_demos(ctx, a.demos, a.mapping, a.label)
    with ctx.executor() as ex:
        result = study.run_study(
            ds, _plant(a.system, a.horizon), test_size=a.test_size, horizon=_steps(a.horizon, ds.dt),
            components=a.components, samples=a.samples, efficiency=a.efficiency, repeats=a.repeats, seed=a.seed,
            progress=ctx.progress, executor=ex, bootstrap=a.bootstrap,
        )
    _print_plant(ctx, result.system, "(plant from the training trials)")
    _require_proposed(result)
    path = write_study_report(result, a.output, title=a.title)
    _print_study(ctx, result)
    ctx.say(f"wrote {path} with figures in {Path(a.output) / 'figures'}")
    return 0


def cmd_demo(ctx: _Context) -> int:
    from rich.markup import escape

    from workbench import study
    from workbench.report import write_study_report
    from workbench.viewer import record_study

    a = ctx.args
    t_start = time.perf_counter()
    out = Path(a.out)
    logs = Path(a.logs) if a.logs else SAMPLE_LOGS
    files = sorted(p for p in logs.iterdir() if p.is_file() and not p.name.startswith(".")) if logs.is_dir() else []
    files = [p for p in files if p.suffix.lower() in (".tlog", ".mcap", ".csv", ".ulg", ".parquet")]
    if not files:
        if a.logs:
            raise DataError(f"{logs}: no logs (.tlog, .mcap, .csv, .ulg) to import")
        from workbench.sample_logs import write_sample_logs

        logs = out / "sample_logs"
        ctx.say(f"{SAMPLE_LOGS} is empty; generating the sample logs into {logs}")
        write_sample_logs(logs, seed=0)
        files = sorted(p for p in logs.iterdir() if p.suffix.lower() in (".tlog", ".mcap", ".csv", ".ulg"))
    timings = {}
    t0 = time.perf_counter()
    ds = _load_demos(ctx, [str(f) for f in files], a.mapping)
    timings["import"] = time.perf_counter() - t0
    by_format: dict[str, int] = {}
    for f in files:
        by_format[f.suffix.lstrip(".")] = by_format.get(f.suffix.lstrip("."), 0) + 1
    ctx.say(
        f"imported {len(ds)} demonstrations ({ds.n_samples} samples; labels {ds.labels}) from {len(files)} logs "
        f"({', '.join(f'{v} {k}' for k, v in by_format.items())}) in {logs}"
    )
    out.mkdir(parents=True, exist_ok=True)
    ds.save(out / "demos.parquet")
    result = study.run_study(
        ds, _plant(a.system), test_size=a.test_size, horizon=_steps(a.horizon, ds.dt), components=a.components,
        samples=a.samples, efficiency=a.efficiency, repeats=a.repeats, seed=a.seed, progress=ctx.progress,
        bootstrap=a.bootstrap,
    )
    timings["fit + compare"] = time.perf_counter() - t0 - timings["import"]
    _require_proposed(result)
    model_dir = out / "models"
    for label, model in result.models.items():
        model.save(model_dir / f"{label}.npz")
    result.save_tables(out / "results.csv")
    t1 = time.perf_counter()
    report = write_study_report(result, out, title="Workbench demo: sample logs")
    timings["report"] = time.perf_counter() - t1
    rrd = out / "demo.rrd"
    t1 = time.perf_counter()
    record_study(result, rrd, progress=ctx.progress)
    timings["recording"] = time.perf_counter() - t1
    _print_study(ctx, result)
    ctx.say("")
    rows = [
        ("report", f"{report}  (figures in {out / 'figures'})"),
        ("recording", f"{rrd}   open it with:  {_viewer_command(rrd)}"),
        ("models", ", ".join(str(model_dir / f"{k}.npz") for k in result.models)),
        ("data", f"{out / 'demos.parquet'}, {out / 'results.csv'}"),
    ]
    for key, value in rows:
        ctx.say(f"[bold]{key:<10}[/bold] {escape(value)}", markup=True)
    parts = ", ".join(f"{k} {v:.1f} s" for k, v in timings.items())
    ctx.say(f"done in {time.perf_counter() - t_start:.1f} s ({parts})")
    return 0


# -- parser ------------------------------------------------------------------------------------------------
_EPILOG = """\
examples:
  workbench demo                                   # sample logs → models, report and out/demo.rrd
  workbench inspect sample_logs/landing_s00.tlog   # streams, rates, fields, time span
  workbench import sample_logs/*.tlog --mapping planar_quadrotor -o demos.parquet
  workbench fit demos.parquet --label CS1 -o cs1.npz
  workbench view demos.parquet --model CS1=cs1.npz --save session.rrd && rerun session.rrd
  workbench replay demos.parquet --model cs1.npz --speed 2
"""


def _common(p: argparse.ArgumentParser, *, top: bool = False) -> None:
    default = False if top else argparse.SUPPRESS
    p.add_argument("--debug", action="store_true", default=default, help="show the traceback of an error")
    p.add_argument("-q", "--quiet", action="store_true", default=default, help="print nothing but errors")


def _study_options(
    p: argparse.ArgumentParser, *, samples: int = 100, efficiency: str | None = "2,5,10,20", repeats: int = 2
) -> None:
    p.add_argument("--test-size", type=float, default=0.2, metavar="F",
                   help="fraction of each strategy's trials held out for testing (default 0.2)")
    p.add_argument("--horizon", type=_positive_float, default=3.0, metavar="SECONDS",
                   help="prediction horizon in seconds (default 3.0, the paper's 60 steps)")
    p.add_argument("--components", type=_components, default=5, metavar="G|auto",
                   help="GMM components, or 'auto' to pick by BIC (default 5, the paper's)")
    p.add_argument("--samples", type=int, default=samples, metavar="N",
                   help=f"Monte Carlo rollouts for the prediction band; 0 turns it off (default {samples})")
    p.add_argument("--efficiency", type=_int_list, default=_int_list(efficiency) if efficiency else None,
                   metavar="N,N,…", help=f"training-set sizes of the data-efficiency curve (default {efficiency})")
    p.add_argument("--no-efficiency", dest="efficiency", action="store_const", const=None,
                   help="skip the data-efficiency curve")
    p.add_argument("--repeats", type=int, default=repeats, metavar="R",
                   help=f"random training subsets per size on the data-efficiency curve (default {repeats})")
    p.add_argument("--seed", type=int, default=0, help="seed of the split, EM and Monte Carlo (default 0)")
    _system_option(p)


def _system_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--system", choices=["auto", "paper", "identify"], default="auto",
                   help="plant (A, B): the paper's planar quadrotor, identified from the data by least squares, "
                   "or auto (the paper's for its state layout at dt 0.05 s, else identified)")


def _output_options(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--save", metavar="FILE.rrd",
                   help="write a rerun recording (without a display the default is out/<input>.rrd)")
    g.add_argument("--spawn", action="store_true", help="stream to a native rerun viewer")
    g.add_argument("--serve", action="store_true", help="serve a web viewer on 127.0.0.1 (localhost only)")


def _executor_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scaling out (Dask)")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--workers", type=int, metavar="N",
                   help="run independent tasks on a local Dask cluster of N worker processes (default: serial, "
                        "in this process)")
    x.add_argument("--scheduler", metavar="ADDRESS",
                   help="run them on a running Dask cluster, e.g. tcp://10.0.0.5:8786 (its workers need the "
                        "workbench and must reach the input files and --staging)")
    g.add_argument("--staging", metavar="DIR",
                   help="folder where data for the workers is written (default a temporary folder; on a cluster, "
                        "a path every worker reaches)")


def _mapping_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--mapping", metavar="M",
                   help=f"channel mapping for raw logs: a shipped name or a TOML file (default {DEFAULT_MAPPING})")


def build_parser() -> argparse.ArgumentParser:
    from workbench import __version__

    parser = argparse.ArgumentParser(
        prog="workbench",
        description="Models of how a human operator flies, from teleoperation and flight logs: u = K x + w, "
        "K from inverse optimal control, w from a task-parameterized GMM read out by GMR.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"workbench {__version__}")
    _common(parser, top=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    def add(name: str, func: Callable[[_Context], int], help: str, example: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help, description=help, epilog=f"example:\n  {example}",
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        _common(p)
        p.set_defaults(func=func)
        return p

    p = add("simulate", cmd_simulate, "simulate landing demonstrations with synthetic operators",
            "workbench simulate --strategy CS1 CS2 --trials 30 -o demos.parquet")
    p.add_argument("-o", "--output", metavar="FILE", help="demonstrations file: .parquet, .csv, .tlog or .mcap")
    p.add_argument("--strategy", nargs="+", default=["CS1", "CS2"], choices=["CS1", "CS2"],
                   help="control strategies: CS1 centre first, CS2 straight line (default both)")
    p.add_argument("--trials", type=int, default=30, help="trials per strategy and subject (default 30)")
    p.add_argument("--subjects", type=int, default=0, help="number of synthetic subjects; 0 = the reference expert")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sample-logs", metavar="DIR", help="instead: regenerate the sample logs into DIR")

    p = add("inspect", cmd_inspect, "show what a log contains: streams, rates, fields, time span",
            "workbench inspect flight.tlog")
    p.add_argument("log", help="a .tlog, .mcap, .ulg, .csv log or a demonstrations .parquet")

    p = add("import", cmd_import, "turn logs into one demonstrations file, or many logs into a partitioned dataset",
            "workbench import 'logs/*.tlog' --mapping planar_quadrotor -o dataset/ --workers 2")
    p.add_argument("logs", nargs="+", metavar="LOG|DIR|GLOB",
                   help="log files, directories of logs, or quoted glob patterns")
    _mapping_option(p)
    p.add_argument("-o", "--output", required=True, metavar="FILE|DIR/",
                   help="a demonstrations file (.parquet, .csv, …), or DIR/ for a dataset with one Parquet file per "
                        "log and subject, imported in parallel; a log that fails is reported and the rest imported")
    p.add_argument("--label", help="set every trial's strategy label")
    _executor_options(p)

    p = add("fit", cmd_fit, "fit a human behavior model (task objective + variability) to demonstrations",
            "workbench fit demos.parquet --label CS1 --components 5 -o cs1.npz")
    p.add_argument("demos", metavar="DEMOS", help="demonstrations (.parquet) or a raw log (with --mapping)")
    p.add_argument("-o", "--output", required=True, metavar="MODEL.npz")
    p.add_argument("--label", help="fit only the trials of this strategy label")
    p.add_argument("--components", type=_fit_components, default=5, metavar="G|auto|cv",
                   help="GMM components (default 5, the paper's); auto: by BIC; cv: the proposed model chooses G and "
                        "reg_covar by cross-validation over the trials (held-out 3 s predictions)")
    p.add_argument("--method", choices=["proposed", "ioc-only", "gmr-only"], default="proposed",
                   help="the proposed model (default) or one of its baselines")
    p.add_argument("--gain", choices=["direct", "dmd", "iv"], default="direct",
                   help="how K̂ is estimated: least squares (direct, default), the paper's DMD, or instrumental "
                        "variables (iv: consistent when the operator's variability is autocorrelated)")
    p.add_argument("--seed", type=int, default=0, help="seed of the k-means initialization (default 0)")
    p.add_argument("--bootstrap", type=int, default=100, metavar="N",
                   help="resample the trials N times (default 100; 0: no intervals) and print 95 %% intervals of "
                        "K̂, the normalized Q, R diagonals and the weight ratios inside coupled parts (the paper "
                        "gives none)")
    _system_option(p)
    _mapping_option(p)
    _executor_options(p)

    p = add("predict", cmd_predict, "predict a trajectory with a fitted model from a recorded or given state",
            "workbench predict --model cs1.npz demos.parquet --demo s00-cs1-003 --horizon 3 --samples 200 -o p.csv")
    p.add_argument("demos", nargs="?", metavar="DEMOS", help="demonstrations to take the start state from")
    p.add_argument("--model", required=True, metavar="MODEL.npz")
    p.add_argument("--demo", metavar="ID", help="trial to start from (default the first)")
    p.add_argument("--start", type=int, default=0, metavar="K", help="sample of the trial to start from (default 0)")
    p.add_argument("--x0", metavar="X,Y,…", help="instead of a trial: the start state, comma-separated")
    p.add_argument("--resample", action="store_true",
                   help="resample demonstrations sampled at another dt than the model's to the model's dt "
                        "(default: refuse them)")
    p.add_argument("--horizon", type=_positive_float, default=3.0, metavar="SECONDS",
                   help="prediction horizon in seconds (default 3.0)")
    p.add_argument("--samples", type=int, default=0, metavar="N",
                   help="Monte Carlo rollouts: adds <state>_lower/_upper band columns (5–95 %%)")
    p.add_argument("--seed", type=int, default=0, help="seed of the Monte Carlo draws (default 0)")
    p.add_argument("-o", "--output", required=True, metavar="FILE", help=".csv or .parquet")
    _mapping_option(p)

    p = add("evaluate", cmd_evaluate,
            "compare the proposed model with IOC-only, GMR-only and persistence on held-out trials; data efficiency",
            "workbench evaluate demos.parquet --horizon 3 -o results.csv")
    p.add_argument("demos", nargs="+", metavar="DEMOS")
    p.add_argument("--label", nargs="+", help="strategy labels to evaluate (default all)")
    p.add_argument("-o", "--output", metavar="FILE", help="tidy results table (.csv or .parquet)")
    p.add_argument("--per-subject", action="store_true",
                   help="the paper's multi-subject design: a model per subject, --n-test held-out trials each, "
                        "ANOVA and paired t-tests across the methods (use --horizon 5 for the paper's)")
    p.add_argument("--n-test", type=int, default=1, metavar="N",
                   help="held-out trials per subject with --per-subject (default 1)")
    p.add_argument("--holdout", choices=["auto", "split", "loso"], default="auto",
                   help="test trials: one random split (--test-size), leave-one-segment-out (every trial tested "
                        "once by models fitted on the others; no data-efficiency curve), or auto: leave-one-out "
                        "when a label has fewer than 10 trials (default)")
    _study_options(p)
    _mapping_option(p)
    _executor_options(p)

    p = add("view", cmd_view, "log demonstrations (and a model's variability and predictions) to rerun",
            "workbench view demos.parquet --model CS1=cs1.npz --model CS2=cs2.npz --save session.rrd")
    p.add_argument("inputs", nargs="+", metavar="DEMOS_OR_LOG")
    p.add_argument("--model", action="append", metavar="[LABEL=]MODEL.npz",
                   help="a fitted model; with LABEL= it explains the trials of that strategy (repeatable)")
    p.add_argument("--label", nargs="+", help="show only these strategy labels")
    p.add_argument("--focus", nargs="+", metavar="ID", help="trials to predict from (default the first per label)")
    p.add_argument("--starts", nargs="+", type=int, metavar="K", help="samples to predict from (default 0)")
    p.add_argument("--horizon", type=_positive_float, default=3.0, metavar="SECONDS",
                   help="prediction horizon in seconds (default 3.0)")
    p.add_argument("--samples", type=int, default=0, metavar="N", help="Monte Carlo rollouts for the band")
    p.add_argument("--seed", type=int, default=0, help="seed of the Monte Carlo draws (default 0)")
    p.add_argument("--resample", action="store_true",
                   help="resample demonstrations sampled at another dt than the model's to the model's dt "
                        "(default: refuse them)")
    _mapping_option(p)
    _output_options(p)

    p = add("replay", cmd_replay, "stream a recorded session as if live, with the model's online predictions",
            "workbench replay demos.parquet --model cs1.npz --speed 1.0 --spawn")
    p.add_argument("log", metavar="LOG", help="demonstrations (.parquet) or a raw log (with --mapping)")
    p.add_argument("--model", metavar="MODEL.npz", help="the model whose online predictions are shown")
    p.add_argument("--to", metavar="CONNECTION",
                   help="instead: send a .tlog's raw MAVLink frames to a link with their recorded timing (a stand-in "
                        "vehicle for `workbench live`), e.g. udpout:127.0.0.1:14550; no model needed")
    p.add_argument("--demo", nargs="+", metavar="ID", help="trials to replay (default the first)")
    p.add_argument("--speed", type=_positive_float, default=1.0, help="multiple of real time (default 1.0)")
    p.add_argument("--no-wait", action="store_true", help="stream as fast as possible")
    p.add_argument("--horizon", type=float, default=1.0, metavar="SECONDS",
                   help="rollout horizon of the online prediction (default 1.0 s; 0 turns rollouts off)")
    p.add_argument("--resample", action="store_true",
                   help="resample demonstrations sampled at another dt than the model's to the model's dt "
                        "(default: refuse them)")
    _mapping_option(p)
    _output_options(p)

    p = add("live", cmd_live, "predict the pilot online from a vehicle's live MAVLink telemetry, into rerun",
            "workbench live udpin:0.0.0.0:14550 --mapping planar_quadrotor --model cs1.npz --spawn")
    p.add_argument("connection", metavar="CONNECTION",
                   help="a pymavlink connection: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or a serial device")
    p.add_argument("--model", required=True, metavar="MODEL.npz")
    p.add_argument("--duration", type=_positive_float, metavar="SECONDS", help="stop after this long (default: Ctrl-C)")
    p.add_argument("--horizon", type=float, default=1.0, metavar="SECONDS",
                   help="rollout horizon at every step (default 1.0 s; 0 turns rollouts off)")
    p.add_argument("--sysid", type=int, metavar="N", help="follow this MAVLink system (default: the first vehicle)")
    p.add_argument("--clock", choices=["vehicle", "arrival"], default="vehicle",
                   help="time samples by the vehicle's time_boot_ms (default) or by their arrival")
    p.add_argument("--silence", type=_positive_float, default=2.0, metavar="SECONDS",
                   help="report the link silent after this long without data (default 2 s)")
    _mapping_option(p)
    _output_options(p)

    p = add("report", cmd_report, "fit, compare and write a Markdown report with PNG figures",
            "workbench report demos.parquet -o report/")
    p.add_argument("demos", nargs="+", metavar="DEMOS")
    p.add_argument("-o", "--output", required=True, metavar="DIR")
    p.add_argument("--label", nargs="+", help="strategy labels to include (default all)")
    p.add_argument("--title", default="Workbench report")
    _bootstrap_option(p)
    _study_options(p)
    _mapping_option(p)
    _executor_options(p)

    p = add("demo", cmd_demo, "the whole pipeline on the sample logs: import, fit CS1 and CS2, compare, report, .rrd",
            "workbench demo --out out/ && rerun out/demo.rrd")
    p.add_argument("--out", default="out", metavar="DIR", help="output directory (default out/)")
    p.add_argument("--logs", metavar="DIR", help=f"logs to import (default {SAMPLE_LOGS})")
    _study_options(p, repeats=1)  # one subset per size keeps the demo well under a minute on two cores
    _bootstrap_option(p)
    _mapping_option(p)
    return parser


def _bootstrap_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bootstrap", type=int, default=100, metavar="N",
                   help="resamples of each strategy's training trials for the intervals of its task objective and "
                        "weight ratios (default 100; 0: point estimates only)")


# -- entry point -------------------------------------------------------------------------------------------
def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"warning: {' '.join(str(message).split())}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = bool(getattr(args, "debug", False))
    previous = warnings.showwarning
    if not debug:
        warnings.showwarning = _show_warning
    try:
        with limit_threads():  # small matrices: one BLAS thread is faster than many (workbench.threads)
            return int(args.func(_Context(args)) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return EXIT_ERROR
    except Exception as exc:
        if debug:
            traceback.print_exc()
        if isinstance(exc, WorkbenchError):
            print(f"error: {_one_line(exc)}", file=sys.stderr)
            return EXIT_ERROR
        if isinstance(exc, OSError):
            where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            print(f"error: {where}{exc.strerror or _one_line(exc)}", file=sys.stderr)
            return EXIT_ERROR
        hint = "" if debug else " (run with --debug for the traceback)"
        print(f"error: {type(exc).__name__}: {_one_line(exc)}{hint}", file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        warnings.showwarning = previous


if __name__ == "__main__":
    raise SystemExit(main())

