"""Protocol files: the shipped ones say what the paper did; a mistake is one line naming the file and the key."""

from __future__ import annotations

import pytest

from workbench.collect.protocol import block_order, load_protocol, plan
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
        assert items[0].kind == "practice" and items[1].kind == "break"
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
