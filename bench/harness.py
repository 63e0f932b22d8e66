"""What every benchmark shares: best-of-N wall-clock timing and the Markdown table its rows print as."""

from __future__ import annotations

import gc
import time
from collections.abc import Callable


def best_time(fn: Callable[[], object], repeats: int = 3, *, collect: bool = False) -> float:
    """The shortest of ``repeats`` wall-clock runs of ``fn`` in seconds (the least disturbed by the machine)."""
    best = float("inf")
    for _ in range(repeats):
        if collect:
            gc.collect()
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


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
