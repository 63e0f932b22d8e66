"""``-`` is standard input where a command reads a file and standard output where it writes one
(workbench/cli/stdio.py); a folder output refuses it, binary output to a terminal is refused."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd
import pytest

from workbench.cli import main
from workbench.data.dataset import load_demonstrations

REPO = Path(__file__).resolve().parents[2]
TLOG = REPO / "sample_logs" / "landing_s00.tlog"
MCAP = REPO / "sample_logs" / "landing_s01.mcap"
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def _run(args: list[str], stdin: bytes = b"") -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench", *args], input=stdin, capture_output=True, env=ENV,
                          timeout=300)


class _Stdin(io.TextIOWrapper):
    """A piped standard input for in-process runs."""

    def __init__(self, data: bytes) -> None:
        super().__init__(io.BytesIO(data))

    def isatty(self) -> bool:
        return False


def test_inspect_reads_a_log_from_standard_input_and_names_it_stdin(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", _Stdin(MCAP.read_bytes()))
    assert main(["inspect", "-"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"<stdin>: mcap, {MCAP.stat().st_size} bytes")
    assert main(["inspect", str(MCAP)]) == 0
    by_name = capsys.readouterr().out
    assert out.splitlines()[1:] == by_name.splitlines()[1:]  # the same table as for the file


def test_import_from_stdin_to_stdout_is_the_same_table_as_from_files(tmp_path):
    result = _run(["import", "-", "-o", "-"], stdin=TLOG.read_bytes())
    assert result.returncode == 0, result.stderr.decode()
    assert result.stdout.startswith(b"PAR1")
    assert b"wrote" in result.stderr and b"wrote" not in result.stdout  # messages on stderr
    piped = tmp_path / "piped.parquet"
    piped.write_bytes(result.stdout)
    assert main(["import", str(TLOG), "-o", str(tmp_path / "named.parquet")]) == 0
    a, b = load_demonstrations(piped), load_demonstrations(tmp_path / "named.parquet")
    assert len(a) == len(b) and a.n_samples == b.n_samples
    assert {str(d.meta.get("source")) for d in a} == {"<stdin>"}
    for x, y in zip(a, b, strict=True):
        assert (x.x == y.x).all() and (x.u == y.u).all()


def test_csv_to_stdout_with_output_format(tmp_path, capsys):
    assert main(["import", str(TLOG), "-o", "-", "--output-format", "csv"]) == 0
    captured = capsys.readouterr()
    table = pd.read_csv(io.StringIO(captured.out))
    assert main(["import", str(TLOG), "-o", str(tmp_path / "named.csv")]) == 0
    pd.testing.assert_frame_equal(table, pd.read_csv(tmp_path / "named.csv"))
    assert "wrote" in captured.err


def test_bytes_no_reader_knows_ask_for_format(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", _Stdin(b"\x00\x01 not a log at all " * 50))
    assert main(["inspect", "-"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "<stdin>" in err[0] and "--format" in err[0]


def test_the_format_can_be_given(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", _Stdin(TLOG.read_bytes()))
    assert main(["inspect", "-", "--format", "tlog"]) == 0
    assert capsys.readouterr().out.startswith("<stdin>: tlog")


def test_errors_name_stdin_not_a_temporary_file():
    bad = bytearray(MCAP.read_bytes())
    result = _run(["import", "-", "-o", "-"], stdin=bytes(bad[: len(bad) // 40]))
    err = result.stderr.decode()
    assert result.returncode == 1 and result.stdout == b""
    assert "<stdin>" in err and "workbench-stdio" not in err


def test_fit_to_stdout_then_predict_reads_the_model_from_stdin(tmp_path):
    fitted = _run(["fit", "-", "--bootstrap", "0", "-o", "-"], stdin=TLOG.read_bytes())
    assert fitted.returncode == 0, fitted.stderr.decode()
    predicted = _run(["predict", str(TLOG), "--model", "-", "-o", "-", "--output-format", "csv"],
                     stdin=fitted.stdout)
    assert predicted.returncode == 0, predicted.stderr.decode()
    model = tmp_path / "m.npz"
    model.write_bytes(fitted.stdout)
    assert main(["predict", str(TLOG), "--model", str(model), "-o", str(tmp_path / "p.csv")]) == 0
    pd.testing.assert_frame_equal(pd.read_csv(io.BytesIO(predicted.stdout)), pd.read_csv(tmp_path / "p.csv"))


def test_stdin_is_read_once(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", _Stdin(TLOG.read_bytes()))
    assert main(["view", "-", "--model", "-", "--save", "x.rrd"]) == 2  # a UsageError: argparse's status
    assert "already" in capsys.readouterr().err


@pytest.mark.parametrize("args", [["report", str(TLOG), "-o", "-"], ["demo", "--out", "-"],
                                  ["simulate", "--sample-logs", "-"]])
def test_a_folder_output_refuses_stdout(args, capsys):
    assert main(args) == 2  # a UsageError: argparse's status
    err = capsys.readouterr().err
    assert "-:" in err and "folder" in err


def test_binary_to_a_terminal_is_refused(monkeypatch, capsys):
    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr(sys, "stdout", Tty())
    assert main(["import", str(TLOG), "-o", "-"]) == 2  # a UsageError: argparse's status
    assert "terminal" in capsys.readouterr().err


def test_view_saves_its_recording_to_stdout(tmp_path):
    result = _run(["view", str(TLOG), "--save", "-"])
    assert result.returncode == 0, result.stderr.decode()
    rrd = tmp_path / "x.rrd"
    rrd.write_bytes(result.stdout)
    rerun = Path(sys.executable).with_name("rerun")
    check = subprocess.run([str(rerun) if rerun.exists() else "rerun", "rrd", "verify", str(rrd)],
                           capture_output=True, text=True, timeout=120)
    assert check.returncode == 0, check.stdout + check.stderr


def test_every_reading_and_writing_command_documents_the_dash():
    from workbench.cli.parser import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name in ("inspect", "import", "fit", "predict", "evaluate", "map", "view", "replay", "report", "simulate"):
        text = sub.choices[name].format_help()
        assert "standard input" in text or "standard output" in text, name


class _Endless(io.RawIOBase):
    """A pipe delivering ``total`` bytes of a tlog's head then zeros, without ever holding them."""

    def __init__(self, head: bytes, total: int) -> None:
        self.head, self.left = head, total

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        n = min(len(b), self.left)
        chunk = (self.head[:n] if self.head else b"") or bytes(n)
        self.head = self.head[len(chunk):]
        b[: len(chunk)] = chunk
        self.left -= len(chunk)
        return len(chunk)


