"""A mapping's grid step is checked against the log before anything is allocated: far below the sample
intervals, or more rows than a set limit, is one line saying why."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import adapters
import adapters.align
from workbench.errors import DataError

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "landing_s00.tlog"


def _mapping(tmp_path: Path, dt: str) -> Path:
    text = (REPO / "adapters" / "mappings" / "planar_quadrotor.toml").read_text()
    out = tmp_path / f"dt_{dt}.toml"
    out.write_text(re.sub(r"^dt = .*$", f"dt = {dt}", text, count=1, flags=re.M))
    return out


@pytest.mark.parametrize("dt", ["1e-5", "1e-6", "1e-300"])
def test_a_dt_far_below_the_logs_sample_intervals_is_refused(tmp_path, dt):
    streams = adapters.read_streams(LOG, ["LOCAL_POSITION_NED"])
    interval = float(np.median(np.diff(streams["LOCAL_POSITION_NED"]["t"].to_numpy())))
    with pytest.raises(DataError, match=r"finer than the log's finest channel") as err:
        adapters.load(LOG, mapping=str(_mapping(tmp_path, dt)))
    assert f"{interval:.3g} s" in str(err.value)


def test_a_grid_of_more_rows_than_the_limit_is_refused(tmp_path, monkeypatch):
    fine = adapters.load(LOG, mapping=str(_mapping(tmp_path, "0.01")))  # 5× finer than the log: allowed
    monkeypatch.setattr(adapters.align, "MAX_ROWS", fine.n_samples // 2)
    with pytest.raises(DataError, match="grid rows"):
        adapters.load(LOG, mapping=str(_mapping(tmp_path, "0.01")))


def test_the_cli_says_it_in_one_line(tmp_path):
    out = subprocess.run([sys.executable, "-m", "workbench", "import", str(LOG), "--mapping",
                          str(_mapping(tmp_path, "1e-5")), "-o", str(tmp_path / "x.parquet")],
                         capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert out.returncode == 1 and len(out.stderr.strip().splitlines()) == 1 and "dt = 1e-05" in out.stderr
    assert not (tmp_path / "x.parquet").exists()
