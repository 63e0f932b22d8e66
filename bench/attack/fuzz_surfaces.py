"""Attack round on the surfaces the last rounds touched: datasets, mappings' dt, the live link, the scheduler
handshake, interrupted writes, standard input, damaged MCAP files, a study on worker processes interrupted.
Not part of the test suite: run it for a bounded time and read the counts.

    PYTHONPATH=. .venv/bin/python bench/attack/fuzz_surfaces.py --seconds 60

Each surface gets the same share of the time. Per surface it counts calls, clean errors (a ``WorkbenchError``:
one line naming the cause), foreign errors (anything else: a traceback from inside a library), hangs (a call
over its time limit) and silent wrong results (a call that returned but broke an invariant the surface
promises: a dataset read differently by pandas, a file read from outside the folder, a count that does not add
up, an old report beside new figures). Each call runs in a child forked from this process, which measures its
peak memory (``wait4``) and time.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from tests import forgeries  # noqa: E402 - the peers the tests fake too
from workbench.errors import WorkbenchError  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
import harness  # noqa: E402 - the shared harness
from harness import HANG_S, _call_in_child, _mutate  # noqa: E402


class Tally(harness.Tally):
    """Each call in a child forked from this process (:func:`harness._call_in_child`): its peak memory and its
    time are its own. A call's random choices come from a generator seeded by this process's, drawn per call."""

    def __init__(self, rng: random.Random) -> None:
        super().__init__()
        self.rng = rng

    def run(self, surface: str, fn, *args) -> None:
        args = tuple(random.Random(self.rng.getrandbits(64)) if isinstance(a, random.Random) else a for a in args)
        self.record(surface, _call_in_child(lambda: fn(*args)))


# -- datasets ----------------------------------------------------------------------------------------------------
def attack_dataset(rng: random.Random, base: Path, study) -> str | None:
    import pandas as pd

    from workbench.data.dataset import DatasetWriter, load_dataset, write_dataset, write_partitions

    root = base / f"ds{rng.randrange(10**9)}"
    outside = base / "outside"
    if not outside.exists():
        write_dataset(study.select(subject="s03"), outside)
    if rng.random() < 0.5:
        write_dataset(study, root)
    else:  # two logs with the same ids
        one = study.select(subject=rng.choice(["s01", "s02"]))
        with DatasetWriter(root) as w:
            w.commit(write_partitions(one, w.tmp, "a", "a.tlog", 0) + write_partitions(one, w.tmp, "b", "b.tlog", 1))
    victim = next(root.rglob("*.parquet"))
    action = rng.choice(["stray_parquet", "stray_text", "symlink_out", "symlink_dir_out", "legacy_dotdot",
                         "legacy_abs", "truncate", "garbage", "hidden_file", "nothing", "empty_subject_dir"])
    if action == "stray_parquet":
        study.select(subject="s03").to_pandas().to_parquet(victim.parent / "stray.parquet")
    elif action == "stray_text":
        note = root / rng.choice(["notes.txt", f"{victim.parent.name}/x.json"])
        note.write_text("x")
    elif action == "symlink_out":
        (victim.parent / "link.parquet").symlink_to(next(outside.rglob("*.parquet")))
    elif action == "symlink_dir_out":
        (root / "subject=zz").symlink_to(next(outside.rglob("*.parquet")).parent)
    elif action in ("legacy_dotdot", "legacy_abs"):
        out_file = next(outside.rglob("*.parquet"))
        bad = str(out_file) if action == "legacy_abs" else "../" + out_file.relative_to(base).as_posix()
        parts = [{"file": p.relative_to(root).as_posix(), "source": None, "subject": None, "ids": [],
                  "n_samples": 0} for p in root.rglob("*.parquet")]
        parts.append({"file": bad, "source": None, "subject": None, "ids": [], "n_samples": 0})
        (root / "_workbench_dataset.json").write_text(json.dumps({"format": "workbench.dataset", "version": 1,
                                                                  "partitions": parts}))
    elif action == "truncate":
        data = victim.read_bytes()
        victim.write_bytes(data[: rng.randrange(len(data))])
    elif action == "garbage":
        data = bytearray(victim.read_bytes())
        for _ in range(rng.randrange(1, 20)):
            data[rng.randrange(len(data))] = rng.randrange(256)
        victim.write_bytes(bytes(data))
    elif action == "hidden_file":
        (root / "_notes.txt").write_text("hidden from every reader")
    elif action == "empty_subject_dir":
        (root / "subject=s09").mkdir()
    ds = load_dataset(root)  # clean error or a set: then every reader must agree with it
    if action in ("symlink_out", "symlink_dir_out", "legacy_dotdot", "legacy_abs"):
        return f"{action}: read a dataset with a path leading outside"
    table = pd.read_parquet(root)
    if len(table) != ds.n_samples or table["demo"].nunique() != len(ds):
        return f"{action}: pandas sees {len(table)} rows / {table['demo'].nunique()} trials, the workbench " \
               f"{ds.n_samples} / {len(ds)}"
    return None


# -- mappings: dt ------------------------------------------------------------------------------------------------
def attack_mapping(rng: random.Random, base: Path) -> str | None:
    import adapters

    dt = rng.choice([10 ** rng.uniform(-320, 1), rng.uniform(0, 0.2), 0.05, -0.05, float("nan"), float("inf"),
                     1e-5, 5e-4, 0.001, "0.05", True])
    text = (REPO / "adapters" / "mappings" / "planar_quadrotor.toml").read_text()
    value = repr(dt) if not isinstance(dt, str) else f'"{dt}"'
    value = {"nan": "nan", "inf": "inf"}.get(value, value).replace("True", "true")
    m = base / f"m{rng.randrange(10**9)}.toml"
    m.write_text(re.sub(r"^dt = .*$", f"dt = {value}", text, count=1, flags=re.M))
    start = time.monotonic()
    ds = adapters.load(REPO / "sample_logs" / "landing_s00.tlog", mapping=str(m))
    if time.monotonic() - start > 10:
        return f"dt = {dt}: took {time.monotonic() - start:.0f} s"
    if ds.n_samples > 5_000_000:
        return f"dt = {dt}: {ds.n_samples} rows"
    return None


# -- live link ---------------------------------------------------------------------------------------------------
def attack_live(rng: random.Random, frames, model) -> str | None:
    from workbench.live.predictor import OnlinePredictor

    pr = OnlinePredictor(model, "planar_quadrotor", horizon_s=0)
    start = rng.randrange(len(frames) - 600)
    n_junk = 0
    for t, f in frames[start:start + 600]:
        kind = rng.random()
        if kind < 0.1:
            data = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300)))
            n_junk += 1
        elif kind < 0.2:
            b = bytearray(f)
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
            data = bytes(b)
        elif kind < 0.25:
            data = f[: rng.randrange(1, len(f))]
        elif kind < 0.3:
            data = f + f
        else:
            data = f
        pr.feed(data, arrival=t)
        pr.pop()
    seen = []
    for _ in range(5):
        p = pr.step()
        if p is not None:
            seen.append((p.segment, p.k))
    if len(seen) > 1:
        return f"step() returned {len(seen)} predictions without a new step"
    st = pr.stats
    if sum(st.received.values()) < st.counts.get("messages", 0):
        return f"received {sum(st.received.values())} < messages {st.counts.get('messages')}"
    return None


# -- scheduler ---------------------------------------------------------------------------------------------------
def attack_scheduler(rng: random.Random) -> str | None:
    from workbench.study.handshake import check_scheduler

    kind = rng.choice(["random", "http", "silent", "close", "huge_length", "plausible", "slow_drip"])

    def respond(conn):
        try:
            if kind == "random":
                conn.sendall(os.urandom(rng.randrange(1, 5000)))
            elif kind == "http":
                conn.recv(100)
            elif kind == "silent":
                time.sleep(4)
            elif kind == "huge_length":
                conn.sendall(struct.pack("<Q", 2 ** 63) + os.urandom(50))
            elif kind == "plausible":
                n = rng.randrange(16, 500)
                conn.sendall(struct.pack("<Q", n) + struct.pack("<Q", 1) + struct.pack("<Q", n - 16)
                             + os.urandom(n - 16))
            elif kind == "slow_drip":
                for b in os.urandom(30):
                    conn.sendall(bytes([b]))
                    time.sleep(0.2)
        except OSError:
            pass

    srv, address = forgeries.serve(respond)
    start = time.monotonic()
    try:
        check_scheduler(address, timeout=2)
    finally:
        srv.close()
        if time.monotonic() - start > 5:
            raise RuntimeError(f"{kind}: {time.monotonic() - start:.1f} s")
    return f"{kind}: accepted as a Dask scheduler"


# -- interrupted writes ------------------------------------------------------------------------------------------
KILL_CODE = """
import sys
from pathlib import Path
from workbench.sim.landing import simulate_study
from workbench.data.dataset import write_dataset
s = simulate_study(n_subjects=3, n_trials=2, strategy="CS1", seed=int(sys.argv[2]))
for _ in range(50):
    write_dataset(s, Path(sys.argv[1]) / "ds")
    s.save(Path(sys.argv[1]) / "one.parquet")
