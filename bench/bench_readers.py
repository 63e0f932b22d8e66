"""Readers against their peer libraries, same files, same values, one run: CSV, ULog, tlog, MCAP (JSON and CDR),
DataFlash (.bin).

Every ratio is ``peer seconds / our seconds`` (above 1: ours is faster), both sides run the same number of
times, interleaved, summarised by the median (``harness``). Three ways of timing each case:

* **warm** — a repeated call in one process (``harness.interleaved``);
* **cold** — the first call in a fresh process, its module imported before the clock starts;
* **process** — ``python -c "import …; read(path)"`` from start to exit.

Peers: ``pandas.read_csv`` (its default C engine; the pyarrow engine is shown too), ``pyulog.ULog`` with its topic
filter, pymavlink's ``mavlink_connection`` + ``recv_match`` loop (``type=`` for typed reads; pymavlink decodes
every message either way), the ``mcap`` library's ``iter_decoded_messages`` (JSON through our decoder
factory, CDR through ``mcap_ros2``'s), and pymavlink's ``DFReader_binary`` + ``recv_msg`` loop over every message
(its C indexer included). Before timing, each case checks that both sides return the same values.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness import (  # noqa: E402
    ROOT,
    first_calls,
    import_and_first_call,
    interleaved,
    peak_memory,
    processes,
    verdict,
)

EXTERNAL = ROOT.parent / "shared" / "external"
SAMPLE_LOGS = ROOT / "sample_logs"

_PYMAVLINK_LOOP = """
def pymavlink_read(path, kind=None, keep=False):
    conn = mavutil.mavlink_connection(str(path))
    out = []
    n = 0
    while True:
        msg = conn.recv_match(type=kind, blocking=False)
        if msg is None:
            break
        n += 1
        if keep:
            out.append(msg)
    conn.close()
    return out if keep else n
