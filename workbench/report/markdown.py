"""The workbench's report: one Markdown file with figures in the spirit of the method paper's, and its tables.

It opens with the held-out prediction error of every method (:mod:`workbench.study.scores`) and how the test
trials were chosen. Every figure is written as PNG (for the Markdown) and as SVG and PDF beside it, sized for one
or two journal columns with print-sized text (:data:`PAPER_RC`); every statistics table also as CSV and LaTeX
under ``tables/``. Figures (``figures/`` beside the report), each drawn on a matplotlib
:class:`~matplotlib.figure.Figure` with the Agg canvas — no pyplot, no global backend, so the report runs headless
and never touches a user's session:

* ``demonstrations.png`` — the flown paths per strategy;
* ``objective.png`` — the contrasts of the task objective the data identify, with their intervals;
* ``variability.png`` — ŵ on a test trial with the GMR mean and 3σ band (eqs. (24)–(27));
* ``calibration.png`` — one-step band coverage against the Gaussian nominal at 0.25σ … 3σ (the calibration curve);
* ``predictions.png`` — predicted vs recorded trajectories of the three methods, with the Monte Carlo band;
* ``rmse.png`` — per-trial horizon RMSE (eq. (35)) per method as box plots, a trial's methods joined by a line;
* ``data_efficiency.png`` — RMSE against the number of training demonstrations;

and the comparison's statistics: method-level differences over refitted splits (the headline), paired differences of
the fitted models with bootstrap intervals over whole trials, exact sign-flip tests (Holm over the headline's rows)
and the mixed model's strategy terms (:mod:`workbench.study.findings`).
"""

from __future__ import annotations

import dataclasses
import os
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.atomic import (
    atomic_write_text,
    deferred_interrupt,
    remove_leftovers,
    temp_sibling,
)
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.models.registry import METHOD_TITLES
from workbench.report.contrasts import objective_figure
from workbench.report.figure_files import save_figure, vector_figures
from workbench.report.figures import (  # the figures live in their own module; their names are kept here
    COLUMN_WIDTH,
    DOUBLE_WIDTH,
    METHOD_COLORS,
    PAPER_RC,
    _label_color,
    _metric_words,
    _plane,
    fig_calibration,
    fig_data_efficiency,
    fig_demonstrations,
    fig_objective,
    fig_predictions,
    fig_rmse,
    fig_variability,
)
from workbench.report.tables import efficiency_means, save_table, scores_section, why_no_statistics
from workbench.report.tables import md_table as _md_table
from workbench.study.pipeline import StudyResult, improvement_table, metric_unit

__all__ = [
    "ReportInputs",
    "fig_data_efficiency",
    "fig_demonstrations",
    "fig_objective",
    "fig_calibration",
    "fig_predictions",
    "fig_rmse",
    "fig_variability",
    "write_report",
    "COLUMN_WIDTH",
    "DOUBLE_WIDTH",
    "METHOD_COLORS",
]



# -- the report -------------------------------------------------------------------------------------------
@dataclass
class ReportInputs:
    """Everything the report shows, computed by the caller (the CLI) so figures and numbers agree.

    ``models[label]`` is the proposed model per strategy; ``baselines[label]`` maps method → model;
    ``train``/``test`` the demonstrations per label; ``rmse`` a tidy table (label, method, metric, value, …);
    ``efficiency`` a tidy table (label, method, n_train, value); ``coverage`` a table per label and input;
    ``stats`` Markdown of a multi-subject test; ``notes`` free lines for the header; ``verdicts`` plain
    sentences saying where the proposed model is not better than IOC-only or persistence (shown first).
    """

    train: Mapping[str, DemonstrationSet]
    test: Mapping[str, DemonstrationSet]
    models: Mapping[str, Any]
    baselines: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    rmse: pd.DataFrame | None = None
    efficiency: pd.DataFrame | None = None
    coverage: pd.DataFrame | None = None
    band: pd.DataFrame | None = None
    stats: str | None = None
    n_steps: int = 60
    samples: int = 0
    seed: int = 0
    notes: list[str] = field(default_factory=list)
    title: str = "Workbench report"
    verdicts: list[str] = field(default_factory=list)
    objectives: Mapping[str, Any] = field(default_factory=dict)
    envelope: pd.DataFrame | None = None
    calibration: pd.DataFrame | None = None
    #: :func:`workbench.study.weights.compare_strategies` of the objectives' ratios when the study computed it
    #: (``StudyResult.ratio_comparison``); None computes it here.
    ratio_comparison: pd.DataFrame | None = None
    paired: Sequence[Any] = ()
    calibration_check: pd.DataFrame | None = None
    #: How the test trials were chosen (a random split, leave-one-segment-out): one sentence, shown first.
    holdout: str = ""
    #: Held-out scores (:func:`workbench.study.scores.heldout_scores`) of the comparison table.
    scores: pd.DataFrame | None = None
    #: Why a section has nothing to show, by section ("efficiency", "statistics", …).
    empty: Mapping[str, str] = field(default_factory=dict)
    #: The comparison's rows of the pilot's own input (:mod:`workbench.study.input_prediction`): its section.
    inputs_table: pd.DataFrame | None = None


