"""A default ``workbench fit`` on real flight logs of 1–4 MB: at most 30 s on this 2-core machine, progress shown.

Issue 41 §5. Each log is fitted as a user fits it: ``workbench fit LOG -o model.npz`` with every default (the
vehicle's shipped mapping, a model per plant group, ``--bootstrap 100`` intervals and the weight ratios), in a fresh
process on a pseudo-terminal, so the progress bars draw as they do for a user; the row says whether one was drawn
(the bootstrap's bar names its resamples). Wall seconds are the target; CPU seconds (the process and its children)
say what the wall time is worth on a shared machine, whose load is printed with the results.

The logs are not in the repository (their origins: ``bench/real_logs.md``): the ``.bin``/``.BIN``/``.tlog``/``.ulg``
files of 1–4 MB in ``WORKBENCH_REAL_LOGS`` (a folder; default ``../shared/external`` beside the repository). A log
whose import stops (no position source, an estimator that does not follow its GPS) is listed with its cause: it is
not a fit anyone waits for. Nothing here tunes a default.
"""

from __future__ import annotations

import os
import pty
import re
import resource
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness import ROOT, child_env, load, verdict  # noqa: E402

BAR_S = 30.0
SIZES_MB = (1.0, 4.0)
SUFFIXES = (".bin", ".BIN", ".tlog", ".ulg")
WORKBENCH = Path(sys.executable).parent / "workbench"
_ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def logs(folder: Path) -> list[Path]:
    lo, hi = (mb * 1024 * 1024 for mb in SIZES_MB)
    return sorted(p for p in folder.iterdir() if p.suffix in SUFFIXES and lo <= p.stat().st_size <= hi)


def fit_on_a_terminal(log: Path, out: Path) -> tuple[int, float, float, str]:
    """``workbench fit LOG -o OUT`` on a pseudo-terminal: exit status, wall and CPU seconds, everything it drew."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    main, sub = pty.openpty()
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(WORKBENCH), "fit", str(log), "-o", str(out)], stdin=subprocess.DEVNULL,
                            stdout=sub, stderr=sub, cwd=ROOT, env=child_env(COLUMNS="100", TERM="xterm"))
    os.close(sub)
    chunks = []
    while True:
        ready, _, _ = select.select([main], [], [], 1.0)
        if ready:
            try:
                data = os.read(main, 65536)
            except OSError:  # the terminal's other end closed: the process is done writing
                break
            if not data:
                break
            chunks.append(data)
        elif proc.poll() is not None:
            break
    code = proc.wait()
    wall = time.perf_counter() - t0
    os.close(main)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return code, wall, cpu, b"".join(chunks).decode("utf-8", "replace")


def run() -> list[dict]:
    folder = Path(os.environ.get("WORKBENCH_REAL_LOGS", ROOT.parent / "shared" / "external"))
    rows = []
    if not folder.is_dir():
        return [{"benchmark": "fit on real logs", "note": f"{folder}: no such folder (WORKBENCH_REAL_LOGS)"}]
    for log in logs(folder):
        with tempfile.TemporaryDirectory() as tmp:
            code, wall, cpu, drawn = fit_on_a_terminal(log, Path(tmp) / "m.npz")
            written = sorted(p.name for p in Path(tmp).glob("m*.npz"))
        text = _ANSI.sub("", drawn)
        progress = "bootstrap:" in text and "resamples of" in text
        errors = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("error:")]
        row = {"benchmark": f"workbench fit {log.name} ({log.stat().st_size / 2**20:.1f} MB), defaults",
               "seconds": wall, "CPU seconds": cpu, "models": len(written),
               "progress bar": "drawn" if progress else "none"}
        if written:
            row.update(target=f"≤ {BAR_S:g} s, progress shown",
                       met=verdict(wall, BAR_S, False) if progress else "NOT met (no progress bar)")
        else:
            row["note"] = (errors[-1] if errors else f"exit {code}")[:160]
        rows.append(row)
    rows.append({"benchmark": "machine during the real-log fits", "note": load()})
    return rows


if __name__ == "__main__":
    from harness import markdown_table

    print(markdown_table(run()))
