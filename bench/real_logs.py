"""Real logs recorded by others, tried as a new user would: ``inspect``, ``import`` / ``fit`` / ``evaluate`` without
``--mapping``, and ``view``; one row per log with each command's outcome (its last line when it stopped), per plant
group (what the sticks command in the segments' modes: each group is its own plant and model), the identified
plants' physics checks and stick responses, and the held-out comparison's position and input prediction errors.

The logs are not in the repository (their origins and licences: ``bench/real_logs.md``); put them in a folder and
run ``python bench/real_logs.py FOLDER [FOLDER …] > table.md`` (each command has ``--timeout`` seconds). The last
lines count the outcomes. Nothing here tunes a default: the table is read, not optimised.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

BIN = Path(sys.executable).parent
LOGS = (".bin", ".BIN", ".tlog", ".ulg")
GROUP_BLOCK = re.compile(r"plant identification \(plant group ([^,]+),")
CHECK = re.compile(r"check: (A\[\w+, \w+\]) = (-?[\d.e+-]+), expected ([\d.e+-]+).*?ratio (-?[\d.e+-]+), (NOT )?within")
HELD = re.compile(r"check: (A\[\w+, \w+\]) = .*? \(held; the free fit's [-\d.e+]+, ratio (-?[\d.e+-]+)\)")
STICK = re.compile(r"stick: (\w+) → (\w+): (.*?) per full stick \(time constant ([\d.e+-]+) s\)"
                   r"|stick: (\w+) → (\w+): the (.*?) loop does not settle")
# the loop judged: the regulator's A + BK̂, or the pilot's loop with its delay and lag (a timed gain)
LOOP = r"ρ\((?:A \+ BK̂|the pilot's loop[^)]*)\)"
RHO = re.compile(r"closed loop[^:]*: " + LOOP + r" = ([\d.e+-]+), (?:[\d.]+ % interval \[([\d.e+-]+), ([\d.e+-]+)\]"
                 r"|(no interval))[^:]*: (stable|not distinguishable|unstable)")
METHODS = ("proposed", "ioc_only", "gmr_only", "persistence", "no_pilot_held", "no_pilot_zero")
TITLES = {"proposed": "proposed", "ioc_only": "IOC-only", "gmr_only": "GMR-only", "persistence": "persistence",
          "no_pilot_held": "input held", "no_pilot_zero": "input 0"}
INPUT_METRICS = {"input_step": "one step", "input_horizon": "over the horizon"}


def _run(args: list[str], timeout: float) -> tuple[int, str, str]:
    try:
        p = subprocess.run([str(BIN / "workbench"), *args], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return -1, "", f"timed out after {timeout:g} s"
    return p.returncode, p.stdout, p.stderr


def _last(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("error:")]
    return lines[-1] if lines else text.strip().splitlines()[-1] if text.strip() else ""


COMPACT = (  # a refusal for stability in a table cell: ρ with its interval, the slow mode and the mode blamed
    (r"the gain \((\w+)\) is not stabilizing: ", r"not stabilizing (\1): "),
    (r"closed loop on [^:]*: " + LOOP + r" = ([\d.e+-]+), [\d.]+ % interval \[([\d.e+-]+), ([\d.e+-]+)\] over [^:]*: ",
     r"ρ \1 [\2, \3] "),
    (r"; the slow mode lies on ", ", slow mode on "),
    (r"\. In these demonstrations .*?\(--task …@states\)", ""),
    (r"\. Likely cause: .*? — ([^:]+?) \(([^)]*)\): there the autopilot .*?regulated ones", r"; likely cause \1 (\2)"),
)


def _short(text: str, width: int = 160) -> str:
    """A cause without ``error:`` and the file's path (the row names the log)."""
    text = re.sub(r"^error: ", "", text.strip())
    for pattern, into in COMPACT:
        text = re.sub(pattern, into, text)
    return re.sub(r"^\S+: (mapping '\S+': )?", "", text)[:width].replace("|", "/")


def _outcome(code: int, out: str, err: str, ok: str) -> str:
    return ok if code == 0 else f"stops: {_short(_last(err) or _last(out), 320)}".replace("|", "/")


def _not_fitted(err: str, what: str) -> dict[str, str]:
    """``warning: plant group G: not fitted: cause`` lines, per group."""
    found = {}
    for m in re.finditer(rf"warning: plant group (\S+): not {what}: (.*)", err):
        found[m.group(1)] = _short(m.group(2), 200)
    return found


