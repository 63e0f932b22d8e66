"""The law behind "demonstrations needed" (:data:`workbench.study.power.LAW`) on simulated spans of known shape."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from workbench.study.power import PowerCurve, _medians, _needed


def _curve(spans: dict[int, list[float]]) -> PowerCurve:
    rows = [{"ratio": "r", "n": n, "repeat": k, "span": v} for n, vs in spans.items() for k, v in enumerate(vs)]
    table = pd.DataFrame(rows)
    return PowerCurve(spans=table, needed={"r": _needed(_medians(table), float(np.log(2.0)))}, target=2.0,
                      n_trials=min(spans))


def test_beyond_the_largest_size_the_span_shrinks_as_one_over_root_n_from_it():
    # spans that shrink faster than 1/√n between the small sizes (as the critical value's few degrees of freedom
    # make them): the law extrapolates from the largest size only
    log_spans = {30: 3.0, 60: 1.6, 120: 1.0}
    curve = _curve({n: [np.exp(v * f) for f in (0.9, 1.0, 1.1)] for n, v in log_spans.items()})
    assert curve.needed["r"] == pytest.approx(120 * (1.0 / np.log(2.0)) ** 2)
    assert curve.predicted_log_span("r", 480) == pytest.approx(1.0 * np.sqrt(120 / 480))
    # the first law (median of log span · √n over every set) would ask for more
    first = np.median([v * f * np.sqrt(n) for n, v in log_spans.items() for f in (0.9, 1.0, 1.1)])
    assert (first / np.log(2.0)) ** 2 > curve.needed["r"]


def test_between_simulated_sizes_the_median_log_span_is_interpolated_in_log_n():
    curve = _curve({30: [np.exp(1.2)], 60: [np.exp(0.5)], 120: [np.exp(0.3)]})
    t = (1.2 - np.log(2.0)) / (1.2 - 0.5)
    assert curve.needed["r"] == pytest.approx(np.exp(np.log(30) + t * np.log(2.0)))
    assert curve.predicted_log_span("r", np.sqrt(30 * 60)) == pytest.approx(0.85)
    # already below the target at the smallest size: the √n law from it
    low = _curve({30: [np.exp(0.5)], 60: [np.exp(0.3)]})
    assert low.needed["r"] == pytest.approx(30 * (0.5 / np.log(2.0)) ** 2)


def test_unbounded_spans_say_more_than_simulated_or_set_a_floor():
    assert _curve({30: [np.exp(2.0)], 60: [np.inf, np.exp(1.0)]}).needed["r"] == np.inf
    # unbounded at 30: nothing below 60 is believed, even where the √n law from 60 would say fewer
    curve = _curve({30: [np.inf], 60: [np.exp(0.3)], 120: [np.exp(0.2)]})
    assert curve.needed["r"] == 60
    assert "more than 60 demonstrations" in _curve({30: [2.0], 60: [np.inf]}).describe()[0]
