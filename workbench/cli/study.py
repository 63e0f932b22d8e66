"""``workbench evaluate``, ``report`` and ``demo``: the comparison of the proposed model with its baselines.
"""

from __future__ import annotations

import importlib
import math
import os
import re
import shutil
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from workbench.atomic import atomic_write_table, recover_swaps, swap_entries, temp_sibling
from workbench.cli.context import Context
from workbench.cli.inputs import resolve
from workbench.cli.options import SAMPLE_LOGS, rollout_budget, steps_of
from workbench.cli.reading import chosen_plant, per_group_path, plant_group_parts, require_proposed, study_plant
from workbench.cli.stdio import STDIN_NAME, is_stdio, refuse_stdio
from workbench.cli.writing import print_plant, viewer_command
from workbench.data.plant_groups import describe_groups
from workbench.data.selection import recorded_test_ids, unrecorded_split
from workbench.errors import DataError, ModelError, PlantRefused, UsageError

__all__ = []

def cmd_evaluate(ctx: Context) -> int:

    a = ctx.args
    output = ctx.output_path(a.output, ".parquet", "the results table") if a.output else None
    inputs = resolve(a, ctx.stdio, a.demos, purpose="study")
    got = ctx.read(inputs)
    ds = got.demos
    parts, said = plant_group_parts(ds, getattr(a, "plant_group", None))
    if said:
        ctx.say(said)
    if len(parts) > 1 and output is not None and ctx.stdio.writes_stdout:
        raise UsageError(f"-o - writes one table, but these demonstrations are {len(parts)} plant groups "
                         f"({', '.join(str(g) for g, _ in parts)}): name one with --plant-group")
    # --per-subject reads a dataset read whole where it lies, each subject's partition by its own task (only where
    # every trial of it is used: nothing left out by the selection, for want of pilot input or by plant group)
    whole = inputs.dataset if (inputs.dataset is not None and len(ds) == got.selected.total
                               and len(parts) == 1) else None
    trials = got.selected.describe()
    return for_each_group(ctx, parts, "evaluated", lambda group, part: _evaluate_group(
        ctx, part, output if len(parts) == 1 or output is None else per_group_path(output, group),
        source=part if whole is None else whole, trials=trials))


def for_each_group(ctx: Context, parts: list[tuple[str | None, Any]], done: str, run: Callable[[Any, Any], Any]) -> int:
    """Run a command's work on each plant group's demonstrations (its own plant and models), each under a heading
    that names the group; with several groups, one group's failure is a warning and the others still run. A plant
    refused for its physics names the sources and the group in its one line, as ``fit``'s does."""
    if len(parts) == 1:
        group, part = parts[0]
        try:
            run(group, part)
        except PlantRefused as exc:
            if exc.report is not None:  # the report the one line refers to, before it (chosen_plant printed its own)
                print(exc.report.describe(warning=False), file=sys.stderr)
            given = getattr(ctx.args, "demos", None) or []
            sources = ", ".join(STDIN_NAME if is_stdio(g) else str(g) for g in given)
            where = (f"{sources}: " if sources else "") + (f"plant group {group}: " if group else "")
            raise ModelError(f"{where}not {done}: {exc}") from None
        return 0
    failed = []
    for group, part in parts:
        ctx.say("")
        ctx.say(f"[bold]plant group {group}[/bold] ({describe_groups(part)})", markup=True)
        try:
            run(group, part)
        except (DataError, ModelError) as exc:
            ctx.warn(f"plant group {group}: not {done}: {exc}")
            failed.append(f"{group}: {exc}")
    if len(failed) == len(parts):
        raise ModelError(f"no plant group could be {done}: {'; '.join(failed)}")
    return 0


def _evaluate_group(ctx: Context, ds: Any, output: Path | None, *, source: Any, trials: str) -> None:
    a = ctx.args
    if a.per_subject:
        _evaluate_per_subject(ctx, ds, source, output)
        return
    result, loso = _holdout_study(ctx, ds, trials=trials)
    if loso and getattr(result.plant, "identification", None) is not None:
        # the plant a user would fit on all segments (its report is itself leave-one-segment-out) and the
        # spread of the folds' plants, which the scores below used
        checks = [c for p in result.plants.values() for c in p.identification.checks]
        # folds whose training segments gave no plant: named with the verdicts (as are those whose test never moves)
        left = sum(f.part == "training" for f in result.folds_left_out)
        spread = (f"each fold's plant from its training segments: {checks[0].name} "
                  f"{min(c.value for c in checks):.4g}–{max(c.value for c in checks):.4g} over {len(checks)} folds"
                  if checks else "each fold's plant is identified from its training segments only") + (
                  f"; {left} fold{'s' if left > 1 else ''} left out, no plant from {'their' if left > 1 else 'its'} "
                  "training segments (below)" if left else "")
        whole = "the one segment" if len(ds) == 1 else f"all {len(ds)} segments"
        print_plant(ctx, chosen_plant(ds, a.plant, a.horizon_s), f"(plant from {whole}; {spread})")
    else:
        print_plant(ctx, result.plant, "(plant from the training trials)")
    _print_study(ctx, result)
    if output is not None:
        result.save_tables(output)
        ctx.say(f"wrote {'standard output' if ctx.stdio.writes_stdout else output}")