def physics(out: str) -> str:
    """Per plant group: the physics check's ratio and what each stick commands (from the plant reports printed)."""
    text = " ".join(out.split())  # the terminal's line wrapping undone
    parts = []
    blocks = GROUP_BLOCK.split(text)
    if len(blocks) == 1:
        blocks = ["", "—", text]
    seen = set()
    for group, body in zip(blocks[1::2], blocks[2::2], strict=True):
        if group in seen:
            continue
        seen.add(group)
        cells = []
        if (h := HELD.search(body)) is not None:  # the free fit failed its check; the entry is held at its physics
            cells.append(f"{h.group(1)} held at its physics (the free fit's {h.group(2)}×)")
        elif (c := CHECK.search(body)) is not None:
            cells.append(f"{c.group(1)} {c.group(4)}× ({'NOT ' if c.group(5) else ''}within ×2)")
        for s in STICK.finditer(body):
            cells.append(f"{s.group(1)}→{s.group(2)} {s.group(3)}, τ {s.group(4)} s" if s.group(1)
                         else f"{s.group(5)}→{s.group(6)}: no steady state")
        parts.append(f"{group}: {'; '.join(cells) or '—'}")
    return " / ".join(parts) or "—"


def stability(out: str) -> dict[str, str]:
    """Per plant group (\"\" for a one-group fit): ρ(A + BK̂) with its interval and the verdict fit printed."""
    blocks = re.split(r"^plant group (\S+)$", out, flags=re.M)
    pairs = zip(blocks[1::2], blocks[2::2], strict=True) if len(blocks) > 1 else [("", out)]
    found = {}
    for group, body in pairs:
        if (m := RHO.search(" ".join(body.split()))) is not None:
            interval = "no interval" if m.group(4) else f"[{float(m.group(2)):.4g}, {float(m.group(3)):.4g}]"
            found[group] = (f"ρ {float(m.group(1)):.4g} {interval} {m.group(5)}"
                            + ("; no objective" if "task objective: not found" in body else ""))
    return found


def fit_cell(code: int, out: str, err: str) -> str:
    if code != 0:
        return _outcome(code, out, err, "")
    rho = stability(out)
    wrote = re.search(r"wrote (\d+) model\(s\), one per plant group: (.*?)(;|$)", out, re.M)
    failed = _not_fitted(err, "fitted")
    if wrote is None:
        group = re.search(r"^plant group (\S+):", out, re.M)
        said = f" ({rho['']})" if "" in rho else ""
        return (f"fitted ({group.group(1)}){said}" if group else f"fitted{said}")
    groups = [Path(p.strip()).stem.split(".", 1)[-1] for p in wrote.group(2).split(",")]
    return ("fitted " + ", ".join(g + (f" ({rho[g]})" if g in rho else "") for g in groups)
            + "".join(f"; {g} not fitted: {c}" for g, c in failed.items()))


def _means(table: Path) -> dict[str, dict[str, str]]:
    """Per method, the mean over test trials (each trial's windows averaged first) of each RMSE and input metric, as
    printed (3 significant digits), or evaluate's word where the method's rollout diverged
    (``workbench.study.divergence``: "diverges (ρ̂ …)", the same rule and words as the terminal's)."""
    import pandas as pd

    from workbench.study.input_prediction import INPUT_METRICS
    from workbench.study.scores import heldout_scores

    t = pd.read_parquet(table)
    t = t[t.get("table", "comparison") == "comparison"]
    metrics = sorted({m for m in t["metric"].unique() if str(m).startswith("rmse_")}) + list(INPUT_METRICS)
    out: dict[str, dict[str, str]] = {}
    for r in heldout_scores(t, metrics).itertuples(index=False):
        out.setdefault(str(r.method), {})[str(r.metric)] = r.note or f"{r.value:.3g}"
    return out


def evaluate_cells(code: int, out: str, err: str, tables: list[Path]) -> tuple[str, str]:
    """The position RMSE per method and the input prediction error per method, per plant group."""
    if code != 0:
        stop = _outcome(code, out, err, "")
        return stop, stop
    pos, inp = [], []
    failed = _not_fitted(err, "evaluated")
    blocks = dict(zip(*(lambda b: (b[1::2], b[2::2]))(re.split(r"^plant group (\S+) \(", out, flags=re.M)),
                      strict=True))
    for table in tables:
        group = table.stem.split(".", 1)[1] if "." in table.stem else ""
        means = _means(table)
        head = f"{group}: " if group else ""
        left = [_short(ln.strip().split("could not be fitted and is left out of the comparison: ")[-1], 160)
                for ln in blocks.get(group, out).splitlines() if "proposed could not be fitted" in ln]
        body = blocks.get(group, out).splitlines()
        # leave-one-out folds whose training segments could not be fitted, and the words where too few remain
        folds = [re.sub(r"^Fold (\d+ of \d+) \(testing \S+\) left out: its training trials could not be fitted — ",
                        r"fold \1 left out: ", ln.strip()) for ln in body if re.match(r"\s*Fold \d+ of \d+ ", ln)]
        few = [ln.strip().split(": the methods", 1)[0] for ln in body
               if re.search(r"folds? was scored: the methods are not compared", ln)]
        pos.append(head + ", ".join(f"{TITLES[m]} {means[m]['rmse_position']}" for m in METHODS
                                    if 'rmse_position' in means.get(m, {}))
                   + (f" (proposed left out: {left[0]})" if left else "")
                   + "".join(f" ({_short(f, 200)})" for f in folds)
                   + (f" ({few[0][0].lower() + few[0][1:]}: methods not compared, no interval)" if few else ""))
        scores = ["{}: {}".format(INPUT_METRICS[k], ", ".join(f"{TITLES[m]} {means[m][k]}" for m in METHODS
                                                              if k in means.get(m, {})))
                  for k in INPUT_METRICS if any(k in v for v in means.values())]
        inp.append(head + ("; ".join(scores) or "— (no input score in this evaluate)"))
    pos += [f"{g} not evaluated: {c}" for g, c in failed.items()]
    return " / ".join(pos) or "compared", " / ".join(inp) or "—"


