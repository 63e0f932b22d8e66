"""What a study's comparison shows: paired differences with intervals and repeated-measures statistics, in words.

One computation for the printed output, the report and the verdicts: :func:`study_statistics` takes the tidy
comparison table (every method scored on the same windows of the same test trials) and returns a
:class:`StudyStatistics` — the method-level differences of :mod:`workbench.study.method_level` (the headline:
the models refitted over random splits, corrected resampled t), the one-fit paired differences of
:mod:`workbench.study.paired` (bootstrap intervals over whole test trials), the exact sign-flip tests and the
mixed-effects model's strategy terms of :mod:`workbench.study.stats` — whose :meth:`~StudyStatistics.text` says
which number answers which question.
No sentence here states a difference that its interval does not show.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import pandas as pd

from workbench.defaults import PAIRED_RESAMPLES
from workbench.models.registry import METHOD_TITLES
from workbench.study.method_level import FLOOR_METHODS, MethodDifference
from workbench.study.paired import ALL_LABELS, PairedDifference, min_units, paired_differences, per_trial
from workbench.study.stats import MixedModelResult, SignFlipTest, holm, mixed_effects, sign_flip_tests

__all__ = ["StudyStatistics", "study_statistics", "windows_sentence", "headline_rows"]

REFERENCE = "proposed"


@dataclass(frozen=True)
class StudyStatistics:
    """The statistics of one comparison (one metric), computed once.

    Attributes
    ----------
    metric, unit : str
    windows : str
        How the test trials were scored (stride, horizon, counts): :func:`windows_sentence`.
    paired : tuple of PairedDifference
        The fitted proposed model against each fitted baseline on the test trials, per strategy and over all.
    tests : tuple of SignFlipTest
        The exact sign-flip test of the same per-trial differences, Holm-corrected over the rows the headline
        uses, each saying whether it can reach 5 % at all with its trials.
    mixed : MixedModelResult or None
        Log error ~ method + strategy with subject (or trial) random effects, read for the strategies only; None
        where there is one strategy or it cannot be fitted.
    method_level : tuple of MethodDifference
        The methods compared over random splits that refit every model (:mod:`workbench.study.method_level`);
        the headline where present.
    """

    metric: str
    unit: str
    windows: str
    paired: tuple[PairedDifference, ...]
    tests: tuple[SignFlipTest, ...]
    mixed: MixedModelResult | None
    method_level: tuple[MethodDifference, ...] = ()

    def difference(self, label: str, baseline: str) -> PairedDifference | None:
        """The paired difference of the proposed model against ``baseline`` on ``label`` (None if not scored)."""
        return next((d for d in self.paired if d.label == label and d.baseline == baseline), None)

    def method_difference(self, label: str, baseline: str) -> MethodDifference | None:
        """The method-level difference against ``baseline`` on ``label`` (None where not computed)."""
        return next((d for d in self.method_level if d.label == label and d.baseline == baseline), None)

    @property
    def headline(self) -> tuple[PairedDifference | MethodDifference, ...]:
        """What the summary and the verdicts use: the method-level rows where computed, else the one-fit rows."""
        return self.method_level or self.paired

    def text(self) -> str:
        """Markdown: the windows, what answers which question, the method-level and one-fit tables, the mixed
        model's strategy terms."""
        if not self.paired and not self.method_level:
            return self.windows
        what = self.metric.removeprefix("rmse_").replace("_", " ")
        u = f" [{self.unit}]" if self.unit else ""
        lines = [self.windows, "", "Which number answers which question:"]
        ml = self.method_level
        family = headline_rows(self.headline)
        if ml:
            m0 = ml[0]
            k = sum(family)
            splits = m0.splits_words("each strategy's")
            if not m0.loo and len({d.n_splits for d in ml}) > 1:  # rows lost different splits: none speaks for all
                splits = (f"{_splits_counted(ml)} random splits of each strategy's {m0.units} (a split where a "
                          "method could not be fitted or diverged is left out of that method's rows, each named "
                          "with its cause)")
            refits = ("Each fold's models are the study's own fits of that fold." if m0.loo else
                      "Each split reruns the whole method on its own training part — the proposed model's "
                      "cross-validated G and regularizer, its fallback to K̂x and, where the plant is identified from "
                      "data, the plant — so the interval includes those choices' own variability; the refits skip "
                      "the task objective and the Monte Carlo band (neither changes a mean prediction).")
            lines.append(
                f"- *Does the proposed method predict this operator better than a baseline method?* (the headline "
                f"and the verdicts) The methods, for this operator: the proposed model and each baseline of the table "
                f"refitted on each of {splits} and scored on that split's test part; the mean over "
                f"splits of `1 − proposed / baseline` (mean per-trial {what} RMSE) with its {m0.ci:g} % interval "
                "from the corrected resampled t (Nadeau & Bengio 2003: the spread of the splits inflated by "
                "n_test / n_train for their overlapping training sets, t on splits − 1 df"
                + ("; for leave-one-out folds a heuristic, as Bouckaert & Frank 2004 use it for k-fold "
                   "cross-validation" if m0.loo else "") + ")" + self._decision_clause(ml) + "; p from the same t, "
                f"Holm-corrected over the {k} row{'s' if k != 1 else ''} the verdicts use. {refits}")
        if self.paired:
            first = self.paired[0]
            how = ("resampling whole subjects, then whole trials within each" if first.resampled.startswith(
                "subjects") else f"resampling whole test trials{first.resampled.removeprefix('trials')}")
            lines.append(
                f"- *Do these two fitted models differ on these test trials?* The paired difference of the mean "
                f"per-trial {what} RMSE of the models fitted on the study's training trials, `1 − proposed / "
                f"baseline`, with its {first.ci:g} % interval from {first.n_boot} bootstrap resamples ({how}; "
                "expanded percentile interval). It holds the fitted models fixed, so it says nothing about "
                "training on another sample of the same operator" + (" (the question above)." if ml else "."))
            lines.append(self._tests_sentence())
        lines.append("A difference is stated only where its interval excludes 0." + self._too_few_sentence())
        if self.mixed is not None and any(e.term.startswith("strategy") for e in self.mixed.effects):
            per = ("subject (a random intercept) and trial within subject (a variance component)"
                   if self.mixed.groups == "subject" else "trial (a random intercept: every method scored on it)")
            lines.append(f"- *Do the strategies differ in error?* A linear mixed model of the log per-trial error: "
                         f"method and strategy fixed, {per}; strategies are flown in different trials. It pools one "
                         "residual variance over the methods, so its method terms are not shown: the rows above "
                         "answer the methods' question.")
        if ml:
            which = ("refitted in every fold" if m0.loo else "refitted on every split; GMR-only, which no verdict "
                     "uses, only as fitted models below")
            where = "folds" if m0.loo else "splits"
            pooled = any(d.p_holm != d.p_holm and d.has_interval for d in ml)
            header = self._ml_header()
            if pooled:  # the pooled rows' p cell is "—": say why once, not in every such cell
                header = header.rstrip(":") + "; the pooled rows (no p) are no verdict's:"
            lines += ["", f"Methods ({which}) — {header}", "",
                      f"| strategy | proposed vs | {where} (train / test {ml[0].units}) | fell back to K̂x in | "
                      f"difference [{ml[0].ci:g} % interval] | p (corrected t, Holm) |", "|---|---|---|---|---|---|"]
            for d in ml:
                p = (f"{d.p_holm:.3g}" if d.p_holm == d.p_holm else
                     "—" if d.has_interval else "— (no interval)")
                lines.append(f"| {d.label} | {METHOD_TITLES.get(d.baseline, d.baseline)} | {d.splits_count()} "
                             f"({d.n_train} / {d.n_test}) | {d.fallback_words()} | {d.sentence()} | {p} |")
        if self.paired:
            tests = {(t.label, t.b): t for t in self.tests}
            show_p = any(t.reachable for t in self.tests if t.p_holm == t.p_holm)
            lines += ["", "These fitted models on these test trials:", "",
                      f"| strategy | proposed vs | trials (windows) | proposed{u} | baseline{u} | difference "
                      f"[{self.paired[0].ci:g} % interval] |" + (" sign-flip p (Holm) |" if show_p else ""),
                      "|---|---|---|---|---|---|" + ("---|" if show_p else "")]
            for d in self.paired:
                row = (f"| {d.label} | {METHOD_TITLES.get(d.baseline, d.baseline)} | {d.n_trials} ({d.n_windows}) "
                       f"| {d.mean_method:.4g} | {d.mean_baseline:.4g} | {d.sentence()} |")
                if show_p:
                    t = tests.get((d.label, d.baseline))
                    row += f" {_p_cell(t)} |"
                lines.append(row)
        if self.mixed is not None and any(e.term.startswith("strategy") for e in self.mixed.effects):
            m = self.mixed
            if not m.converged:  # its estimates are where the optimizer stopped, not a fit: no factor, no p
                # the optimizer's own "failed to converge" would repeat the sentence; a boundary variance says why
                why = "; ".join(part for part in m.note.split("; ") if part and "converge" not in part)
                lines += ["", f"Mixed-effects model (statsmodels MixedLM, REML) of log {what} RMSE: {m.n_obs} "
                              f"observations, {m.n_groups} {m.groups}s: it did not converge"
                              f"{' (' + why + ')' if why else ''}, so whether the strategies differ is not "
                              "answered and no factor or p-value is given."]
                return "\n".join(lines)
            lines += ["", f"Mixed-effects model (statsmodels MixedLM, REML) of log {what} RMSE: {m.n_obs} "
                          f"observations, {m.n_groups} {m.groups}s"
                          f"{'; ' + m.note if m.note else ''}. Factors against the first strategy; p from t with "
                          "the between-within df (not the Wald z):", "",
                      "| term | factor [95 % interval] | p (t, df) |", "|---|---|---|"]
            for e in m.effects:
                kind, level = e.term.split(" ", 1)
                if kind != "strategy":
                    continue
                shown = "" if e.lo <= 1.0 <= e.hi else (" (higher)" if e.lo > 1.0 else " (lower)")
                lines.append(f"| strategy {level} | ×{e.factor:.3g} [{e.lo:.3g}, {e.hi:.3g}]{shown} | {e.p:.3g} "
                             f"({e.df:.0f}) |")
        return "\n".join(lines)

    def legend(self) -> list[tuple[str, str]]:
        """Which number answers which question, as ``(question, how)`` pairs of a few words each: the terminal's
        legend, where :meth:`text` (the report, ``--explain``) says it at length."""
        out = []
        ml = self.method_level
        if ml:
            m0 = ml[0]
            k = sum(headline_rows(self.headline))
            folds = f"{m0.n_splits} leave-one-out folds" if m0.loo else f"{_splits_counted(ml)} refitted splits"
            out.append(("method better?", f"{folds}, corrected resampled t; p Holm over {k}"))
        if self.paired:
            first = self.paired[0]
            whole = ("subjects, then trials" if first.resampled.startswith("subjects") else "whole test trials")
            out.append(("these fits differ?", f"{first.n_boot} bootstrap resamples of {whole}"))
            head = [t for t in self.tests if t.p_holm == t.p_holm]
            if head and not any(t.reachable for t in head):
                n = max(t.n for t in head)
                out.append(("beyond chance?", f"no sign-flip test can reach 5 % with {n} test trials"))
            else:
                out.append(("beyond chance?", f"exact sign-flip tests; p Holm over {len(head)}"))
        if self.mixed is not None and any(e.term.startswith("strategy") for e in self.mixed.effects):
            per = "subject and trial" if self.mixed.groups == "subject" else "trial"
            out.append(("strategies differ?", f"mixed model of the log error, random per {per}" if self.mixed.converged
                        else "not answered: the mixed model did not converge"))
        return out

    @staticmethod
    def _decision_clause(ml: Sequence[MethodDifference]) -> str:
        """Where a row's variance holds the fallback's decision term (:func:`workbench.study.method_level.
        decision_variance`): what it adds, with the largest chance of another decision among those rows."""
        flips = [d.p_flip for d in ml if d.decision_var > 0 and d.p_flip == d.p_flip]
        if not flips:
            return ""
        # a chance that rounds to 0 % is not 0: say it is below the printed digit
        shown = f"{100 * max(flips):.0f}"  # decided on the printed digit: 0.005 itself rounds to "0" (half to even)
        most = f"up to {shown} %" if shown != "0" else "under 0.5 %"
        return (", and where the proposed model's fallback to K̂x was near its threshold, the chance that another "
                f"sample of the operator decides it otherwise ({most}, from each "
                f"{'fold' if ml[0].loo else 'split'}'s cross-validation margin) times the difference that decision "
                "makes, squared")

    def _too_few_sentence(self) -> str:
        """Where a row has no interval for want of units, why (once): the sign test's bound (:func:`min_units`)."""
        rows = [d for d in (*self.method_level, *self.paired) if not d.has_interval and "needed" in d.no_interval]
        if not rows:
            return ""
        ci = rows[0].ci
        return (f" No interval is given from fewer than {min_units(ci)} test trials, splits or folds: the range of n "
                f"of them holds their median with probability 1 − 2^(1−n), below {ci:g} % for fewer, and no "
                "interval resampled from them reaches beyond about that range.")

    def _ml_header(self) -> str:
        m0 = self.method_level[0]
        if m0.loo:
            return f"{m0.splits_words()}, each training on all of its strategy's {m0.units} but the one it tests:"
        return f"{_splits_counted(self.method_level)} random splits:"

    def _tests_sentence(self) -> str:
        """What the sign-flip column answers, or why there is none: with few trials no test can reach 5 %."""
        head = [t for t in self.tests if t.p_holm == t.p_holm]
        k = len(head)
        if head and not any(t.reachable for t in head):
            n = max(t.n for t in head)
            pmin = 2.0 / 2.0**n
            return (f"- *Is that difference more than chance on these trials?* No test can say so at 5 % here: with "
                    f"{n} test trials the exact sign-flip test of the per-trial differences cannot go below p = "
                    f"{pmin:.3g}" + (f" ({min(1.0, pmin * k):.3g} after Holm over the {k} rows the verdicts use)"
                                     if k > 1 else "") + ", so the fitted models' table below has no p column; "
                    + ("read its intervals" if any(d.has_interval for d in self.paired) else
                       # the sign test's bound that leaves no p below 5 % leaves no interval either (min_units)
                       "nor has it intervals (too few test trials for either)")
                    + (" (the p-values of the methods' table are the corrected t's, over splits)."
                       if self.method_level else "."))
        return ("- *Is that difference more than chance on these trials?* The exact sign-flip (permutation) test of "
                f"the per-trial differences, Holm-corrected over the {k} row{'s' if k != 1 else ''} the verdicts "
                "use (the only rows given a p); \"cannot reach 5 %\" where its trials are too few for any p of that "
                "family to be below 0.05.")


