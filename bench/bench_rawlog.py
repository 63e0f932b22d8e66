"""The raw view's logging: ``send_columns`` per stream (workbench.viewer.rawlog) against a per-row ``rr.log`` loop.

A big generated tlog (``--minutes`` of flight of every message type the sample logs carry, at their rates and
a 50 Hz ATTITUDE / LOCAL_POSITION_NED / MANUAL_CONTROL) is read once; then the same streams are logged to an
``.rrd`` by :func:`workbench.viewer.rawlog.log_raw` and by a loop of ``set_time`` + ``rr.log`` per row and stream.
The per-row side runs on the first ``--rows`` rows of every stream and is scaled to the whole log (it is linear
in rows), so the bench ends in seconds; the row counts are printed.

``python bench/bench_rawlog.py [--minutes 60] [--rows 20000]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rerun as rr  # noqa: E402

import adapters  # noqa: E402
from adapters.rawlog import raw_log  # noqa: E402
from workbench.viewer.rawlog import log_raw  # noqa: E402


def _big_tlog(path: Path, minutes: float) -> Path:
    rng = np.random.default_rng(0)
    t50 = 1.7e9 + np.arange(0.0, 60.0 * minutes, 0.02)
    n = t50.size
    ms = np.rint((t50 - t50[0]) * 1000).astype(np.int64)
    streams = {
        "ATTITUDE": pd.DataFrame({"t": t50, "time_boot_ms": ms, **{k: rng.normal(size=n) for k in
                                  ("roll", "pitch", "yaw", "rollspeed", "pitchspeed", "yawspeed")}}),
        "LOCAL_POSITION_NED": pd.DataFrame({"t": t50 + 0.001, "time_boot_ms": ms,
                                            **{k: rng.normal(size=n) for k in ("x", "y", "z", "vx", "vy", "vz")}}),
        "MANUAL_CONTROL": pd.DataFrame({"t": t50 + 0.002, **{k: rng.integers(-1000, 1000, n) for k in "xyzr"}}),
    }
    t1 = t50[::50]
    streams["HEARTBEAT"] = pd.DataFrame({"t": t1, "type": 2, "autopilot": 3, "base_mode": 129, "custom_mode": 0,
                                         "system_status": 4, "mavlink_version": 3})
    adapters.FORMATS["tlog"].write(path, streams)
    return path


def _columnar(raw, path: Path) -> float:
    rec = rr.RecordingStream("bench_raw")
    rec.save(path)
    t0 = time.perf_counter()
    log_raw(rec, raw)
    rec.flush()
    rec.disconnect()
    return time.perf_counter() - t0


def _per_row(raw, path: Path, rows: int) -> tuple[float, int]:
    rec = rr.RecordingStream("bench_raw")
    rec.save(path)
    t0 = time.perf_counter()
    done = 0
    for s in raw.streams:
        entity = f"log/streams/{s.name}"
        for k in range(min(rows, len(s.t))):
            rec.set_time("time", duration=float(s.t[k] - raw.t_start))
            rec.log(entity, rr.Scalars(s.values[k]))
            done += 1
    rec.flush()
    rec.disconnect()
    return time.perf_counter() - t0, done


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--rows", type=int, default=20000)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        log = _big_tlog(Path(tmp) / "big.tlog", a.minutes)
        size = log.stat().st_size
        t0 = time.perf_counter()
        raw = raw_log(adapters.read(log))
        read_s = time.perf_counter() - t0
        total = sum(len(s.t) for s in raw.streams)
        col = _columnar(raw, Path(tmp) / "col.rrd")
        row_s, done = _per_row(raw, Path(tmp) / "row.rrd", a.rows)
        row_all = row_s * total / done
    print(f"| raw view of a {size / 1e6:.0f} MB tlog ({total} rows, {sum(s.values.size for s in raw.streams)} values)"
          f" | read + gather {read_s:.2f} s | send_columns {col:.2f} s | per-row rr.log {row_all:.1f} s "
          f"(measured on {done} rows, scaled) | {row_all / col:.0f}× |")


if __name__ == "__main__":
    main()
