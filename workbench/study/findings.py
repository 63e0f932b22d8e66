"""What a study's comparison shows: paired differences with intervals and repeated-measures statistics, in words.

One computation for the printed output, the report and the verdicts: :func:`study_statistics` takes the tidy
comparison table (every method scored on the same windows of the same test trials) and returns a
:class:`StudyStatistics` — the paired differences of :mod:`workbench.study.paired` (the headline, with bootstrap
intervals over whole trials), the Wilcoxon / paired t-tests and the mixed-effects model of
:mod:`workbench.study.stats` — whose :meth:`~StudyStatistics.text` says which number answers which question.
No sentence here states a difference that its interval does not show.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import pandas as pd

from workbench.models.names import METHOD_TITLES
from workbench.study.paired import ALL_LABELS, PairedDifference, paired_differences, per_trial
from workbench.study.stats import MixedModelResult, PairedTest, holm, mixed_effects, paired_tests

__all__ = ["StudyStatistics", "study_statistics", "windows_sentence"]

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
        The proposed model against each baseline, per strategy and over all of them.
    tests : tuple of PairedTest
        Wilcoxon signed-rank and paired t-tests of the same per-trial values, Holm-corrected over all rows.
    mixed : MixedModelResult or None
        Log error ~ method + strategy with subject (or trial) random effects; None where it cannot be fitted.
    """

    metric: str
    unit: str
    windows: str
    paired: tuple[PairedDifference, ...]
    tests: tuple[PairedTest, ...]
    mixed: MixedModelResult | None

    def difference(self, label: str, baseline: str) -> PairedDifference | None:
        """The paired difference of the proposed model against ``baseline`` on ``label`` (None if not scored)."""
        return next((d for d in self.paired if d.label == label and d.baseline == baseline), None)

    def text(self) -> str:
        """Markdown: the windows, what answers which question, the paired table, the mixed model."""
        if not self.paired:
            return self.windows
        what = self.metric.removeprefix("rmse_").replace("_", " ")
        u = f" [{self.unit}]" if self.unit else ""
        first = self.paired[0]
        how = ("resampling whole subjects, then whole trials within each" if first.resampled.startswith("subjects")
               else f"resampling whole test trials{first.resampled.removeprefix('trials')}")
        lines = [
            self.windows, "",
            "Which number answers which question:",
            f"- *Is the proposed model's error lower than a baseline's on the same trials?* The paired difference "
            f"of the mean per-trial {what} RMSE, `1 − proposed / baseline`, with its {first.ci:g} % interval from "
            f"{first.n_boot} bootstrap resamples ({how}; expanded percentile interval, which keeps its coverage "
            "with few trials); a difference is "
            "stated only where the interval excludes 0.",
            "- *Is that difference more than chance on these trials?* The Wilcoxon signed-rank test of the "
            "per-trial differences (and the paired t-test), Holm-corrected over every row of the table.",
        ]
        if self.mixed is not None:
            per = ("subject (a random intercept) and trial within subject (a variance component)"
                   if self.mixed.groups == "subject" else "trial (a random intercept: every method scored on it)")
            lines.append(f"- *By what factor does each method's error differ from the proposed model's, and do the "
                         f"strategies differ?* A linear mixed model of the log per-trial error: method and strategy "
                         f"fixed, {per}. Strategies are flown in different trials, so they are compared between "
                         "trials, methods within them.")
        tests = {(t.label, t.b): t for t in self.tests}
        lines += ["", f"| strategy | proposed vs | trials (windows) | proposed{u} | baseline{u} | difference "
                      f"[{first.ci:g} % interval] | Wilcoxon p (Holm) | paired t p (Holm) |",
                  "|---|---|---|---|---|---|---|---|"]
        for d in self.paired:
            t = tests.get((d.label, d.baseline))
            tw = "" if t is None else f"{t.p_wilcoxon:.3g} ({t.p_wilcoxon_holm:.3g})"
            tt = "" if t is None else f"{t.p_t:.3g} ({t.p_t_holm:.3g})"
            lines.append(f"| {d.label} | {METHOD_TITLES.get(d.baseline, d.baseline)} | {d.n_trials} ({d.n_windows}) "
                         f"| {d.mean_method:.4g} | {d.mean_baseline:.4g} | {d.sentence()} | {tw} | {tt} |")
        if self.mixed is not None:
            m = self.mixed
            lines += ["", f"Mixed-effects model (statsmodels MixedLM, REML) of log {what} RMSE: {m.n_obs} "
                          f"observations, {m.n_groups} {m.groups}s{'' if m.converged else ', NOT converged'}"
                          f"{'; ' + m.note if m.note else ''}. Factors on the error against the proposed model "
                          "(methods) and against the first strategy (strategies); intervals and p from a t "
                          "distribution with the between-within degrees of freedom of the term's level (df), "
                          "not the Wald z, which is far too confident with this few trials:", "",
                      "| term | factor [95 % interval] | p (t, df) |", "|---|---|---|"]
            for e in m.effects:
                kind, level = e.term.split(" ", 1)
                name = METHOD_TITLES.get(level, level) + (" vs proposed" if kind == "method" else "")
                shown = ("" if e.lo <= 1.0 <= e.hi else
                         (" (higher)" if e.lo > 1.0 else " (lower)"))
                lines.append(f"| {kind} {name} | ×{e.factor:.3g} [{e.lo:.3g}, {e.hi:.3g}]{shown} | {e.p:.3g} "
                             f"({e.df:.0f}) |")
        return "\n".join(lines)


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
              f"from every {stride_steps} steps ({stride_steps * dt:g} s) of each test trial whose record covers "
              "the horizon, and from its first state")
    return (f"Predictions over {n_steps} steps ({n_steps * dt:g} s) scored {stride}: {n_w} windows on {n_t} test "
            f"trials ({per_trial_windows.min()}–{per_trial_windows.max()} per trial); a trial's windows are averaged, "
            "so every trial weighs the same.")


def study_statistics(
    table: pd.DataFrame,
    metric: str,
    unit: str,
    subjects: Mapping[str, str],
    windows: str,
    baselines: Sequence[str] | None = None,
    n_boot: int = 4000,
    seed: int = 0,
) -> StudyStatistics:
    """Paired differences (per strategy, and over all), their tests and the mixed model of one metric.

    ``subjects`` maps trial ids to subjects (empty when none are named).
    """
    subj = dict(subjects) or None
    paired = tuple(paired_differences(table, metric, REFERENCE, baselines, subjects=subj, n_boot=n_boot, seed=seed))
    wide = per_trial(table, metric, subj)
    tests: list[PairedTest] = []
    flat = []
    for d in paired:
        part = wide if d.label == ALL_LABELS else wide.xs(d.label, level="label", drop_level=False)
        flat += paired_tests(part, [(REFERENCE, d.baseline)], label=d.label, correction="none")
    # one family for the Holm correction: every row of the table
    if flat:
        qw, qt = holm([t.p_wilcoxon for t in flat]), holm([t.p_t for t in flat])
        tests = [PairedTest(t.a, t.b, t.label, t.n, t.median_difference, t.wilcoxon, t.p_wilcoxon, float(a),
                            t.t, t.p_t, float(b)) for t, a, b in zip(flat, qw, qt, strict=True)]
    long = wide.drop(columns=["n_windows"]).reset_index().melt(
        id_vars=["label", "trial", "subject"], var_name="method", value_name="value")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fit's own warnings are kept in its note
        mixed = mixed_effects(long, REFERENCE) if len(paired) else None
    return StudyStatistics(metric=metric, unit=unit, windows=windows, paired=paired, tests=tuple(tests), mixed=mixed)
