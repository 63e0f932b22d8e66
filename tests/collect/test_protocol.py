"""Protocol files: the shipped ones say what the paper did; a mistake is one line naming the file and the key."""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.collect.plan import block_order, plan
from workbench.collect.protocol import load_protocol
from workbench.errors import DataError

from .conftest import write_protocol


def _trials(items):
    return [i for i in items if i.kind == "trial"]


def test_paper_single_subject_is_the_papers_design():
    p = load_protocol("paper_single_subject")
    items = plan(p, "s01", 0)
    trials = _trials(items)
    count = {}
    for t in trials:
        count[(t.label, t.role)] = count.get((t.label, t.role), 0) + 1
    assert count == {("CS1", "train"): 30, ("CS2", "train"): 30, ("CS1", "test"): 3, ("CS2", "test"): 3}
    breaks = [i for i in items if i.kind == "break"]
    assert len(breaks) == len(p.blocks) - 1 and all(b.duration_s == 60 for b in breaks)
    assert [t.slot for t in trials] == list(range(len(trials)))


def test_paper_single_subject_declares_the_instructed_references():
    # the instructions are references a fit regulates the deviation from (issue 41 §1): CS1 level first, CS2 a line
    p = load_protocol("paper_single_subject")
    assert {(b.label, b.reference) for b in p.blocks} == {("CS1", "horizontal-first"), ("CS2", "line")}


def test_paper_multi_subject_holds_one_trial_out_at_random():
    p = load_protocol("paper_multi_subject")
    assert p.practice_s == 600 and not p.practice_recorded
    held = []
    for j, subject in enumerate(f"s{k:02d}" for k in range(10)):
        items = plan(p, subject, j)
        assert [i.kind for i in items[:3]] == ["message", "practice", "break"]  # the briefing, then practice
        assert items[0].duration_s == 300 and items[0].title == "Briefing"
        trials = _trials(items)
        assert len(trials) == 11 and sum(t.role == "test" for t in trials) == 1
        held.append(next(t.trial for t in trials if t.role == "test"))
        assert plan(p, subject, j) == items  # a resumed session continues the same plan
    assert len(set(held)) > 1  # drawn per subject, not always the same trial


@pytest.mark.parametrize("mode, expect", [("none", [["A", "B"], ["A", "B"]]), ("reverse", [["A", "B"], ["B", "A"]]),
                                          ("rotate", [["A", "B"], ["B", "A"]])])
def test_counterbalancing_reorders_conditions_and_keeps_train_before_test(tmp_path, mode, expect):
    path = write_protocol(tmp_path / "p.toml", [
        {"label": "A", "instructions": "a", "trials": 2}, {"label": "B", "instructions": "b", "trials": 2},
        {"label": "A", "instructions": "a", "trials": 1, "role": "test"},
        {"label": "B", "instructions": "b", "trials": 1, "role": "test"}], counterbalance=mode)
    p = load_protocol(path)
    for index, labels in enumerate(expect):
        blocks = [p.blocks[j] for j in block_order(p, index)]
        assert [b.label for b in blocks] == labels * 2
        assert [b.role for b in blocks] == ["train", "train", "test", "test"]


def test_shortened_cuts_trials_and_pauses():
    p = load_protocol("paper_multi_subject").shortened(3, 1.0)
    assert [b.trials for b in p.blocks] == [3] and p.practice_s == 1.0 and p.between_blocks_s == 1.0
    assert sum(t.role == "test" for t in _trials(plan(p, "s01", 0))) == 1