def write_report(out_dir: str | os.PathLike, inputs: ReportInputs) -> Path:
    """Write ``out_dir/report.md`` and ``out_dir/figures/*.png``; returns the report's path.

    The report is built in a hidden folder inside ``out_dir`` and swapped in with Ctrl-C held back: the old
    ``report.md`` goes first and the new one comes last, so an interrupted run never leaves an old report
    beside new figures (a kill inside the few renames can leave figures without a ``report.md``, never a
    mix); the hidden folders of a killed run are removed by the next one. Other files in ``out_dir`` stay.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    remove_leftovers(out_dir, "report")
    build = temp_sibling(out_dir / "report")
    build.mkdir()
    try:
        import matplotlib

        with matplotlib.rc_context(PAPER_RC):  # text sized for print at a column's width, in every format
            _write_report(build, inputs)
        with deferred_interrupt():
            old = temp_sibling(out_dir / "report", "old")
            old.mkdir()
            # the old report first: never an old report.md beside new figures
            for name in ("report.md", "figures", "tables"):
                if (out_dir / name).exists():
                    os.replace(out_dir / name, old / name)
            # the new report last: its presence says the figures are its own
            for name in ("figures", "tables", "report.md"):
                if name == "report.md" or (build / name).exists():
                    os.replace(build / name, out_dir / name)
        shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(build, ignore_errors=True)
    return out_dir / "report.md"


def _write_report(out_dir: Path, inputs: ReportInputs) -> Path:
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    labels = list(inputs.models)
    any_set = next(iter(inputs.train.values()))
    state_names, input_names, dt = any_set.state_names, any_set.input_names, any_set.dt
    md: list[str] = [f"# {inputs.title}", ""]
    md += [f"- {line}" for line in inputs.notes]
    if inputs.holdout:
        md += [f"- held out: {inputs.holdout}"]
    md += [""]
    md += [f"**{line}**\n" for line in inputs.verdicts]
    plant = inputs.models[labels[0]].plant
    tab_dir = out_dir / "tables"
    tab_dir.mkdir(parents=True, exist_ok=True)
    md += scores_section(inputs, plant, tab_dir)
    if inputs.inputs_table is not None and len(inputs.inputs_table):
        from workbench.study.input_prediction import input_markdown, input_scores

        save_table(input_scores(inputs.inputs_table), tab_dir / "input_scores.csv")
        md += input_markdown(inputs.inputs_table)

    # data
    rows = []
    for label in labels:
        tr, te = inputs.train[label], inputs.test.get(label)
        rows.append({
            "strategy": label,
            "train": len(tr),
            "test": 0 if te is None else len(te),
            "samples": tr.n_samples + (0 if te is None else sum(len(d) for d in te if d.id not in set(tr.ids))),
            "subjects": len({d.meta.get("subject") for d in tr}),
            "sources": ", ".join(sorted({Path(str(d.meta.get("source", "?"))).name for d in tr}))[:80],
        })
    md += ["## Demonstrations", "", _md_table(pd.DataFrame(rows)), ""]
    # leave-one-segment-out trains on every trial and tests each once: the same trials in both sets, drawn once
    all_sets = {label: inputs.train[label].with_demos(
        [*inputs.train[label], *(d for d in inputs.test.get(label, []) if d.id not in set(inputs.train[label].ids))])
        for label in labels}
    save_figure(fig_demonstrations(all_sets), fig_dir / "demonstrations.png")
    md += ["![Demonstrations per strategy](figures/demonstrations.png)", "",
           "*Flown paths per strategy in the plane of the position roles; dots are start points, the bar is the pad "
           "(where known).*" if _plane(any_set.roles, state_names) is not None else
           "*Every state against time per strategy (the plant declares no plane of positions).*", ""]

    # objective
    md += ["## Task objective (inverse LQR)", ""]
    # what each strategy's pilot regulates, relative to what, and its loop's stability with its interval
    tasks = [f"- {lb}: {m.task_.describe(state_names)}"
             + (f"; {m.stability_.describe()}" if getattr(m, "stability_", None) is not None else "")
             for lb in labels if getattr(m := inputs.models.get(lb), "task_", None) is not None]
    md += [*tasks, ""] if tasks else []
    obj_rows = []
    for label in labels:
        model = inputs.models[label]
        o = model.objective_ if model.has_gain else None
        if o is None:
            reason = model.objective_error_ if model.has_gain else None
            if reason:
                obj_rows.append({"strategy": label, "α*": f"not found: {reason}"})
            continue
        names = model.plant_regulated.state_names  # the objective weighs the regulated states
        n = len(names)
        Mn = np.asarray(o.M_normalized)
        oi = inputs.objectives.get(label)
        choice = model.gain_choice_
        row = {"strategy": label, "gain K̂": "" if choice is None else choice.method, "α*": float(o.alpha),
               "forward-gain error": float(o.forward_gain_error)}
        q, r = np.diag(Mn[:n, :n]), np.diag(Mn[n:, n:])
        if oi is None:
            row.update({f"Q {s}": float(v) for s, v in zip(names, q, strict=True)})
            row.update({f"R {s}": float(v) for s, v in zip(input_names, r, strict=True)})
        else:
            b = oi.boot
            row.update({f"Q {s}": f"{v:.3g} [{lo:.3g}, {hi:.3g}]"
                        for s, v, lo, hi in zip(names, q, b.Q_diag_lo, b.Q_diag_hi, strict=True)})
            row.update({f"R {s}": f"{v:.3g} [{lo:.3g}, {hi:.3g}]"
                        for s, v, lo, hi in zip(input_names, r, b.R_diag_lo, b.R_diag_hi, strict=True)})
        obj_rows.append(row)
    if obj_rows:
        md += [_md_table(pd.DataFrame(obj_rows), ".3g"), ""]
        md += _objective_interval_notes(inputs.objectives, labels, state_names, input_names,
                                        inputs.ratio_comparison)
        md += [f"- {lb}: {m.gain_choice_}" for lb in labels if (m := inputs.models[lb]).has_gain] + [""]
    if obj_rows:  # only the contrasts the data identify, with their intervals (workbench/report/contrasts.py)
        md += objective_figure(inputs.objectives, labels, inputs.ratio_comparison, fig_dir / "objective.png",
                               save_figure, {lb: _label_color(lb, labels) for lb in labels}, COLUMN_WIDTH)

    # variability and predictions on one test trial per label
    cases_w, cases_p = {}, {}
    for label in labels:
        te = inputs.test.get(label)
        if te is None or not len(te):
            continue
        demo = te[0]
        model = inputs.models[label]
        if model.has_variability:
            cases_w[label] = (demo, model)
        preds = {"proposed": _predict(model, demo, inputs.n_steps, inputs.samples, inputs.seed)}
        for method, bm in inputs.baselines.get(label, {}).items():
            preds[method] = _predict(bm, demo, inputs.n_steps, 0, inputs.seed)
        cases_p[label] = (demo, preds)
    md += ["## Variability (TP-GMM + GMR)", ""]
    if inputs.coverage is not None and len(inputs.coverage):
        save_table(inputs.coverage, tab_dir / "coverage.csv")
        md += ["One-step coverage of ŵ by the GMR bands on the test trials (`tables/coverage.csv`):", "",
               _md_table(inputs.coverage, ".1f"), ""]
    if inputs.calibration_check is not None and len(inputs.calibration_check):
        from workbench.study.calibration import check_table

        md += ["Calibration at 1σ, 2σ, 3σ: inputs at their limits (the plant's bounds, or a stick pinned at the "
               "extreme of its travel) are censored, not Gaussian, so they are counted apart and the band is "
               "judged without them; it is called too narrow or too wide only where the share inside lies outside "
               "the binomial 95 % range of the nominal share over the effective number of samples (samples within "
               "a trial are correlated: N_eff = N(1 − ρ)/(1 + ρ), ρ the lag-1 autocorrelation of inside/outside).",
               "", _md_table(check_table(inputs.calibration_check)), "",
               "(`tables/calibration_check.csv`: every count and interval)", ""]
        save_table(inputs.calibration_check, tab_dir / "calibration_check.csv")
    if inputs.calibration is not None and len(inputs.calibration):
        save_figure(fig_calibration(inputs.calibration), fig_dir / "calibration.png")
        md += ["![One-step band calibration](figures/calibration.png)", "",
               "*Share of the test trials' inputs inside the model's one-step band μ̂ ± cσ̂ against the share a "
               "Gaussian puts there, for c from 0.25σ to 3σ: on the diagonal the band is calibrated at every level, "
               "below it too narrow.*", ""]
    if cases_w:
        units = {n: any_set.roles.unit(n) for n in input_names} if any_set.roles else {}
        save_figure(fig_variability(cases_w, input_names, units), fig_dir / "variability.png")
        md += ["![Residual variability with GMR bands](figures/variability.png)", "",
               "*ŵ = u − K̂x on a test trial with the GMR mean μ(x) and its ±3σ band (eqs. (24)–(27)).*", ""]
    md += ["## Predictions", ""]
    if cases_p:
        save_figure(fig_predictions(cases_p, state_names, dt, any_set.roles), fig_dir / "predictions.png")
        band = f", shaded: the proposed model's Monte Carlo band ({inputs.samples} rollouts)" if inputs.samples else ""
        md += ["![Predicted vs recorded trajectories](figures/predictions.png)", "",
               f"*{inputs.n_steps * dt:.1f} s predictions from the test trial's start{band}.*", ""]
    if inputs.rmse is not None and len(inputs.rmse):
        metrics = [(m, metric_unit(plant, m)) for m in dict.fromkeys(inputs.rmse["metric"])]
        save_figure(fig_rmse(inputs.rmse, metrics), fig_dir / "rmse.png")
        improvement = improvement_table(inputs.rmse, inputs.paired)
        # a percentage says which comparison it is: the columns beside these means are the methods' differences
        # over refitted splits, not the ratio of the two means they stand next to (issue 38)
        improvement = improvement.rename(columns={c: f"{c} {_which_comparison(inputs.paired)}"
                                                  for c in improvement.columns if str(c).startswith("vs ")})
        save_table(improvement, tab_dir / "comparison.csv")
        md += [_md_table(improvement), "", "(`tables/comparison.csv`)", ""]
        md += _envelope_line(inputs.envelope)
        md += [f"**{line}**\n" for line in inputs.verdicts]
        md += [
               "![RMSE per method](figures/rmse.png)", "",
               "*Horizon RMSE (eq. (35)) per test trial (the mean of its windows, as in the table); boxes: quartiles "
               "over trials; gray lines join one trial's errors across methods, the pairs the statistics compare.*",
               ""]
    if inputs.band is not None and len(inputs.band):
        b = inputs.band.groupby(["label", "metric", "method"], sort=False)["value"].mean().unstack("method")
        b = (100.0 * b).rename(columns=METHOD_TITLES).reset_index()
        save_table(b, tab_dir / "mc_band.csv")
        md += [f"Monte Carlo trajectory bands (5–95 %, {inputs.samples} rollouts): share of the horizon's steps "
               "at which every state of the block lies inside the band [%] (persistence has no band):", "",
               _md_table(b, ".1f"), ""]
    if inputs.efficiency is not None and len(inputs.efficiency):
        what = str(inputs.efficiency["metric"].iloc[0]) if "metric" in inputs.efficiency else "rmse_position"
        save_figure(fig_data_efficiency(inputs.efficiency, metric_unit(plant, what), _metric_words(what)),
                    fig_dir / "data_efficiency.png")
        eff = efficiency_means(inputs.efficiency).rename(columns=METHOD_TITLES)
        save_table(eff, tab_dir / "data_efficiency.csv")
        md += ["## Data efficiency", "", _md_table(eff), "",
               "![Data efficiency](figures/data_efficiency.png)", "",
               f"*Mean {_metric_words(what)} on the test trials against the number of training demonstrations, "
               "scored like the tables above (every window of every test trial, a trial's windows and the random "
               "training subsets drawn at that size averaged, then the mean over trials); error bars: ± one "
               "standard error of that mean over the test trials; the smaller sizes refit the proposed model at "
               "the settings its cross-validation chose on all training trials, its fallback to K̂x included, and the "
               "last size — the whole training set — is the tables' own rows).*", ""]
    elif inputs.empty.get("efficiency"):
        md += ["## Data efficiency", "", f"*None: {inputs.empty['efficiency']}.*", ""]
    md += ["## Statistics of the comparison", ""]
    if inputs.stats:
        md += [inputs.stats, ""]
    if not inputs.paired:
        md += [f"*No paired differences: {inputs.empty.get('statistics') or why_no_statistics(inputs)}.*", ""]
    else:
        # every field the study's paired differences carry, whatever they are (workbench.study.paired owns them)
        rows = [{k: v for k, v in dataclasses.asdict(d).items() if np.ndim(v) == 0} for d in inputs.paired]
        save_table(pd.DataFrame(rows), tab_dir / "paired_differences.csv")
        md += ["(`tables/paired_differences.csv`)", ""]
    path = out_dir / "report.md"
    atomic_write_text(path, "\n".join(md).rstrip() + "\n")
    return path


def _which_comparison(paired: Sequence[Any]) -> str:
    """``"(as methods, over 8 refits)"`` for method-level differences, ``"(these fitted models)"`` for paired ones."""
    first = next(iter(paired), None)
    n = getattr(first, "n_splits", None)
    if n is None:
        return "(these fitted models, on these test trials)"
    design = getattr(first, "design", "random splits")
    if "leave" in str(design):
        return f"(as methods, over {n} leave-one-out folds)"
    return f"(as methods, over {first.splits_count()} refits)"


def _envelope_line(envelope: pd.DataFrame | None) -> list[str]:
    """How many predictions left the envelope of their model's training states (``left_envelope`` rows)."""
    if envelope is None or not len(envelope):
        return []
    counts = envelope.groupby("method", sort=False)["value"].agg(["sum", "count"])
    parts = [f"{METHOD_TITLES.get(m, m)} {int(r['sum'])} of {int(r['count'])}" for m, r in counts.iterrows()]
    return ["Predictions whose mean rollout left the envelope of the training states (the model extrapolates "
            "there): " + ", ".join(parts) + ".", ""]


