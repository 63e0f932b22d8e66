"""A tab per focus trial (up to three): per state, the recorded state and every method's prediction with its Monte
Carlo band, zoomed to the prediction window, titled with the label's held-out RMSE, over the label's held-out
scores. It logs the predictions from each focus trial's starts and the held-out scores (the study's table, or the
models scored here on the trials they were not fitted on: :func:`workbench.viewer.heldout.heldout_table`).
"""

from __future__ import annotations

from typing import Any

import rerun.blueprint as rrb

from workbench.viewer import entities as paths
from workbench.viewer.entities import LoggedSession
from workbench.viewer.tab import SessionRun, Tab
from workbench.viewer.views import focus_trials, plot, prediction_paths

__all__ = ["TAB"]


def _score_title(s: LoggedSession, demo_id: str) -> str:
    """``"held-out RMSE: proposed 0.0996 m, persistence 0.418 m"`` for the label of ``demo_id`` (the study's or
    the view's held-out scores), or what the trial is when it has none."""
    from workbench.models.registry import METHOD_TITLES

    where = " (this trial IN-SAMPLE)" if demo_id in s.in_sample else ""
    if s.scores is None or not len(s.scores):
        return "no held-out scores" + where
    label = s.trial_labels.get(demo_id, "")
    sc = s.scores[s.scores["label"] == label]
    if not len(sc):
        sc = s.scores[s.scores["label"] == s.scores["label"].iloc[0]]
    metric = "rmse_position" if (sc["metric"] == "rmse_position").any() else str(sc["metric"].iloc[0])
    rows = {r.method: r for r in sc[sc["metric"] == metric].itertuples(index=False)}
    shown = [m for m in ("proposed", "persistence") if m in rows]
    what = metric.removeprefix("rmse_")
    # a rollout that diverged is said, not given a number (workbench.study.divergence)
    return (f"held-out {what} RMSE: " + ", ".join(f"{METHOD_TITLES.get(m, m)} "
                                                   f"{getattr(rows[m], 'note', '') or format(rows[m].value, '.3g')}"
                                                   for m in shown) + where)


class Predictions(Tab):
    name = "predictions"
    order = 40
    description = "a tab per focus trial: every method's prediction of each state with its Monte Carlo band"

    def log(self, logger: Any, run: SessionRun) -> None:
        if run.models is None:
            return
        by_id = {d.id: d for d in run.demos}
        for fid in run.focus:
            d = by_id[fid]
            methods = run.methods_for(d)
            if not methods:
                continue
            for k in run.starts:
                if k < len(d):
                    logger.log_predictions(d, methods, start=int(k), n_steps=run.n_steps, samples=run.samples,
                                           seed=run.seed)
        from workbench.viewer.heldout import heldout_table, score_units, scores_of

        table, note = run.scores if run.scores is not None else heldout_table(
            run.demos, run.models, run.baselines, n_steps=run.n_steps, samples=run.samples, seed=run.seed)
        logger.log_scores(scores_of(table), note, score_units(run.models))

    def views(self, session: LoggedSession) -> list[Any]:
        s = session
        out = []
        for i in [f for f in focus_trials(s) if f in s.predictions]:
            # one tab per focus trial: six plots of one trial are tall enough for a y-tick every few pixels rows
            pred_views: list[Any] = []
            fit = _score_title(s, i) if paths.SCORES in s.entities else ""
            for j, name in enumerate(s.state_names):
                key = paths.prediction_plot(i, name)
                pred_views.append(plot((f"{fit} · " if fit and j == 0 else "") + s.title(name),
                                       prediction_paths(s, i, name),
                                       legend=rrb.PlotLegend(s.corners.get(key, "LeftTop"), visible=j == 0),
                                       y_range=s.ranges.get(key), window=s.windows.get(i)))
            label_doc = paths.label_scores_path(s.trial_labels.get(i, ""))
            title = f"{self.name} · {i}" + (" (in-sample)" if i in s.in_sample else "")
            grid = rrb.Grid(*pred_views, grid_columns=len(s.state_names) // 2 or 1)
            if label_doc in s.entities:  # the label's held-out numbers under its plots, a few lines tall
                # the table sized to its rows (a title, a header and a row per method, ~24 px each, of ~900 px)
                doc = 24.0 * (len(s.methods) + 5)
                out.append(rrb.Vertical(grid, rrb.TextDocumentView(origin=paths.origin(label_doc),
                                                                   name="held-out prediction error"),
                                        row_shares=[max(900.0 - doc, 300.0), doc], name=title))
            else:
                out.append(rrb.Grid(*pred_views, grid_columns=len(s.state_names) // 2 or 1, name=title))
        return out


TAB = Predictions()