def _holdout_study(ctx: Context, ds: Any, *, bootstrap: int = 0, power: int = 0, trials: str = "") -> tuple[Any, bool]:
    """The study of ``evaluate`` and ``report`` (one rule, so both print the same numbers for the same data):
    ``--holdout`` picks one random split or leave-one-segment-out; auto keeps the test trials a collected session
    recorded, else leaves one out where a label has fewer than :data:`~workbench.study.pipeline.LOSO_BELOW`
    trials, and evaluates one manual segment by a time split inside it. Returns the result (which says which
    trials it held out and why, and ``trials``: which were used) and whether it left one out."""
    from dataclasses import replace

    from workbench.study import pipeline as study

    a = ctx.args
    pieces = len(ds) == 1
    if pieces:  # one manual segment: leave-one-segment-out would have nothing to train on
        duration = float(ds[0].t[-1] - ds[0].t[0])
        ds = study.split_in_time(ds, steps_of(a.horizon_s, ds.dt))
        ctx.say(f"one manual segment ({duration:.1f} s): evaluated by a time split inside it, {len(ds)} contiguous "
                "pieces each scored by models and a plant fitted on the others (parts of one flight, not "
                "independent trials)")
    rollout_budget(a.samples, steps_of(a.horizon_s, ds.dt))
    smallest = min(len(ds.by_label(lbl)) for lbl in ds.labels) if ds.labels else len(ds)
    # a collected session declares its test trials (the protocol's test blocks, held-out trials): auto keeps them
    recorded = recorded_test_ids(ds) if a.holdout == "auto" else None
    loso = recorded is None and (a.holdout == "loso" or (a.holdout == "auto" and smallest < study.LOSO_BELOW))
    if recorded is not None:
        ctx.say(f"test trials as recorded: the {len(recorded)} with role test; the other {len(ds) - len(recorded)} "
                "train")
    elif a.holdout == "auto" and any(d.meta.get("role") is not None for d in ds):
        # a session that recorded its test trials, but not for every strategy among the trials used: said, not hidden
        ctx.say(f"the recorded test trials are not used: {unrecorded_split(ds)}; the test trials are chosen as "
                "for data without a recording")
    # a split study's strategies are independent tasks (run side by side on local processes, as in report and demo)
    with ctx.executor(local_tasks=0 if loso else len(ds.labels)) as ex:
        if loso:
            # the pieces of one segment are said above; "over 3 segments" after "one manual segment" contradicted it
            if not pieces:
                ctx.say(f"leave-one-segment-out over {len(ds)} segments (each scored by models and a plant fitted "
                        "on the others)")
            result = study.run_loso(
                ds, study_plant(a.plant, a.horizon_s), n_steps=steps_of(a.horizon_s, ds.dt),
                n_components=a.n_components,
                samples=a.samples, seed=a.seed, progress=ctx.progress, executor=ex, stride_s=a.stride_s,
                task=getattr(a, "task", None),
            )
        else:
            result = study.run_study(
                ds, study_plant(a.plant, a.horizon_s), test_size=a.test_size, n_steps=steps_of(a.horizon_s, ds.dt),
                n_components=a.n_components, samples=a.samples, efficiency=a.efficiency, repeats=a.repeats,
                seed=a.seed, progress=ctx.progress, executor=ex, stride_s=a.stride_s, bootstrap=bootstrap,
                power=power, test_ids=recorded, task=getattr(a, "task", None),
            )
    if recorded is not None:
        result = replace(result, holdout=study.holdout_text(
            result.test, "those the session recorded with role test (the protocol's test trials; the models were "
            "trained on the trials recorded with role train)"))
    return replace(result, trials=trials), loso