"""
_PM_IMPORTS = "from pymavlink import mavutil\n" + _PYMAVLINK_LOOP


def _pymavlink(path: Path, kind: str | None = None, keep: bool = False):
    from pymavlink import mavutil

    namespace = {"mavutil": mavutil}
    exec(_PYMAVLINK_LOOP, namespace)  # the same source the subprocess cases run
    return namespace["pymavlink_read"](path, kind, keep)


def _row(reader: str, case: str, mode: str, ours: float, peer: float, peer_name: str, **extra) -> dict:
    return {"reader": reader, "case": case, "mode": mode, "ours_s": ours, "peer": peer_name, "peer_s": peer,
            "speed_ratio": peer / ours, **extra}


def _target(row: dict, bar: float, text: str) -> dict:
    row.update(target=text, met=verdict(row["speed_ratio"], bar, True))
    return row


# ------------------------------------------------------------------------------------------------------- CSV
def _csv_files(tmp: Path) -> dict[str, Path]:
    from workbench.sim.landing import simulate_landings

    big = tmp / "landings_300.csv"
    ds = simulate_landings("CS1", 150, seed=3)
    ds2 = simulate_landings("CS2", 150, seed=4)
    pd.concat([ds.to_pandas(), ds2.to_pandas()], ignore_index=True).to_csv(big, index=False)
    return {"landing_s02.csv (sample log)": SAMPLE_LOGS / "landing_s02.csv", "300 simulated landings": big}


def bench_csv(tmp: Path) -> list[dict]:
    from adapters.formats import csv

    rows = []
    for case, path in _csv_files(tmp).items():
        ours_frame, peer_frame = csv.read(path)["csv"], pd.read_csv(path)
        for c in peer_frame.columns:
            if c not in ("t", "demo") and peer_frame[c].dtype.kind in "biuf":
                assert np.array_equal(ours_frame[c].to_numpy(float), peer_frame[c].to_numpy(float), equal_nan=True)
        case = f"{case}, {path.stat().st_size / 1e6:.1f} MB, {len(peer_frame)} rows"
        warm = interleaved({"ours": lambda p=path: csv.read(p), "c": lambda p=path: pd.read_csv(p),
                            "pa": lambda p=path: pd.read_csv(p, engine="pyarrow")}, 7)
        rows.append(_target(_row("CSV", case, "warm", warm["ours"], warm["c"], "pandas.read_csv"), 0.8, "≥ 0.8×"))
        rows.append(_row("CSV", case, "warm", warm["ours"], warm["pa"], "pandas.read_csv(engine='pyarrow')"))
        cold = first_calls({"ours": ("from adapters.formats import csv", "csv.read(sys.argv[1])"),
                            "peer": ("import pandas as pd", "pd.read_csv(sys.argv[1])")}, 3, str(path))
        rows.append(_target(_row("CSV", case, "cold", cold["ours"], cold["peer"], "pandas.read_csv"), 0.8, "≥ 0.8×"))
        proc = processes({"ours": "import sys, adapters; adapters.read_streams(sys.argv[1])",
                          "peer": "import sys, pandas as pd; pd.read_csv(sys.argv[1])"}, 3, str(path))
        rows.append(_row("CSV", case, "process", proc["ours"], proc["peer"], "pandas.read_csv"))
    return rows


# ------------------------------------------------------------------------------------------------------ ULog
def bench_ulog() -> list[dict]:
    from pyulog import ULog

    import adapters
    from adapters.formats import ulog

    path = EXTERNAL / "px4_sample_log_small.ulg"
    if not path.exists():
        return [{"reader": "ULog", "case": f"{path} missing: not measured"}]
    mapped = adapters.load_mapping("px4_manual").for_format("ulog").stream_candidates()
    rows = []
    for label, topics in ((f"mapped topics {mapped}", mapped), ("all topics", None)):
        ours = ulog.read(path, topics)
        peer = ULog(str(path), topics)
        for d in peer.data_list:
            frame = ours[d.name if d.multi_id == 0 else f"{d.name}/{d.multi_id}"]
            for k, v in d.data.items():
                if k != "timestamp":
                    assert np.array_equal(frame[k].to_numpy(), v, equal_nan=True)
        case = f"px4_sample_log_small.ulg ({path.stat().st_size / 1e6:.1f} MB), {label}"
        warm = interleaved({"ours": lambda t=topics: ulog.read(path, t),
                            "peer": lambda t=topics: ULog(str(path), t)}, 7)
        row = _row("ULog", case, "warm", warm["ours"], warm["peer"], "pyulog.ULog")
        rows.append(_target(row, 1.0, "≥ 1×") if topics else row)
        arg = repr(topics)
        cold = first_calls({"ours": ("from adapters.formats import ulog", f"ulog.read(sys.argv[1], {arg})"),
                            "peer": ("from pyulog import ULog", f"ULog(sys.argv[1], {arg})")}, 3, str(path))
        row = _row("ULog", case, "cold", cold["ours"], cold["peer"], "pyulog.ULog")
        rows.append(_target(row, 1.0, "≥ 1×") if topics else row)
        proc = processes({"ours": f"import sys, adapters; adapters.read_streams(sys.argv[1], {arg})",
                          "peer": f"import sys; from pyulog import ULog; ULog(sys.argv[1], {arg})"}, 3, str(path))
        rows.append(_row("ULog", case, "process", proc["ours"], proc["peer"], "pyulog.ULog"))
    return rows


# ------------------------------------------------------------------------------------------------------ tlog
def generate_log(path: Path, n_messages: int, seed: int = 0) -> int:
    """A MAVLink 2 tlog of about ``n_messages`` records: a vehicle streaming the usual telemetry (10 types)."""
    from adapters.formats.tlog_write import write_tlog

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


def generate_many_types(path: Path, n_types: int = 41, size_bytes: int = 1_000_000, seed: int = 0) -> int:
    """A ~1 MB MAVLink 2 tlog with ``n_types`` message types (ids below 256, numeric fields), random values."""
    from adapters.formats.mavlink_dialect import load_dialect
    from adapters.formats.tlog_write import write_tlog

    rng = np.random.default_rng(seed)
    dialect = load_dialect()
    layouts = [lay for lay in sorted(dialect.by_id.values(), key=lambda x: x.msgid)
               if lay.msgid < 256 and not any(f.is_text for f in lay.fields)][:n_types]
    per_type = max(1, size_bytes // sum(lay.size + 20 for lay in layouts))
    records = {}
    for j, lay in enumerate(layouts):
        cols: dict[str, np.ndarray] = {"t": 1.7e9 + np.sort(rng.uniform(0, 600, per_type)) + j * 1e-4}
        for f in lay.fields:
            for c in f.columns:
                cols[c] = (rng.normal(0, 100, per_type) if f.wire_dtype.kind == "f"
                           else rng.integers(0, min(np.iinfo(f.wire_dtype).max, 100) + 1, per_type))
        records[lay.name] = cols
    return write_tlog(path, records)


def _check_tlog(path: Path) -> None:
    from adapters.formats.tlog import read_tlog

    ours = read_tlog(path)
    msgs = _pymavlink(path, keep=True)
    good = [m for m in msgs if m.get_type() != "BAD_DATA"]
    assert len(good) == sum(ours.report.counts.values()), (len(good), ours.report.counts)
    att = [m for m in good if m.get_type() == "ATTITUDE"]
    if att:
        assert np.array_equal(ours.streams["ATTITUDE"]["roll"].to_numpy(), np.array([m.roll for m in att]))
        assert np.array_equal(ours.streams["ATTITUDE"]["t"].to_numpy(), np.array([m._timestamp for m in att]))


def bench_tlog(tmp: Path) -> list[dict]:
    from adapters.formats.tlog import read_streams, read_tlog

    small = tmp / "many_types_1MB.tlog"
    generate_many_types(small)
    large = tmp / "generated_400k.tlog"
    generate_log(large, 400_000)
    cases = [("small", f"generated, 41 message types, {small.stat().st_size / 1e6:.1f} MB", small)]
    dronekit = EXTERNAL / "dronekit_flight.tlog"
    if dronekit.exists():
        cases.append(("small", f"dronekit_flight.tlog (real flight, {dronekit.stat().st_size / 1e6:.1f} MB)",
                      dronekit))
    cases.append(("large", f"generated, 10 types, 400k messages, {large.stat().st_size / 1e6:.1f} MB", large))
    rows = []
    for size, case, path in cases:
        _check_tlog(path)
        reps = 5 if size == "small" else 1
        # The large log's first calls (cold) come from fresh processes below; in-process, the checks above
        # already ran both readers once, so every timed call here is warm.
        warm = interleaved({"ours": lambda p=path: read_tlog(p), "peer": lambda p=path: _pymavlink(p)}, reps,
                           warmup=size == "small")
        rows.append(_row("tlog", case, "warm", warm["ours"], warm["peer"], "pymavlink recv_match"))
        cold = first_calls({"ours": ("from adapters.formats import tlog", "tlog.read_tlog(sys.argv[1])"),
                            "peer": (_PM_IMPORTS, "pymavlink_read(sys.argv[1])")}, 3 if size == "small" else 1,
                           str(path))
        row = _row("tlog", case, "cold (first call in a process)", cold["ours"], cold["peer"], "pymavlink recv_match")
        rows.append(_target(row, 10.0, "≥ 10×") if size == "small" else _target(row, 20.0, "≥ 20×"))
        proc = processes({"ours": "import sys, adapters; adapters.read_streams(sys.argv[1])",
                          "peer": "import sys\n" + _PM_IMPORTS + "pymavlink_read(sys.argv[1])"},
                         3 if size == "small" else 1, str(path))
        rows.append(_row("tlog", case, "process", proc["ours"], proc["peer"], "pymavlink recv_match"))
        if size == "small":
            # issue 18: what `workbench inspect` waits for beyond the interpreter: the reader's imports (numpy,
            # no pandas) and the read into numpy columns, against pymavlink's import and read of the same file
            for cold_cache in (True, False):
                first = import_and_first_call(
                    {"ours": ("import adapters", "adapters.read(sys.argv[1])"),
                     "peer": (_PM_IMPORTS, "pymavlink_read(sys.argv[1])")}, 3, str(path), cold=cold_cache)
                mode = f"first call (fresh process, import + read), file cache {'cold' if cold_cache else 'warm'}"
                rows.append(_target(_row("tlog", case, mode, first["ours"], first["peer"], "pymavlink recv_match"),
                                    10.0, "≥ 10×"))
        if path != small:
            typed = interleaved({"ours": lambda p=path: read_streams(p, ["ATTITUDE"]),
                                 "peer": lambda p=path: _pymavlink(p, "ATTITUDE")}, reps, warmup=size == "small")
            row = _row("tlog", case, "typed read, warm: ATTITUDE only", typed["ours"], typed["peer"],
                       "pymavlink recv_match(type=)")
            rows.append(_target(row, 10.0, "≥ 10×"))
    # Peak memory of one read of the large log, above the baseline after the imports.
    mb = large.stat().st_size / 2**20
    ours = peak_memory("from adapters.formats import tlog\nfrom adapters.formats.mavlink_dialect import load_dialect",
                       "tlog.read_tlog(sys.argv[1])", str(large), warm="load_dialect()")
    peer = peak_memory(_PM_IMPORTS, "pymavlink_read(sys.argv[1], keep=True)", str(large))
    for name, m in (("ours", ours), ("pymavlink, keeping the messages", peer)):
        row = {"reader": "tlog", "case": f"peak memory, {name}, {mb:.1f} MiB file", "mode": "memory",
               "rss_peak_MB": m["rss_MB"], "traced_peak_MB": m["traced_MB"],
               "rss_x_file": m["rss_MB"] / mb, "traced_x_file": m["traced_MB"] / mb}
        if name == "ours":
            row.update(target="≤ 2× file (RSS high-water mark)", met=verdict(row["rss_x_file"], 2.0, False))
        rows.append(row)
    return rows


# ------------------------------------------------------------------------------------------------------ MCAP
def _mcap_json(path: Path, n: int) -> Path:
    from adapters.formats import mcap

    rng = np.random.default_rng(0)
    k = n // 2
    t = 1_704_067_200.0 + 0.05 * np.arange(k)
    state = pd.DataFrame({"t": t, "demo": np.arange(k) // 200})
    for group in ("pose", "twist"):
        for axis in ("x", "y", "phi"):
            state[f"{group}.{axis}"] = rng.standard_normal(k)
    sticks = pd.DataFrame({"t": t, "sticks[0]": rng.uniform(-1, 1, k), "sticks[1]": rng.uniform(-1, 1, k)})
    return mcap.write(path, {"/quadrotor/state": state, "/quadrotor/input": sticks})


def _mcap_cdr(path: Path, n: int) -> Path:
    from mcap_ros2.writer import Writer

    rng = np.random.default_rng(0)
    with open(path, "wb") as f:
        writer = Writer(f)
        schema = writer.register_msgdef("geometry_msgs/msg/Vector3", "float64 x\nfloat64 y\nfloat64 z")
        for i in range(n):
            x, y, z = rng.standard_normal(3)
            stamp = 1_704_067_200_000_000_000 + i * 10_000_000
            writer.write_message("/vector", schema, {"x": x, "y": y, "z": z}, log_time=stamp, publish_time=stamp)
        writer.finish()
    return path


def _mcap_library(path: Path) -> int:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from adapters.formats import mcap

    count = 0
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[mcap.JsonDecoderFactory(), DecoderFactory()])
        for _schema, _channel, _message, _decoded in reader.iter_decoded_messages():
            count += 1
    return count


def bench_mcap(tmp: Path) -> list[dict]:
    from adapters.formats import mcap

    rows = []
    for case, path in (("JSON channels, zstd, 200k messages", _mcap_json(tmp / "json.mcap", 200_000)),
                       ("ROS 2 CDR, one Vector3 topic, 50k messages", _mcap_cdr(tmp / "cdr.mcap", 50_000))):
        assert sum(len(f) for f in mcap.read(path).frames.values()) == _mcap_library(path)
        warm = interleaved({"ours": lambda p=path: mcap.read(p), "peer": lambda p=path: _mcap_library(p)}, 3)
        row = _row("MCAP", f"{case}, {path.stat().st_size / 1e6:.1f} MB", "warm", warm["ours"], warm["peer"],
                   "mcap iter_decoded_messages")
        rows.append(_target(row, 1 / 1.3, "≥ 0.77× (time ≤ 1.3× the library loop)"))
    return rows


# ------------------------------------------------------------------------------------------------- DataFlash
_DFREADER_LOOP = """
def dfreader_read(path, kind=None):
    reader = DFReader.DFReader_binary(str(path))
    n = 0
    while (reader.recv_msg() if kind is None else reader.recv_match(type=kind)) is not None:
        n += 1
    reader.close()
    return n
