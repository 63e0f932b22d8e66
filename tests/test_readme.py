"""The README is checked against the code: every path, module name, command and flag it names exists, its times
are the ones `bench/results.md` holds, and its code blocks run (the slow ones with `make test-all`)."""

from __future__ import annotations

import argparse
import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
TEXT = (REPO / "README.md").read_text(encoding="utf-8")
FENCES = re.findall(r"```(\w*)\n(.*?)```", TEXT, flags=re.S)
PROSE = re.sub(r"```\w*\n.*?```", "", TEXT, flags=re.S)
SPANS = re.findall(r"`([^`\n]+)`", PROSE)
BLOCKS = [code for lang, code in FENCES if lang == "python"]
SHELL = [code for lang, code in FENCES if lang in ("sh", "bash")]
BIN = Path(sys.executable).parent

# examples that listen on a UDP port forever: their imports are checked, they are not run
NEEDS_OUTSIDE = ("mavlink_connection",)
# where the README names a path, it is one of these (or a file at the top of the repository)
TOP = ("../shared/", ".ci/", "adapters/", "bench/", "docs/", "sample_logs/", "tests/", "workbench/")
TOP_FILES = ("Makefile", "README.md", "pyproject.toml", "requirements.lock")
# dotted names that are not Python names: the Parquet metadata's format name
NOT_MODULES = {"workbench.demonstrations"}
# flags of the other programs the README shows (pip, apt-get, rerun, dask, pytest)
OTHER_FLAGS = {"--constraint", "--upgrade-strategy", "--no-install-recommends", "--headless", "--nthreads"}


def _words() -> list[str]:
    """Every whitespace-separated word of the prose's code spans, the shell blocks and the links' targets."""
    words = [w for span in SPANS for w in span.split()]
    words += [w for block in SHELL for line in block.splitlines() for w in line.split("#", 1)[0].split()]
    words += re.findall(r"\]\(([^)#\s]+)\)", PROSE)
    return [w.strip("'\"(),;:") for w in words]


def named_paths() -> list[str]:
    paths = {w for w in _words() if w.startswith(TOP) or w in TOP_FILES or re.fullmatch(r"[\w.-]+\.(py|md|toml)", w)}
    return sorted(paths)


def test_every_path_the_readme_names_exists():
    paths = named_paths()
    assert len(paths) >= 30, paths  # the extraction finds them (else this test checks nothing)
    missing = []
    for p in paths:
        if p.startswith("../shared/") and not (REPO / "../shared").is_dir():
            continue  # a user's fresh clone has no shared folder beside it
        if not (list(REPO.glob(p)) if "*" in p else (REPO / p).exists()):
            missing.append(p)
    assert not missing, f"README names paths that do not exist: {missing}"


