"""The terminal at 80 columns: every line of ``evaluate`` fits (tables as tables where they fit, per strategy or
in long form where they do not), and no raw Markdown reaches a terminal."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07")


def _on_a_terminal(argv: list[str], columns: int) -> str:
    """Run ``argv`` with a pseudo-terminal of ``columns`` columns as its standard output and error."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 50, columns, 0, 0))
    env = {**os.environ, "COLUMNS": str(columns), "TERM": "xterm-256color"}
    proc = subprocess.Popen(argv, stdout=slave, stderr=slave, stdin=subprocess.DEVNULL, env=env, cwd=REPO)
    os.close(slave)
    out = b""
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # the child closed the terminal
            break
        if not chunk:
            break
        out += chunk
    os.close(master)
    assert proc.wait(timeout=600) == 0, out.decode("utf-8", "replace")[-2000:]
    return out.decode("utf-8", "replace")


@pytest.mark.slow
def test_evaluate_at_80_columns_has_no_line_over_80_and_no_raw_markdown():
    text = _on_a_terminal([sys.executable, "-m", "workbench", "evaluate", "sample_logs/landing_s02.csv",
                           "--n-components", "2", "--samples", "10", "--no-efficiency"], 80)
    # a progress bar redraws its line with carriage returns: each redraw is a line of its own
    lines = [line for line in ANSI.sub("", text).replace("\r\n", "\n").replace("\r", "\n").split("\n")]
    too_long = [line for line in lines if len(line) > 80]
    assert not too_long, too_long[:5]
    body = "\n".join(lines)
    assert "held-out prediction error" in body
    assert not [line for line in lines if line.lstrip().startswith("|")], "a Markdown table reached the terminal"
    assert "**" not in body and "`" not in body
