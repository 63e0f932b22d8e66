"""Seeded fuzzing of every input kind: a corrupt file loads or raises a WorkbenchError, never anything else.

Kinds: MAVLink tlog, MCAP, ULog, CSV, ArduPilot DataFlash (``.bin``, new-style and old-style logs in turn), the
Parquet demonstration file, the ``.npz`` model file and a mapping TOML.
Each is written once from a small simulated set (and a model fitted on it; every other model file uncompressed,
as ``np.savez`` writes them, so that damage reaches the ``.npy`` headers directly), then damaged by one of seven
mutations — truncation, bit flips, an inserted chunk, a deleted chunk, a zeroed region, a huge length field
(a 16-, 32- or 64-bit integer near its maximum written over the bytes) and random bytes behind the valid magic —
and loaded the way the CLI loads it. Per call the outcome must be a successful load or a
:class:`~workbench.errors.WorkbenchError`; a call may not outlast a timeout (a hang) and the worker process runs
under an address-space limit (``RLIMIT_AS``) with its peak resident memory reported, so that a damaged length
field cannot make a reader allocate gigabytes. Nothing may be printed along the way (a library printing on damaged
input breaks the CLI's one-line errors).

The loads run in a subprocess (this file run as a script, one JSON line per call) so that a hang in C code or an
allocation that the address-space limit stops cannot take the test session with it. The default run fuzzes a
fast subset (10 files per kind); ``-m slow`` runs the full 200 per kind.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

KINDS = ("tlog", "mcap", "ulog", "csv", "parquet", "npz", "mapping", "dataflash")
MUTATIONS = ("truncate", "bitflip", "insert", "delete", "zero", "huge_length", "random_behind_magic")
_EXT = {"tlog": ".tlog", "mcap": ".mcap", "ulog": ".ulg", "csv": ".csv", "parquet": ".parquet", "npz": ".npz",
        "mapping": ".toml", "dataflash": ".bin"}
_MAGIC = 16  # bytes kept by "random_behind_magic": every format's signature fits in them
CALL_TIMEOUT = 30.0  # s per load; a tiny file loads in well under one even on a loaded machine
MEMORY_BUDGET_MB = 1024  # address space a worker may add after start-up (RLIMIT_AS): a hard stop
RSS_GROWTH_MB = 256  # peak resident growth allowed over all loads of files of 3-20 kB (observed: under 25 MB)


# -- mutations ---------------------------------------------------------------------------------------------
def mutate(data: bytes, kind: str, rng: np.random.Generator) -> bytes:
    """``data`` damaged by one mutation of kind ``kind`` (see the module docstring), deterministic for ``rng``."""
    out = bytearray(data)
    n = len(out)
    at = int(rng.integers(0, max(n, 1)))
    if kind == "truncate":
        return bytes(out[:at])
    if kind == "bitflip":
        for _ in range(int(rng.integers(1, 9))):
            i = int(rng.integers(0, n))
            out[i] ^= 1 << int(rng.integers(0, 8))
        return bytes(out)
    if kind == "insert":
        chunk = rng.integers(0, 256, int(rng.integers(1, 257)), dtype=np.uint8).tobytes()
        return bytes(out[:at] + chunk + out[at:])
    if kind == "delete":
        return bytes(out[:at] + out[at + int(rng.integers(1, 257)):])
    if kind == "zero":
        size = int(rng.integers(1, 513))
        out[at:at + size] = bytes(len(out[at:at + size]))
        return bytes(out)
    if kind == "huge_length":
        width = int(rng.choice([2, 4, 8]))
        value = [2 ** (8 * width) - 1, 2 ** (8 * width - 1) - 1, 2 ** (8 * width - 1)][int(rng.integers(0, 3))]
        order = "little" if rng.random() < 0.75 else "big"
        out[at:at + width] = value.to_bytes(width, order)[: len(out[at:at + width])]
        return bytes(out)
    if kind == "random_behind_magic":
        head = bytes(out[:_MAGIC])
        return head + rng.integers(0, 256, max(n - _MAGIC, 0), dtype=np.uint8).tobytes()
    raise ValueError(f"unknown mutation {kind!r}")


def cases(kind: str, n: int, seed: int) -> list[tuple[int, str, np.random.Generator]]:
    """The ``n`` seeded cases of a kind: (index, mutation, generator), mutations in turn."""
    root = np.random.SeedSequence([seed, KINDS.index(kind)])
    return [(i, MUTATIONS[i % len(MUTATIONS)], np.random.default_rng(s)) for i, s in enumerate(root.spawn(n))]


# -- the worker (this file run as a script) ---------------------------------------------------------------
class _Hang(BaseException):
    """Raised by the per-call alarm; a BaseException so that no reader's ``except Exception`` swallows it."""