"""


def attack_kill(rng: random.Random, base: Path) -> str | None:
    from workbench.data.dataset import load_dataset
    from workbench.data.demonstrations import DemonstrationSet

    folder = base / "kill"
    folder.mkdir(exist_ok=True)
    proc = subprocess.Popen([sys.executable, "-c", KILL_CODE, str(folder), "1"], cwd=REPO,
                            env={**os.environ, "PYTHONPATH": str(REPO)}, stderr=subprocess.DEVNULL)
    time.sleep(rng.uniform(1.0, 6.0))
    proc.send_signal(rng.choice([signal.SIGKILL, signal.SIGINT, signal.SIGTERM]))
    proc.wait(timeout=60)
    if proc.returncode in (-signal.SIGABRT, 134):
        return "the interpreter aborted"
    # what is there must be whole; leftovers must go with the next write
    if (folder / "ds").exists():
        load_dataset(folder / "ds")
    if (folder / "one.parquet").exists():
        DemonstrationSet.load(folder / "one.parquet")
    from workbench.data.dataset import write_dataset
    from workbench.sim.landing import simulate_study

    s = simulate_study(n_subjects=1, n_trials=1, strategy="CS1", seed=2)
    write_dataset(s, folder / "ds")
    s.save(folder / "one.parquet")
    left = sorted(p.name for p in folder.iterdir() if p.name.startswith("."))
    return f"leftovers after the next write: {left}" if left else None


# -- standard input -----------------------------------------------------------------------------------------------
def attack_stdin(rng: random.Random, logs: dict[str, bytes]) -> str | None:
    """``workbench inspect -`` / ``import - --format F -o -`` on damaged log bytes: exit 0 or one line, never a
    traceback, a signal or a half-written file on stdout."""
    fmt, data = rng.choice(sorted(logs.items()))
    data = _mutate(rng, data)
    args = rng.choice([["inspect", "-"], ["inspect", "-", "--format", fmt],
                       ["import", "-", "--format", fmt, "--mapping", "planar_quadrotor", "-o", "-"]])
    proc = subprocess.run([sys.executable, "-m", "workbench", *args], input=data, capture_output=True,
                          cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=HANG_S * 3)
    err = proc.stderr.decode(errors="replace")
    if proc.returncode < 0 or "Traceback" in err or proc.returncode == 3:
        raise RuntimeError(f"{' '.join(args)}: exit {proc.returncode}: {err.strip()[-200:]}")
    if proc.returncode == 0 and args[0] == "import":
        import io

        import pandas as pd

        pd.read_parquet(io.BytesIO(proc.stdout))  # what reached stdout is a whole file
    elif proc.returncode not in (0, 1):
        return f"{' '.join(args)}: exit {proc.returncode}"
    return None


# -- MCAP files ------------------------------------------------------------------------------------------------------
def attack_mcap(rng: random.Random, base: Path, data: bytes) -> str | None:
    """A damaged MCAP read in this process: streams or a clean error naming the file."""
    import adapters

    path = base / f"m{rng.randrange(10**9)}.mcap"
    path.write_bytes(_mutate(rng, data))
    try:
        adapters.read(path)
    except WorkbenchError as exc:
        if str(path) not in str(exc):
            return f"an error that does not name the file: {str(exc)[:120]}"
        raise
    finally:
        path.unlink()
    return None


# -- a study on worker processes, interrupted ------------------------------------------------------------------------
# As the console script runs it: main() without arguments is the whole process (its own Ctrl-C handling),
# main(argv) is a call from a program that keeps its own (tests).
STUDY_CODE = """
import sys
from workbench.cli import main
sys.argv = ["workbench", "report", sys.argv[1], "-o", sys.argv[2], "--bootstrap", "8", "--samples", "4",
            "--efficiency", "2", "--n-components", "2"]
