"""Attack ``workbench view`` with Ctrl-C (SIGINT) at random moments and count how it ends.

    PYTHONPATH=. .venv/bin/python bench/attack/sigint_view.py --trials 50

Each trial starts ``python -m workbench view LOG … --save OUT.rrd`` (a raw view, a mapped view, a view with a
model; ``--serve`` too with ``--serve``: it needs no display) and sends SIGINT after a delay drawn from
``--min``…``--max`` seconds. A trial ends in one of:

* ``interrupted``: exit 130, stderr exactly ``interrupted`` (after any warnings), no OUT.rrd, no temporary files
  left beside it;
* ``interrupted late``: the same, but the signal came after OUT.rrd was complete and in place (``rerun rrd verify``
  accepts it);
* ``finished``: the run was done before the signal arrived (exit 0, a complete OUT.rrd);
* ``abort``: SIGABRT (``Fatal Python error``), the fault this script was written for;
* ``python startup``: the signal came while the interpreter itself was starting (``Fatal Python error:
  init_import_site``, exit 1): before any of the workbench's code runs, so nothing it can handle;
* ``killed``: ended by the signal itself (exit -2: SIGINT arrived where Python had put back the default handler,
  e.g. during interpreter shutdown), without the ``interrupted`` line or any cleanup;
* ``traceback``: a Python traceback on stderr;
* ``partial``: a temporary file, or an OUT.rrd that ``rerun rrd verify`` rejects, left behind;
* ``other``: any other exit code or stderr; ``hang``: no exit within ``--hang`` seconds (then SIGKILL).

Prints one line per trial and the counts; exits 1 when any trial ended in one of the bad kinds (all but
``interrupted`` and ``finished``).
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
BAD = ("abort", "killed", "traceback", "partial", "other", "hang")


def _model(folder: Path, python: str) -> Path:
    """A small model to view beside the sample log (fitted once per run)."""
    model = folder / "cs1.npz"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    subprocess.run([python, "-m", "workbench", "-q", "fit", str(REPO / "sample_logs" / "landing_s00.tlog"),
                    "--bootstrap", "0", "-o", str(model)], check=True, env=env, cwd=folder)
    return model


def variants(folder: Path, python: str, serve: bool) -> dict[str, list[str]]:
    log = str(REPO / "sample_logs" / "landing_s00.tlog")
    out = {
        "raw": ["view", log],
        "mapped": ["view", log, "--mapping", "planar_quadrotor"],
        "model": ["view", log, "--mapping", "planar_quadrotor", "--model", str(_model(folder, python))],
    }
    if serve:
        out["serve"] = ["view", log, "--serve"]
    return out


def complete(rrd: Path) -> bool:
    """Whether rerun itself reads the recording whole (a cut file has no RRD footer)."""
    rerun = Path(sys.executable).with_name("rerun")
    result = subprocess.run([str(rerun) if rerun.exists() else "rerun", "rrd", "verify", str(rrd)],
                            capture_output=True, text=True)
    return result.returncode == 0 and "error" not in (result.stdout + result.stderr).lower().replace(
        "without error", "")


def classify(rc: int | None, err: str, out_file: Path, serve: bool) -> str:
    if rc is None:
        return "hang"
    if "init_import_site" in err and rc == 1:
        return "python startup"
    if rc == -signal.SIGABRT or "Fatal Python error" in err:
        return "abort"
    if rc < 0:
        return "killed"
        return "abort"
    if "Traceback (most recent call last)" in err:
        return "traceback"
    leftovers = [p for p in out_file.parent.iterdir() if p.name.startswith(f".{out_file.name}")]
    for p in leftovers:  # counted once, then cleared so the next trial starts clean
        p.unlink()
    if leftovers:
        return "partial"  # a temporary file left beside the output
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("warning:")]
    if out_file.exists() and not complete(out_file):
        return "partial"  # a recording rerun cannot read whole, in place
    if rc == 130 and lines == ["interrupted"]:
        return "interrupted late" if out_file.exists() else "interrupted"
    if rc == 0 and not lines and (serve or out_file.exists()):
        return "finished"
    return "other"


def trial(cmd: list[str], delay: float, out_file: Path, hang: float, serve: bool) -> tuple[str, int | None, str]:
    out_file.unlink(missing_ok=True)
    env = {**os.environ, "PYTHONPATH": str(REPO), "DISPLAY": "", "WAYLAND_DISPLAY": ""}
    args = cmd if serve else [*cmd, "--save", str(out_file)]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=out_file.parent)
    time.sleep(delay)
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        _, err_b = proc.communicate(timeout=hang)
        rc: int | None = proc.returncode
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err_b = proc.communicate()
        rc = None
    err = err_b.decode(errors="replace")
    return classify(rc, err, out_file, serve), rc, err


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trials", type=int, default=50)
    p.add_argument("--min", type=float, default=0.05, help="shortest delay before SIGINT (s)")
    p.add_argument("--max", type=float, default=3.0, help="longest delay before SIGINT (s)")
    p.add_argument("--hang", type=float, default=30.0, help="seconds after SIGINT that count as a hang")
    p.add_argument("--serve", action="store_true", help="also attack `view --serve` (binds 127.0.0.1:9090/9876)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--python", default=sys.executable)
    a = p.parse_args()
    rng = random.Random(a.seed)
    counts: Counter[str] = Counter()
    by_variant: dict[str, Counter[str]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cases = variants(folder, a.python, a.serve)
        names = list(cases)
        for i in range(a.trials):
            name = names[i % len(names)]
            delay = rng.uniform(a.min, a.max)
            out_file = folder / f"view_{name}.rrd"
            kind, rc, err = trial([a.python, "-m", "workbench", *cases[name]], delay, out_file, a.hang,
                                  name == "serve")
            counts[kind] += 1
            by_variant.setdefault(name, Counter())[kind] += 1
            last = err.strip().splitlines()[-1:] if err.strip() else [""]
            print(f"{i:3d} {name:<7} SIGINT at {delay:5.2f} s: {kind:<16} exit {rc}  {last[0][:100]}", flush=True)
            if kind in BAD:
                print("    " + err.strip().replace("\n", "\n    ")[:2000], flush=True)
    print("counts:", dict(counts))
    for name, c in by_variant.items():
        print(f"  {name}: {dict(c)}")
    return 1 if any(counts[k] for k in BAD) else 0


if __name__ == "__main__":
    sys.exit(main())
