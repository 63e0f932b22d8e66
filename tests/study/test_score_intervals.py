"""The held-out scores' intervals: a share is kept inside [0, 1], an error only above 0."""

from __future__ import annotations

import numpy as np
import pandas as pd
import scipy.stats

from workbench.study.scores import heldout_scores


def _table(metric: str, values) -> pd.DataFrame:
    return pd.DataFrame({"label": "all", "method": "proposed", "metric": metric, "trial": [f"t{i}" for i in
                         range(len(values))], "start": 0, "value": values})


def test_an_input_error_s_interval_is_not_cut_at_one():
    """evaluate on GPS_issues1 printed the pilot's input error "0.3 [0, 1]": the input metrics were taken for
    shares and their t interval cut at 1, though a stick error in [-1, 1] units reaches 2."""
    values = np.array([0.1, 0.9, 0.2, 1.4])
    half = scipy.stats.t.ppf(0.975, len(values) - 1) * values.std(ddof=1) / np.sqrt(len(values))
    assert values.mean() + half > 1  # the interval this test is about reaches beyond 1
    for metric in ("input_step", "input_horizon", "rmse_position"):
        row = heldout_scores(_table(metric, values), metrics=[metric]).iloc[0]
        assert row["hi"] == values.mean() + half and row["lo"] == max(0.0, values.mean() - half)
    share = heldout_scores(_table("band_position", values / 2), metrics=["band_position"]).iloc[0]
    assert share["hi"] <= 1.0 and share["lo"] >= 0.0