def _evaluate_per_subject(ctx: Context, ds: Any, source: Any, output: Path | None) -> int:
    from rich.markup import escape
    from rich.table import Table

    from workbench.models.factory import METHOD_TITLES, make_models
    from workbench.study import evaluate
    from workbench.study.paired import paired_differences
    from workbench.study.pipeline import verdicts

    a = ctx.args
    components = 5 if a.n_components == "bic" else a.n_components
    plant = study_plant(a.plant)
    subjects = sorted({str(d.meta.get("subject")) for d in ds if d.meta.get("subject") is not None})
    seed = a.seed
    # a collected session declares its test trials: auto keeps them here too, as for the split study
    recorded = recorded_test_ids(ds, by="subject") if a.holdout == "auto" else None
    if recorded is not None:
        ctx.say(f"test trials as recorded: the {len(recorded)} with role test; the other {len(ds) - len(recorded)} "
                "train")
    elif a.holdout == "auto" and any(d.meta.get("role") is not None for d in ds):
        # a session that recorded its test trials, but not for every subject among the trials used: said, not hidden
        ctx.say(f"the recorded test trials are not used: {unrecorded_split(ds, by='subject')}; {a.n_test} held-out "
                "trial(s) are drawn at random instead")
    per = "subject and strategy" if len(ds.labels) > 1 else "subject"
    if len(ds.labels) > 1:
        ctx.say(f"a model per subject and strategy ({', '.join(ds.labels)}): each strategy's models are fitted and "
                "tested on its own trials; a subject's score averages its strategies' held-out trials")
    with ctx.executor() as ex, ctx.progress() as progress:
        task = progress.add_task(f"a model per {per} ({len(subjects)} subjects)", total=len(subjects))
        res = evaluate.per_subject(
            # each subject's plant from its training trials only, never from the held-out ones
            lambda train: make_models(plant(train), n_components=components, random_state=seed,
                                      task=getattr(a, "task", None)), source,
            n_test=a.n_test,
            n_steps=steps_of(a.horizon_s, ds.dt), seed=a.seed,
            progress=lambda done, total: progress.update(task, completed=done), executor=ex, test_ids=recorded,
        )
    for failure in res.failures:
        ctx.warn(f"{failure}")
    table = Table("subject", *[METHOD_TITLES.get(m, m) for m in res.groups],
                  title=f"per-subject {res.metric} ({'the recorded test trials' if recorded is not None else a.n_test}"
                        f" held-out trial(s) per {per}, {a.horizon_s:g} s horizon)")
    for i, subject in enumerate(res.subjects):
        table.add_row(subject, *[f"{g[i]:.4g}" for g in res.groups.values()])
    ctx.say(table)
    _print_anovas(ctx, res, METHOD_TITLES)
    paired = paired_differences(res.table.assign(label=""), res.metric,
                                subjects={str(t): str(s) for t, s in zip(res.table["trial"], res.table["subject"],
                                                                          strict=True)}, seed=a.seed)
    for d in paired:
        ctx.say(f"proposed vs {METHOD_TITLES.get(d.baseline, d.baseline)}: {d.sentence()} ({d.n_trials} held-out "
                f"trials; bootstrap over {d.resampled})")
    for line in verdicts(paired, res.metric):
        ctx.say(f"[bold]{escape(line)}[/bold]", markup=True)
    if output is not None:
        atomic_write_table(res.table, output)
        ctx.say(f"wrote {'standard output' if ctx.stdio.writes_stdout else output}")
    return 0


def _print_anovas(ctx: Context, res: Any, titles: dict[str, str]) -> None:
    """Ours (methods within subjects) and the paper's (methods as independent groups) side by side, labelled,
    with the difference between them said once."""
    def named(r: Any) -> str:
        return str(r).replace(f"{r.a} vs {r.b}", f"{titles.get(r.a, r.a)} vs {titles.get(r.b, r.b)}", 1)

    rm = res.rm_anova
    ctx.say(f"ours: {rm} (methods are a within-subject factor: every subject is scored under each)")
    ctx.say("  paired t-tests over subjects (Holm-corrected):")
    for r in res.ttests.values():
        ctx.say(f"    {named(r)}")
    paper = res.paper_anova
    if paper is None:
        return
    names = ", ".join(titles.get(m, m) for m in paper.groups)
    ctx.say(f"the paper's analysis, as the paper ran it: {paper} ({names}; the paper reported F(2, 27) = 4.55, "
            "p = 0.02, η² = 0.25 for its 10 subjects)")
    ctx.say("  pairwise two-sample Student t-tests, methods as independent groups (Holm; the paper names no "
            "correction), mean differences with 95 % intervals:")
    for r in res.paper_ttests.values():
        ctx.say(f"    {named(r)}")
    ctx.say(f"the difference: the paper's ANOVA treats each method's {len(res.subjects)} subjects as "
            f"{len(paper.groups)} independent groups (F({paper.df_between:g}, {paper.df_within:g})); every subject "
            f"was scored by every method, so ours compares the methods within subjects (F({rm.df_num:g}, "
            f"{rm.df_den:g})), which takes the subjects' own spread out of the error, and it includes "
            + ", ".join(titles.get(m, m) for m in res.groups if m not in paper.groups)
            + "; where the two disagree, the within-subject test is the one this design supports")


#: The head lines of the statistics' blocks a terminal prints in its own form (:func:`_print_statistics`): what
#: answers which question as a legend, the proposed model's settings as a table
_LEGEND_HEAD = "Which number answers which question:"
_SETTINGS_HEAD = "The proposed model's settings"


