"""The sample logs (workbench/sample_logs.py): bit-identical for a seed, small, and loadable in every format."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

import adapters
from workbench.cli.sample_logs import FILES, TRIALS, simulated_set, write_sample_logs

REPO = Path(__file__).resolve().parents[2]


def _digests(paths):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in paths}


def test_regeneration_is_bit_identical_and_matches_the_committed_logs(tmp_path):
    first = write_sample_logs(tmp_path / "a", seed=0)
    second = write_sample_logs(tmp_path / "b", seed=0)
    assert _digests(first) == _digests(second)
    committed = [REPO / "sample_logs" / name for name in FILES]
    if all(p.is_file() for p in committed):
        assert _digests(committed) == _digests(first), "sample_logs/ is stale: run `make sample-logs`"
    assert sum(p.stat().st_size for p in first) <= 5 * 2**20
    assert _digests(write_sample_logs(tmp_path / "c", seed=1)) != _digests(first)


def test_every_sample_log_loads_as_its_simulated_set(tmp_path):
    total = {"CS1": 0, "CS2": 0}
    for path in write_sample_logs(tmp_path, seed=0):
        fmt, subject = FILES[path.name]
        ds = adapters.load(path, "planar_quadrotor")
        expected = simulated_set(subject, seed=0)
        assert ds.ids == expected.ids
        assert [len(d) for d in ds] == [len(d) for d in expected]
        for a, b in zip(expected, ds, strict=True):
            assert b.meta["label"] == a.meta["label"] and b.meta["subject"] == subject
            np.testing.assert_allclose(b.x, a.x, rtol=1e-6, atol=1e-6)
            np.testing.assert_allclose(b.u, a.u, rtol=0, atol=5e-4 + 1e-12)
        for label in total:
            total[label] += len(ds.by_label(label))
    assert total == {"CS1": len(FILES) * TRIALS, "CS2": len(FILES) * TRIALS}
    assert min(total.values()) >= 20
