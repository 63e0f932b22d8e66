"""The experimenter's view reads: one colour per outcome with a legend in the scene, one label (the newest
trial's) instead of one per track, the whole outcome table, fits with their held-out error, exclusions, and where
the session and the recording are written."""

from __future__ import annotations

import numpy as np

from workbench.collect.experimenter import OUTCOME_COLORS, ExperimenterView
from workbench.collect.task import OUTCOMES, task_spec


def _view(tmp_path):
    import rerun as rr

    rec = rr.RecordingStream("workbench-collect-test")
    rec.memory_recording()
    logged: list[tuple[str, object]] = []
    log = rec.log
    rec.log = lambda path, entity, **kw: (logged.append((path, entity)), log(path, entity, **kw))
    view = ExperimenterView(rec, task_spec(), out=str(tmp_path / "session"), saved=str(tmp_path / "view.rrd"))
    return view, logged


def _last(logged, path):
    return [e for p, e in logged if p == path][-1]


def test_each_outcome_has_its_own_colour_and_the_legend_names_them(tmp_path):
    view, logged = _view(tmp_path)
    assert len(set(OUTCOME_COLORS.values())) == len(OUTCOMES) and set(OUTCOME_COLORS) == set(OUTCOMES)
    legend = _last(logged, "scene/legend")
    assert [str(t) for t in legend.labels.pa_array.to_pylist()] == list(OUTCOMES)
    x = np.zeros((5, 6))
    x[:, 1] = np.linspace(2.5, 0.0, 5)
    for j, outcome in enumerate(OUTCOMES):
        result = {"id": f"s01-{j:03d}-CS1-train", "subject": "s01", "outcome": outcome,
                  "outcome_reason": f"{outcome}: why"}
        view.trial(result, {"x": x.tolist()}, {"label": "CS1", "role": "train"})
        track = _last(logged, f"trials/s01/{result['id']}")
        assert track.labels is None  # tracks carry no label: a thousand of them never pile up
        colour = track.colors.pa_array.to_pylist()[0]
        assert colour == int.from_bytes(bytes([*OUTCOME_COLORS[outcome], 255]), "big")
        newest = _last(logged, "trials/newest")
        assert newest.labels.pa_array.to_pylist() == [f"{result['id']}: {outcome}"]
    summary = str(_last(logged, "summary").text.pa_array.to_pylist()[0])
    assert "| subject | label | role | trials | landed | crashed | left the domain | time limit |" in summary
    assert "| s01 | CS1 | train | 4 | 1 | 1 | 1 | 1 |" in summary
    assert f"this recording: `{tmp_path / 'view.rrd'}`" in summary and "trials.csv" in summary


def test_fits_and_exclusions_are_in_the_summary(tmp_path):
    view, logged = _view(tmp_path)
    view.fit({"state": "failed", "subject": "s02", "label": "CS1", "reason": "2 landed trials; needs 3"})
    view.event("exclusion", "s01-003-CS1-train excluded (the subject sneezed)")
    summary = str(_last(logged, "summary").text.pa_array.to_pylist()[0])
    assert "| s02 | CS1 | — | not fitted: 2 landed trials; needs 3 | — |" in summary
    assert "`s01-003-CS1-train` excluded (the subject sneezed)" in summary
    view.event("exclusion", "s01-003-CS1-train included again")
    assert "s01-003" not in str(_last(logged, "summary").text.pa_array.to_pylist()[0])
