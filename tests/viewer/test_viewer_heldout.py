"""The first question a user asks of a recording — how well does this model predict data it never saw — is
answered where the eye lands: the demo's first view carries every method's held-out RMSE as ``results.csv`` holds
it; a model shown on its own training trials is labelled in-sample; the viewer, the terminal and the report word a
band's calibration with one function.

Expected values are computed here from ``results.csv`` and the models' own record of their training trials.
"""

from __future__ import annotations

import pandas as pd

from workbench.models import load_model
from workbench.study.scores import fmt, heldout_scores

from ..rrd import blueprint_names, read_rrd
from . import viewer_recordings

recordings = viewer_recordings.load()  # one instance per process: test_viewer.py's recordings


def _text(ents: dict, path: str) -> str:
    (text,) = [v for v in ents[path]["static:TextDocument:text"]]
    return text[0] if isinstance(text, list) else text


def test_the_demos_first_view_carries_the_held_out_rmse_of_results_csv():
    paths = recordings.cli_recordings()
    table = pd.read_csv(recordings.workdir() / "demo" / "results.csv")
    scores = heldout_scores(table[table["table"] == "comparison"])
    rmse = scores[scores["metric"].str.startswith("rmse_")]
    assert set(rmse["method"]) >= {"proposed", "persistence"} and set(rmse["metric"]) >= {"rmse_position",
                                                                                          "rmse_velocity"}
    text = _text(read_rrd(paths["demo"]), "/scores")
    for r in scores.itertuples(index=False):
        shown = fmt(r.value, r.lo, r.hi, share=r.metric.startswith("band_"))
        assert shown in text, (r, text)
    names = blueprint_names(paths["demo"])
    assert "held-out prediction error" in names  # the view beside the scene, in the first tab
    proposed = rmse[(rmse["method"] == "proposed") & (rmse["metric"] == "rmse_position")]["value"].iloc[0]
    assert any(n.startswith(f"held-out position RMSE: proposed {proposed:.3g}") for n in names), names


def _view(*argv: str) -> None:
    from workbench.cli import main

    assert main(["view", *argv, "-q"]) == 0


def test_a_model_viewed_on_its_own_training_trials_is_labelled_in_sample(tmp_path):
    recordings.cli_recordings()
    d = recordings.workdir() / "demo"
    demos, model_path = d / "demos.parquet", d / "models" / "CS1.npz"
    model = load_model(model_path)
    trained = model.train_ids_
    assert trained, "the demo's model file records its training trials"
    out = tmp_path / "in.rrd"
    _view(str(demos), "--model", str(model_path), "--label", "CS1", "--focus", trained[0], "--samples", "0",
          "--horizon", "1", "--save", str(out))
    names = blueprint_names(out)
    assert f"predictions · {trained[0]} (in-sample)" in names, names
    # by default the view focuses on a trial the model was not fitted on, and scores only those
    out2 = tmp_path / "default.rrd"
    _view(str(demos), "--model", str(model_path), "--label", "CS1", "--samples", "0", "--horizon", "1",
          "--save", str(out2))
    names = blueprint_names(out2)
    tabs = [n for n in names if n.startswith("predictions · ")]
    assert tabs and all("in-sample" not in n and n.split(" · ")[1] not in trained for n in tabs), tabs
    text = _text(read_rrd(out2), "/scores")
    from workbench.data.dataset import load_demonstrations

    n_all = len(load_demonstrations(demos).by_label("CS1"))
    assert f"{n_all - len(trained)} of {n_all} trial(s) held out" in text, text


def test_the_viewer_and_the_report_word_a_band_with_one_function(monkeypatch):
    """Replace the one verdict function: the viewer's titles and the report's table both print its answer."""
    import workbench.study.calibration as cal
    from workbench.data.dataset import load_demonstrations
    from workbench.viewer import verdict

    recordings.cli_recordings()
    d = recordings.workdir() / "demo"
    model = load_model(d / "models" / "CS1.npz")
    demos = load_demonstrations(d / "demos.parquet").by_label("CS1")
    held = [x for x in demos if x.id not in set(model.train_ids_)]
    real = cal.band_verdict
    monkeypatch.setattr(cal, "band_verdict", lambda *a, **k: real(*a, **k).astype(object) + " (sentinel)")
    titles = verdict.trial_band_titles(model, held)
    assert titles and all(t.count("(sentinel)") == len(verdict.LEVELS) for t in titles.values()), titles
    v = verdict.verdict("CS1", model, demos.with_demos(held))
    assert v.band_text().count("(sentinel)") == len(verdict.LEVELS) * len(demos.input_names)
    table = cal.check_table(cal.calibration_check(cal.calibration_counts(model, held)))
    assert table["calibration"].str.endswith("(sentinel)").all()


