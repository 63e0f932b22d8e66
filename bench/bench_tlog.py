"""Benchmark: reading MAVLink telemetry logs with adapters.tlog versus pymavlink's own parser.

Run ``python bench/bench_tlog.py`` (``--quick`` for a smaller generated log) from the repository root; a
driver may call :func:`run`. Cases:

* ``dronekit_flight.tlog`` (``../shared/external``, a real 1377 s ArduCopter flight, MAVLink 1): both
  readers on the whole file;
* a generated ~1 M-message MAVLink 2 log (written by :func:`adapters.tlog.write_tlog` into a temporary
  folder): our reader on the whole file, pymavlink on a prefix of its first messages (100 k; 20 k with
  ``quick``), since its rate does not depend on file length. Rates are messages per second; the ratio is
  ours / pymavlink's.

pymavlink is timed as its users run it: ``mavutil.mavlink_connection(path)`` then ``recv_match()`` until it
returns None. Our times are the best of a few warm runs (the first call in a process also imports the
pymavlink dialect module, reported separately as ``ours_cold_s``). Peak memory of one read is measured in a
fresh subprocess (Linux): the high-water mark of its resident set size, reset just before the read
(after the imports), minus the resident size at that moment; and tracemalloc's peak of traced
allocations (numpy reports its buffers to tracemalloc).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from adapters.tlog import read_tlog, write_tlog  # noqa: E402

EXTERNAL = ROOT / ".." / "shared" / "external"

_MEMORY_PROBE = """
import json, sys, tracemalloc
import numpy, pandas
from adapters.mavlink_dialect import load_dialect
from adapters.tlog import read_tlog

def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(key))

load_dialect()
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # reset the high-water mark VmHWM to the current RSS
before = status("VmRSS:")
if sys.argv[2] == "trace":
    tracemalloc.start()