def _objective_interval_notes(
    objectives: Mapping[str, Any], labels: Sequence[str], state_names: Sequence[str], input_names: Sequence[str],
    table: pd.DataFrame | None = None,
) -> list[str]:
    """What the intervals are, and the weight ratios inside coupled parts compared between strategies."""
    from workbench.study.weights import (
        NOT_EXPLAINED,
        compare_strategies,
        format_interval,
        gain_contrasts,
        identified_first,
    )

    if not objectives:
        return ["*No intervals: the study ran without bootstrap resamples (`--bootstrap 0`); the values above "
                "are point estimates.*", ""]
    first = next(iter(objectives.values())).boot
    md = [f"*In brackets: {first.ci:g} % percentile intervals over {first.n_boot} bootstrap resamples of the "
          "training trials.*", ""]
    ratios = {lb: objectives[lb].ratios for lb in labels if lb in objectives and objectives[lb].ratios}
    if not ratios:
        return md
    if table is None:
        table = compare_strategies(ratios)
    gains = sorted({objectives[lb].ratio_gain for lb in ratios})
    found = identified_first(table)
    md += ["### What the data identify", "",
           *([f"- {line}" for line in found] or ["- no weight ratio and no factor between strategies: every interval "
                                                "below spans more than ×10 or its part is not of the diagonal form"]),
           ""]
    contrasts = gain_contrasts(table)
    if contrasts:
        md += ["### Gain entries compared between strategies", "",
               f"Beside each weight ratio Q_s / R_u, the factor between two strategies' gain entry K̂[u, s] (how hard "
               f"the pilot pushes input u on state s), with Fieller's {first.ci:g} % interval from each entry's "
               "standard error over whole trials (the delete-one-trial jackknife's, as the weight ratios' covariance; "
               "words where the first strategy's entry is not distinguishable from 0 or the interval includes 0). "
               "The gains are "
               "what a fit estimates directly: where a weight barely moves its gain, the ratio's interval has no "
               "upper end while the gains still compare.", "",
               _md_table(pd.DataFrame(contrasts)), ""]
    def once(text: Any) -> Any:  # a part's mismatch is said once, in its part's line under the table
        return f"{NOT_EXPLAINED} (its part's mismatch below)" if str(text).startswith(NOT_EXPLAINED) else text

    rows = []
    for r in table.itertuples():
        note = once(r.note)
        row = {"ratio": r.ratio, "strategy": r.strategy, "estimate [interval]": format_interval(r.estimate, r.lo, r.hi),
               "note": note}
        if len(ratios) > 1:
            factor = getattr(r, "factor", float("nan"))
            first = labels[0] if labels[0] in ratios else next(iter(ratios))
            row[f"× vs {first}"] = "" if not np.isfinite(factor) else format_interval(factor, r.factor_lo, r.factor_hi)
            if r.strategy != first and r.factor_note and once(r.factor_note) != note:
                row["note"] = f"{note}; factor: {once(r.factor_note)}" if note else f"factor: {once(r.factor_note)}"
        rows.append(row)
    fwd = ", ".join(f"{lb} {ratios[lb].forward_gain_error:.2g}" for lb in ratios)
    md += ["### Weight ratios inside coupled parts", "",
           "The cost above is the SDP's minimum-condition-number member and keeps no ratio between strategies. "
           "A cost with S = 0 and diagonal Q, R is unique up to one scale per decoupled part of the plant, so its "
           "ratios inside a part compare between strategies. Each strategy's ratios are those whose LQR gain is "
           f"closest to its estimated gain ({', '.join(gains)}) in the metric of that gain's bootstrap "
           "covariance; the intervals are profile intervals of that distance, and a factor's interval profiles both "
           f"strategies' distances together (forward-gain error of each diagonal cost: {fwd}). "
           "Whether a part is of the diagonal form is tested only where it has overidentifying restrictions (gain "
           "entries beyond its free ratios); a part with none is not tested, and counts as not of this form only "
           "where its estimated gain departs from the closest diagonal cost's by more than its spread in some entry. "
           "For such a part, the row gives that closest cost (the pseudo-true value) with misspecification-robust "
           "(sandwich) intervals and the mismatch per gain entry. An interval wider than ×10 is not identifiable; "
           "the number of demonstrations that would make it narrower than ×2 comes from a power curve simulated "
           "from the fitted model.", "",
           _md_table(pd.DataFrame(rows)), ""]
    md += [f"- {lb}: {f.describe()}" for lb in ratios for f in ratios[lb].fits] + [""]
    curves = {lb: objectives[lb].power for lb in ratios if getattr(objectives[lb], "power", None) is not None}
    for lb, curve in curves.items():
        md += [f"Power curve of {lb} (demonstrations simulated from its fitted model, refitted; interval span by "
               f"number of demonstrations; needed: {curve.law}):", "", *[f"- {line}" for line in curve.describe()], ""]
    return md