def _print_study(ctx: Context, result: Any, report: Path | None = None) -> None:
    from rich.markup import escape

    from workbench.models.registry import METHOD_TITLES
    from workbench.study.scores import cell as score_cell
    from workbench.study.scores import heldout_scores

    # the first answer: each method's held-out error with its interval (the numbers the first view shows; a
    # rollout that diverged is said instead, workbench.study.divergence)
    scores = heldout_scores(result.table)
    rows = []
    for (label, method), g in scores.groupby(["label", "method"], sort=False):
        cell = {r.metric: score_cell(r) for r in g.itertuples(index=False)}
        if (g["note"] != "").any():  # a diverged rollout: its ρ̂ once, in the first column, the others say the word
            cell = {m: "diverges" if c.startswith("diverges") and m != "rmse_position" else c for m, c in cell.items()}
        rows.append([label, METHOD_TITLES.get(method, method), cell.get("rmse_position", "—"),
                     cell.get("rmse_velocity", "—"), cell.get("band_position", "—"), str(int(g["n_trials"].max()))])
    if rows:
        ctx.say_table(["label", "method", "position RMSE", "velocity RMSE", "MC band", "trials"], rows,
                      title="held-out prediction error (mean of trials [95 % interval])")
    _print_inputs(ctx, result.table)
    # the methods' differences are the statistics' tables below, each saying which comparison it is: a percentage
    # here, beside two means it does not compare, read as their ratio (issue 38)
    if result.coverage is not None and len(result.coverage):
        # "inside 1σ [%] (nominal 68.3)" → "1σ (68.3)": the title says the rest, and the header stays one line
        head = [re.sub(r"inside (\S+) \[%\] \(nominal ([\d.]+)\)", r"\1 (\2)", str(c)) for c in result.coverage.columns]
        ctx.say_table(head, [[f"{v:.1f}" if isinstance(v, float) else str(v) for v in row]
                             for row in result.coverage.itertuples(index=False)],
                      title="ŵ inside GMR bands [%] (nominal)")
    check = getattr(result, "calibration_check", None)
    if check is not None and len(check):
        from workbench.study.calibration import check_table

        # the terminal's columns; the report's table (and its CSV) holds every count
        shown = check_table(check).drop(columns=["inside [%]"]).rename(columns={
                                                   "inside, limits excluded [%]": "inside [%]",
                                                   "sampling 95 % range [%] (N_eff)": "95 % range [%] (N_eff)"})
        keep = [c for c in ("label", "input", "band", "nominal [%]", "inside [%]", "95 % range [%] (N_eff)",
                            "calibration") if c in shown.columns]
        shown = shown[keep]
        ctx.say_table(list(shown.columns), [[str(v) for v in row] for row in shown.itertuples(index=False)],
                      title="one-step calibration (inputs at a limit left out)")
    _print_efficiency(ctx, result)
    if result.stats_text:
        _print_statistics(ctx, result, report)
    _print_objective_comparison(ctx, result, report)
    for line in result.verdicts():
        ctx.say(f"[bold]{escape(line)}[/bold]", markup=True)


def _print_inputs(ctx: Context, table: Any) -> None:
    """Each method's held-out error in predicting the pilot's own input, against the models with no pilot, and the
    headline sentences that name the no-pilot model they compare with."""
    from workbench.study.input_prediction import input_differences, input_scores, title
    from workbench.study.scores import cell as score_cell

    scores = input_scores(table)
    if scores.empty:
        return
    rows = []
    for (label, method), g in scores.groupby(["label", "method"], sort=False):
        cell = {r.metric: score_cell(r) for r in g.itertuples(index=False)}
        rows.append([label, title(method), cell.get("input_step", "—"), cell.get("input_horizon", "—")])
    ctx.say_table(["label", "method", "one step ahead", "over the horizon"], rows,
                  title="held-out error predicting the pilot's input (RMS over inputs, mean [95 %])")
    # the headline sentences as a table: the two means are the rows above, the difference is the paired one
    diffs = input_differences(table)
    if diffs:
        ctx.say_table(["label", "ahead", "proposed vs", "difference [95 % interval]"],
                      [[label, "one step" if metric == "input_step" else "horizon", title(ref), d.sentence()]
                       for label, metric, ref, d in diffs],
                      title="proposed vs the better model with no pilot (paired)")


