"""Real logs recorded by others, tried as a new user would: ``inspect``, ``import`` / ``fit`` / ``evaluate`` without
``--mapping``, and ``view``; one row per log with each command's outcome (its last line when it stopped) and the
identified plant's physics check (``A[xdot, phi]`` against g·dt).

The logs are not in the repository (their origins and licences: ``bench/real_logs.md``); put them in a folder and
run ``python bench/real_logs.py FOLDER [FOLDER …] > table.md`` (each command has ``--timeout`` seconds). Nothing here
tunes a default: the table is read, not optimised.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

BIN = Path(sys.executable).parent
LOGS = (".bin", ".BIN", ".tlog", ".ulg")
CHECK = re.compile(r"check: (A\[\w+, \w+\]) = (-?[\d.e+-]+), expected ([\d.e+-]+).*?"
                   r"ratio (-?[\d.e+-]+), (NOT )?within", re.S)


def _run(args: list[str], timeout: float) -> tuple[int, str, str]:
    try:
        p = subprocess.run([str(BIN / "workbench"), *args], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return -1, "", f"timed out after {timeout:g} s"
    return p.returncode, p.stdout, p.stderr


def _last(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("error:")]
    return (lines[-1] if lines else text.strip().splitlines()[-1] if text.strip() else "")[:220]


def _short(text: str) -> str:
    """A cause without the file's path (the row names the log)."""
    return re.sub(r"^\S+: (mapping '\S+': )?", "", text)[:160].replace("|", "/")


def _outcome(code: int, out: str, err: str, ok: str) -> str:
    return ok if code == 0 else f"stops: {_last(err) or _last(out)}".replace("|", "/")


def row(log: Path, timeout: float) -> list[str]:
    with tempfile.TemporaryDirectory() as tmp:
        code, out, err = _run(["inspect", str(log)], timeout)
        head = out.splitlines()
        vehicle = next((ln for ln in head if ln.startswith("flight modes")), "")
        vehicle = vehicle[vehicle.find("(") + 1: vehicle.find(")")] if "(" in vehicle else ""
        armed = next((ln for ln in head if ln.startswith("armed")), "")
        inspect = f"{vehicle or '?'}; {armed}" if code == 0 else _outcome(code, out, err, "")
        code, out, err = _run(["import", str(log), "-o", f"{tmp}/d.parquet"], timeout)
        chosen = re.search(r"mapping (\S+) \(", out + err)
        imp = _outcome(code, out, err, re.sub(r".*(wrote \d+ demonstrations).*", r"\1", _last(out)))
        imp = f"{chosen.group(1) if chosen else '?'}: {imp}"
        code, out, err = _run(["fit", str(log), "-o", f"{tmp}/m.npz"], timeout)
        fit = _outcome(code, out, err, "fitted")
        m = CHECK.search(" ".join((out + err).split()))  # the terminal's line wrapping undone
        physics = f"{m.group(1)} / (g·dt) = {m.group(4)} ({'NOT ' if m.group(5) else ''}within ×2)" if m else "—"
        stop = re.search(r"bootstrap stopped after (\d+ of \d+) resamples", err)
        if stop:
            fit += f" (bootstrap stopped after {stop.group(1)})"
        code, out, err = _run(["evaluate", str(log)], timeout)
        lines = [ln for ln in out.splitlines() if ln.startswith("│") and "rmse_position" in ln]
        evaluate = _outcome(code, out, err, " / ".join(" ".join(ln.strip("│ ").split()) for ln in lines)
                            or "compared")
        if code == 0 and "time split" in out:
            evaluate = "time split: " + evaluate
        code, out, err = _run(["view", str(log), "--save", f"{tmp}/v.rrd"], timeout)
        raw = re.search(r"warning: (.*); showing the raw log alone", err)
        shown = re.search(r"\((\d+ demonstrations)\)", out)
        view = _outcome(code, out, err, f"states ({shown.group(1)})" if shown and not raw
                        else "raw log" + (f" (the mapping: {_short(raw.group(1))})" if raw else ""))
    return [log.name, inspect, imp, fit, evaluate, view, physics]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folders", nargs="+")
    p.add_argument("--timeout", type=float, default=900.0)
    p.add_argument("--only", nargs="*", default=None, metavar="NAME", help="only the logs with these file names")
    a = p.parse_args()
    logs = sorted(f for d in a.folders for f in Path(d).iterdir() if f.suffix in LOGS)
    if a.only is not None:
        logs = [f for f in logs if f.name in a.only]
    print("| log | inspect (vehicle; armed) | import, no --mapping | fit | evaluate (position RMSE per method) | "
          "view | physics check |")
    print("|---|---|---|---|---|---|---|")
    for log in logs:
        print("| " + " | ".join(row(log, a.timeout)) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
