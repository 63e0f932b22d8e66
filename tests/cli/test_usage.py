"""Usage errors: argparse's one line and status 2, with the nearest flag of the command for a mistyped one."""

from __future__ import annotations

import pytest

from workbench.cli import main


@pytest.mark.parametrize(("argv", "typo", "meant"), [
    (["fit", "demos.parquet", "--lable", "CS1", "-o", "m.npz"], "--lable", "--label"),
    (["import", "x.tlog", "--maping", "ardupilot_manual", "-o", "d.parquet"], "--maping", "--mapping"),
    (["evaluate", "demos.parquet", "--n-componets=3"], "--n-componets=3", "--n-components"),
])
def test_a_mistyped_flag_names_the_commands_nearest(argv, typo, meant, capsys):
    with pytest.raises(SystemExit) as ended:
        main(argv)
    assert ended.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"workbench {argv[0]}: error: unrecognized arguments:")
    assert f"{typo} (did you mean {meant}?)" in err[-1]


def test_a_word_far_from_every_flag_gets_no_guess(capsys):
    with pytest.raises(SystemExit) as ended:
        main(["fit", "demos.parquet", "--zzzzzz", "-o", "m.npz"])
    assert ended.value.code == 2
    err = capsys.readouterr().err
    assert "unrecognized arguments: --zzzzzz" in err and "did you mean" not in err


@pytest.mark.parametrize("argv", [
    ["simulate", "--trials", "1"],                                               # neither -o nor --sample-logs
    ["simulate", "--trials", "1", "-o", "x.parquet", "--output-format", "csv"],  # --output-format is for -o -
    ["import", "-", "-o", "dataset/"],                                           # standard input into a folder
    ["demo", "--out", "-"],                                                      # a folder on standard output
    ["replay", "sample_logs/landing_s00.tlog"],                                  # neither --model nor --to
    ["import", "sample_logs/landing_s00.tlog", "-o", "demos.xyz"],               # no format has that extension
])
def test_arguments_that_do_not_go_together_are_a_usage_error(argv, tmp_path, monkeypatch, capsys):
    """A UsageError: one line and argparse's status 2 (they were status 1, as for a bad file)."""
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    monkeypatch.chdir(tmp_path)
    argv = [str(repo / a) if a.startswith("sample_logs/") else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err


def test_a_usage_error_is_a_workbench_error():
    from workbench.errors import UsageError, WorkbenchError

    assert issubclass(UsageError, WorkbenchError) and issubclass(UsageError, ValueError)