sys.exit(main())
"""


def attack_study_interrupt(rng: random.Random, base: Path, demos: Path) -> str | None:
    """Ctrl-C (to the whole process group, as a terminal sends it) while a report's strategies run on worker
    processes: exit 130 and one line, no worker left running, no staging folder or half report left."""
    out = base / "report"
    tmp_before = {p.name for p in Path(tempfile.gettempdir()).glob("workbench-staging-*")}
    proc = subprocess.Popen([sys.executable, "-c", STUDY_CODE, str(demos), str(out)], cwd=REPO,
                            env={**os.environ, "PYTHONPATH": str(REPO)}, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True)
    time.sleep(rng.uniform(0.5, 12.0))
    try:
        os.killpg(proc.pid, signal.SIGINT)
    except ProcessLookupError:
        pass
    err = proc.communicate(timeout=HANG_S * 3)[1].decode(errors="replace")
    alive = True
    for _ in range(50):  # a worker's last moments as a zombie, until init reaps it, are not a worker left running
        ps = subprocess.run(["ps", "-o", "stat=", "-g", str(proc.pid)], capture_output=True, text=True).stdout
        alive = any(not st.startswith("Z") for st in ps.split())
        if not alive:
            break
        time.sleep(0.1)
    if alive:
        os.killpg(proc.pid, signal.SIGKILL)
        return "a worker outlived the interrupted command"
    if "Traceback" in err or proc.returncode not in (0, 130):
        keep = os.environ.get("WB_ATTACK_KEEP")  # a folder: the whole stderr of each failure, to read the trace
        if keep:
            Path(keep).mkdir(parents=True, exist_ok=True)
            (Path(keep) / f"study-{time.time_ns()}.txt").write_text(err)
        raise RuntimeError(f"exit {proc.returncode}: {err.strip()[-200:]}")
    left = {p.name for p in Path(tempfile.gettempdir()).glob("workbench-staging-*")} - tmp_before
    if left:
        return f"staging folders left: {sorted(left)}"
    if proc.returncode == 130 and (out / "report.md").exists() and not (out / "figures").exists():
        return "a report without its figures"
    shutil.rmtree(out, ignore_errors=True)
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", action="append", help="run only the surfaces whose name contains this")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    sys.path.insert(0, str(Path(__file__).parent))

    import pandas  # noqa: F401 - imported once here, so every forked call starts with it as a command would

    import adapters
    from adapters.link.mavlink import tlog_frames
    from workbench.models import HumanBehaviorModel
    from workbench.plant.system import planar_quadrotor
    from workbench.sim.landing import simulate_study

    study = simulate_study(n_subjects=3, n_trials=2, strategy="CS1", seed=1)
    tlog = REPO / "sample_logs" / "landing_s00.tlog"
    frames = list(tlog_frames(tlog))
    model = HumanBehaviorModel(planar_quadrotor(), n_components=2, noise_folds=0).fit(
        adapters.load(tlog, mapping="planar_quadrotor").by_label("CS1")[:4])
    tally = Tally(rng)
    base = Path(tempfile.mkdtemp(prefix="wb-attack-"))
    logs = {"tlog": tlog.read_bytes(), "mcap": (REPO / "sample_logs" / "landing_s01.mcap").read_bytes(),
            "csv": (REPO / "sample_logs" / "landing_s02.csv").read_bytes()}
    demos = base / "two_strategies.parquet"
    adapters.load(tlog, mapping="planar_quadrotor").save(demos)
    surfaces = {
        "stdin (damaged logs)": lambda: tally.run("stdin (damaged logs)", attack_stdin, rng, logs),
        "MCAP (damaged)": lambda: tally.run("MCAP (damaged)", attack_mcap, rng, base, logs["mcap"]),
        "study on worker processes, Ctrl-C": lambda: tally.run("study on worker processes, Ctrl-C",
                                                               attack_study_interrupt, rng, base, demos),
        "datasets": lambda: tally.run("datasets", attack_dataset, rng, base, study),
        "mappings (dt)": lambda: tally.run("mappings (dt)", attack_mapping, rng, base),
        "live link": lambda: tally.run("live link", attack_live, rng, frames, model),
        "scheduler": lambda: tally.run("scheduler", attack_scheduler, rng),
        "interrupted writes": lambda: tally.run("interrupted writes", attack_kill, rng, base),
    }
    if args.only:
        surfaces = {k: v for k, v in surfaces.items() if any(o.lower() in k.lower() for o in args.only)}
    share = args.seconds / len(surfaces)
    try:
        for call in surfaces.values():
            end = time.monotonic() + share
            while time.monotonic() < end:
                call()
    finally:
        shutil.rmtree(base, ignore_errors=True)
    tally.print_table()


if __name__ == "__main__":
    main()