def _print_statistics(ctx: Context, result: Any, report: Path | None) -> None:
    """The statistics' text (:meth:`workbench.study.findings.StudyStatistics.text`) with two blocks in a terminal's
    form: which number answers which question as a legend of one line per question, its full text in the report
    (``demo``, ``report``) or with ``--explain``; and the proposed model's settings as a table (one row per
    strategy, where a bullet each took five lines at 80 columns)."""
    stats = getattr(result, "statistics", None)
    explain = bool(getattr(ctx.args, "explain", False))
    block: list[str] = []
    lines = result.stats_text.splitlines()
    i = 0
    while i < len(lines):
        head = lines[i]
        legend = head.startswith(_LEGEND_HEAD) and stats is not None and not explain
        settings = head.startswith(_SETTINGS_HEAD) and _settings_rows(result)
        if not (legend or settings):
            block.append(head)
            i += 1
            continue
        if block:
            ctx.say_markdown("\n".join(block))
            block = []
        i += 1
        while i < len(lines) and lines[i].strip():  # the block runs to the next blank line
            i += 1
        if legend:
            _print_legend(ctx, stats, report)
        else:
            _print_settings(ctx, result)
    if block:
        ctx.say_markdown("\n".join(block))


def _print_legend(ctx: Context, stats: Any, report: Path | None) -> None:
    """Which number answers which question, a line each (:meth:`~workbench.study.findings.StudyStatistics.legend`),
    and where it is said at length."""
    ctx.say(_LEGEND_HEAD)
    pairs = stats.legend()
    width = max((len(q) for q, _ in pairs), default=0)
    for question, how in pairs:
        ctx.say(f"  {question:<{width}}  {how}")
    ctx.say("  A difference is stated only where its interval excludes 0.")
    ctx.say(f"  (at length: {report}, \"Statistics of the comparison\")" if report is not None else
            "  (at length: --explain)")


def _settings_rows(result: Any) -> list[list[str]]:
    """Per strategy, the proposed model's settings where cross-validation chose them (the rows of
    :func:`_print_settings`)."""
    rows = []
    for label, model in result.models.items():
        auto = model.auto_ if model.chooses_settings else None
        if auto is None:
            continue
        best = next((r for r in auto.scores if r.get("chosen")), None)
        scored = best is not None and auto.ioc_only_rmse == auto.ioc_only_rmse
        rows.append([str(label), str(auto.n_components), f"{auto.reg_covar:g}",
                     f"{best['heldout_rmse']:.4g} vs {auto.ioc_only_rmse:.4g}" if scored else "—",
                     f"{auto.gain:.2g} ± {auto.gain_se:.2g}" if auto.gain == auto.gain else "—",
                     _predicts_with(auto)])
    return rows


def _predicts_with(auto: Any) -> str:
    """What the proposed model predicts with, and where it fell back to ``K̂x`` because its fit on all trials
    predicted them worse than ``K̂x`` alone (:meth:`~workbench.models.autoconfig.AutoSettings.describe`), the two."""
    if not auto.fallback:
        return "K̂x + GMR"
    fitted, alone = getattr(auto, "fitted_rmse", math.nan), getattr(auto, "fitted_ioc_rmse", math.nan)
    return f"K̂x alone (fitted on all: {fitted:.4g} vs {alone:.4g})" if fitted > alone else "K̂x alone"


def _print_settings(ctx: Context, result: Any) -> None:
    """The proposed model's settings as a table: what cross-validation chose, its held-out rollout error against
    IOC-only's, the per-trial margin with its standard error, and what the model predicts with (``K̂x`` alone where
    the variability model did not earn its place; it then keeps it for the input band)."""
    autos = [m.auto_ for m in result.models.values() if m.chooses_settings and m.auto_ is not None]
    folds = {f"{a.folds}-fold CV ({a.criterion})" for a in autos}
    ctx.say_table(["strategy", "G", "reg_covar", "rollout RMSE vs IOC-only", "below it ± SE", "predicts with"],
                  _settings_rows(result), title=f"the proposed model's settings, by {', '.join(sorted(folds))}")


def _print_efficiency(ctx: Context, result: Any) -> None:
    """The data-efficiency curve: the mean held-out error of each method by the number of training demonstrations,
    computed as the report's table (:func:`workbench.report.tables.efficiency_means`); its last row per strategy is the
    comparison's own models, the numbers of the table above."""
    from workbench.models.registry import METHOD_TITLES
    from workbench.report.tables import efficiency_means
    from workbench.study.pipeline import metric_unit

    eff = getattr(result, "efficiency", None)
    if eff is None or not len(eff):
        return
    means = efficiency_means(eff)
    methods = [c for c in means.columns if c not in ("label", "n_train")]
    metric = str(eff["metric"].iloc[0]) if "metric" in eff else "rmse_position"
    plant = next((m.plant for m in result.models.values() if getattr(m, "plant", None) is not None), None)
    unit = metric_unit(plant, metric) if plant is not None else ""
    what = metric.removeprefix("rmse_").replace("_", " ")
    ctx.say_table(["label", "n", *[METHOD_TITLES.get(m, m) for m in methods]],
                  [[str(r["label"]), str(int(r["n_train"])), *[f"{r[m]:.3g}" for m in methods]]
                   for _, r in means.iterrows()],
                  title=f"data efficiency: mean {what} RMSE{f' [{unit}]' if unit else ''} by n training trials")


