"""A command's result set is one transaction (workbench/atomic.py): swapped in whole, or the old set kept whole,
also when the process is killed inside the swap."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from workbench.atomic import recover_swaps, swap_entries, temp_sibling

REPO = Path(__file__).resolve().parents[1]


def _set(folder: Path, tag: str, names=("a.csv", "report.md", "models")) -> None:
    for name in names:
        if name == "models":
            (folder / name).mkdir(parents=True, exist_ok=True)
            (folder / name / "m.npz").write_text(tag)
        else:
            (folder / name).write_text(tag)


def _contents(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): p.read_text() for p in sorted(folder.rglob("*"))
            if p.is_file() and not any(part.startswith(".") for part in p.relative_to(folder).parts)}


def test_a_swap_replaces_the_set_and_leaves_other_files_alone(tmp_path):
    _set(tmp_path, "old")
    (tmp_path / "sample_logs").mkdir()
    build = temp_sibling(tmp_path / "demo")
    build.mkdir()
    _set(build, "new")
    swap_entries(build, tmp_path, "demo")
    assert set(_contents(tmp_path).values()) == {"new"} and (tmp_path / "sample_logs").is_dir()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "models", "report.md", "sample_logs"]


# a child does the swap's moves by hand and dies (SIGKILL) after `cut` of them, as a kill inside the swap would
_KILLED = """
import json, os, signal, sys
from pathlib import Path
folder, cut = Path(sys.argv[1]), int(sys.argv[2])
from workbench.atomic import temp_sibling
build = temp_sibling(folder / "demo"); build.mkdir()
for name in ("a.csv", "report.md"):
    (build / name).write_text("new")
(build / "models").mkdir(); (build / "models" / "m.npz").write_text("new")
names = sorted(p.name for p in build.iterdir())
old = folder / f".demo.old-{build.name.split('.tmp-', 1)[1]}"
old.mkdir(); (old / ".swap-names.json").write_text(json.dumps(names))
moves = [(folder / n, old / n) for n in names] + [(build / n, folder / n) for n in names]
for src, dst in moves[:cut]:
    os.replace(src, dst)
os.kill(os.getpid(), signal.SIGKILL)
"""


@pytest.mark.parametrize("cut", range(7))
def test_a_swap_killed_at_any_move_is_undone_by_the_next_run(tmp_path, cut):
    _set(tmp_path, "old")
    before = _contents(tmp_path)
    out = subprocess.run([sys.executable, "-c", _KILLED, str(tmp_path), str(cut)], cwd=REPO,
                         env={**os.environ, "PYTHONPATH": str(REPO)})
    assert out.returncode == -9
    recover_swaps(tmp_path, "demo")
    assert _contents(tmp_path) == before  # the old set, whole
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".demo.")]  # nothing left behind
