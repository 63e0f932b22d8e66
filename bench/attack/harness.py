"""What the attack scripts share: a call run in a forked child (its own peak memory and time) and the damage real
transfers do to a log's bytes. Both scripts import this module; neither imports the other.
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
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from workbench.errors import WorkbenchError  # noqa: E402

HANG_S = 60.0  # the acceptance's bound for a call on an input under 10 MB
FOREIGN_TEXT = re.compile(r"ZstdError|codec can't decode|cannot fit|Traceback|RecursionError|OverflowError|"
                          r"need at least one array|WebSocketError|TypeError")


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
