"""``report`` and ``evaluate`` answer one question with one number: the same holdout rules (leave-one-segment-out
on a flight of a few segments) and the same held-out scores on a real flight."""

from __future__ import annotations

import pandas as pd
import pytest

from workbench.study.scores import heldout_scores


@pytest.mark.slow
def test_report_and_evaluate_give_equal_numbers_on_the_dronekit_flight(tmp_path, external):
    from workbench.cli import main

    flight = str(external("dronekit_flight.tlog"))
    common = ["--mapping", "ardupilot_manual", "--samples", "10", "-q"]
    assert main(["evaluate", flight, "-o", str(tmp_path / "evaluate.csv"), *common]) == 0
    assert main(["report", flight, "-o", str(tmp_path / "report"), *common]) == 0
    evaluated = heldout_scores(pd.read_csv(tmp_path / "evaluate.csv"))
    reported = pd.read_csv(tmp_path / "report" / "tables" / "heldout_scores.csv")
    assert len(evaluated) and set(evaluated["metric"]) >= {"rmse_position", "rmse_velocity"}
    pd.testing.assert_frame_equal(reported, evaluated, check_dtype=False, rtol=1e-12)
    text = (tmp_path / "report" / "report.md").read_text(encoding="utf-8")
    assert "leave-one-segment-out" in text
    # no section is empty without saying why
    assert "## Data efficiency\n\n*None: leave-one-segment-out" in text
