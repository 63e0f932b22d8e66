"""Kill ``workbench demo`` and ``workbench report`` at random moments and check what they leave.

    PYTHONPATH=. nice .venv/bin/python bench/attack/kill_runs.py --runs 60 --dask-runs 6   # 20 per signal

For each command: one complete run makes the *old* result set (seed 0); then ``--runs`` runs, each with another
seed (so its results differ from the old set's), get SIGINT, SIGTERM or SIGKILL (each a third of the runs) after a
delay drawn uniformly from the first run's duration; ``report-dask`` is ``report --workers 2`` (a Dask
``LocalCluster``: nannies in the command, worker processes spawned by them), ``--dask-runs`` times. After each kill
it checks:

* **whole set**: the output folder holds the old set or a complete new one, never a mix (each seed-dependent file
  equal to the old set's, or every one different, and none missing);
* **no live child**: every process of the command's tree (its workers, their resource tracker), listed just before
  the signal, is gone 5 s after it;
* **no leftovers after the next run**: after a final complete run, no staging folder of a process that no longer
  runs in the temporary folder and no build or aside folder in the output folder.

Not part of the test suite; the study options keep each run short (no Monte Carlo band, no efficiency curve).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import psutil

REPO = Path(__file__).resolve().parents[2]
FAST = ["--samples", "0", "--no-efficiency", "--bootstrap", "20"]
SEED_FILES = {"demo": ["results.csv", "report.md", "models"], "report": ["report.md", "figures"],
              "report-dask": ["report.md", "figures"]}
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGKILL]


def _command(kind: str, out: Path, demos: Path, seed: int) -> list[str]:
    base = [sys.executable, "-m", "workbench"]
    if kind == "demo":
        return [*base, "demo", "--out", str(out), "--seed", str(seed), *FAST]
    dask = ["--workers", "2"] if kind == "report-dask" else []
    return [*base, "report", str(demos), "-o", str(out), "--seed", str(seed), *FAST, *dask]


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    if path.is_dir():
        for p in sorted(path.rglob("*")):
            if p.is_file():
                h.update(p.relative_to(path).as_posix().encode())
                h.update(p.read_bytes())
    elif path.is_file():
        h.update(path.read_bytes())
    else:
        return "missing"
    return h.hexdigest()


def _state(kind: str, out: Path) -> dict[str, str]:
    return {name: _digest(out / name) for name in SEED_FILES[kind]}


def _stale_staging() -> list[str]:
    """Staging folders this code made (named with their process id) whose process is gone. Folders without an id
    are another checkout's (the machine is shared), not counted."""
    found = []
    for p in Path(tempfile.gettempdir()).glob("workbench-staging-*"):
        pid = p.name.removeprefix("workbench-staging-").split("-", 1)[0]
        if pid.isdigit() and not psutil.pid_exists(int(pid)):
            found.append(p.name)
    return found


def _leftovers(out: Path) -> list[str]:
    return sorted(p.name for p in out.glob(".*") if ".tmp-" in p.name or ".old-" in p.name)


def _run(cmd: list[str], env: dict) -> float:
    start = time.monotonic()
    subprocess.run(cmd, env=env, capture_output=True, check=True, cwd=REPO)
    return time.monotonic() - start


def attack(kind: str, runs: int, rng: random.Random, base: Path, env: dict, demos: Path) -> Counter:
    out = base / f"{kind}-out"
    duration = _run(_command(kind, out, demos, 0), env)
    old = _state(kind, out)
    print(f"{kind}: a complete run takes {duration:.0f} s", flush=True)
    tally: Counter = Counter()
    # each signal equally often (runs // 3 each, the rest drawn), in a random order
    signals = [*SIGNALS * (runs // len(SIGNALS)), *rng.sample(SIGNALS, runs % len(SIGNALS))]
    rng.shuffle(signals)
    for i, sig in enumerate(signals):
        delay = rng.uniform(0.3, duration)
        proc = subprocess.Popen(_command(kind, out, demos, 100 + i), env=env, cwd=REPO,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        time.sleep(delay)
        tree: list[psutil.Process] = []
        try:
            tree = psutil.Process(proc.pid).children(recursive=True)
        except psutil.NoSuchProcess:
            pass
        finished = proc.poll() is not None
        if not finished:
            proc.send_signal(sig)
        try:
            code = proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            proc.kill()
            code = proc.wait()
            tally["hang"] += 1
        time.sleep(5)
        alive = [p.pid for p in tree if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
        now = _state(kind, out)
        same = [k for k in now if now[k] == old[k]]
        missing = [k for k in now if now[k] == "missing"]
        whole = not missing and (len(same) in (0, len(now)))
        outcome = "finished" if finished else ("old set" if len(same) == len(now) else "new set")
        if not whole:
            outcome = "MIX"
        if alive:
            tally["live children after 5 s"] += 1
        tally[outcome] += 1
        tally[f"signal {signal.Signals(sig).name}"] += 1
        print(f"{kind} run {i + 1:2d}: {signal.Signals(sig).name:7s} after {delay:5.1f} s -> exit {code}, {outcome}, "
              f"{len(tree)} children, {len(alive)} alive after 5 s", flush=True)
        if outcome != "old set" and whole:
            old = now  # the new set is the old one of the next run
    _run(_command(kind, out, demos, 0), env)
    tally["stale staging folders after the next run"] = len(_stale_staging())
    tally["build/aside folders after the next run"] = len(_leftovers(out))
    return tally


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dask-runs", type=int, default=6, help="runs of report --workers 2 (0: none)")
    parser.add_argument("--only", choices=["demo", "report", "report-dask"])
    args = parser.parse_args()
    rng = random.Random(args.seed)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    with tempfile.TemporaryDirectory(prefix="wb-kill-") as tmp:
        base = Path(tmp)
        demos = base / "demos.parquet"
        subprocess.run([sys.executable, "-m", "workbench", "import", *sorted(map(str, (REPO / "sample_logs").glob(
            "landing_s0*"))), "-o", str(demos)], env=env, cwd=REPO, check=True, capture_output=True)
        kinds = [args.only] if args.only else ["demo", "report", "report-dask"]
        for kind in kinds:
            runs = args.dask_runs if kind == "report-dask" else args.runs
            if runs <= 0:
                continue
            tally = attack(kind, runs, rng, base, env, demos)
            print(f"== {kind}: " + ", ".join(f"{k} {v}" for k, v in sorted(tally.items())), flush=True)


if __name__ == "__main__":
    main()