def _write_originals(folder: Path) -> dict[str, Path]:
    """One valid file per kind, from three short simulated landings (and a model fitted on them)."""
    import warnings

    import adapters
    from workbench.data.demonstrations import DemonstrationSet
    from workbench.models import HumanBehaviorModel
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.landing import simulate_landings

    ds = simulate_landings("CS1", 2, seed=5, time_limit=1.5) + simulate_landings("CS2", 1, seed=5, time_limit=1.5)
    # cut short, the trials' outcome reads "time limit": a value with a space, which a tlog text marker cannot carry
    ds = DemonstrationSet([d.with_meta(outcome=None) for d in ds], ds.state_names, ds.input_names, ds.dt,
                          roles=ds.roles)
    out = {}
    for kind in ("tlog", "mcap", "ulog", "csv"):
        out[kind] = adapters.write(ds, folder / f"original{_EXT[kind]}")
    out["parquet"] = ds.save(folder / "original.parquet")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = HumanBehaviorModel(planar_quadrotor(dt=ds.dt), n_components=2, noise_folds=0).fit(ds)
    out["npz"] = model.save(folder / "original.npz")
    # the same archive uncompressed (np.savez writes such files): damage then lands on .npy headers directly
    out["npz_stored"] = folder / "original-stored.npz"
    with zipfile.ZipFile(out["npz"]) as zin, zipfile.ZipFile(out["npz_stored"], "w", zipfile.ZIP_STORED) as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, zin.read(info))
    # DataFlash: no demonstration layout of its own; a generated flight of each log generation (12-16 kB)
    from adapters.formats import dataflash_write

    out["dataflash"] = dataflash_write.write_example(folder / "original.bin", "new", "copter", seconds=1.0)
    out["dataflash_old"] = dataflash_write.write_example(folder / "original-old.bin", "old", "plane", seconds=1.5)
    shipped = Path(adapters.mapping.MAPPINGS_DIR) / "planar_quadrotor.toml"
    out["mapping"] = folder / "original.toml"
    out["mapping"].write_bytes(shipped.read_bytes())
    return out


def _loader(kind: str, originals: dict[str, Path]):
    """The call that loads a file of a kind, as the CLI does (logs: ``import`` and ``inspect``; mappings: on a log)."""
    import adapters
    from workbench.data.demonstrations import DemonstrationSet
    from workbench.models import load_model

    if kind in ("tlog", "mcap", "ulog", "csv"):
        # in turn: load with the shipped mapping or inspect (every stream), the format detected or named
        def log(path: Path, i: int) -> object:
            fmt = kind if i % 2 else None
            if i % 4 < 2:
                return adapters.load(path, "planar_quadrotor", format=fmt)
            return str(adapters.inspect(path, format=fmt))

        return log
    if kind == "dataflash":
        # in turn: a typed read of a few streams or inspect (every stream), the format detected or named
        def bin_log(path: Path, i: int) -> object:
            fmt = kind if i % 2 else None
            if i % 4 < 2:
                return adapters.read(path, ["ATT", "IMU", "MODE", "MSG", "GPS[0]"], format=fmt)
            return str(adapters.inspect(path, format=fmt))

        return bin_log
    if kind == "parquet":
        return lambda path, i: DemonstrationSet.load(path)
    if kind == "npz":
        return lambda path, i: load_model(path)
    log = originals["mcap"]
    return lambda path, i: adapters.load(log, path)


def _vm_bytes() -> int:
    """The process's address-space size (Linux), 0 where /proc does not say."""
    status = Path("/proc/self/status")
    for line in status.read_text().splitlines() if status.is_file() else []:
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    return 0