def _predict(model: Any, demo: Demonstration, n_steps: int, samples: int, seed: int) -> Any:
    kwargs: dict[str, Any] = {"target": demo.target}
    if samples:
        kwargs.update(samples=samples, seed=seed)
    return model.predict(demo.x[0], n_steps, **kwargs)


def _held_plant_notes(result: StudyResult) -> list[str]:
    """Where the study's plant was held at its physics (the identification report's ``fixed:`` lines of held entries,
    :attr:`~workbench.plant.identification.IdentificationReport.held`): the line itself for one plant; for the folds'
    plants of leave-one-segment-out, each held entry with the number of folds that held it (the comparisons, one per
    fold, are in ``workbench evaluate``'s output)."""
    plants = list(result.plants.values()) if result.plants else [result.plant]
    held = [getattr(getattr(p, "identification", None), "held", ()) for p in plants]
    if len(plants) == 1:
        return [f"plant fixed: {line}" for line in held[0]]
    entries: dict[str, int] = {}
    for lines in held:
        for line in lines:  # "A[xdot, phi] = 0.9807 (g·dt; the free fit's …" → "A[xdot, phi] = 0.9807 (g·dt"
            key = line.split(";")[0].split(" — ")[0]
            entries[key] = entries.get(key, 0) + 1
    return [f"plant fixed: {key.rstrip(')')}) in {k} of the {len(plants)} folds' plants (the free fit failing its "
            "physics check; held where the held-out segments do not show it worse)" for key, k in entries.items()]


