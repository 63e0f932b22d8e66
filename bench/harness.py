"""What every benchmark shares: like-for-like timing, whole-process timing, peak memory, and the Markdown table.

Rules the helpers enforce (issue 11, "a bench that tells the truth"):

* both sides of a ratio run the same number of times, interleaved (A B A B …), and each side is summarised by
  its median — never a best-of-N of ours against a single run of the peer;
* *cold* is the first call in a fresh interpreter after the reader's module is imported (a lazy import or a
  table built on first use counts), *whole process* is the wall time of ``python -c <script>`` from start to
  exit, *warm* is a repeated call in one process;
* peak memory is measured in a fresh interpreter after the imports: the high-water mark of the resident set
  (Linux ``VmHWM``, reset just before the call) and tracemalloc's peak of traced allocations (numpy, pyarrow
  and Python objects report theirs; a memory-mapped file's pages do not count there).
"""

from __future__ import annotations

import gc
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHON = sys.executable


def interleaved(fns: dict[str, Callable[[], object]], repeats: int, warmup: bool = True) -> dict[str, float]:
    """Median wall-clock seconds of each function, run alternately ``repeats`` times each (after one warm-up)."""
    for fn in fns.values() if warmup else ():
        fn()
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            gc.collect()
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return {k: statistics.median(v) for k, v in times.items()}


def child_env(**extra: str) -> dict[str, str]:
    """The environment of a benchmark's fresh process: this one's, with Python's bytecode cache allowed.

    A user's installed packages have their bytecode cached (pip compiles it at install; the editable workbench's
    modules are compiled on their first import and cached); where the cache is forbidden
    (``PYTHONDONTWRITEBYTECODE``, set on some CI machines and on this one) every fresh process would compile the
    workbench's modules from source while the peer's come compiled from site-packages: a timing of the compiler.
    """
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.update(extra)
    return env


def run_script(code: str, *args: str, env: dict[str, str] | None = None) -> tuple[float, str]:
    """Wall seconds of a fresh ``python -c code args…`` (start to exit) and its stdout."""
    t0 = time.perf_counter()
    out = subprocess.run([PYTHON, "-c", code, *args], capture_output=True, text=True, cwd=ROOT,
                         env=child_env(**(env or {})))
    wall = time.perf_counter() - t0
    if out.returncode:
        raise RuntimeError(f"benchmark script failed:\n{out.stderr[-2000:]}")
    return wall, out.stdout


def processes(codes: dict[str, str], repeats: int, *args: str) -> dict[str, float]:
    """Median whole-process wall seconds of each script, interleaved."""
    times: dict[str, list[float]] = {k: [] for k in codes}
    for _ in range(repeats):
        for name, code in codes.items():
            times[name].append(run_script(code, *args)[0])
    return {k: statistics.median(v) for k, v in times.items()}


_FIRST_CALL = """
import json, sys, time
{imports}
t0 = time.perf_counter()
{call}
print(json.dumps({{"first_call_s": time.perf_counter() - t0}}))
"""


def first_calls(cases: dict[str, tuple[str, str]], repeats: int, *args: str) -> dict[str, float]:
    """Median seconds of the first call in a fresh process (imports done before the clock starts), interleaved.

    ``cases`` maps a name to (imports, call) source lines; ``sys.argv[1:]`` are ``args``.
    """
    times: dict[str, list[float]] = {k: [] for k in cases}
    for imports, call in cases.values():  # once, untimed: the bytecode cache a user's second run has
        run_script(_FIRST_CALL.format(imports=imports, call=call), *args)
    for _ in range(repeats):
        for name, (imports, call) in cases.items():
            out = run_script(_FIRST_CALL.format(imports=imports, call=call), *args)[1]
            times[name].append(json.loads(out.strip().splitlines()[-1])["first_call_s"])
    return {k: statistics.median(v) for k, v in times.items()}


_IMPORT_AND_CALL = """
import json, os, sys, time
if {evict}:  # the file's pages out of the page cache: the read starts from the disk, as after a reboot
    fd = os.open(sys.argv[1], os.O_RDONLY)
    os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    os.close(fd)
t0 = time.perf_counter()
{imports}
{call}
print(json.dumps({{"first_call_s": time.perf_counter() - t0}}))
"""


def import_and_first_call(
    cases: dict[str, tuple[str, str]], repeats: int, path: str, *, cold: bool
) -> dict[str, float]:
    """Median seconds of importing a reader and its first call on ``path`` in a fresh process, interleaved.

    Unlike :func:`first_calls` the clock starts before the imports: what a user's one-shot command waits for
    beyond the bare interpreter. ``cold``: the file is dropped from the page cache before every run
    (``posix_fadvise(DONTNEED)``, this file only); else it is cached (the previous run read it).
    """
    times: dict[str, list[float]] = {k: [] for k in cases}
    for imports, call in cases.values():  # once, untimed: the bytecode cache a user's second run has
        run_script(_IMPORT_AND_CALL.format(imports=imports, call=call, evict=False), path)
    for _ in range(repeats):
        for name, (imports, call) in cases.items():
            code = _IMPORT_AND_CALL.format(imports=imports, call=call, evict=bool(cold))
            out = run_script(code, path)[1]
            times[name].append(json.loads(out.strip().splitlines()[-1])["first_call_s"])
    return {k: statistics.median(v) for k, v in times.items()}


_MEMORY = """
import json, sys, tracemalloc
{imports}
def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(key))
{warm}
import gc; gc.collect()
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # reset VmHWM to the current resident size
before = status("VmRSS:")
tracemalloc.start()
result = {call}
traced = tracemalloc.get_traced_memory()[1]
tracemalloc.stop()
print(json.dumps({{"rss_MB": (status("VmHWM:") - before) / 1024, "traced_MB": traced / 2**20}}))
"""


def peak_memory(imports: str, call: str, *args: str, warm: str = "") -> dict[str, float]:
    """Peak memory above the import baseline of one call in a fresh process: RSS high-water mark and traced."""
    out = run_script(_MEMORY.format(imports=imports, call=call, warm=warm), *args)[1]
    return json.loads(out.strip().splitlines()[-1])


def load() -> str:
    """The machine's load averages (1, 5, 15 min) and core count: context for every absolute time."""
    one, five, fifteen = os.getloadavg()
    return f"load {one:.2f} / {five:.2f} / {fifteen:.2f} on {os.cpu_count()} cores"


def verdict(value: float, bar: float, higher_is_better: bool) -> str:
    ok = value >= bar if higher_is_better else value <= bar
    return "met" if ok else "NOT met"


def _cell(value: object) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def markdown_table(rows: list[dict]) -> str:
    """Rows of dicts as one Markdown table; the columns are the union of the rows' keys in order of appearance."""
    cols: list[str] = []
    for row in rows:
        cols += [c for c in row if c not in cols]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(_cell(row.get(c, "")) for c in cols) + " |" for row in rows]
    return "\n".join(lines)


def best_time(fn: Callable[[], object], repeats: int = 3, *, collect: bool = False) -> float:
    """Median of ``repeats`` runs (kept under its old name for the benchmarks that time ours alone)."""
    times = []
    for _ in range(repeats):
        if collect:
            gc.collect()
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)