"""
_DF_IMPORTS = "from pymavlink import DFReader\n" + _DFREADER_LOOP


def _dfreader(path: Path, kind: str | None = None) -> int:
    from pymavlink import DFReader

    namespace = {"DFReader": DFReader}
    exec(_DFREADER_LOOP, namespace)  # the same source the subprocess cases run
    return namespace["dfreader_read"](path, kind)


def _check_dataflash(path: Path) -> int:
    from pymavlink import DFReader

    from adapters.formats import dataflash

    ours = dataflash.read(path)
    reader = DFReader.DFReader_binary(str(path))
    roll = []
    n = 0
    while (m := reader.recv_msg()) is not None:
        n += 1
        if m.get_type() == "ATT":
            roll.append(m.Roll)
    reader.close()
    assert n == sum(ours.counts.values()), (n, ours.counts)
    assert np.array_equal(ours["ATT"]["Roll"].to_numpy(), np.array(roll))
    return n


def bench_dataflash(tmp: Path) -> list[dict]:
    """Every message of a .bin, cold and warm: the real 2015 ArduCopter log and a generated 4.x-style log."""
    from adapters.formats import dataflash, dataflash_write

    big = tmp / "generated_copter.bin"
    dataflash_write.write_example(big, "new", "copter", seconds=300.0, rate=7.0, seed=2)
    cases = []
    real = EXTERNAL / "erle_copter_83.BIN"
    if real.exists():
        cases.append(("small", real, f"erle_copter_83.BIN (real ArduCopter 3.3, {real.stat().st_size / 1e6:.1f} MB"))
    mb = big.stat().st_size / 1e6
    cases.append(("large", big, f"generated ArduCopter 4.x-style log (FMTU, instances, {mb:.1f} MB"))
    rows = []
    for size, path, label in cases:
        n = _check_dataflash(path)
        case = f"{label}, {n} messages)"
        reps = 7 if size == "small" else 3
        warm = interleaved({"ours": lambda p=path: dataflash.read(p), "peer": lambda p=path: _dfreader(p)}, reps)
        row = _row("DataFlash", case, "warm", warm["ours"], warm["peer"], "pymavlink DFReader_binary recv_msg")
        rows.append(_target(row, 10.0, "≥ 10×"))
        cold = first_calls({"ours": ("from adapters.formats import dataflash", "dataflash.read(sys.argv[1])"),
                            "peer": (_DF_IMPORTS, "dfreader_read(sys.argv[1])")}, reps, str(path))
        row = _row("DataFlash", case, "cold (first call in a process)", cold["ours"], cold["peer"],
                   "pymavlink DFReader_binary recv_msg")
        rows.append(_target(row, 10.0, "≥ 10×"))
        proc = processes({"ours": "import sys, adapters; adapters.read_streams(sys.argv[1])",
                          "peer": "import sys\n" + _DF_IMPORTS + "dfreader_read(sys.argv[1])"}, 3, str(path))
        rows.append(_row("DataFlash", case, "process", proc["ours"], proc["peer"],
                         "pymavlink DFReader_binary recv_msg"))
        typed = interleaved({"ours": lambda p=path: dataflash.read(p, ["ATT"]),
                             "peer": lambda p=path: _dfreader(p, "ATT")}, reps)
        rows.append(_row("DataFlash", case, "typed read, warm: ATT only", typed["ours"], typed["peer"],
                         "pymavlink DFReader_binary recv_match(type=)"))
    mb = big.stat().st_size / 2**20
    m = peak_memory("from adapters.formats import dataflash", "dataflash.read(sys.argv[1])", str(big))
    rows.append({"reader": "DataFlash", "case": f"peak memory, ours, {mb:.1f} MiB generated file", "mode": "memory",
                 "rss_peak_MB": m["rss_MB"], "traced_peak_MB": m["traced_MB"], "rss_x_file": m["rss_MB"] / mb,
                 "traced_x_file": m["traced_MB"] / mb})
    return rows


_DFREADER_COLUMNS = """
def dfreader_columns(path):
    reader = DFReader.DFReader_binary(str(path))
    n = 0
    while (m := reader.recv_msg()) is not None:
        n += len(m.to_dict())  # every column of every message, as DFReader gives it (multiplied, text decoded)
    reader.close()
    return n
