"""Startup: ``workbench --help`` and ``import adapters`` as a user meets them, each in fresh processes.

``workbench --help`` runs the installed console script, start to exit (median of 7). ``import adapters`` is the
import alone, timed inside a fresh interpreter (median of 7), with the whole process beside it; a bare
``python -c pass`` is the floor every process pays. The heavy libraries each command loads are listed: keeping
pandas, pyarrow, cvxpy, scikit-learn and scipy out of startup is what keeps it fast.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness import PYTHON, ROOT, run_script, verdict  # noqa: E402

HEAVY = ("numpy", "pandas", "pyarrow", "cvxpy", "sklearn", "scipy", "matplotlib", "rerun")
REPEATS = 7

_IMPORT = """
import json, sys, time
t0 = time.perf_counter()
import {module}
elapsed = time.perf_counter() - t0
print(json.dumps({{"s": elapsed, "heavy": sorted({{m.split('.')[0] for m in sys.modules}} & set({heavy!r}))}}))
"""


def _command(argv: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(argv, capture_output=True, check=True, cwd=ROOT)
    return time.perf_counter() - t0


def run() -> list[dict]:
    script = str(Path(PYTHON).with_name("workbench"))
    floor = statistics.median(run_script("pass")[0] for _ in range(REPEATS))
    rows = []
    for argv, label in (([script, "--help"], "workbench --help"), ([script, "fit", "--help"], "workbench fit --help")):
        wall = statistics.median(_command(argv) for _ in range(REPEATS))
        probe = ("import sys\nfrom workbench.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n"
                 f"    pass\nprint(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r})))")
        heavy = run_script(probe, *argv[1:])[1].strip().splitlines()[-1]
        row = {"benchmark": label, "mode": "process", "seconds": wall, "python -c pass s": floor,
               "above the bare interpreter s": wall - floor, "heavy libraries loaded": heavy}
        if label == "workbench --help":
            row.update(target="≤ 0.25 s", met=verdict(wall, 0.25, False))
        rows.append(row)
    for module, bar in (("adapters", 0.3), ("workbench.cli", None), ("workbench.models.proposed", None)):
        probes = [json.loads(run_script(_IMPORT.format(module=module, heavy=HEAVY))[1].strip().splitlines()[-1])
                  for _ in range(REPEATS)]
        wall = statistics.median(run_script(f"import {module}")[0] for _ in range(REPEATS))
        row = {"benchmark": f"import {module}", "mode": "in-process import", "seconds": statistics.median(
            p["s"] for p in probes), "process s": wall, "python -c pass s": floor,
            "heavy libraries loaded": probes[-1]["heavy"]}
        if bar is not None:
            row.update(target=f"≤ {bar} s", met=verdict(row["seconds"], bar, False))
        rows.append(row)
    return rows


if __name__ == "__main__":
    from harness import markdown_table

    print(markdown_table(run()))
