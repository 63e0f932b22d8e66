"""The terminal at 80 columns: every line of ``evaluate`` fits (tables as tables where they fit, per strategy or
in long form where they do not), and no raw Markdown reaches a terminal."""

from __future__ import annotations

import fcntl
import io
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
    from rich.cells import cell_len

    too_long = [line for line in lines if cell_len(line) > 80]  # columns on the screen ("K̂" is one)
    assert not too_long, too_long[:5]
    body = "\n".join(lines)
    assert "held-out prediction error" in body
    assert not [line for line in lines if line.lstrip().startswith("|")], "a Markdown table reached the terminal"
    assert "**" not in body and "`" not in body


def _printed(header, rows, width, title=""):
    import io

    from rich.console import Console

    from workbench.cli.context import Context

    ctx = Context.__new__(Context)
    ctx.quiet = False
    buf = io.StringIO()
    ctx.out = Console(file=buf, width=width, force_terminal=True, color_system=None)
    ctx.say_table(header, rows, title)
    return buf.getvalue()


def test_a_wide_table_narrows_itself_before_it_turns_into_a_list():
    """At 80 columns a table keeps its form: a light frame, headers wrapped at their spaces, abbreviated words,
    fewer digits; every cell whole. The key/value list comes only where no narrowing fits."""
    header = ["label", "method", "position RMSE", "velocity RMSE", "MC band", "trials"]
    rows = [["CS1", "persistence", "0.0812 [0.0041, 0.16]", "0.0505 [0.035, 0.066]", "83 % [31, 100]", "6"],
            ["CS2", "proposed", "0.0245 [0, 0.077]", "0.0413 [0.0044, 0.078]", "79 % [0, 100]", "6"]]
    wide = _printed(header, rows, 200)
    narrow = _printed(header, rows, 80)
    assert all(len(line) <= 80 for line in narrow.splitlines())
    assert "  method: persistence" not in narrow  # not the long form
    assert len(narrow.splitlines()) <= 1.3 * len(wide.splitlines())
    assert "persistence" in narrow and "83% [31,100]" in narrow  # every cell whole, if tighter
    # the check can fail: at 30 columns nothing narrows enough, and the long form it falls back to says so
    assert "  method: persistence" in _printed(header, rows, 30)


def test_narrowing_steps_shorten_headers_and_digits():
    from workbench.cli.context import abbreviate, fewer_digits

    assert abbreviate("position RMSE") == "pos. RMSE"
    assert fewer_digits("0.1106 [0.072, 0.15]") == "0.11 [0.072, 0.15]"
    assert fewer_digits("8 (24 / 6)") == "8 (24 / 6)" and fewer_digits("u2") == "u2"


def test_a_combining_accent_takes_no_column_of_its_own():
    """"K̂" is two code points in one column: a table exactly as wide as the terminal with it in a header and a cell
    still fits as a table (the previous main counted code points and printed the long form)."""
    from rich.cells import cell_len

    header = ["strategy", "fell back to K̂x in", "difference"]
    rows = [["CS1", "2 of 6", "K̂x " + "x" * 40], ["CS2", "none", "lower by 23 % [3 %, 43 %]"]]
    from rich.console import Console

    from workbench.cli.context import narrowed_tables

    console = Console(width=200, record=True, file=io.StringIO())
    console.print(narrowed_tables(header, rows)[-1])  # the narrowest form, drawn where nothing constrains it
    width = max(cell_len(line) for line in console.export_text().splitlines())
    exact = _printed(header, rows, width)
    assert "  fell back to K̂x in:" not in exact  # not the long form
    assert all(cell_len(line) <= width for line in exact.splitlines())
