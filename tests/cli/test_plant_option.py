"""``--plant`` chooses the plant (the glossary's word); ``--system``, its old spelling, still works and says so in
one line on standard error."""

from __future__ import annotations

import argparse

import pytest

from workbench.cli.parser import build_parser


def _commands_with_plant(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {name: a for name, p in sub.choices.items() for a in p._actions if "--plant" in a.option_strings}


def test_every_command_choosing_a_plant_takes_both_spellings():
    found = _commands_with_plant(build_parser())
    assert {"fit", "evaluate"} <= set(found)
    for name, action in found.items():
        assert action.option_strings == ["--plant", "--system"], name
        assert action.dest == "plant" and action.default == "auto", name


@pytest.mark.parametrize("spelling", ["--plant", "--system"])
def test_both_spellings_choose_the_plant(spelling, capsys):
    action = _commands_with_plant(build_parser())["fit"]
    namespace = argparse.Namespace()
    action(None, namespace, "identify", spelling)
    assert namespace.plant == "identify"
    err = capsys.readouterr().err
    if spelling == "--plant":
        assert err == ""
    else:
        assert err == "warning: --system is the old spelling of --plant (still accepted)\n"


def test_the_old_spelling_through_the_command_line(tmp_path, capsys):
    from workbench.cli.app import main

    status = main(["fit", str(tmp_path / "missing.parquet"), "-o", str(tmp_path / "m.npz"), "--system", "paper"])
    err = capsys.readouterr().err
    assert "warning: --system is the old spelling of --plant (still accepted)" in err
    assert status == 1 and "missing.parquet" in err  # the option was taken; the missing file is the error


def test_every_plant_choice_is_the_libraries_and_the_help_states_the_rule():
    # the choices were a second literal list beside workbench.plant.choice's; "free" collided with identification's
    # structure "free" (every entry fitted); the help said "no worse" where the rule is "not shown worse"
    from workbench.plant.choice import PLANT_CHOICES, choose_plant
    from workbench.plant.identification import STRUCTURES

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, action in _commands_with_plant(parser).items():
        assert tuple(action.choices) == PLANT_CHOICES, name
        shown = " ".join(sub.choices[name].format_help().split())  # as `workbench NAME --help` prints it
        assert "95 % HAC interval" in shown and "no worse" not in shown, name
    taken = (set(PLANT_CHOICES) - {"auto"}) & set(STRUCTURES)
    assert not taken, f"a plant choice named like an identification structure: {taken}"
    with pytest.raises(Exception, match="unknown plant choice 'free'"):
        choose_plant(None, "free")  # type: ignore[arg-type]
