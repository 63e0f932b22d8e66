"""The paper's multi-subject study end to end, shortened: three scripted subjects through the server's session
(consent, briefing, practice, the recorded trials), an excluded trial, then the analyst's side: trials.csv, the
data dictionary, the consent records, the per-subject evaluation with the paper's one-way ANOVA beside ours, and
each subject's model fitted on their own training, landed, not excluded trials (the fit step's function).
Slow: three subjects' models are fitted and evaluated."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from workbench.collect.fitting import fit_subject
from workbench.collect.protocol import load_protocol
from workbench.collect.records import set_exclusion
from workbench.collect.session import HIDDEN, Session
from workbench.data.dataset import load_demonstrations
from workbench.data.digest import set_digest

from .conftest import join
from .test_session import flown

pytestmark = pytest.mark.slow


def test_the_papers_multi_subject_study_shortened_with_three_scripted_subjects(tmp_path, capsys):
    from workbench.cli import main

    out = tmp_path / "subjects"
    s = Session(out, load_protocol("paper_multi_subject").shortened(6, 0))
    for j in range(3):
        subject = f"s{j + 1:02d}"
        join(s, subject, {"age": 20 + j, "gaming": "weekly"})
        s.calibrate(subject, {"kind": "keyboard", "ramp_steps": 5, "ramp_per_step": 0.2, "confirmed": True})
        for item in s.plan(subject):
            if item.kind in ("message", "practice", "break", "instructions"):
                s.advance(subject, item.key)
            elif item.kind == "trial":
                s.start_trial(subject, item.slot)
                # each subject their own way down; some trials land, some crash
                s.write_trial(flown(s, subject, item.slot, y_ref=(-0.02, -0.05, -0.15)[(j + item.slot) % 3]))
        assert s.status(subject)["next"]["kind"] == "end"
    ds = load_demonstrations(out)
    assert len(ds) == 18 and sum(d.meta["role"] == "test" for d in ds) == 3
    excluded = next(d.id for d in ds if d.meta["subject"] == "s02" and d.meta["role"] == "train")
    set_exclusion(out, excluded, True, "the subject looked away")

    # what the session leaves for the analyst
    table = pd.read_csv(out / HIDDEN / "trials.csv")
    assert len(table) == 18 and set(table["subject"]) == {"s01", "s02", "s03"}
    assert table.set_index("id").loc[excluded, "exclusion_note"] == "the subject looked away"
    assert table["started"].notna().all() and (table["attempts"] == 1).all()
    dictionary = (out / HIDDEN / "data_dictionary.md").read_text()
    assert all(f"| `{c}` |" in dictionary for c in table.columns) and "| `age` | Age (years) | number |" in dictionary
    consent = json.loads((out / HIDDEN / "consent.json").read_text())
    sha = s.protocol.consent_sha256
    assert [(c["subject"], c["agreed"], c["consent_sha256"]) for c in consent] == [
        ("s01", True, sha), ("s02", True, sha), ("s03", True, sha)]
    assert all(d.meta["consent_sha256"] == sha for d in load_demonstrations(out))

    # the paper's analysis beside ours
    assert main(["evaluate", str(out), "--per-subject", "--n-components", "1", "--horizon", "5",
                 "-o", str(tmp_path / "per_subject.csv")]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert "the paper's analysis, as the paper ran it: one-way ANOVA over 3 methods as independent groups: F(2, 6)" \
        in printed
    assert "ours: repeated-measures ANOVA over methods within 3 subjects" in printed
    assert "the difference: the paper's ANOVA treats each method's 3 subjects as 3 independent groups" in printed

    # each subject's model: their training, landed, not excluded trials, nothing else
    for subject in ("s01", "s02", "s03"):
        record = fit_subject((str(out), subject, "landing", "train", 2, 0))
        mine = load_demonstrations(out).filter(
            lambda d, subject=subject: d.meta["subject"] == subject and d.meta["role"] == "train"
            and d.meta["outcome"] == "landed" and not d.meta["excluded"])
        assert record["train_ids"] == mine.ids and record["data_digest"] == set_digest(mine)
        assert excluded not in record["train_ids"]
