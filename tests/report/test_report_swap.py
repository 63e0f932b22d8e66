"""An interrupted report never leaves an old report.md beside new figures; leftovers of killed runs and of killed
atomic writes are removed by the next run; Ctrl-C inside the swap is held back until it is done."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from workbench import atomic
from workbench.report import markdown

REPO = Path(__file__).resolve().parents[2]


def _old_report(out: Path) -> None:
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "old.png").write_bytes(b"old figure")
    (out / "report.md").write_text("old report")
    (out / "models.npz").write_bytes(b"not the report's")


def _fake(fail: bool):
    def build(folder: Path, inputs) -> Path:
        (folder / "figures").mkdir()
        (folder / "figures" / "new.png").write_bytes(b"new figure")
        if fail:
            raise KeyboardInterrupt
        (folder / "report.md").write_text("new report")
        return folder / "report.md"
    return build


def test_a_failed_report_leaves_the_old_one_whole(tmp_path, monkeypatch):
    _old_report(tmp_path)
    monkeypatch.setattr(markdown, "_write_report", _fake(fail=True))
    with pytest.raises(KeyboardInterrupt):
        markdown.write_report(tmp_path, None)
    assert (tmp_path / "report.md").read_text() == "old report"
    assert sorted(p.name for p in (tmp_path / "figures").iterdir()) == ["old.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figures", "models.npz", "report.md"]


def test_a_report_replaces_report_and_figures_together(tmp_path, monkeypatch):
    _old_report(tmp_path)
    monkeypatch.setattr(markdown, "_write_report", _fake(fail=False))
    markdown.write_report(tmp_path, None)
    assert (tmp_path / "report.md").read_text() == "new report"
    assert sorted(p.name for p in (tmp_path / "figures").iterdir()) == ["new.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figures", "models.npz", "report.md"]


def test_a_killed_report_leaves_the_old_one_and_the_next_run_cleans_up(tmp_path):
    _old_report(tmp_path)
    code = textwrap.dedent(f"""
        import time
        from pathlib import Path
        from workbench.report import markdown
        def slow(folder, inputs):
            (folder / "figures").mkdir()
            (folder / "figures" / "new.png").write_bytes(b"new figure")
            print("building", flush=True)
            time.sleep(60)
        markdown._write_report = slow
        markdown.write_report(Path({str(tmp_path)!r}), None)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=REPO,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.stdout.readline().strip() == "building"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert (tmp_path / "report.md").read_text() == "old report"
    assert sorted(p.name for p in (tmp_path / "figures").iterdir()) == ["old.png"]
    leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(".report.tmp-")]
    assert leftovers == [f".report.tmp-{proc.pid}-" + leftovers[0].rsplit("-", 1)[1]]
    markdown._write_report, original = _fake(fail=False), markdown._write_report
    try:
        markdown.write_report(tmp_path, None)
    finally:
        markdown._write_report = original
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figures", "models.npz", "report.md"]


def test_a_killed_atomic_write_is_cleaned_by_the_next_write_of_that_file(tmp_path):
    target = tmp_path / "model.npz"
    code = textwrap.dedent(f"""
        import os, signal
        from workbench.atomic import atomic_path
        with atomic_path({str(target)!r}) as tmp:
            tmp.write_bytes(b"half")
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == -signal.SIGKILL
    left = [p.name for p in tmp_path.iterdir()]
    assert len(left) == 1 and left[0].startswith(".model.npz.") and left[0].endswith(".npz.tmp")
    atomic.atomic_write_bytes(target, b"whole")
    assert [p.name for p in tmp_path.iterdir()] == ["model.npz"] and target.read_bytes() == b"whole"


def test_ctrl_c_inside_a_swap_is_raised_after_it():
    done = []
    with pytest.raises(KeyboardInterrupt):
        with atomic.deferred_interrupt():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # the handler has run by now: it only noted the signal
            done.append(True)
    assert done == [True]