def _splits_counted(rows: Sequence[MethodDifference]) -> str:
    """How many random splits the method-level rows were made from: "6", "5 of 6" (a split left out of every row)
    or "4–5 of 6" (rows that lost different splits)."""
    drawn = max(max(d.n_drawn, d.n_splits) for d in rows)
    scored = sorted({d.n_splits for d in rows})
    if scored == [drawn]:
        return str(drawn)
    return f"{scored[0]} of {drawn}" if len(scored) == 1 else f"{scored[0]}–{scored[-1]} of {drawn}"


def _p_cell(t: SignFlipTest | None) -> str:
    if t is None:
        return ""
    if t.p_holm != t.p_holm:
        return "— (not a verdict's row)"
    if not t.reachable:
        return f"cannot reach 5 % ({t.n} trials)"
    return f"{t.p:.3g} ({t.p_holm:.3g})"


def headline_rows(rows: Sequence[PairedDifference | MethodDifference]) -> list[bool]:
    """Which rows the verdicts use: per strategy (the pooled row only where there is no strategy), against the
    baselines the proposed model must beat (:data:`workbench.study.method_level.FLOOR_METHODS`)."""
    labels = {d.label for d in rows}
    per_strategy = labels - {ALL_LABELS}
    return [d.baseline in FLOOR_METHODS and (d.label != ALL_LABELS or not per_strategy) for d in rows]


