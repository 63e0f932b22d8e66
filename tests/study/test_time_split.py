"""One manual segment is evaluated by a time split inside it (workbench.study.pipeline.split_in_time)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.errors import DataError
from workbench.study.pipeline import TIME_SPLIT_PIECES, split_in_time


def _one(n: int) -> DemonstrationSet:
    t = 0.1 * np.arange(n)
    x = np.column_stack([np.sin(t), np.cos(t)])
    return DemonstrationSet([Demonstration(t, x, x[:, :1], {"id": "flight-000", "t0": 50.0})], ["a", "b"], ["u"], 0.1)


def test_one_segment_becomes_contiguous_pieces_longer_than_the_horizon():
    ds, n_steps = _one(400), 30
    parts = split_in_time(ds, n_steps)
    assert len(parts) == TIME_SPLIT_PIECES
    assert sum(len(d.t) for d in parts) == len(ds[0].t)
    np.testing.assert_array_equal(np.concatenate([d.x for d in parts]), ds[0].x)
    assert all(len(d.t) > n_steps + 1 for d in parts)
    starts = [d.meta["t0"] for d in parts]
    assert starts[0] == 50.0 and starts == sorted(starts)
    assert [d.id for d in parts] == [f"flight-000.t{i + 1}" for i in range(len(parts))]


def test_a_segment_too_short_for_two_pieces_says_so():
    with pytest.raises(DataError, match="too short to split into two pieces longer than the 3 s horizon"):
        split_in_time(_one(50), 30)


def test_evaluate_of_one_segment_names_pieces_not_segments(tmp_path, capsys):
    """flug LetzteTestsGerolfing log_27 (one POSCTL segment) printed "one manual segment (50.4 s): evaluated by a
    time split inside it, 3 contiguous pieces …" and then "leave-one-segment-out over 3 segments"."""
    from workbench.cli.app import main
    from workbench.sim.modes import ModeVehicle, fly

    one = fly(ModeVehicle(), "angle", seconds=30.0, n=1, seed=0)
    path = one.save(tmp_path / "one.parquet")
    assert main(["evaluate", str(path), "--samples", "0", "--no-efficiency", "--n-components", "1"]) == 0
    out = capsys.readouterr().out
    assert f"{TIME_SPLIT_PIECES} contiguous pieces" in out
    assert f"over {TIME_SPLIT_PIECES} segments" not in out and "leave-one-segment-out over" not in out