def test_standard_input_is_streamed_to_its_file_not_held(monkeypatch, tmp_path):
    import tracemalloc

    from workbench.cli.stdio import Stdio

    total = 64 << 20
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BufferedReader(_Endless(TLOG.read_bytes()[:4096], total))))
    monkeypatch.setattr(sys.stdin, "isatty", lambda: False, raising=False)
    stdio = Stdio()
    tracemalloc.start()
    try:
        path = stdio.input("-")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    try:
        assert path.stat().st_size == total
        assert peak < total / 8  # the previous main held all of it (and a copy) in memory
    finally:
        stdio.cleanup()


def test_a_killed_commands_spool_is_removed_when_the_next_command_starts(tmp_path, monkeypatch):
    """SIGKILL runs no clean-up: the spool of standard input stays behind (287 MB in the attack, for good on the
    previous main); the next command removes it, and leaves a running command's spool alone."""
    import os
    import signal
    import subprocess
    import time

    env = {**os.environ, "TMPDIR": str(tmp_path)}
    run = subprocess.Popen([sys.executable, "-m", "workbench", "inspect", "-"], stdin=subprocess.PIPE,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=REPO)
    try:
        # over a block (1 MiB) of a log, and more to follow: the command spools it and waits for the end of its input
        run.stdin.write(TLOG.read_bytes() * 4)
        run.stdin.flush()
        deadline = time.monotonic() + 60
        while not list(tmp_path.glob("workbench-stdio-*/stdin.tlog")) and time.monotonic() < deadline:
            time.sleep(0.05)
        (spool,) = tmp_path.glob("workbench-stdio-*")
        os.kill(run.pid, signal.SIGKILL)
        run.wait(timeout=30)
    finally:
        run.kill()
        run.stdin.close()
    assert spool.is_dir()  # left behind by the killed command
    running = tmp_path / f"workbench-stdio-{os.getpid()}-alive"  # a running command's (this test's process)
    running.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # this process's temporary folder: the same one
    assert main(["inspect", str(TLOG), "-q"]) == 0
    assert not spool.exists() and running.is_dir()