def test_every_module_and_name_the_readme_names_imports():
    names = sorted({m for span in SPANS for m in re.findall(r"\b((?:workbench|adapters)(?:\.[A-Za-z_]\w*)+)", span)}
                   - NOT_MODULES)
    assert len(names) >= 10, names
    missing = []
    for name in names:
        parts = name.split(".")
        for cut in range(len(parts), 0, -1):  # the longest importable module, then attributes
            try:
                obj = importlib.import_module(".".join(parts[:cut]))
            except ModuleNotFoundError:
                continue
            try:
                for attr in parts[cut:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                missing.append(name)
            break
        else:
            missing.append(name)
    assert not missing, f"README names what the code does not have: {missing}"


def _commands() -> dict[str, argparse.ArgumentParser]:
    from workbench.cli.parser import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {"": parser, **sub.choices}


def _flags(p: argparse.ArgumentParser) -> set[str]:
    return {s for a in p._actions for s in a.option_strings}


def _uses() -> list[tuple[str, str, str]]:
    """``(where, command, text)`` for every use of a command: the table's rows (the whole row belongs to the
    command of its first cell), code spans and shell lines that call ``workbench COMMAND``."""
    uses = []
    for m in re.finditer(r"^\| `(?:\.venv/bin/)?workbench (\w+)([^\n]*)", PROSE, flags=re.M):
        uses.append(("table row", m.group(1), m.group(2)))
    for span in SPANS:
        for m in re.finditer(r"(?:^|\s|/)workbench (\w+)([^|&]*)", span):
            uses.append(("`" + span + "`", m.group(1), m.group(2)))
    for block in SHELL:
        for line in block.splitlines():
            m = re.match(r"\s*(?:\S*/)?workbench (\w+)(.*)", line.split("#", 1)[0])
            if m:
                uses.append((line.strip(), m.group(1), m.group(2)))
    return uses


def test_every_command_the_readme_shows_exists_with_its_flags():
    commands = _commands()
    uses = _uses()
    assert len(uses) >= 20 and len({c for _, c, _ in uses}) >= 10, uses
    wrong = []
    for where, command, rest in uses:
        if command not in commands:
            wrong.append(f"no command {command!r}: {where}")
            continue
        known = _flags(commands[command]) | _flags(commands[""])
        wrong += [f"{command} has no {flag}: {where}" for flag in re.findall(r"(?<![\w-])--[a-z][\w-]*", rest)
                  if flag not in known]
    assert not wrong, "\n".join(wrong)


def test_every_flag_the_readme_names_is_a_flag_of_some_command():
    """A flag named alone (``--n-components cv``) is one that some command has (the old ``--components`` was not)."""
    known = set().union(*(_flags(p) for p in _commands().values())) | OTHER_FLAGS
    named = {f for span in SPANS for f in re.findall(r"(?<![\w-])--[a-z][\w-]*", span)}
    assert len(named) >= 20
    assert not named - known, f"README names flags no command has: {sorted(named - known)}"


def _bench_row(section: str) -> list[str]:
    results = (REPO / "bench" / "results.md").read_text(encoding="utf-8")
    part = results.split(f"## {section}", 1)[1]
    return [c.strip() for c in re.search(r"^\| workbench demo[^\n]*", part, flags=re.M).group(0).split("|")[1:-1]]


def test_the_demo_times_are_bench_results():
    """`make demo`'s wall and CPU time in the README are `bench_demo`'s row of bench/results.md, rounded."""
    row = _bench_row("bench_demo")
    wall, cpu = round(float(row[1])), round(float(row[2]))
    m = re.search(r"three fresh runs: (\d+) s on the 2-core machine of ([\d-]+) with the machine to itself, (\d+) s "
                  r"of CPU", " ".join(TEXT.split()))
    assert m, "the README's sentence on the demo's time is gone"
    assert (int(m.group(1)), int(m.group(3))) == (wall, cpu)
    assert m.group(2) in (REPO / "bench" / "results.md").read_text(encoding="utf-8")


def test_the_readme_has_examples():
    assert len(BLOCKS) >= 3 and len(SHELL) >= 3


@pytest.mark.parametrize("block", BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_examples_import_only_the_public_faces(block):
    """``from workbench import …`` or a subpackage's public face (``workbench.study``), never a module path."""
    for line in block.splitlines():
        m = re.match(r"\s*from (workbench[\w.]*) import ", line) or re.match(r"\s*import (workbench[\w.]*)", line)
        if m:
            assert m.group(1).count(".") <= 1, f"README imports a module path: {line.strip()}"


def _fleet(where: Path) -> None:
    """A dataset of the sample logs, one partition per subject, where the scaling-out example reads it."""
    out = subprocess.run([str(BIN / "workbench"), "-q", "import", str(REPO / "sample_logs"), "-o", "out/fleet/"],
                         cwd=where, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr


# the scaling-out example starts a Dask cluster and runs a per-subject study (minutes under load): make test-all
RUNS = [pytest.param(b, marks=pytest.mark.slow) if "make_executor(workers" in b else b for b in BLOCKS]


@pytest.mark.parametrize("block", RUNS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_examples_run(block, tmp_path):
    """Each block as a script of its own (``python example.py``), as a user would save and run it."""
    if any(s in block for s in NEEDS_OUTSIDE):
        block = "\n".join(line for line in block.splitlines() if re.match(r"\s*(from|import) ", line))
    if "make_executor(workers" in block:
        pytest.importorskip("distributed")
        _fleet(tmp_path)
    (tmp_path / "example.py").write_text(block, encoding="utf-8")
    out = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]


def _runnable(block: str) -> bool:
    """A shell block of the venv's commands (not `make`, which is what sets the venv up)."""
    lines = [ln for ln in block.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    return all(ln.lstrip().startswith(".venv/bin/") for ln in lines)


@pytest.mark.slow
@pytest.mark.parametrize("block", [b for b in SHELL if _runnable(b)],
                         ids=[f"shell{i}" for i, b in enumerate(SHELL) if _runnable(b)])
def test_shell_examples_run(block, tmp_path):
    """The shell blocks, run by bash in a folder laid out as the repository is (sample_logs/, ../shared/), with
    this venv's commands. No cluster here: `--scheduler ADDRESS` becomes `--workers 2`; the viewer is not opened,
    the recording it would show is checked to exist."""
    repo = tmp_path / "repo"
    repo.mkdir()
    (repo / "sample_logs").symlink_to(REPO / "sample_logs")
    if "../shared/" in block:
        if not (REPO / "../shared/external").is_dir():
            pytest.skip("no ../shared/external beside the repository")
        (tmp_path / "shared").symlink_to((REPO / "../shared").resolve())
    lines = []
    for line in block.splitlines():
        line = re.sub(r"--scheduler \S+", "--workers 2", line.replace(".venv/bin/", f"{BIN}/"))
        if line.startswith(f"{BIN}/rerun "):
            rrd = line.split()[1]
            line = f"wait; test -s {rrd}"
        lines.append(line)
    script = "set -e\n" + "\n".join(lines) + "\nwait\n"
    out = subprocess.run(["bash", "-c", script], cwd=repo, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]


def test_the_screenshot_is_the_one_make_took():
    """docs/viewer.png is what `make readme-screenshot` saved: its record beside it has its digest and the scores
    its first view shows (so a PNG edited or copied in by hand is caught here)."""
    import hashlib
    import json

    record = json.loads((REPO / "docs" / "viewer.json").read_text(encoding="utf-8"))
    assert record["png_sha256"] == hashlib.sha256((REPO / "docs" / "viewer.png").read_bytes()).hexdigest()
    assert "held-out prediction error" in record["scores"]


@pytest.mark.slow
def test_the_screenshot_shows_what_the_demo_prints_now(tmp_path):
    """Stale when the demo's first view would show other scores than the screenshot recorded: run the demo, read
    its recording's scores and compare (run `make readme-screenshot` to renew it)."""
    import json

    from workbench.cli import main
    from workbench.viewer.screenshot import first_view_scores

    assert main(["demo", "--out", str(tmp_path / "demo"), "-q"]) == 0
    record = json.loads((REPO / "docs" / "viewer.json").read_text(encoding="utf-8"))
    assert first_view_scores(tmp_path / "demo" / "demo.rrd") == record["scores"], "run: make readme-screenshot"