def _rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker(kinds: list[str], n: int, seed: int, folder: Path, budget_mb: int, timeout: float) -> None:
    """Fuzz ``kinds`` and print one JSON line per call (outcome, exception, seconds, peak RSS growth)."""
    import resource
    import warnings

    from workbench.errors import WorkbenchError

    warnings.simplefilter("ignore")
    originals = _write_originals(folder)
    loaders = {kind: _loader(kind, originals) for kind in kinds}
    for kind in kinds:  # warm every code path once so that lazy imports do not count as growth
        try:
            loaders[kind](originals[kind], 0)
        except WorkbenchError:
            pass
    vm = _vm_bytes()
    if vm:  # Linux; elsewhere the resident-growth check alone bounds memory
        resource.setrlimit(resource.RLIMIT_AS, (vm + budget_mb * 2**20, vm + budget_mb * 2**20))
    rss0 = _rss_mb()

    def alarm(signum, frame):
        raise _Hang()

    signal.signal(signal.SIGALRM, alarm)
    for kind in kinds:
        data = originals[kind].read_bytes()
        stored = originals["npz_stored"].read_bytes()
        old_bin = originals["dataflash_old"].read_bytes()
        for i, mutation, rng in cases(kind, n, seed):
            path = folder / f"{kind}-{i:03d}{_EXT[kind]}"
            old = kind == "dataflash" and (i // 2) % 2  # the old-style .bin every other pair of cases
            path.write_bytes(mutate(old_bin if old else stored if kind == "npz" and i % 2 else data, mutation, rng))
            record = {"kind": kind, "i": i, "mutation": mutation, "path": str(path)}
            t0 = time.perf_counter()
            signal.setitimer(signal.ITIMER_REAL, timeout)
            try:
                loaders[kind](path, i)
                record["outcome"] = "ok"
            except _Hang:
                record.update(outcome="hang")
            except WorkbenchError as exc:
                record.update(outcome="error", names_file=path.name in str(exc), message=str(exc)[:300])
            except BaseException as exc:  # noqa: BLE001 — the point: anything else is a finding
                record.update(outcome="foreign", exception=type(exc).__name__, message=str(exc)[:300])
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            record["seconds"] = round(time.perf_counter() - t0, 4)
            record["rss_growth_mb"] = round(_rss_mb() - rss0, 1)
            print(json.dumps(record), flush=True)
            if record["outcome"] != "foreign":
                path.unlink()


def run(kinds: tuple[str, ...], n: int, seed: int = 0, *, budget_mb: int = MEMORY_BUDGET_MB,
        timeout: float = CALL_TIMEOUT) -> list[dict]:
    """Run the worker in a subprocess and return its records (a worker that dies is one ``crash`` record)."""
    with tempfile.TemporaryDirectory(prefix="wb-fuzz-") as tmp:
        cmd = [sys.executable, __file__, "--kinds", ",".join(kinds), "-n", str(n), "--seed", str(seed),
               "--dir", tmp, "--budget-mb", str(budget_mb), "--timeout", str(timeout)]
        env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
        root = str(Path(__file__).resolve().parents[1])
        env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
        try:
            # generous (a loaded machine), but finite: a hang in C code that the alarm cannot interrupt ends here
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=root,
                                  timeout=120 + 2 * timeout + 2.0 * n * len(kinds))
            stdout, stderr, code = proc.stdout, proc.stderr, proc.returncode
        except subprocess.TimeoutExpired as exc:
            def text(b):
                return b.decode(errors="replace") if isinstance(b, bytes) else (b or "")

            stdout, stderr, code = text(exc.stdout), text(exc.stderr), "timeout"
    records = [json.loads(line) for line in stdout.splitlines() if line.startswith("{")]
    # a reader that prints on damaged input breaks the CLI's one-line errors (warnings are off in the worker)
    stray = [line for line in stdout.splitlines() if line.strip() and not line.startswith("{")]
    if code == 0 and (stray or stderr.strip()):
        records.append({"kind": "worker", "outcome": "stray output", "stdout": stray[:20], "stderr": stderr[-2000:]})
    if code != 0:
        last = records[-1] if records else None
        records.append({"kind": "worker", "outcome": "crash", "returncode": code, "after": last,
                        "stderr": stderr[-2000:]})
    return records


def summarize(records: list[dict]) -> dict[str, dict[str, int]]:
    """Outcome counts per kind."""
    out: dict[str, dict[str, int]] = {}
    for r in records:
        counts = out.setdefault(r["kind"], {})
        counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
    return out


# -- tests -------------------------------------------------------------------------------------------------
# CSV is read by adapters/csv.py, another engineer's slice: its known escapes (exception name, message part)
# turn a fuzz run that finds nothing else into an xfail that names them, instead of hiding them.
_CSV_KNOWN: tuple[tuple[str, str], ...] = ()


def _check(records: list[dict], n: int, kinds: tuple[str, ...]) -> None:
    crashes = [r for r in records if r["kind"] == "worker"]
    assert not crashes, f"the fuzz worker died or printed: {crashes}"
    counts = summarize(records)
    assert set(counts) == set(kinds) and all(sum(c.values()) == n for c in counts.values()), counts
    bad = [r for r in records if r["outcome"] in ("foreign", "hang")]
    known = [r for r in bad if r["kind"] == "csv"
             and any(r.get("exception") == e and m in r.get("message", "") for e, m in _CSV_KNOWN)]
    bad = [r for r in bad if r not in known]
    assert not bad, "foreign exceptions or hangs:\n" + "\n".join(
        f"{r['kind']} #{r['i']} ({r['mutation']}): {r['outcome']} {r.get('exception', '')}: {r.get('message', '')}"
        for r in bad
    )
    unnamed = [r for r in records if r["outcome"] == "error" and not r["names_file"] and r["kind"] != "mapping"]
    assert not unnamed, "errors that do not name the file:\n" + "\n".join(r["message"] for r in unnamed)
    growth = max(r["rss_growth_mb"] for r in records)
    assert growth < RSS_GROWTH_MB, f"peak resident memory grew by {growth} MB while loading small corrupt files"
    if known:
        pytest.xfail(f"{len(known)} damaged CSV files raise {known[0]['exception']} ({known[0]['message']}) from "
                     f"adapters/csv.py, another engineer's slice; every other load passed")