"""

#: FMT-rich ArduCopter 3.4 – 4.6 logs recorded by others (bench/real_logs.md says where each comes from), looked
#: for in the folder given with --logs (never in the repository)
FMT_RICH = ("beastayyg_log_0036_mechanical_failure.bin", "beastayyg_sample.bin", "erle_pxf_copter_Erle-Brain3.BIN",
            "erle_erlebrain_APM_22.BIN", "erle_pxf_copter_PXFv2.0b+Rpi.BIN", "amc_backend_log_80k.bin")


def bench_dataflash_columns(tmp: Path, logs: Path | None = None) -> list[dict]:
    """Every column of every message of FMT-rich ArduCopter 3.4 – 4.6 logs: ``dataflash.read`` (all types, every
    field decoded into numpy columns, multipliers applied, text decoded) against DFReader's ``recv_msg`` loop with
    ``to_dict()`` of each message (every field as DFReader decodes it) and, beside it, the bare ``recv_msg`` loop
    (DFReader unpacks every field; it applies multipliers and decodes text only when a column is asked for)."""
    import contextlib
    import io

    from pymavlink import DFReader

    from adapters.formats import dataflash, dataflash_write

    namespace = {"DFReader": DFReader}
    exec(_DFREADER_COLUMNS, namespace)  # the same source the subprocess cases run
    columns = namespace["dfreader_columns"]
    big = tmp / "generated_copter.bin"
    if not big.exists():
        dataflash_write.write_example(big, "new", "copter", seconds=300.0, rate=7.0, seed=2)
    cases = [(logs / name, name) for name in FMT_RICH if logs is not None and (logs / name).exists()]
    cases.append((big, "generated ArduCopter 4.x-style log (FMTU, instances)"))
    rows = []
    for path, label in cases:
        ours = dataflash.read(path)
        firmware = ours.info.get("firmware", "")
        n = _check_dataflash(path)
        values = sum((len(c) - 1) * len(c["t"]) for c in (ours.columns(k) for k in ours.frames))
        case = (f"{label} ({firmware.split(' (')[0]}, {path.stat().st_size / 1e6:.2f} MB, {len(ours.frames)} streams "
                f"of {len(ours.info['formats'])} written types, {n} messages, every column)")
        with contextlib.redirect_stdout(io.StringIO()):  # DFReader prints what it skips
            warm = interleaved({"ours": lambda p=path: dataflash.read(p), "columns": lambda p=path: columns(p),
                                "recv": lambda p=path: _dfreader(p)}, 5)
        row = _row("DataFlash", case, "warm, all columns", warm["ours"], warm["columns"],
                   "pymavlink DFReader_binary recv_msg + to_dict", fields=values)
        rows.append(_target(row, 10.0, "≥ 10×"))
        rows.append(_row("DataFlash", case, "warm, all columns", warm["ours"], warm["recv"],
                         "pymavlink DFReader_binary recv_msg (bare)"))
    return rows


def run() -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="bench_readers_") as tmp:
        tmp = Path(tmp)
        logs = Path(os.environ["WORKBENCH_REAL_LOGS"]) if os.environ.get("WORKBENCH_REAL_LOGS") else None
        return (bench_csv(tmp) + bench_ulog() + bench_tlog(tmp) + bench_mcap(tmp) + bench_dataflash(tmp)
                + bench_dataflash_columns(tmp, logs))


if __name__ == "__main__":
    import argparse

    from harness import markdown_table

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("section", nargs="?", choices=["dataflash", "dataflash-columns", "tlog"],
                        help="one section alone (all by default)")
    parser.add_argument("--logs", type=Path, help="a folder holding the FMT-rich real logs of FMT_RICH")
    args = parser.parse_args()
    sections = {"dataflash": bench_dataflash, "tlog": bench_tlog,
                "dataflash-columns": lambda tmp: bench_dataflash_columns(tmp, args.logs)}
    if args.section:  # one section alone: python bench/bench_readers.py dataflash-columns --logs /work/team/logs
        with tempfile.TemporaryDirectory(prefix="bench_readers_") as tmp:
            print(markdown_table(sections[args.section](Path(tmp))))
    else:
        print(markdown_table(run()))
