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