def test_mutations_are_seeded_and_change_the_bytes():
    data = bytes(range(256)) * 8
    for kind in MUTATIONS:
        a = [mutate(data, m, rng) for _, m, rng in cases("mcap", 14, 7) if m == kind]
        b = [mutate(data, m, rng) for _, m, rng in cases("mcap", 14, 7) if m == kind]
        assert a == b, kind
        assert any(x != data for x in a), kind


def test_ulog_whose_first_message_runs_past_the_end_does_not_hang(tmp_path):
    """Found by the fuzzer: on a message longer than the rest of the file pyulog seeks back and loops forever."""
    import adapters
    from adapters.formats.ulog import MAGIC
    from workbench.errors import DataError

    path = tmp_path / "loop.ulg"
    path.write_bytes(MAGIC + bytes(16 - len(MAGIC)) + (0xFFFF).to_bytes(2, "little") + b"\0")

    def alarm(signum, frame):
        raise _Hang()

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, CALL_TIMEOUT)
    try:
        with pytest.raises(DataError, match="damaged ULog file") as info:
            adapters.read(path)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert str(path) in str(info.value)


EXTERNAL_MCAP = Path(__file__).resolve().parents[2] / "shared" / "external" / "rosbag2_talker.mcap"


@pytest.mark.skipif(not EXTERNAL_MCAP.is_file(), reason=f"{EXTERNAL_MCAP} is not there")
def test_damaged_ros2_schema_is_skipped_without_printing(tmp_path, capfd):
    """Found by the fuzzer: the ROS 2 schema parser printed a damaged schema's lines to stderr."""
    import adapters

    data = EXTERNAL_MCAP.read_bytes()
    assert data.count(b"uint8 level") == 1
    path = tmp_path / "schema.mcap"
    damaged = bytearray(data.replace(b"uint8 level", b"uint8 l%vel"))  # not a valid ROS 2 field name
    # the schema's readable copy is the summary's, which its CRC now rejects (and the reader then scans the intact
    # chunks): a summary CRC of 0 ("not computed", the footer's last field before the magic) lets the damaged
    # schema reach the parser, as a writer that computes no CRCs would
    assert damaged[-8:] == b"\x89MCAP0\r\n"
    damaged[-12:-8] = bytes(4)
    path.write_bytes(bytes(damaged))
    summary = str(adapters.inspect(path))
    assert "/rosout: undecodable messages" in summary
    assert capfd.readouterr().err == ""


@pytest.mark.parametrize(
    ("header", "cause"),
    [(b"demo,t,x\xe4y,y", "not UTF-8"),  # found by the fuzzer (seeds 8, 11): a UnicodeDecodeError from pyarrow
     (b"demo,t,x\rz,y", "not a readable CSV")],  # found by the fuzzer (seed 1): a _csv.Error from the header
    ids=["not-utf8", "carriage-return"],
)
def test_csv_header_damage_is_a_data_error(tmp_path, header, cause):
    import adapters
    from workbench.errors import DataError

    path = tmp_path / "header.csv"
    path.write_bytes(header + b"\na,0,1,2\na,0.1,1,2\n")
    with pytest.raises(DataError, match=cause) as info:
        adapters.load(path, format="csv")
    assert str(path) in str(info.value)


def test_fuzz_fast_subset():
    """Ten damaged files per kind (every mutation at least once): loads or WorkbenchErrors only."""
    n = len(MUTATIONS) + 3
    _check(run(KINDS, n, seed=0), n, KINDS)


@pytest.mark.slow
def test_fuzz_full():
    """The full run: 200 damaged files per kind, 1,400 loads."""
    _check(run(KINDS, 200, seed=1), 200, KINDS)


if __name__ == "__main__":
    # run as a script, sys.path[0] is tests/, whose adapters/ folder would shadow the package
    sys.path[0] = str(Path(__file__).resolve().parents[1])
    parser = argparse.ArgumentParser(description="fuzz worker (see the module docstring)")
    parser.add_argument("--kinds", default=",".join(KINDS))
    parser.add_argument("-n", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dir", type=Path, default=None)
    parser.add_argument("--budget-mb", type=int, default=MEMORY_BUDGET_MB)
    parser.add_argument("--timeout", type=float, default=CALL_TIMEOUT)
    a = parser.parse_args()
    if a.dir is None:
        a.dir = Path(tempfile.mkdtemp(prefix="wb-fuzz-"))
    worker(a.kinds.split(","), a.n, a.seed, a.dir, a.budget_mb, a.timeout)