def test_the_pilots_own_input_is_judged_in_evaluate_report_and_viewer(tmp_path):
    """Each method's held-out error in predicting the pilot's input, one step ahead and over the horizon, beside the
    models with no pilot: the same numbers in `evaluate`'s output, the report (and its table) and the viewer's
    first view (issue 40 §4)."""
    import io
    from contextlib import redirect_stdout

    from workbench.cli import main
    from workbench.study.input_prediction import input_differences, input_headlines, input_scores, title

    paths = recordings.cli_recordings()
    demo = recordings.workdir() / "demo"
    table = pd.read_csv(demo / "results.csv")
    table = table[table["table"] == "comparison"]
    scores = input_scores(table)
    assert set(scores["metric"]) == {"input_step", "input_horizon"}
    assert {"proposed", "ioc_only", "no_pilot_held", "no_pilot_zero"} <= set(scores["method"])
    # the report: its section, its table, the headline naming the no-pilot model
    text = (demo / "report.md").read_text(encoding="utf-8")
    assert "## Predicting the pilot's input" in text
    reported = pd.read_csv(demo / "tables" / "input_scores.csv")
    # a CSV reads back an empty note (no diverged rollout) as NaN, in a float column
    reported["note"] = reported["note"].astype(object).where(reported["note"].notna(), "")
    pd.testing.assert_frame_equal(reported, scores.reset_index(drop=True), check_dtype=False, rtol=1e-12)
    for line in input_headlines(table):
        assert line in text and "for the better model with no pilot, the plant with the input" in line
    # the viewer's first view
    shown = _text(read_rrd(paths["demo"]), "/scores")
    for r in scores.itertuples(index=False):
        assert fmt(r.value, r.lo, r.hi) in shown and title(r.method) in shown
    # evaluate: its printed table and the rows of its results file
    said = io.StringIO()
    with redirect_stdout(said):
        assert main(["evaluate", str(demo / "demos.parquet"), "--label", "CS1", "--n-components", "1", "--samples",
                     "0", "--no-efficiency", "--horizon", "1", "-o", str(tmp_path / "e.csv")]) == 0
    out = said.getvalue()
    evaluated = input_scores(pd.read_csv(tmp_path / "e.csv"))
    assert "held-out error predicting the pilot's input" in out and "no pilot (input held)" in out
    # the headline as a table: a row per horizon naming the better no-pilot model, with the paired difference
    diffs = input_differences(pd.read_csv(tmp_path / "e.csv"))
    assert diffs
    for _, metric, ref, d in diffs:
        ahead = "one step" if metric == "input_step" else "horizon"
        assert any(ahead in line and title(ref) in line and d.sentence() in line for line in out.splitlines())
    for r in evaluated.itertuples(index=False):
        assert fmt(r.value, r.lo, r.hi) in out


def test_the_demos_report_and_output_print_no_number_where_nothing_is_identified():
    """No interval of [0, 0], [0, ∞] or ∞ as a number, no zero-width difference, no "−0.0 %" — in the demo's
    report and in what it printed (evaluate's printer) (issue 40 §3)."""
    import re

    recordings.cli_recordings()
    demo = recordings.workdir() / "demo"
    for text in ((demo / "report.md").read_text(encoding="utf-8"), (demo / "said.txt").read_text(encoding="utf-8")):
        assert "∞" not in text and not re.search(r"\binf\b", text)
        assert not re.search(r"\[\s*0(\.0+)?\s*,\s*0(\.0+)?\s*\]", text)  # [0, 0]
        assert not re.search(r"\[[+−-]?0(\.0+)? %, [+−-]?0(\.0+)? %\]", text)  # [+0 %, +0 %]
        assert not re.search(r"[−-]0\.0 %", text)
