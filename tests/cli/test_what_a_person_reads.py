"""What a person reads on the terminal (issues 38 and 40), as a reviewer found it on landing_s02 and real logs: a
warning wrapped at words, no round-off printed as a relevance, no finding from a mixed model that did not converge,
no interval whose ends print as one value, two gain values each said for what it is, a plant warning said once."""

from __future__ import annotations

import io
from types import SimpleNamespace

from rich.console import Console

from workbench.cli.context import Context

REPO_SAMPLE = "sample_logs/landing_s02.csv"


def _context(width: int = 80) -> tuple[Context, io.StringIO, io.StringIO]:
    """A context whose consoles are terminals of ``width`` columns writing to buffers (as the pty tests emulate)."""
    ctx = Context.__new__(Context)
    ctx.quiet = False
    out, err = io.StringIO(), io.StringIO()
    ctx.out = Console(file=out, width=width, force_terminal=True, color_system=None)
    ctx.err = Console(file=err, width=width, force_terminal=True, color_system=None)
    ctx.args = SimpleNamespace()
    return ctx, out, err


def test_a_warning_that_intervals_were_not_computed_wraps_at_words_at_80_columns(monkeypatch):
    # `fit` on one trial: "warning: intervals not computed: …" was one plain print, which an 80-column terminal cut
    # mid-word ("mor/e")
    from workbench.cli import model as model_cli
    from workbench.errors import ModelError

    cause = ("1 demonstration(s): resampling needs two or more to estimate how the gain and the objective vary, so "
             "no interval can be given")

    def refuse(*args, **kwargs):
        raise ModelError(cause)

    monkeypatch.setattr(model_cli, "_print_bootstrap", refuse)
    monkeypatch.setattr(model_cli, "_print_ratios", refuse)
    model = SimpleNamespace(pilot_view=lambda ds: ds, timing="none", timing_=None, objective_=object(),
                            gain_method_="direct")
    ctx, _, err = _context(80)
    model_cli._print_intervals(ctx, model, [], None, 10, 0, 0, "m.npz")
    lines = err.getvalue().splitlines()
    assert len(lines) > 2 and all(len(line) <= 80 for line in lines), lines
    words = " ".join(err.getvalue().split())
    expected = f"warning: intervals not computed: {cause} (intervals of K̂, Q and R; the model is written)"
    assert expected in words  # every word whole: wrapped only at spaces


def test_a_warning_to_a_pipe_stays_one_line(capsys):
    ctx, _, _ = _context(80)
    ctx.err = Console(file=io.StringIO(), width=80, force_terminal=False)  # not a terminal: plain stderr
    text = "x " * 60
    ctx.warn(text)
    assert capsys.readouterr().err == f"warning: {text}\n"
