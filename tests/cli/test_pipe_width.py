"""Output piped from a terminal is as wide as that terminal: a pager in an 80-column pane showed a 100-column table
with every row wrapped."""

from __future__ import annotations

import argparse
import os

from workbench.cli import context


def test_piped_output_takes_the_width_of_the_terminal_it_runs_in(monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)
    width = context.PIPE_WIDTH - 20  # a terminal narrower than the pipe's default
    monkeypatch.setattr(os, "isatty", lambda fd: fd == 2)
    monkeypatch.setattr(os, "get_terminal_size", lambda fd=1: os.terminal_size((width, 50)))
    ctx = context.Context(argparse.Namespace())
    assert not ctx.out.is_terminal and ctx.out.width == width


def test_output_with_no_terminal_anywhere_keeps_the_pipe_width(monkeypatch):
    monkeypatch.delenv("COLUMNS", raising=False)
    monkeypatch.setattr(os, "isatty", lambda fd: False)
    assert context.Context(argparse.Namespace()).out.width == context.PIPE_WIDTH
