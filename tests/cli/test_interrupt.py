"""Ctrl-C (SIGINT) ends ``workbench view`` with one line ``interrupted``, exit 130, no recording half-written
and never an abort (bench/attack/sigint_view.py is the long version: ~50 random moments)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from workbench.viewer.output import open_output

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "landing_s00.tlog"
ENV = {**os.environ, "PYTHONPATH": str(REPO), "DISPLAY": "", "WAYLAND_DISPLAY": ""}


def _leftovers(folder: Path, name: str) -> list[Path]:
    return [p for p in folder.iterdir() if p.name.startswith(f".{name}")]


def test_sigint_while_logging_leaves_no_recording(tmp_path):
    out = tmp_path / "x.rrd"
    proc = subprocess.Popen([sys.executable, "-m", "workbench", "view", str(LOG), "--mapping", "planar_quadrotor",
                             "--save", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV,
                            cwd=tmp_path)
    end = time.monotonic() + 60
    while not _leftovers(tmp_path, out.name) and proc.poll() is None and time.monotonic() < end:
        time.sleep(0.01)  # the recording's temporary file appears when logging starts
    assert proc.poll() is None, "the view ended before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    lines = [ln for ln in err.decode().splitlines() if ln.strip() and not ln.startswith("warning:")]
    assert proc.returncode == 130 and lines == ["interrupted"], err.decode()
    assert not out.exists() and not _leftovers(tmp_path, out.name)


def test_sigint_during_shutdown_neither_kills_nor_prints_a_traceback(tmp_path):
    """A SIGINT arriving after the command is done (here from an exit hook, where the rerun SDK flushes its
    recordings) finds nothing left to interrupt."""
    code = (
        "import atexit, os, signal, sys, time\n"
        "atexit.register(lambda: (os.kill(os.getpid(), signal.SIGINT), time.sleep(0.2)))\n"
        f"sys.argv = ['workbench', 'inspect', {str(LOG)!r}]\n"
        "from workbench.cli import main\n"
        "raise SystemExit(main())\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, cwd=tmp_path,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr and "KeyboardInterrupt" not in result.stderr


class _Recording:
    """A stand-in for a rerun recording whose flush is interrupted half-way through writing its file."""

    def save(self, path):
        self.path = Path(path)
        self.path.write_bytes(b"first half")

    def send_blueprint(self, *args, **kwargs):
        pass

    def flush(self, timeout_sec=None):
        os.kill(os.getpid(), signal.SIGINT)
        with open(self.path, "ab") as f:
            f.write(b", second half")

    def disconnect(self):
        pass


def test_an_interrupted_flush_puts_no_file_in_place(tmp_path):
    target = tmp_path / "x.rrd"
    with pytest.raises(KeyboardInterrupt):
        with open_output(_Recording(), save=target):
            pass
    assert not target.exists() and not _leftovers(tmp_path, target.name)


def test_a_flush_that_ends_puts_the_whole_file_in_place(tmp_path):
    class Done(_Recording):
        def flush(self, timeout_sec=None):
            with open(self.path, "ab") as f:
                f.write(b", second half")

    target = tmp_path / "x.rrd"
    with open_output(Done(), save=target):
        pass
    assert target.read_bytes() == b"first half, second half"


# A finaliser that receives Ctrl-C: CPython runs the handler inside it and drops the KeyboardInterrupt ("Exception
# ignored in …"). The attack round met it in one of four interrupted studies (a WeakSet's callback): the command
# then went on and ended in its workers' deaths (BrokenProcessPool) with a traceback instead of ``interrupted``.
_DROPPER = (
    "import os, signal\n"
    "class Dropper:\n"
    "    def __del__(self):\n"
    "        os.kill(os.getpid(), signal.SIGINT)\n"
    "        for _ in range(10_000):\n"
    "            pass  # the handler runs here, inside the finaliser\n"
)


@pytest.mark.parametrize("ending", [
    "raise RuntimeError('a worker process died')",  # what the Ctrl-C did to the workers
    "raise BrokenPipeError()",  # what it did to the reader of the output pipe
    "return 0",  # nothing: the command ran to its end
], ids=["fails", "broken pipe", "completes"])
def test_an_interrupt_a_finaliser_swallowed_still_ends_the_command_in_one_line(ending):
    code = _DROPPER + (
        "import sys\n"
        "from workbench.cli import app, parser\n"
        "def command(ctx):  # stands in for a command's work, inside the command line's handling\n"
        "    Dropper()  # finalised at once\n"
        f"    {ending}\n"
        "parser.cmd_inspect = command\n"
        "sys.argv = ['workbench', 'inspect', 'x.tlog']\n"
        "raise SystemExit(app.main())\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=60)
    assert result.returncode == 130 and result.stderr.splitlines() == ["interrupted"], result.stderr


def test_a_command_that_handles_ctrl_c_itself_still_reports_its_own_failure():
    """``live`` and ``send`` take Ctrl-C as "stop": a failure after it (the recording's folder gone) is that
    failure, not an interrupt."""
    code = (
        "import os, signal, sys, time\n"
        "from workbench import interrupts\n"
        "from workbench.cli import app, parser\n"
        "from workbench.errors import DataError\n"
        "def command(ctx):\n"
        "    try:\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "        time.sleep(5)\n"
        "    except KeyboardInterrupt:\n"
        "        interrupts.clear()  # as workbench.live.predictor.listen does\n"
        "    raise DataError('out/c.rrd: cannot save the recording: No such file or directory')\n"
        "parser.cmd_inspect = command\n"
        "sys.argv = ['workbench', 'inspect', 'x.tlog']\n"
        "raise SystemExit(app.main())\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=60)
    assert result.returncode == 1 and result.stderr.startswith("error: out/c.rrd"), result.stderr


def test_tasks_stop_after_an_interrupt_a_finaliser_swallowed():
    code = _DROPPER + (
        "from workbench import interrupts\n"
        "from workbench.study.executor import SerialExecutor\n"
        "interrupts.install()\n"
        "ran = []\n"
        "def task(i):\n"
        "    ran.append(i)\n"
        "    if i == 1:\n"
        "        Dropper()\n"
        "    return i\n"
        "try:\n"
        "    SerialExecutor().map(task, range(5))\n"
        "except KeyboardInterrupt:\n"
        "    print('stopped after', ran)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=60)
    assert result.stdout.strip() == "stopped after [0, 1]", (result.stdout, result.stderr)
    assert "Exception ignored" not in result.stderr and "Traceback" not in result.stderr, result.stderr


def test_a_demo_stopped_after_its_import_keeps_the_old_result_set_whole(tmp_path, monkeypatch):
    from workbench.cli import main
    from workbench.study import pipeline

    out = tmp_path / "demo"
    out.mkdir()
    old = {"demos.parquet": "old data", "report.md": "old report", "results.csv": "old results"}
    for name, text in old.items():
        (out / name).write_text(text)

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt  # Ctrl-C during the study, after the import

    monkeypatch.setattr(pipeline, "run_study", stopped)
    assert main(["demo", "--out", str(out), "--samples", "0", "--no-efficiency"]) == 130
    # the previous main had already written the new demos.parquet beside the old report
    assert {p.name: p.read_text() for p in out.iterdir()} == old