def _print_objective_comparison(ctx: Context, result: Any, report: Path | None = None) -> None:
    """What the data identify about the task objective first (factors between strategies, then ratios), then every
    weight ratio per strategy with its interval or why it has none, and each part's structure check."""

    from workbench.study.power import LAW
    from workbench.study.weights import (
        NOT_EXPLAINED,
        compare_strategies,
        format_interval,
        gain_contrasts,
        identified_first,
    )

    objectives = getattr(result, "objectives", {})
    ratios = {lb: oi.ratios for lb, oi in objectives.items() if oi.ratios is not None}
    if not ratios:
        return
    table = getattr(result, "ratio_comparison", None)  # computed once by the study, shared with the report
    if table is None:
        table = compare_strategies(ratios)
    first = next(iter(ratios))
    found = identified_first(table)
    ctx.say("what the data identify about the task objective (95 % intervals within ×10):"
            + ("" if found else " nothing"))
    for line in found:  # one per line: a list read down, not a paragraph of semicolons
        ctx.say(f"  {line}")
    head = ["ratio", "strategy", "estimate [95 % interval]", f"× vs {first}", "note"]
    rows = []
    footnotes: dict[str, int] = {}
    for r in table.itertuples():
        factor = getattr(r, "factor", float("nan"))
        note = r.note if r.strategy == first else (r.factor_note or r.note)
        if note and note.startswith(NOT_EXPLAINED):  # its mismatch is the part's, printed once under the table
            note = NOT_EXPLAINED
        elif note and ": " in note:
            # the verdict in the table, its reason once under it: twelve rows repeating a sentence were 70 lines
            # at 80 columns
            word, why = note.split(": ", 1)
            note = f"{word} [{footnotes.setdefault(why, len(footnotes) + 1)}]"
        rows.append([r.ratio, str(r.strategy), format_interval(r.estimate, r.lo, r.hi),
                     "" if factor != factor else format_interval(factor, r.factor_lo, r.factor_hi), note or ""])
    ctx.say_table(head, rows, title="task-objective weight ratios inside coupled parts (diagonal cost, S = 0)")
    for why, k in footnotes.items():
        ctx.say(f"  [{k}] {why}")
    contrasts = gain_contrasts(table)
    if contrasts:  # the gains compare where a weight that barely moves them does not
        ctx.say_table(list(contrasts[0]), [list(c.values()) for c in contrasts],
                      title=f"gain K̂[u, s] between strategies beside Q_s / R_u (Fieller {ratios[first].ci:g} %, "
                            "over trials)")
    # each part's structure check once, for every strategy it reads the same for
    fits: dict[str, list[str]] = {}
    for lb, wr in ratios.items():
        for f in wr.fits:
            fits.setdefault(f.describe(), []).append(str(lb))
    for said, labels in fits.items():
        ctx.say(f"  {', '.join(labels)}: {said}")
    if report is not None:  # the report explains the estimates and notes at length
        ctx.say(f"(how the estimates, intervals and notes are made: {report}, \"Weight ratios inside coupled parts\")")
        return
    ctx.say("(estimates: the diagonal cost closest to the bias-corrected gain, profile intervals simultaneous per "
            "part; \"not of this form\": no diagonal cost within the gain's spread, the row gives the closest one "
            "with sandwich intervals, the part's mismatch above; \"not identifiable\": wider than ×10, with the "
            "demonstrations a simulated power curve (n/2, n, 2n; at least 3 sets each, more until monotone) says "
            "would make it narrower than ×2, with its 90 % interval; the report says how: " + LAW.split(",")[0] + ")")


def cmd_report(ctx: Context) -> int:
    a = ctx.args
    refuse_stdio(a.output, "-o", "a report is a folder (report.md and its figures), not one file")
    got = ctx.read(resolve(a, ctx.stdio, a.demos, purpose="study"))
    parts, said = plant_group_parts(got.demos, getattr(a, "plant_group", None))
    if said:
        ctx.say(said)
    trials = got.selected.describe()
    # one plant group: the report in -o; several: a report of each in -o/GROUP/, each titled with its group
    return for_each_group(ctx, parts, "reported", lambda group, part: _report_group(
        ctx, part, Path(a.output) if len(parts) == 1 else Path(a.output) / str(group).replace(" ", "-"),
        a.title if group is None else f"{a.title} (plant group {group})", trials))


