"""Run every benchmark in bench/ in one process run and write bench/results.md.

Each ``bench/bench_*.py`` exposes ``run() -> list[dict]``; a row has at least ``benchmark`` and whatever
figures it measured (times, rates, ratios against the peer library on the same data, in the same run).
Speed is reported as ratios, never asserted: the machine is shared and timings drift.

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

from harness import markdown_table  # noqa: E402

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
        "Ratios compare against the peer library on the same data in the same run.",
    ]
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
        table = markdown_table(rows)
        print(table, flush=True)
        sections += ["", f"## {path.stem} ({time.perf_counter() - t0:.0f} s)", "", table]
    atomic_write_text(HERE / "results.md", "\n".join(sections) + "\n")
    print(f"wrote {HERE / 'results.md'}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
