"""`fit`'s line of the default model's cross-validation scores."""

from __future__ import annotations


def test_a_candidate_not_scored_is_said_in_words():
    # peterbarker_1: "held-out 3 s RMSE per candidate: G1/0.3 0.41, …, G5/0.3 nan"
    import math

    from workbench.cli.model import candidate_scores

    scored = 0.25 + 0.16
    rows = ({"n_components": 1, "reg_covar": 0.3, "heldout_rmse": scored},
            {"n_components": 5, "reg_covar": 0.3, "heldout_rmse": math.nan})
    line = candidate_scores(rows, 3.0)
    assert "nan" not in line.lower()
    assert line == f"held-out 3 s RMSE per candidate: G1/0.3 {scored:.3g}, G5/0.3 not scored on every fold"
