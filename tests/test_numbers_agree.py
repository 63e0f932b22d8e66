"""One number, one value everywhere (issue 38): the demo's report, what it printed (``evaluate``'s tables: the
demo prints them through the same function) and its recording show the same numbers for the same quantities —
the test trials per strategy, the one-step 3σ coverage, the headline error and the data-efficiency curve at every
training trial (the comparison's own models).

The shared demo run of the viewer tests (``tests/viewer/viewer_recordings.py``) is read, not run again. The
expected values come from the demo's own tidy results (``results.csv``) through the one function each quantity
has; each place must show that value as it formats it.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

_spec = importlib.util.spec_from_file_location(
    "_viewer_recordings", Path(__file__).parent / "viewer" / "viewer_recordings.py")
_loader = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_loader)
recordings = _loader.load()


def _texts(rrd: Path) -> dict[str, str]:
    """Every static text document of a recording, by entity path."""
    from rerun.chunk import RrdReader

    out = {}
    for chunk in RrdReader(rrd).stream():
        if not chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("TextDocument:text"):
                values = batch.column(name).to_pylist()
                if values and values[0]:
                    out[chunk.entity_path] = str(values[0][0] if isinstance(values[0], list) else values[0])
    return out


@pytest.fixture(scope="module")
def demo():
    folder, said = recordings.demo_run()
    results = pd.read_csv(folder / "results.csv")
    return {"folder": folder, "said": said, "report": (folder / "report.md").read_text(encoding="utf-8"),
            "results": results, "texts": _texts(folder / "demo.rrd")}


def _scores(results: pd.DataFrame) -> pd.DataFrame:
    from workbench.study.scores import heldout_scores

    rows = results[results["table"] != "data_efficiency"] if "table" in results else results
    return heldout_scores(rows)


def _terminal_forms(cell: str) -> list[str]:
    """Every way the terminal's self-narrowing table can print ``cell`` (:func:`narrowed_tables`' steps)."""
    from workbench.cli.context import _tight, fewer_digits

    fewer = [fewer_digits(cell, d) for d in range(2, 7)]  # a row keeps the digits that tell its numbers apart
    return [cell, _tight(cell), *fewer, *(_tight(f) for f in fewer)]


def test_headline_error_is_the_same_in_report_terminal_and_recording(demo):
    from workbench.study.scores import fmt

    scores = _scores(demo["results"])
    recording = "\n".join(demo["texts"].values())
    rows = scores[scores["metric"] == "rmse_position"]
    assert len(rows)
    for r in rows.itertuples():
        shown = fmt(r.value, r.lo, r.hi)
        assert shown in demo["report"], (r.label, r.method, shown)
        # the terminal's table may have narrowed itself to the width it had (fewer digits, tighter intervals)
        assert any(form in demo["said"] for form in _terminal_forms(shown)), (r.label, r.method, shown)
        assert shown in recording, (r.label, r.method, shown)


def test_test_trials_are_counted_per_strategy_everywhere(demo):
    scores = _scores(demo["results"])
    counts = scores[scores["method"] == "proposed"].groupby("label")["n_trials"].max()
    for label, n in counts.items():
        # the report's demonstrations table (strategy | train | test | …) and its held-out table's trials column
        assert re.search(rf"^\| {label} \| \d+ \| {n} \|", demo["report"], re.M), label
        # the recording's per-strategy scores say that strategy's count, not the study's total
        note = demo["texts"][f"/label_scores/{label}"]
        assert f"{n} test trial{'s' if n != 1 else ''}," in note, note[:300]
        # the terminal's held-out table: a trials column per row
        assert re.search(rf"{label}\W.*proposed.*\W{n}\W*$", demo["said"], re.M), label
    total = int(counts.sum())
    assert f"{total} test trial" in demo["texts"]["/scores"]


def test_coverage_is_one_computation(demo):
    check = pd.read_csv(demo["folder"] / "tables" / "calibration_check.csv")
    three = check[np.isclose(check["n_sigma"], 3.0)]
    assert len(three)
    verdicts = {p: t for p, t in demo["texts"].items() if p.endswith("/verdict")}
    assert verdicts
    cov_col = "coverage_free"  # inputs at a limit left out: the share every verdict judges
    for r in three.itertuples():
        share = f"{100 * getattr(r, cov_col):.1f} %"
        # the objective tab's verdict pools the same test trials as the report's table
        assert any(share in t for t in verdicts.values()), (r.label, r.input, share, list(verdicts.values())[:1])
        assert f"{100 * getattr(r, cov_col):.1f}" in demo["said"], (r.label, r.input)


def test_data_efficiency_at_full_n_is_the_headline(demo):
    from workbench.report.tables import efficiency_means

    results = demo["results"]
    eff = results[results["table"] == "data_efficiency"]
    assert len(eff)
    means = efficiency_means(eff)
    scores = _scores(results)
    for label, g in means.groupby("label"):
        last = g[g["n_train"] == g["n_train"].max()].iloc[0]
        head = scores[(scores["label"] == label) & (scores["method"] == "proposed")
                      & (scores["metric"] == "rmse_position")].iloc[0]
        np.testing.assert_allclose(last["proposed"], head["value"], rtol=1e-12)
        # the terminal prints the curve, its last point at the headline's value
        assert f"{last['proposed']:.3g}" in demo["said"]
        report_table = pd.read_csv(demo["folder"] / "tables" / "data_efficiency.csv")
        row = report_table[(report_table["label"] == label) & (report_table["n_train"] == last["n_train"])]
        np.testing.assert_allclose(row["proposed"].iloc[0], head["value"], rtol=1e-9)


def test_a_percentage_says_which_comparison_it_is(demo):
    """The report's comparison table puts method-level differences beside two means they do not compare: its
    header names the comparison."""
    table = pd.read_csv(demo["folder"] / "tables" / "comparison.csv")
    vs = [c for c in table.columns if c.startswith("vs ")]
    assert vs and all("as methods" in c or "these fitted models" in c for c in vs), vs
