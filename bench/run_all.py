"""Run every benchmark in bench/ in one process run and write bench/results.md.

Each ``bench/bench_*.py`` exposes ``run() -> list[dict]``; a row has at least ``benchmark`` and whatever
figures it measured (times, rates, ratios against the peer library on the same data, in the same run). Rows
that carry a ``target`` and a ``met`` verdict (``"met"`` / ``"NOT met"``) are gathered into the summary at the
top of ``bench/results.md``, with the machine's load before and after: the machine is shared and absolute
times drift with it, ratios much less.

Usage: ``python bench/run_all.py [name ...]`` (names like ``tlog`` select ``bench_tlog.py``).
"""

from __future__ import annotations

import importlib.util
import platform
import sys
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from harness import load, markdown_table  # noqa: E402

from workbench.atomic import atomic_write_text  # noqa: E402


def _load(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main(argv: list[str]) -> int:
    files = sorted(HERE.glob("bench_*.py"))
    if argv:
        files = [f for f in files if f.stem.removeprefix("bench_") in argv]
    sections = [
        "# Benchmark results",
        "",
        f"Written by `python bench/run_all.py` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
        f"Python {platform.python_version()}, {platform.machine()}, {sys.platform}. "
        "Ratios compare against the peer library on the same data in the same run "
        "(peer seconds / our seconds: above 1 ours is faster).",
        "",
        f"Machine at the start: {load()}.",
    ]
    summary: list[dict] = []
    failed = 0
    for path in files:
        print(f"== {path.name}", flush=True)
        t0 = time.perf_counter()
        try:
            rows = _load(path).run()
        except Exception:  # a broken benchmark must not hide the others' results
            failed += 1
            sections += ["", f"## {path.stem}", "", "```", traceback.format_exc(), "```"]
            traceback.print_exc()
            continue
        for row in rows:
            if type(row.get("met")).__name__ in ("bool", "bool_"):  # older benchmarks give True / False
                row = {**row, "met": "met" if row["met"] else "NOT met"}
            if str(row.get("target", "-")) in ("-", ""):
                continue  # a figure without a target: in its section only
            if row.get("met") in ("met", "NOT met") or str(row.get("met", "")).startswith("met ("):
                value = next((row[k] for k in ("speed_ratio", "seconds", "rss_x_file", "ratio (×)", "ratio", "speedup")
                              if k in row), "")
                summary.append({"bench": path.stem, "what": " · ".join(
                    str(row[k]) for k in ("reader", "benchmark", "case", "mode") if k in row),
                    "value": value, "target": row.get("target", ""), "verdict": row["met"]})
        table = markdown_table(rows)
        print(table, flush=True)
        sections += ["", f"## {path.stem} ({time.perf_counter() - t0:.0f} s)", "", table]
    sections[5:5] = ["", f"Machine at the end: {load()}.", "", "## Targets (issue 11)", "",
                     markdown_table(summary) if summary else "(none measured)"]
    atomic_write_text(HERE / "results.md", "\n".join(sections) + "\n")
    print(f"wrote {HERE / 'results.md'}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
