"""The main job: ``workbench demo`` from a fresh process, three times; the median wall time and CPU time (issue 18).

Wall time is what a user waits for; on a machine shared with others it drifts with their load, so the user + system
CPU time of the process and its children (``resource.getrusage(RUSAGE_CHILDREN)``, what ``/usr/bin/time`` reports)
is recorded beside it, with the machine's load. The demo's own phase breakdown (its last line) is kept from the
median run. The README's stated time is this row's median.

``python bench/bench_demo.py --against DIR`` runs the demo of another checkout (``DIR``, e.g. ``git archive`` of the
previous main unpacked) interleaved with this one's (A B A B …, three each) and reports both medians and their
ratio: on a machine whose speed drifts with others' load, the ratio taken side by side is what carries over to a
quiet machine.
"""

from __future__ import annotations

import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time

from harness import PYTHON, ROOT, child_env, load, verdict

RUNS = 3
TARGET_S = 30.0


def _one(out: str, tree: str = str(ROOT)) -> tuple[float, float, str]:
    """Wall seconds, user + system CPU seconds and the 'done in' line of one demo run into ``out`` (of the
    checkout ``tree``)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([PYTHON, "-m", "workbench", "demo", "--out", out], capture_output=True, text=True,
                          cwd=tree, env=child_env(PYTHONPATH=tree))
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode:
        raise RuntimeError(f"workbench demo failed:\n{proc.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    done = next((line.strip() for line in reversed(proc.stdout.splitlines()) if line.startswith("done in")), "")
    return wall, cpu, re.sub(r"\s+", " ", done)


def run() -> list[dict]:
    start = load()
    runs = []
    with tempfile.TemporaryDirectory(prefix="bench_demo_") as tmp:
        for i in range(RUNS):
            runs.append(_one(os.path.join(tmp, f"out{i}")))
    walls = [r[0] for r in runs]
    median = statistics.median(walls)
    phases = runs[walls.index(sorted(walls)[len(walls) // 2])][2]
    return [{
        "benchmark": f"workbench demo, fresh process, median of {RUNS}",
        "seconds": median,
        "cpu_s (user+sys)": statistics.median(r[1] for r in runs),
        "runs_s": ", ".join(f"{w:.1f}" for w in walls),
        "target": f"≤ {TARGET_S:g} s",
        "met": verdict(median, TARGET_S, False),
        "machine": f"{start} → {load()}",
        "phases (median run)": phases,
    }]


def against(other: str) -> list[dict]:
    """This checkout's demo and ``other``'s, interleaved, three runs each: medians, CPU and the ratio."""
    start = load()
    runs: dict[str, list] = {"this": [], "other": []}
    with tempfile.TemporaryDirectory(prefix="bench_demo_") as tmp:
        for i in range(RUNS):
            for name, tree in (("other", other), ("this", str(ROOT))):
                runs[name].append(_one(os.path.join(tmp, f"{name}{i}"), tree))
    med = {k: statistics.median(r[0] for r in v) for k, v in runs.items()}
    return [{
        "benchmark": f"workbench demo, this checkout against {other}, interleaved, median of {RUNS} each",
        "seconds (this)": med["this"], "seconds (other)": med["other"], "ratio": med["this"] / med["other"],
        "cpu_s (this / other)": " / ".join(f"{statistics.median(r[1] for r in runs[k]):.1f}"
                                           for k in ("this", "other")),
        "runs_s (this; other)": "; ".join(", ".join(f"{r[0]:.1f}" for r in runs[k]) for k in ("this", "other")),
        "machine": f"{start} → {load()}",
        **{f"phases ({k}, median run)": runs[k][[r[0] for r in runs[k]].index(
            sorted(r[0] for r in runs[k])[len(runs[k]) // 2])][2] for k in ("this", "other")},
    }]


if __name__ == "__main__":
    from harness import markdown_table

    if len(sys.argv) == 3 and sys.argv[1] == "--against":
        sys.exit(print(markdown_table(against(sys.argv[2]))))
    sys.exit(print(markdown_table(run())))
