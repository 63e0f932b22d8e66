"""The sample logs in ``sample_logs/``: simulated landings written as a MAVLink tlog, an MCAP file and a CSV.

``python -m workbench.cli.sample_logs OUT_DIR [--seed N]`` (``make sample-logs``) regenerates them. The output
depends only on the seed: the simulator is seeded, times start at a fixed epoch (2024-01-01T00:00:00Z), and
no writer records a wall-clock time, so two runs give bit-identical files.

Each file holds one synthetic subject flying both control strategies (CS1: centre first, then descend; CS2:
straight line), :data:`TRIALS` trials each, with every demonstration's id, label, subject, target, success
and outcome in the log itself. Read any of them with ``adapters.load(path, mapping="planar_quadrotor")``.

This module joins the simulator and the adapters' writers, so only the CLI (floor 4) imports it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from adapters.formats import get_format
from adapters.mapping import load_mapping
from adapters.writer import demo_streams, layout
from workbench.data.demonstrations import DemonstrationSet
from workbench.sim.landing import STRATEGIES, simulate_landings

__all__ = ["write_sample_logs", "FILES", "TRIALS", "EPOCH", "PAUSE"]

#: file name -> (format, subject)
FILES = {
    "landing_s00.tlog": ("tlog", "s00"),
    "landing_s01.mcap": ("mcap", "s01"),
    "landing_s02.csv": ("csv", "s02"),
}
TRIALS = 10  # per strategy and file: 30 per strategy over the three files
EPOCH = 1_704_067_200.0  # 2024-01-01T00:00:00Z, the logs' fixed start
PAUSE = 2.0  # s between trials
MAPPING = "planar_quadrotor"


def simulated_set(subject: str, seed: int = 0, trials: int = TRIALS) -> DemonstrationSet:
    """Both strategies of one subject, CS1 trials first."""
    sets = [simulate_landings(s, trials, seed=seed, subject=subject) for s in STRATEGIES]
    out = sets[0]
    for s in sets[1:]:
        out = out + s
    return out


def _heartbeats(ds: DemonstrationSet) -> pd.DataFrame:
    """ArduCopter-like HEARTBEATs: STABILIZE and armed at 1 Hz during each trial, disarmed after it."""
    rows = []
    for start, end in layout(ds, EPOCH, PAUSE):
        for t in np.arange(start, end, 1.0):
            rows.append((t, 129, 4))  # MAV_MODE_FLAG_SAFETY_ARMED | CUSTOM_MODE_ENABLED, MAV_STATE_ACTIVE
        rows.append((end + PAUSE / 2, 1, 3))  # disarmed, MAV_STATE_STANDBY
    t, base_mode, status = (np.array(c) for c in zip(*rows, strict=True))
    n = len(t)
    return pd.DataFrame({
        "t": t, "type": np.full(n, 2), "autopilot": np.full(n, 3), "base_mode": base_mode,
        "custom_mode": np.zeros(n, dtype=np.int64), "system_status": status, "mavlink_version": np.full(n, 3),
    })


def _with_boot_time(streams: dict[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """Fill the messages' ``time_boot_ms`` as an autopilot booted at the epoch would."""
    for name in ("LOCAL_POSITION_NED", "ATTITUDE", "NAMED_VALUE_INT"):
        if name in streams:
            frame = streams[name].copy()
            frame["time_boot_ms"] = np.rint((frame["t"].to_numpy() - EPOCH) * 1000.0).astype(np.int64)
            streams[name] = frame
    return streams


def write_sample_logs(out_dir: str | Path, seed: int = 0) -> list[Path]:
    """Simulate and write the sample logs into ``out_dir``; returns the files written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    mapping = load_mapping(MAPPING)
    written = []
    for name, (fmt, subject) in FILES.items():
        ds = simulated_set(subject, seed)
        m = mapping.for_format(fmt)
        streams = demo_streams(ds, m, epoch=EPOCH, pause=PAUSE)
        options: dict = {}
        if fmt == "tlog":
            streams = _with_boot_time(streams)
            streams["HEARTBEAT"] = _heartbeats(ds)
        elif fmt == "mcap":
            options["metadata"] = {
                "workbench": {"generator": "workbench.cli.sample_logs", "seed": str(seed), "subject": subject,
                              "mapping": MAPPING, "epoch": f"{EPOCH:.0f}"}
            }
        path = out / name
        get_format(fmt).write(path, streams, **options)
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m workbench.cli.sample_logs", description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", nargs="?", default="sample_logs")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    for path in write_sample_logs(args.out_dir, args.seed):
        print(f"{path}  {path.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