def row(log: Path, timeout: float) -> tuple[list[str], dict[str, str]]:
    with tempfile.TemporaryDirectory() as tmp:
        code, out, err = _run(["inspect", str(log)], timeout)
        head = out.splitlines()
        vehicle = next((ln for ln in head if ln.startswith("flight modes")), "")
        vehicle = vehicle[vehicle.find("(") + 1: vehicle.find("):")] if "):" in vehicle else ""
        armed = next((ln for ln in head if ln.startswith("armed")), "")
        inspect = f"{vehicle or '?'}; {armed}" if code == 0 else _outcome(code, out, err, "")
        code, out, err = _run(["import", str(log), "-o", f"{tmp}/d.parquet"], timeout)
        chosen = re.search(r"mapping (\S+) \(", out + err)
        imported = code == 0
        imp = _outcome(code, out, err, re.sub(r".*(wrote \d+ demonstrations).*", r"\1", _last(out)))
        imp = f"{chosen.group(1) if chosen else '?'}: {imp}"
        code, out, err = _run(["fit", str(log), "-o", f"{tmp}/m.npz"], timeout)
        groups = re.search(r"^(\d+ plant groups.*|plant group .*)$", out, re.M)
        fit = fit_cell(code, out, err)
        fitted = code == 0
        plants = physics(out + err)
        code, out, err = _run(["evaluate", str(log), "-o", f"{tmp}/r.parquet"], timeout)
        tables = sorted(Path(tmp).glob("r*.parquet"))
        evaluate, inputs = evaluate_cells(code, out, err, tables)
        proposed = [_means(t).get("proposed", {}).get("rmse_position") for t in tables] if code == 0 else []
        compared = any(v is not None and not v.startswith("diverges") for v in proposed)
        diverges = any(v is not None and v.startswith("diverges") for v in proposed)
        if code == 0 and "time split" in out:
            evaluate = "time split: " + evaluate
        code, out, err = _run(["view", str(log), "--save", f"{tmp}/v.rrd"], timeout)
        raw = re.search(r"warning: (.*); showing the raw log alone", err)
        shown = re.search(r"\((\d+ demonstrations)\)", out)
        view = _outcome(code, out, err, f"states ({shown.group(1)})" if shown and not raw
                        else "raw log" + (f" (the mapping: {_short(raw.group(1))})" if raw else ""))
    group_cell = (groups.group(1).replace(" (--plant-group NAME takes one)", "") if groups else "—").replace("|", "/")
    status = {"imported": str(imported), "fitted": str(fitted), "compared": str(compared), "diverges": str(diverges)}
    stop = imp.split(": ", 1)[1] if not imported else None
    fit, evaluate, inputs = ("same stop" if stop is not None and c == stop else c for c in (fit, evaluate, inputs))
    if plants.replace("—", "").strip(": ") == "":
        plants = "—"
    return [log.name, inspect, imp, group_cell, fit, plants, evaluate, inputs, view], status


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("folders", nargs="+")
    p.add_argument("--timeout", type=float, default=900.0)
    p.add_argument("--only", nargs="*", default=None, metavar="NAME", help="only the logs with these file names")
    a = p.parse_args()
    logs = sorted(f for d in a.folders for f in Path(d).iterdir() if f.suffix in LOGS)
    if a.only is not None:
        logs = [f for f in logs if f.name in a.only]
    print("| log | inspect (vehicle; armed) | import, no --mapping | plant groups | fit | physics and sticks per "
          "group | evaluate (position RMSE per method, m) | input prediction (RMSE per method) | view |")
    print("|---|---|---|---|---|---|---|---|---|")
    counts: Counter = Counter()
    for log in logs:
        cells, status = row(log, a.timeout)
        print("| " + " | ".join(cells) + " |", flush=True)
        counts.update(k for k, v in status.items() if v == "True")
    print(f"\n{len(logs)} logs: {counts['imported']} imported, {counts['fitted']} fitted (a model for at least one "
          f"plant group), {counts['compared']} compared with the proposed model in the held-out evaluation (its "
          f"position RMSE a number in at least one plant group); in {counts['diverges']} the proposed model's rollout "
          "diverges in at least one plant group (said in place of its horizon scores).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
