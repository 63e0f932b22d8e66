"""The paper's multi-subject study end to end, shortened: three scripted subjects on a virtual gamepad in Chromium
(consent, the subject form, calibration, the briefing, the recorded trials), served by ``workbench collect``, an
excluded trial, then the analyst's side: trials.csv, the data dictionary, the consent records, the per-subject
evaluation with the paper's one-way ANOVA beside ours, and each subject's model fitted on their own training,
landed, not excluded trials (the fit step's function). Slow: the subjects fly in real time."""

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
from workbench.errors import DataError

pytestmark = pytest.mark.slow


def test_the_papers_multi_subject_study_shortened_with_three_scripted_subjects(browser, tmp_path, capsys):
    import signal

    from workbench.cli import main

    from .conftest import calibrate, consent, new_page, pilot_gain, pilot_js
    from .test_adaptive import _serve, _step

    out = tmp_path / "subjects"
    proc, url = _serve(out, "paper_multi_subject", "--max-trials", "4", "--max-pause", "0")
    try:
        for j, y_ref in enumerate((-0.05, -0.1, -0.05)):  # each subject their own way down
            context, page = new_page(browser, gamepad=True)
            try:
                consent(page, url, f"s{j + 1:02d}")
                calibrate(page)
                page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(100.0 - 40 * j), y_ref)}; }}")
                _step(page, "!document.querySelector('#summary').hidden")
            finally:
                context.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    s = Session(out, load_protocol("paper_multi_subject").shortened(4, 0))  # the same session, read back
    ds = load_demonstrations(out)
    assert len(ds) == 12 and sum(d.meta["role"] == "test" for d in ds) == 3
    excluded = next(d.id for d in ds if d.meta["subject"] == "s01" and d.meta["role"] == "train")
    set_exclusion(out, excluded, True, "the subject looked away")

    # what the session leaves for the analyst
    table = pd.read_csv(out / HIDDEN / "trials.csv")
    assert len(table) == 12 and set(table["subject"]) == {"s01", "s02", "s03"}
    assert table.set_index("id").loc[excluded, "exclusion_note"] == "the subject looked away"
    assert table["started"].notna().all() and (table["attempts"] == 1).all()
    dictionary = (out / HIDDEN / "data_dictionary.md").read_text()
    assert all(f"| `{c}` |" in dictionary for c in table.columns) and "| `age` | Age (years) | number |" in dictionary
    assert (table["device"] == "gamepad").all() and (table["gamepad_rule"] == "latest").all()
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
        mine = load_demonstrations(out).filter(
            lambda d, subject=subject: d.meta["subject"] == subject and d.meta["role"] == "train"
            and d.meta["outcome"] == "landed" and not d.meta["excluded"])
        if len(mine) < 2:  # a subject who landed too rarely: the fit step says so, in one line
            with pytest.raises(DataError, match=f"{len(mine)} landed, not excluded landing train trial"):
                fit_subject((str(out), subject, "landing", "train", 2, 0))
            continue
        record = fit_subject((str(out), subject, "landing", "train", 2, 0))
        assert record["train_ids"] == mine.ids and record["data_digest"] == set_digest(mine)
        assert excluded not in record["train_ids"]
