"""What the attack scripts share: a call run in a forked child (its own peak memory and time), the tally of the
calls' outcomes and the damage real transfers do to a log's bytes. Both scripts import this module; neither imports
the other.
"""

from __future__ import annotations

import json
import os
import random
import re
import resource
import signal
import sys
import time
import traceback
from collections import Counter
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from workbench.errors import WorkbenchError  # noqa: E402

HANG_S = 60.0  # the acceptance's bound for a call on an input under 10 MB
FOREIGN_TEXT = re.compile(r"ZstdError|codec can't decode|cannot fit|Traceback|RecursionError|OverflowError|"
                          r"need at least one array|WebSocketError|TypeError")


class Tally:
    """The calls' outcomes per surface (:func:`_call_in_child`'s kinds counted, examples of the bad ones) with the
    slowest call and the highest peak memory; each script's ``run`` makes the call and hands its outcome here."""

    def __init__(self) -> None:
        self.by_surface: dict[str, Counter] = {}
        self.examples: dict[str, list[str]] = {}
        self.peak: dict[str, float] = {}
        self.slowest: dict[str, float] = {}

    def record(self, surface: str, outcome: tuple[str, str | None, float, int], what: str | None = None) -> None:
        """Count one call's ``(kind, detail, seconds, peak bytes)``; ``what`` names its input in the examples."""
        kind, detail, took, peak = outcome
        c = self.by_surface.setdefault(surface, Counter())
        c["calls"] += 1
        self.slowest[surface] = max(self.slowest.get(surface, 0.0), took)
        self.peak[surface] = max(self.peak.get(surface, 0.0), peak / 2**20)
        def example(text: str) -> None:
            self.examples.setdefault(surface, []).append(text)

        if kind == "clean":
            c["clean errors"] += 1
        elif kind == "foreign":
            c["foreign errors"] += 1
            example(f"{detail}" + (f" ({what})" if what is not None else ""))
        if kind == "hang" or took > HANG_S:
            c["hangs"] += 1
            example(f"hang: {what if what is not None else detail}")
        if kind == "ok" and detail:
            c["silent wrong results"] += 1
            example(f"wrong: {detail}")

    def columns(self, surface: str) -> dict[str, str]:
        """The table's columns after the counts, for one surface."""
        return {"peak MiB": f"{self.peak[surface]:.0f}", "longest call s": f"{self.slowest[surface]:.1f}"}

    def print_table(self, most_examples: int | None = None) -> None:
        """The Markdown table of RESULTS.md (a row per surface), then each surface's distinct examples."""
        keys = ["calls", "clean errors", "foreign errors", "hangs", "silent wrong results"]
        rows = {name: [str(c.get(k, 0)) for k in keys] + list(self.columns(name).values())
                for name, c in self.by_surface.items()}
        extra = list(self.columns(next(iter(rows)))) if rows else []
        print("| surface | " + " | ".join(keys + extra) + " |")
        print("|---|" + "---|" * (len(keys) + len(extra)))
        for name, cells in rows.items():
            print(f"| {name} | " + " | ".join(cells) + " |")
        for name, ex in self.examples.items():
            for e in list(dict.fromkeys(ex))[:most_examples]:
                print(f"{name}: {e}")


def _call_in_child(call: Callable[[], str | None]) -> tuple[str, str | None, float, int]:
    """Run ``call`` in a forked child: (kind, detail, seconds, peak RSS in bytes); kind is ``ok`` (detail: what
    was wrong, if anything), ``clean``, ``foreign`` or ``hang``."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: the call, its verdict, its time; nothing of it returns but through the pipe
        os.close(r)
        code = 0
        try:
            start = time.monotonic()
            try:
                out = ["ok", call()]
            except WorkbenchError as exc:
                out = ["foreign" if FOREIGN_TEXT.search(str(exc)) else "clean", str(exc)[:300]]
            except BaseException as exc:  # noqa: BLE001 - the point of the fuzzer: count what escapes
                where = traceback.extract_tb(exc.__traceback__)[-1].filename if exc.__traceback__ else "?"
                out = ["foreign", f"{type(exc).__name__}: {str(exc)[:200]} @ {where}"]
            out.append(time.monotonic() - start)
            out.append(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024)
            os.write(w, json.dumps(out).encode()[:60_000])
        except BaseException:  # noqa: BLE001
            code = 1
        finally:
            os._exit(code)
    os.close(w)
    deadline = time.monotonic() + 2 * HANG_S
    hung = False
    while True:
        done, _, usage = os.wait4(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            _, _, usage = os.wait4(pid, 0)
            hung = True
            break
        time.sleep(0.01)
    with os.fdopen(r, "rb") as f:
        raw = f.read()
    peak = usage.ru_maxrss * 1024
    if hung or not raw:
        return ("hang" if hung else "foreign"), ("killed" if hung else "child died"), 2 * HANG_S, peak
    kind, detail, took, kids = json.loads(raw)
    return kind, detail, took, max(peak, kids)


def _mutate(rng: random.Random, data: bytes) -> bytes:
    """A real log's bytes, damaged the ways transfers damage them: cut, flipped bytes, a block zeroed or repeated."""
    b = bytearray(data)
    how = rng.choice(["cut", "flip", "zero", "repeat", "prefix"])
    if how == "cut":
        return bytes(b[: rng.randrange(len(b))])
    if how == "flip":
        for _ in range(rng.randrange(1, 50)):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif how == "zero":
        a = rng.randrange(len(b))
        b[a : a + rng.randrange(1, 4096)] = bytes(min(len(b) - a, 4096))[: len(b[a : a + 4096])]
    elif how == "repeat":
        a = rng.randrange(len(b))
        b[a:a] = b[a : a + rng.randrange(1, 2048)]
    else:
        b[:0] = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64)))
    return bytes(b)