def _report_group(ctx: Context, ds: Any, folder: Path, title: str, trials: str) -> None:
    from workbench.report.markdown import write_study_report

    a = ctx.args
    # evaluate's holdout rules, so both commands score a flight the same way (leave-one-segment-out on a few
    # segments) and print the same numbers
    result, loso = _holdout_study(ctx, ds, bootstrap=a.bootstrap, power=a.power, trials=trials)
    print_plant(ctx, result.plant, "(plants fitted without each left-out segment)" if loso
                else "(plant from the training trials)")
    require_proposed(result)
    path = write_study_report(result, folder, title=title)
    _print_study(ctx, result, path)
    ctx.say(f"wrote {path} with figures in {folder / 'figures'}")


#: What the demo needs after its study (the report, the recording, the models its workers send back): imported by a
#: thread while this process waits for the workers, instead of before it starts them.
_AFTER_STUDY = ("workbench.models.factory", "workbench.report.markdown", "workbench.viewer", "workbench.study.findings")
#: What the demo's worker processes import for their tasks (a strategy, a method-level split), imported once by the
#: server they are forked from while the demo reads the logs (:func:`workbench.study.executor.warm_local_workers`).
_WORKER_MODULES = ("workbench.study.pipeline", "workbench.study.method_level", "workbench.study.weights",
                   "workbench.study.power", "workbench.models.factory", "workbench.method.inverse_lqr_sdp",
                   "workbench.method.timing", "sklearn.cluster", "scipy.optimize")


def _import_in_background(modules: Sequence[str]) -> threading.Thread:
    """Import ``modules`` in a daemon thread (a module's first import is then shared, not repeated)."""

    def run() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 - the real import later raises it where it can be reported
                return

    thread = threading.Thread(target=run, name="workbench-preload", daemon=True)
    thread.start()
    return thread


def demo_logs(folder: Path) -> list[Path]:
    """The files ``demo --logs FOLDER`` imports, sorted: every declared log format's files and demonstration files
    (:data:`adapters.batch.LOG_SUFFIXES`), not hidden ones; none for a folder that does not exist."""
    from adapters.batch import LOG_SUFFIXES

    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir()
                  if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in LOG_SUFFIXES)


def cmd_demo(ctx: Context) -> int:
    a = ctx.args
    refuse_stdio(a.out, "--out", "the demo writes a folder (report, models, data, recording)")
    refuse_stdio(a.logs, "--logs", "the demo reads a folder of logs")
    t_start = time.perf_counter()
    if getattr(a, "workers", None) is None and getattr(a, "scheduler", None) is None:
        from workbench.study.executor import available_cpus, warm_local_workers

        if available_cpus() >= 2:  # the study will run on local workers: their imports run beside the logs' import
            warm_local_workers(_WORKER_MODULES)
    out = Path(a.out)
    if out.is_dir():
        recover_swaps(out, "demo")  # what a killed run left half done is undone before anything else
    logs = Path(a.logs) if a.logs else _as_given(SAMPLE_LOGS)
    files = demo_logs(logs)
    if not files:
        if a.logs:
            from adapters.batch import LOG_SUFFIXES

            raise DataError(f"{logs}: no logs ({', '.join(LOG_SUFFIXES)}) to import")
        from workbench.cli.sample_logs import write_sample_logs

        logs = out / "sample_logs"
        ctx.say(f"{SAMPLE_LOGS} is empty; generating the sample logs into {logs}")
        write_sample_logs(logs, seed=0)
        files = demo_logs(logs)
    # the interpreter and the command's modules before this function: part of what a user waits for
    timings = {"startup": _seconds_since_process_start(t_start)}
    t0 = time.perf_counter()
    ds = ctx.read(resolve(a, ctx.stdio, [str(f) for f in files], purpose="study")).demos
    timings["import"] = time.perf_counter() - t0
    rollout_budget(a.samples, steps_of(a.horizon_s, ds.dt))
    by_format: dict[str, int] = {}
    for f in files:
        by_format[f.suffix.lstrip(".")] = by_format.get(f.suffix.lstrip("."), 0) + 1
    ctx.say(
        f"imported {len(ds)} demonstrations ({ds.n_samples} samples; labels "
        f"{', '.join(map(str, ds.labels)) or 'none'}) from {len(files)} logs "
        f"({', '.join(f'{v} {k}' for k, v in by_format.items())}) in {logs}"
    )
    out.mkdir(parents=True, exist_ok=True)
    # One transaction: the whole result set is built beside the old one and swapped in at the end, so a stopped
    # or killed demo leaves the previous run's set whole (never new data beside an old report).
    build = temp_sibling(out / "demo")
    build.mkdir()
    try:
        status = _demo_into(ctx, ds, out, build, timings, t_start)
    finally:
        if build.exists():
            shutil.rmtree(build, ignore_errors=True)
    return status