@pytest.mark.parametrize("text, where", [
    ('consent = "x"\n', "blocks: missing"),
    ('consent = "x"\n[[blocks]]\nlabel = "A"\ninstructions = "a"\ntrials = 0\n', "blocks[0].trials"),
    ('consent = "x"\n[[blocks]]\nlabel = "A"\ninstructions = "a"\ntrials = "3"\n', "blocks[0].trials: expected"),
    ('consent = "x"\n[[blocks]]\nlabel = "A"\ninstructions = "a"\ntrials = 3\nrole = "exam"\n', "blocks[0].role"),
    ('consent = "x"\n[[blocks]]\nlabel = "A"\ninstructions = "a"\ntrials = 3\nheld_out = 3\n', "blocks[0].held_out"),
    ('consent = "x"\ncounterbalance = "random"\n[[blocks]]\nlabel = "A"\ninstructions = "a"\ntrials = 3\n',
     "counterbalance"),
    ('consent = "x"\n[[fields]]\nname = "age"\ntype = "choice"\n[[blocks]]\nlabel = "A"\ninstructions = "a"\n'
     'trials = 1\n', "fields[0].choices"),
    ('consent = "x"\n[breaks]\nbetween_blocks_s = -1\n[[blocks]]\nlabel = "A"\ninstructions = "a"\ntrials = 1\n',
     "breaks.between_blocks_s"),
    ('consent = "x"\ncolour = 1\n[[blocks]]\nlabel = "A"\ninstructions = "a"\ntrials = 1\n', "colour: unknown key"),
    ('consent = "x"\n[[blocks]]\nlabel = "A/B"\ninstructions = "a"\ntrials = 1\n', "blocks[0].label"),
    ('consent = "x"\n[[blocks]]\nlabel = "A"\ninstructions = "a"\ntrials = 1\nreference = "spiral"\n',
     "blocks[0].reference: 'spiral' is not one of line, horizontal-first"),
    ("consent = \n", "not valid TOML"),
    ("consent = " + "[" * 100_000 + "]" * 100_000 + "\n", "nested too deeply"),
])
def test_a_bad_protocol_is_one_line_naming_file_and_key(tmp_path, text, where):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(DataError) as info:
        load_protocol(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message and where in message, message


def test_an_unknown_protocol_names_the_shipped_ones():
    with pytest.raises(DataError, match="paper_single_subject"):
        load_protocol("paper_triple_subject")


def _latin(tmp_path, n_conditions: int, **top):
    labels = [f"C{k}" for k in range(n_conditions)]
    return load_protocol(write_protocol(tmp_path / "p.toml", [{"label": c, "instructions": c, "trials": 1}
                                                               for c in labels], **top)), labels


@pytest.mark.parametrize("n", [2, 3, 4, 5])
def test_a_balanced_latin_square_puts_each_condition_once_in_each_place_and_after_each_other_equally(n):
    from workbench.collect.protocol import williams

    rows = williams(n)
    assert len(rows) == (2 * n if n % 2 else n)
    for place in range(n):  # each condition equally often in each place
        counts = np.bincount([r[place] for r in rows], minlength=n)
        assert (counts == counts[0]).all()
    follows = np.zeros((n, n), int)  # and each immediately after each other equally often
    for r in rows:
        for a, b in zip(r, r[1:], strict=False):
            follows[a, b] += 1
    off = follows[~np.eye(n, dtype=bool)]
    assert (off == off[0]).all() and off[0] > 0


def test_latin_orders_go_by_the_declared_id_not_by_registration(tmp_path):
    """One mistyped ID no longer shifts every later subject's conditions: the row is the declared ID's place."""
    from workbench.collect.protocol import condition_order

    p, labels = _latin(tmp_path, 3, counterbalance="latin", subjects=["s01", "s02", "s03"])
    by_id = {s: condition_order(p, s, 0)[0] for s in ("s01", "s02", "s03")}
    late = {s: condition_order(p, s, 7)[0] for s in ("s01", "s02", "s03")}  # registered after a typo: same order
    assert by_id == late and len({tuple(v) for v in by_id.values()}) == 3
    order, why = condition_order(p, "s99", 4)
    assert sorted(order) == labels and "not a declared subject" in why


def test_assigned_orders_are_the_experimenters(tmp_path):
    from workbench.collect.protocol import condition_order

    path = write_protocol(tmp_path / "p.toml", [{"label": "A", "instructions": "a", "trials": 1},
                                                {"label": "B", "instructions": "b", "trials": 1}],
                          counterbalance="assigned", subjects=["s01", "s02"])
    path.write_text(path.read_text() + '[orders]\ns01 = ["B", "A"]\ns02 = ["A", "B"]\n')
    p = load_protocol(path)
    assert condition_order(p, "s01", 1) == (["B", "A"], "assigned by the experimenter")
    assert [p.blocks[j].label for j in block_order(p, 0, "s01")] == ["B", "A"]
    assert "not a declared subject" in condition_order(p, "s77", 0)[1]
    path.write_text(path.read_text().replace('s02 = ["A", "B"]', 's02 = ["A", "A"]'))
    with pytest.raises(DataError, match="orders.s02: must list each condition once"):
        load_protocol(path)


def test_message_fit_and_input_steps_are_read_and_laid_out(tmp_path):
    p = load_protocol("assisted_single_subject")
    kinds = [i.kind for i in plan(p, "s01", 0)]
    assert kinds[0] == "message" and kinds.count("fit") == 1
    assert kinds[: kinds.index("fit")].count("trial") == 12  # after the 12 trials it is fitted on and checked by
    trials = _trials(plan(p, "s01", 0))
    assisted = [t for t in trials if t.assist != "none"]
    assert assisted and all(t.model == "fit" for t in assisted) and sum(t.role == "test" and t.assist == "none"
                                                                        for t in trials) == 2
    assert p.input.deadzone == "measured" and p.input.gamepad_rule == "latest"


@pytest.mark.parametrize("blocks, message", [
    ([{"fit": {"label": "A"}}, {"label": "A", "instructions": "a", "trials": 1}],
     "no train block of label 'A' before it"),
    ([{"label": "A", "instructions": "a", "trials": 1, "assist": "show"}, {"fit": {"label": "A"}},
      {"label": "A", "instructions": "a", "trials": 1, "role": "test"}], "its fit step comes later"),
    ([{"label": "A", "instructions": "a", "trials": 1}, {"fit": {"label": "A", "from": "test"}}], "fit.from"),
    ([{"label": "A", "instructions": "a", "trials": 1}, {"message": {"text": "x", "colour": 1}}], "message.colour"),
    ([{"label": "A", "instructions": "a", "trials": 3, "stop": {"landed": 4}}], "stop.landed"),
    ([{"label": "A", "instructions": "a", "trials": 3, "stop": {"identified": "phi"}}], "stop.identified"),
    ([{"label": "A", "instructions": "a", "trials": 3, "stop": {"min_trials": 3}}], "stop.min_trials"),
])
def test_a_fit_or_message_step_that_cannot_work_is_one_line(tmp_path, blocks, message):
    lines = ['consent = "x"']
    for b in blocks:
        lines.append("[[blocks]]")
        for k, v in b.items():
            if isinstance(v, dict):
                lines.append(f"{k} = {{ " + ", ".join(f"{kk} = {json.dumps(vv)}" for kk, vv in v.items()) + " }")
            else:
                lines.append(f"{k} = {json.dumps(v)}")
    path = tmp_path / "p.toml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError) as info:
        load_protocol(path)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_the_input_table_is_checked(tmp_path):
    path = write_protocol(tmp_path / "p.toml", [{"label": "A", "instructions": "a", "trials": 1}])
    base = path.read_text()
    path.write_text(base + '[input]\ndevice = "gamepad"\ndeadzone = 0.02\nexpo = 0.4\ngamepad_rule = "mean"\n')
    p = load_protocol(path)
    assert (p.input.device, p.input.deadzone, p.input.expo, p.input.gamepad_rule) == ("gamepad", 0.02, 0.4, "mean")
    for bad, where in (("deadzone = 0.6", "input.deadzone"), ("expo = 2", "input.expo"),
                       ('device = "mouse"', "input.device"), ('gamepad_rule = "max"', "input.gamepad_rule")):
        path.write_text(base + f"[input]\n{bad}\n")
        with pytest.raises(DataError, match=where):
            load_protocol(path)
