"""``workbench simulate``, ``inspect`` and ``import``: logs in, demonstrations out.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from workbench.cli.context import EXIT_ERROR, Context
from workbench.cli.inputs import resolve
from workbench.cli.options import MAX_SIMULATED_TRIALS
from workbench.cli.stdio import is_stdio, refuse_stdio
from workbench.cli.writing import write_demos
from workbench.errors import UsageError

__all__ = []

# -- commands ----------------------------------------------------------------------------------------------
def cmd_simulate(ctx: Context) -> int:
    a = ctx.args
    if a.sample_logs:
        refuse_stdio(a.sample_logs, "--sample-logs", "the sample logs are several files")
        from workbench.cli.sample_logs import write_sample_logs

        written = write_sample_logs(a.sample_logs, seed=a.seed)
        files = list(written) if written is not None else sorted(Path(a.sample_logs).iterdir())
        ctx.say(f"wrote {len(files)} sample logs to {a.sample_logs}")
        return 0
    if not a.output:
        raise UsageError("simulate needs -o FILE (.parquet or a log format's extension: .csv, .tlog, …) or "
                             "--sample-logs DIR")
    from workbench.sim.landing import simulate_landings

    if len(a.strategy) * max(a.subjects, 1) * max(a.trials, 0) > MAX_SIMULATED_TRIALS:
        raise UsageError(f"--trials {a.trials} × --subjects {a.subjects} × {len(a.strategy)} strategies: more than "
                         f"{MAX_SIMULATED_TRIALS} trials in one call; simulate fewer, or several files into a dataset")
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
    out = ctx.output_path(a.output, ".parquet", "the demonstrations")
    write_demos(ds, out)
    labels = ", ".join(map(str, ds.labels)) or "none"
    ctx.say(f"wrote {len(ds)} demonstrations ({ds.n_samples} samples, labels {labels}) to {_named(ctx, out)}")
    return 0


def _named(ctx: Context, out: Path) -> str:
    return "standard output" if ctx.stdio.writes_stdout else str(out)


def cmd_inspect(ctx: Context) -> int:
    from rich.markup import escape
    from rich.table import Table

    source = resolve(ctx.args, ctx.stdio, [ctx.args.log], mapping=False, what="the log").sources[0]
    path = source.path
    if source.demos:
        from workbench.data.dataset import load_demonstrations

        ds = load_demonstrations(path)
        ctx.say(f"[bold]{escape(source.shown)}[/bold]: workbench demonstrations, {len(ds)} trials, "
                f"{ds.n_samples} samples, dt {ds.dt} s", markup=True)
        ctx.say(f"states {', '.join(ds.state_names)}; inputs {', '.join(ds.input_names)}")
        table = Table("id", "label", "subject", "samples", "duration [s]", "success", "source")
        for d in ds:
            table.add_row(d.id, str(d.label), str(d.meta.get("subject")), str(len(d)), f"{d.duration:.2f}",
                          str(d.meta.get("success")), Path(str(d.meta.get("source", ""))).name)
        ctx.say(table)
        return 0
    import adapters

    summary = adapters.inspect(path, format=source.format)
    t0 = summary.t_start
    ctx.say(
        f"[bold]{escape(ctx.shown(summary.path))}[/bold]: {summary.format}, {summary.size_bytes} bytes, "
        f"{len(summary.streams)} streams, {summary.duration:.1f} s",
        markup=True,
    )
    table = Table("stream", "messages", "mean rate [Hz]", "from [s]", "to [s]", "fields")
    for st in summary.streams:
        fields = ", ".join(st.fields[:8]) + (f", … (+{len(st.fields) - 8})" if len(st.fields) > 8 else "")
        # no span, no rate: 395 untimed PARM messages at one stamp read "0 Hz", as if the stream were silent
        rate = f"{st.rate_hz:.3g}" if st.count > 1 and st.t_end > st.t_start else "—"
        table.add_row(st.name, str(st.count), rate, f"{st.t_start - t0:.2f}", f"{st.t_end - t0:.2f}", fields)
    ctx.say(table)
    if summary.modes:
        # the duration from the endpoints as shown: 85.04–95.64 s read "85.0–95.6 s (10.7 s)", which disagrees
        spans = [(m.mode, round(m.start - t0, 1), round(min(m.end, summary.t_end) - t0, 1)) for m in summary.modes]
        ctx.say(f"flight modes{f' ({summary.vehicle})' if summary.vehicle else ''}: " + "; ".join(
            f"{mode} {a:.1f}–{b:.1f} s ({b - a:.1f} s)" for mode, a, b in spans))
    if summary.armed_text:  # the armed spans, or "never armed" when the log says so
        ctx.say(summary.armed_text)
    if summary.skipped:
        ctx.say("skipped: " + ", ".join(f"{k} {v}" for k, v in summary.skipped))
    if summary.damaged:  # where: the runs of bytes that are no message (a DataFlash log has no checksum)
        ctx.say(f"damaged: {summary.damaged}")
    return 0


def cmd_map(ctx: Context) -> int:
    """Draft a mapping from a log (adapters.draft) and write it, or print it without -o."""
    import adapters
    from adapters.draft import draft_mapping
    from workbench.atomic import atomic_path

    a = ctx.args
    source = resolve(a, ctx.stdio, [a.log], mapping=False, what="the log").sources[0]
    output = None if is_stdio(a.output) else a.output  # `-o -`: printed, as without -o
    name = Path(output).stem if output else ("stdin" if source.stdin else source.path.stem)
    draft = draft_mapping(adapters.read(source.path, format=source.format), name=name)
    if output:
        with atomic_path(output) as tmp:
            Path(tmp).write_text(ctx.shown(draft.toml), encoding="utf-8")
        ctx.say(f"wrote {output}: a mapping for {draft.vehicle} (template {draft.template}); "
                f"try: workbench import {a.log} --mapping {output} -o demos.parquet")
    else:
        print(ctx.shown(draft.toml), end="")  # <stdin>, not the temporary file's name
    for item in draft.undecided:  # what the draft could not decide, on stderr so a piped TOML stays clean
        print(f"undecided: {item}", file=sys.stderr)
    return 0


def _is_dataset_output(output: str) -> bool:
    """``-o DIR/`` (or an existing directory, or a name without a suffix) asks for a partitioned dataset;
    ``-o -`` is one file, on standard output."""
    if is_stdio(output):
        return False
    return output.endswith(("/", os.sep)) or Path(output).is_dir() or not Path(output).suffix


def _import_dataset(ctx: Context) -> int:
    from adapters.batch import expand_logs, import_logs

    a = ctx.args
    if any(is_stdio(log) for log in a.logs):
        raise UsageError("- (standard input) is one log: import it into one file (-o FILE or -o -), not a "
                             "dataset folder")
    files = expand_logs(a.logs)
    with ctx.executor() as ex, ctx.progress() as progress:
        task = progress.add_task(f"importing {len(files)} logs", total=len(files))
        report = import_logs(files, a.output, a.mapping, label=a.label, executor=ex,
                             progress=lambda done, total: progress.update(task, completed=done))
    for log in report.imported:
        if log.skipped:  # a damaged or partly unmapped file still gave data: say what was left out
            what = ", ".join(f"{k.replace('_', ' ')}: {v}" for k, v in log.skipped)
            ctx.warn(f"{log.source}: skipped {what}")
    for source, cause in report.failures:
        print(f"error: {source}: not imported: {cause}", file=sys.stderr)
    subjects = {p.subject for log in report.imported for p in log.partitions if p.subject is not None}
    ctx.say(f"wrote {report.n_demos} demonstrations ({report.n_samples} samples, {len(subjects)} subjects) from "
            f"{len(report.imported)} of {len(files)} logs to the dataset {report.path}/")
    return EXIT_ERROR if report.failures else 0


def cmd_import(ctx: Context) -> int:
    a = ctx.args
    if _is_dataset_output(a.output):
        return _import_dataset(ctx)
    if a.workers or a.scheduler:
        ctx.warn(f"--workers and --scheduler import in parallel into a dataset (-o DIR/); {a.output} is one file, so "
                 "the logs are read here, one after another")
    from adapters.batch import expand_logs

    out = ctx.output_path(a.output, ".parquet", "the demonstrations")  # before reading: refused on a terminal
    # `-` is standard input, not a file name a glob or folder could expand to
    names = [name for log in a.logs for name in (["-"] if is_stdio(log) else [str(f) for f in expand_logs([log])])]
    # an import writes what it reads: no trial is chosen among them (--label here sets the strategy label)
    ds = ctx.read(resolve(a, ctx.stdio, names, labels=False), select=False).demos
    if a.label:
        ds = ds.with_demos(d.with_meta(label=a.label) for d in ds)  # keeps the mapping's roles
    write_demos(ds, out, a.mapping)
    labels = ", ".join(map(str, ds.labels)) or "none"
    ctx.say(f"wrote {len(ds)} demonstrations ({ds.n_samples} samples, labels {labels}) to {_named(ctx, out)}")
    return 0