def windows_sentence(table: pd.DataFrame, n_steps: int, stride_steps: int | None, dt: float) -> str:
    """How the test trials were scored: the horizon, the stride between windows, the counts."""
    t = table[table["metric"].str.startswith("rmse_")]
    if t.empty:
        return "No prediction was scored."
    first = t["method"].iloc[0]
    t = t[t["method"] == first]
    per_trial_windows = t.groupby("trial")["start"].nunique()
    n_w, n_t = int(per_trial_windows.sum()), len(per_trial_windows)
    stride = ("from each trial's first state only" if not stride_steps else
              f"from each trial's first state and every {stride_steps} steps ({stride_steps * dt:g} s) its record "
              "covers")
    return (f"Scored: {n_w} windows on {n_t} test trials ({per_trial_windows.min()}–{per_trial_windows.max()} per "
            f"trial), {n_steps} steps ({n_steps * dt:g} s) ahead {stride}; a trial's windows are averaged, so every "
            "trial weighs the same.")


def study_statistics(
    table: pd.DataFrame,
    metric: str,
    unit: str,
    subjects: Mapping[str, str],
    windows: str,
    baselines: Sequence[str] | None = None,
    n_boot: int = PAIRED_RESAMPLES,
    seed: int = 0,
    method_level: Sequence[MethodDifference] | None = None,
) -> StudyStatistics:
    """Paired differences (per strategy, and over all), their sign-flip tests, the mixed model's strategy terms
    and — where given — the method-level differences, with p Holm-corrected over the rows the verdicts use.

    ``subjects`` maps trial ids to subjects (empty when none are named).
    """
    subj = dict(subjects) or None
    paired = tuple(paired_differences(table, metric, REFERENCE, baselines, subjects=subj, n_boot=n_boot, seed=seed))
    wide = per_trial(table, metric, subj)
    ml = tuple(method_level or ())
    if ml:
        fam = headline_rows(ml)
        idx = [i for i, f in enumerate(fam) if f]
        adj = dict(zip(idx, holm([ml[i].p for i in idx]), strict=True)) if idx else {}
        ml = tuple(replace(d, p_holm=float(adj[i])) if i in adj else d for i, d in enumerate(ml))
    # the one-fit tests' family: the rows the verdicts would use if these were the headline
    tests = tuple(sign_flip_tests(wide, [(d.label, REFERENCE, d.baseline) for d in paired],
                                  family=headline_rows(paired), seed=seed)) if paired else ()
    mixed = None
    if paired and wide.index.get_level_values("label").nunique() > 1:  # its strategy terms are all it is read for
        long = wide.drop(columns=["n_windows"]).reset_index().melt(
            id_vars=["label", "trial", "subject"], var_name="method", value_name="value")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the fit's own warnings are kept in its note
            mixed = mixed_effects(long, REFERENCE)
    return StudyStatistics(metric=metric, unit=unit, windows=windows, paired=paired, tests=tests, mixed=mixed,
                           method_level=ml)