def _demo_into(ctx: Context, ds: Any, out: Path, build: Path, timings: dict[str, float], t_start: float) -> int:
    from workbench.study import pipeline as study

    a = ctx.args
    t0 = time.perf_counter()
    ds.save(build / "demos.parquet")
    timings["files"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    with ctx.executor(local_tasks=len(ds.labels)) as ex:
        preload = _import_in_background(_AFTER_STUDY) if ex.parallel else None
        result = study.run_study(
            ds, study_plant(a.plant), test_size=a.test_size, n_steps=steps_of(a.horizon_s, ds.dt),
            n_components=a.n_components, samples=a.samples, efficiency=a.efficiency, repeats=a.repeats, seed=a.seed,
            progress=ctx.progress, bootstrap=a.bootstrap, stride_s=a.stride_s, power=a.power, executor=ex,
        )
        workers = ex.workers if ex.parallel else 1
    from workbench.study.executor import stop_local_workers

    stop_local_workers()  # the workers' server, if the demo started one: no longer needed
    if preload is not None:
        preload.join()
    study_s = time.perf_counter() - t0
    if workers > 1:
        # the strategies ran side by side: their phases add up to process time, not to the wall time of the study
        parts = ", ".join(f"{k} {v:.1f}" for k, v in _study_phases(result.timings, 0.0).items())
        timings[f"study on {workers} processes [{parts} s of process time]"] = study_s
    else:
        timings.update(_study_phases(result.timings, study_s))
    require_proposed(result)
    t0 = time.perf_counter()
    model_dir = out / "models"
    for label, model in result.models.items():
        model.save(build / "models" / f"{label}.npz")
    result.save_tables(build / "results.csv")
    timings["files"] += time.perf_counter() - t0
    from rich.markup import escape

    from workbench.report.markdown import write_study_report
    from workbench.viewer import record_study

    t1 = time.perf_counter()
    write_study_report(result, build, title="Workbench demo: sample logs", vector=False)  # PNG: the budget
    timings["report"] = time.perf_counter() - t1
    rrd = out / "demo.rrd"
    t1 = time.perf_counter()
    record_study(result, build / rrd.name, progress=ctx.progress)
    timings["recording"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    swap_entries(build, out, "demo")
    report = out / "report.md"
    timings["files"] += time.perf_counter() - t1
    t1 = time.perf_counter()
    _print_study(ctx, result, report)
    ctx.say("")
    rows = [
        ("report", f"{report}  (figures in {out / 'figures'})"),
        ("recording", f"{rrd}   open it with:  {viewer_command(rrd)}"),
        ("models", ", ".join(str(model_dir / f"{k}.npz") for k in result.models)),
        ("data", f"{out / 'demos.parquet'}, {out / 'results.csv'}"),
    ]
    for key, value in rows:
        ctx.say(f"[bold]{key:<10}[/bold] {escape(value)}", markup=True)
    timings["tables"] = time.perf_counter() - t1
    total = time.perf_counter() - t_start + timings["startup"]
    # whatever no phase above measured (argument checks, listing the logs): shown, so the parts add up to the total
    timings["other"] = max(0.0, total - sum(timings.values()))
    parts = ", ".join(f"{k} {v:.1f} s" for k, v in timings.items())
    ctx.say(f"done in {total:.1f} s ({parts})")
    return 0


def _as_given(path: Path) -> Path:
    """``path`` as a user in the current folder would type it (``sample_logs``), the absolute path elsewhere: the
    demo's default folder printed the way a given one is, not as ``/work/…/sample_logs``."""
    try:
        rel = Path(os.path.relpath(path))
    except ValueError:  # another drive
        return path
    return path if rel.parts[:1] == ("..",) else rel


def _seconds_since_process_start(now: float) -> float:
    """Seconds from this process's start to ``now`` (a ``perf_counter`` reading): Linux's ``/proc/self/stat``
    start time against the boot clock; 0 where that cannot be read."""
    try:
        with open("/proc/self/stat") as f:
            start_ticks = int(f.read().rsplit(")", 1)[1].split()[19])
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
        ticks = os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return 0.0
    return max(0.0, uptime - (time.perf_counter() - now) - start_ticks / ticks)


def _study_phases(timings: dict[str, float], total: float) -> dict[str, float]:
    """The study's own phase times (``StudyResult.timings``, per label) summed over labels: fit, compare, data
    efficiency, objective intervals, ratio comparison; what they leave out of ``total`` (the split, the plant,
    statistics) is added to the fit."""
    phases: dict[str, float] = {}
    for key, seconds in timings.items():
        phase = key.split(" ")[0] if key.split(" ")[0] in ("fit", "compare", "efficiency") else key
        phases[phase] = phases.get(phase, 0.0) + seconds
    phases["fit"] = phases.get("fit", 0.0) + max(0.0, total - sum(phases.values()))
    return {("data efficiency" if k == "efficiency" else k): v for k, v in phases.items()}