read = read_tlog(sys.argv[1])
peak = tracemalloc.get_traced_memory()[1] if sys.argv[2] == "trace" else 0
after = status("VmHWM:")
out = sum(int(df.memory_usage(deep=True).sum()) for df in read.streams.values())
print(json.dumps({"rss_kb": after - before, "traced": peak, "output": out}))
"""


def generate_log(path: Path, n_messages: int, seed: int = 0) -> int:
    """Write a MAVLink 2 tlog of about ``n_messages`` records: a vehicle streaming the usual telemetry."""
    rng = np.random.default_rng(seed)
    rates = {
        "ATTITUDE": 50, "LOCAL_POSITION_NED": 50, "MANUAL_CONTROL": 50, "GLOBAL_POSITION_INT": 25,
        "RC_CHANNELS": 25, "SERVO_OUTPUT_RAW": 25, "SYS_STATUS": 5, "HEARTBEAT": 1, "NAMED_VALUE_INT": 1,
        "STATUSTEXT": 0.2,
    }
    duration = n_messages / sum(rates.values())
    records = {}
    for name, hz in rates.items():
        n = int(round(duration * hz))
        k = np.arange(n)
        cols: dict[str, np.ndarray] = {"t": 1.7e9 + k / hz + rng.uniform(0.0, 1e-3, n)}
        if name in ("ATTITUDE", "LOCAL_POSITION_NED"):
            fields = ("roll", "pitch", "yaw", "rollspeed", "pitchspeed", "yawspeed") if name == "ATTITUDE" \
                else ("x", "y", "z", "vx", "vy", "vz")
            cols.update(time_boot_ms=k * 20, **{f: rng.normal(0.0, 1.0, n) for f in fields})
        elif name == "MANUAL_CONTROL":
            cols.update(target=np.ones(n), **{f: rng.integers(-1000, 1001, n) for f in "xyzr"},
                        buttons=rng.integers(0, 4, n))
        elif name == "GLOBAL_POSITION_INT":
            cols.update(time_boot_ms=k * 40, lat=rng.integers(-900_000_000, 900_000_000, n),
                        lon=rng.integers(-1_800_000_000, 1_800_000_000, n), alt=rng.integers(0, 100_000, n),
                        relative_alt=rng.integers(0, 100_000, n), hdg=rng.integers(0, 36_000, n))
        elif name == "RC_CHANNELS":
            cols.update(time_boot_ms=k * 40, chancount=np.full(n, 8), rssi=np.full(n, 255),
                        **{f"chan{i}_raw": rng.integers(1000, 2000, n) for i in range(1, 9)})
        elif name == "SERVO_OUTPUT_RAW":
            cols.update(time_usec=(k * 40_000) % 2**32,
                        **{f"servo{i}_raw": rng.integers(1000, 2000, n) for i in range(1, 9)})
        elif name == "SYS_STATUS":
            cols.update(voltage_battery=rng.integers(10_000, 12_600, n), load=rng.integers(0, 1000, n))
        elif name == "HEARTBEAT":
            cols.update(type=np.full(n, 2), autopilot=np.full(n, 3), base_mode=np.where(k % 2, 209, 81),
                        custom_mode=k % 6, system_status=np.full(n, 4), mavlink_version=np.full(n, 3))
        elif name == "NAMED_VALUE_INT":
            cols.update(time_boot_ms=k * 1000, name=np.array(["demo"] * n, dtype=object), value=k % 30)
        else:
            cols.update(severity=np.full(n, 6), text=np.array([f"event {i}" for i in k], dtype=object))
        records[name] = cols
    return write_tlog(path, records)


def time_pymavlink(path: Path, limit: int | None = None) -> tuple[float, int]:
    """Seconds pymavlink's recv_match loop takes for the first ``limit`` messages (all if None), and the
    number of decoded messages among them (its BAD_DATA reports of corrupt frames are not counted)."""
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(path))
    n = n_bad = 0
    try:
        start = time.perf_counter()
        while limit is None or n < limit:
            msg = conn.recv_match(blocking=False)
            if msg is None:
                break
            n += 1
            n_bad += msg.get_type() == "BAD_DATA"
        elapsed = time.perf_counter() - start
    finally:
        conn.close()
    return elapsed, n - n_bad


def time_ours(path: Path, repeat: int) -> tuple[float, float, int]:
    """(first-call seconds, best warm seconds, records) of read_tlog."""
    start = time.perf_counter()
    read = read_tlog(path)
    cold = time.perf_counter() - start
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        read_tlog(path)
        best = min(best, time.perf_counter() - start)
    return cold, best, read.report.n_records


def peak_memory(path: Path) -> dict[str, float]:
    """Peak memory of one read in a fresh interpreter: RSS growth and tracemalloc peak, in MB."""
    result = {}
    for mode in ("rss", "trace"):
        out = subprocess.run(
            [sys.executable, "-c", _MEMORY_PROBE, str(path), mode],
            capture_output=True, text=True, check=True, cwd=ROOT,
        )
        probe = json.loads(out.stdout.strip().splitlines()[-1])
        if mode == "rss":
            result["peak_rss_delta_MB"] = probe["rss_kb"] / 1024
            result["output_MB"] = probe["output"] / 2**20
        else:
            result["peak_traced_MB"] = probe["traced"] / 2**20
    return result


def _case(name: str, path: Path, pm_limit: int | None, repeat: int, memory: bool) -> dict:
    pm_s, pm_n = time_pymavlink(path, pm_limit)
    cold, warm, n = time_ours(path, repeat)
    row = {
        "case": name,
        "messages": n,
        "file_MB": path.stat().st_size / 2**20,
        "pymavlink_messages_timed": pm_n,
        "pymavlink_s": pm_s,
        "pymavlink_msg_per_s": pm_n / pm_s,
        "ours_s": warm,
        "ours_cold_s": cold,
        "ours_msg_per_s": n / warm,
    }
    row["ratio"] = row["ours_msg_per_s"] / row["pymavlink_msg_per_s"]
    if memory:
        row.update(peak_memory(path))
    return row


def run(quick: bool = False) -> list[dict]:
    """Run every case; one dict of measurements per case."""
    rows = []
    dronekit = EXTERNAL / "dronekit_flight.tlog"
    if dronekit.exists():
        rows.append(_case("dronekit_flight.tlog (real, MAVLink 1)", dronekit, None, 5 if quick else 10, False))
    n_big = 200_000 if quick else 1_000_000
    with tempfile.TemporaryDirectory(prefix="bench_tlog_") as tmp:
        big = Path(tmp) / "generated.tlog"
        start = time.perf_counter()
        written = generate_log(big, n_big)
        write_s = time.perf_counter() - start
        row = _case(
            f"generated {written / 1e6:.2f} M messages (MAVLink 2)", big, 20_000 if quick else 100_000,
            2 if quick else 3, True,
        )
        row["write_tlog_s"] = write_s
        rows.append(row)
    return rows


def markdown(rows: list[dict]) -> str:
    head = ("| case | messages | file MB | pymavlink msg/s (msgs timed) | ours msg/s | ratio | ours s (cold s) "
            "| peak RSS Δ MB | traced peak MB | output MB |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['messages']:,} | {r['file_MB']:.1f} "
            f"| {r['pymavlink_msg_per_s']:,.0f} ({r['pymavlink_messages_timed']:,}) "
            f"| {r['ours_msg_per_s']:,.0f} | {r['ratio']:.1f}× | {r['ours_s']:.3f} ({r['ours_cold_s']:.3f}) "
            f"| {r.get('peak_rss_delta_MB', float('nan')):.0f} | {r.get('peak_traced_MB', float('nan')):.0f} "
            f"| {r.get('output_MB', float('nan')):.0f} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="200 k generated messages, shorter timings")
    args = parser.parse_args()
    rows = run(quick=args.quick)
    print(markdown(rows))
    if any(r.get("write_tlog_s") for r in rows):
        r = rows[-1]
        print(f"\nwrite_tlog wrote the generated log in {r['write_tlog_s']:.2f} s "
              f"({r['messages'] / r['write_tlog_s']:,.0f} msg/s).")


if __name__ == "__main__":
    main()