def write_study_report(result: StudyResult, out_dir: str | os.PathLike, *, title: str = "Workbench report",
                       vector: bool = True) -> Path:
    """``out_dir/report.md`` with figures under ``out_dir/figures`` (PNG, and SVG and PDF unless not ``vector``)."""
    token = vector_figures.set(vector)
    try:
        return _write_study_report(result, out_dir, title=title)
    finally:
        vector_figures.reset(token)


def _write_study_report(result: StudyResult, out_dir: str | os.PathLike, *, title: str) -> Path:
    notes = [
        f"{len(result.demos)} demonstrations, {result.demos.n_samples} samples, dt = {result.demos.dt:g} s; "
        f"states {', '.join(result.demos.state_names)}; inputs {', '.join(result.demos.input_names)}",
        f"prediction horizon {result.n_steps} steps ({result.n_steps * result.demos.dt:.2f} s); "
        f"{result.samples} Monte Carlo rollouts per band; seed {result.seed}",
    ]
    if getattr(result, "trials", ""):  # which of a collected session's trials were used, and what was left out
        notes.insert(0, result.trials)
    notes += _held_plant_notes(result)
    cov = None
    if result.coverage is not None:
        cov = result.coverage.copy()
        front = [c for c in ("label",) if c in cov.columns]
        cov = cov[front + [c for c in cov.columns if c not in front]]
    from workbench.study.divergence import MARKERS as DIVERGENCE_MARKERS
    from workbench.study.scores import heldout_scores

    n_test = sum(len(te) for te in result.test.values())
    if result.plants:
        holdout = (f"leave-one-segment-out: each of {n_test} trials scored by models (and a plant) fitted on the "
                   "others")
        left = getattr(result, "folds_left_out", ())
        for part, why in (("training", "their training trials could not be fitted"),
                          ("test", "their test trials never move")):  # the verdicts name each with its cause
            these = [f for f in left if getattr(f, "part", "training") == part]
            if these:
                holdout += (f"; {len(these)} of {n_test + len(left)} folds left out, {why} ("
                            + ", ".join(f"fold {f.index}, testing {f.trial}" for f in these) + ")")
    else:  # how the study chose them (recorded test trials, or drawn at random), with their ids
        holdout = getattr(result, "holdout", "") or (f"{n_test} test trial(s) chosen at random (seed {result.seed}); "
                                                     "the models never saw them")
    empty = {}
    if result.efficiency is None:
        empty["efficiency"] = ("leave-one-segment-out has no data-efficiency curve (each fold trains on all other "
                               "trials)" if result.plants else "the study ran without one (--no-efficiency)")
    return write_report(
        out_dir,
        ReportInputs(
            holdout=holdout, scores=heldout_scores(result.table), empty=empty,
            # with the rows that say where a rollout diverged (workbench.study.divergence), read beside the scores
            inputs_table=result.table[result.table["metric"].str.startswith("input_")
                                      | result.table["metric"].isin(DIVERGENCE_MARKERS)],
            train=result.train, test=result.test, models=result.models, baselines=result.baselines,
            rmse=result.rmse, efficiency=result.efficiency, coverage=cov, band=result.band if result.samples else None,
            stats=result.stats_text, verdicts=result.verdicts(), objectives=result.objectives,
            envelope=result.table[result.table["metric"] == "left_envelope"], calibration=result.calibration,
            ratio_comparison=getattr(result, "ratio_comparison", None),
            n_steps=result.n_steps, samples=result.samples, seed=result.seed, notes=notes, title=title,
            paired=() if result.statistics is None else result.statistics.headline,
            calibration_check=result.calibration_check,
        ),
    )
