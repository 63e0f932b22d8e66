"""What `workbench report` and `demo` print: paired differences with intervals, repeated-measures statistics, and
no sentence that states a difference its interval does not show."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest


def _wb(*args: str, timeout: float = 900) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": "250", "PYTHONWARNINGS": "ignore"}
    r = subprocess.run([sys.executable, "-m", "workbench", *args], capture_output=True, text=True, timeout=timeout,
                       env=env)
    assert r.returncode == 0, f"exit {r.returncode}\n{r.stdout}\n{r.stderr}"
    return r


def _check(stdout: str, report: str, assert_claims_shown) -> None:
    for text in (stdout, report):
        assert "Which number answers which question" in text
        assert "sign-flip" in text and "Mixed-effects model" in text and "Wilcoxon" not in text
        assert "corrected resampled t" in text and "Methods (refitted on every split" in text
        assert "one-way ANOVA" not in text.lower().replace("repeated-measures anova", "")
        assert "windows on" in text  # the stride and the window count are stated
        assert "calibration" in text
        assert_claims_shown(text)
    # the same statistics in both: the printed table's difference sentences appear in the report
    for line in stdout.splitlines():
        if line.startswith("| ") and ("lower by" in line or "no difference shown" in line):
            assert line in report


def test_report_prints_paired_differences_with_intervals(tmp_path, assert_claims_shown):
    from workbench.cli import main

    data = tmp_path / "s.parquet"
    assert main(["simulate", "--strategy", "CS1", "CS2", "--trials", "8", "--subjects", "2", "-o", str(data),
                 "-q"]) == 0
    r = _wb("report", str(data), "-o", str(tmp_path / "rep"), "--n-components", "2", "--horizon", "1.5",
            "--samples", "0", "--no-efficiency", "--bootstrap", "0", "--test-size", "0.4")
    _check(r.stdout, (tmp_path / "rep" / "report.md").read_text(), assert_claims_shown)


@pytest.mark.slow
def test_demo_prints_paired_differences_with_intervals(tmp_path, assert_claims_shown):
    r = _wb("demo", "--out", str(tmp_path / "demo"), timeout=1800)
    report = Path(tmp_path / "demo" / "report.md").read_text()
    _check(r.stdout, report, assert_claims_shown)
    assert assert_claims_shown(report) >= 1
