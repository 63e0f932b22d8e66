"""What a person reads on the terminal (issues 38 and 40), as a reviewer found it on landing_s02 and real logs: a
warning wrapped at words, no round-off printed as a relevance, no finding from a mixed model that did not converge,
no interval whose ends print as one value, two gain values each said for what it is, a plant warning said once."""

from __future__ import annotations

import io
import re
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
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


def test_one_trial_prints_no_round_off_as_a_relevance(tmp_path, capsys):
    # one trial: the timing's relevance came out as -7.6e-15 (-5.8e-16 on another), round-off printed as a number
    from workbench.cli.app import main

    table = pd.read_csv(REPO_SAMPLE)
    one = tmp_path / "one.csv"
    table[table["demo"] == table["demo"].iloc[0]].to_csv(one, index=False)
    assert main(["fit", str(one), "-o", str(tmp_path / "m.npz"), "--bootstrap", "0"]) == 0
    text = capsys.readouterr().out
    shown = re.findall(r"relevance (\S+?)\)", text)
    assert shown, text
    for value in shown:
        assert value == "0" or abs(float(value)) >= 1e-9, shown


def test_relevance_text_says_zero_only_at_round_off():
    from workbench.method.gain import RELEVANCE_ROUND_OFF, relevance_text

    assert relevance_text(-RELEVANCE_ROUND_OFF / 10) == "0"
    assert relevance_text(-0.015) == f"{-0.015:.2g}"  # below chance, a measurement: its sign stays


def _paired(change_lo: float, change_hi: float, n_trials: int):
    from workbench.study.paired import PairedDifference

    mid = 0.5 * (change_lo + change_hi)
    return PairedDifference("proposed", "persistence", "rmse_position", "CS2", mid, change_lo, change_hi, 0.04,
                            0.32, n_trials, 13, 1, "trials", 4000)


def test_a_mixed_model_that_did_not_converge_gives_no_factor_and_no_p():
    # landing_s02: "NOT converged" followed by "strategy CS2 ×0.393 [0.242, 0.64] (lower) 0.0144 (2)"
    from workbench.study.findings import StudyStatistics
    from workbench.study.stats import MixedEffect, MixedModelResult

    effect = MixedEffect("strategy CS2", 0.393, 0.242, 0.64, 0.0144, 2.0)
    mixed = MixedModelResult("proposed", (effect,), "trial", 16, 4, converged=False,
                             note="Maximum Likelihood optimization failed to converge")
    stats = StudyStatistics("rmse_position", "m", "Scored: …", (_paired(0.6, 0.7, 4),), (), mixed)
    text = stats.text()
    assert "did not converge" in text and "no factor or p-value" in text
    assert f"×{effect.factor:.3g}" not in text and f"{effect.p:.3g}" not in text
    legend = dict(stats.legend())
    assert "did not converge" in legend["strategies differ?"]
    converged = StudyStatistics("rmse_position", "m", "Scored: …", (_paired(0.6, 0.7, 4),), (),
                                MixedModelResult("proposed", (effect,), "trial", 16, 4, converged=True))
    assert f"×{effect.factor:.3g}" in converged.text()  # the check can fail: a converged fit's factor is shown


def test_an_interval_whose_ends_print_alike_is_said_in_words():
    # landing_s02, 2 test trials: "lower by 88 % [88 %, 88 %]"
    from workbench.study.paired import paired_difference

    baseline = np.array([0.30, 0.34])
    wide = pd.DataFrame({"proposed": baseline * np.array([0.1200, 0.1201]), "persistence": baseline,
                         "n_windows": [6, 7], "subject": [None, None]}, index=["t1", "t2"])
    from workbench.study.paired import difference_sentence, min_units

    d = paired_difference(wide, "proposed", "persistence", "rmse_position", "CS2")
    words = d.sentence()
    assert "[" not in words and words == f"no interval ({d.n_trials} test trials; {min_units()} needed)", words
    # two trials are too few for any interval (min_units), whatever their spread; ends that print alike from enough
    # trials are words too, and an interval of some width is printed
    wider = paired_difference(wide.assign(proposed=baseline * np.array([0.10, 0.15])), "proposed", "persistence")
    assert wider.lo is None and "[" not in wider.sentence()
    assert "[" not in difference_sentence(0.88, 0.8801, 0.8804) and "[" in difference_sentence(0.88, 0.85, 0.9)


def test_the_weight_ratios_say_their_gain_entry_is_bias_corrected():
    # landing_s02: K̂[u1, phi] printed -0.447, then "u1 on phi -0.469 […]" also called "the estimated gain entry"
    from workbench.study.weights import PartFit

    closest = SimpleNamespace(shown=np.array([True, False]), k_hat=np.array([-0.469, 0.1]),
                              k_closest=np.array([-0.554, 0.1]), mismatch_lo=np.array([0.049, 0.0]),
                              mismatch_hi=np.array([0.121, 0.0]))
    fit = PartFit(("phi", "xdot"), ("u1",), 3.0, 0, float("nan"), None, closest, 19.0, 0, bias_corrected=True)
    words = fit.mismatch_words()
    assert "after the jackknife's bias correction" in words and "K̂ as printed above is uncorrected" in words
    plain = PartFit(("phi", "xdot"), ("u1",), 3.0, 0, float("nan"), None, closest, 19.0, 0)
    assert "the estimated gain entry" in plain.mismatch_words()


def test_the_weight_ratios_bias_correct_where_they_have_leave_one_out_gains():
    # the flag follows the computation: PartDistance corrects (and has a dof) only with leave-one-out gains
    from workbench.method.ratio_profile import PartDistance

    rng = np.random.default_rng(0)
    A, B = np.array([[1.0, 0.05], [0.0, 1.0]]), np.array([[0.0], [0.05]])
    K = np.array([[-0.5, -0.8]])
    samples = K + 0.05 * rng.standard_normal((40, 1, 2))
    loo = K + 0.01 * rng.standard_normal((10, 1, 2))
    corrected = PartDistance.from_samples(A, B, K, samples, 10, loo)
    plain = PartDistance.from_samples(A, B, K, samples, 10)
    assert corrected.dof is not None and plain.dof is None
    assert not np.allclose(corrected.k_hat, K.ravel()) and np.allclose(plain.k_hat, K.ravel())


def test_an_identified_plants_warning_is_printed_once(capsys):
    # yuneec_position.ulg: "identified plant: worse than persistence …" in the report and again on stderr
    from workbench.cli.writing import print_plant
    from workbench.plant.identification import IdentificationReport

    states = ("x", "xdot")
    r = np.array([0.01, 0.2])
    report = IdentificationReport(
        structure="kinematic", validation="leave-one-out", n_segments=3, n_pairs=500, dt=0.05, n_steps=60,
        state_names=states, one_step_rmse=r, one_step_rmse_persistence=r / 2, horizon_rmse=r,
        horizon_rmse_persistence=r, one_step_score=0.216, one_step_score_persistence=0.193, horizon_score=1.7,
        horizon_score_persistence=1.85, spectral_radius=1.0, spectral_radius_beyond_integrators=0.97,
        n_integrators=1, condition_number=6.0, warnings=("worse than persistence on held-out segments",))
    ctx, out, err = _context(200)
    print_plant(ctx, SimpleNamespace(identification=report))
    seen = out.getvalue() + err.getvalue() + "".join(capsys.readouterr())
    assert seen.count(report.warning) == 1, seen
    assert f"warning: {report.warning}" in err.getvalue()
    assert report.warning in str(report)  # the report alone (the Python API) keeps its warning line


@pytest.mark.parametrize("value", [0.0, 1e-12])
def test_relevance_round_off_both_signs(value):
    from workbench.method.gain import relevance_text

    assert relevance_text(value) == relevance_text(-value) == "0"


def test_evaluate_prints_no_interval_from_too_few_test_trials(tmp_path, capsys, monkeypatch):
    """evaluate on 4 test trials (fewer than min_units): the fitted models' table and the input-prediction table say
    "no interval" with the count in every difference cell (the previous main printed "[…]" intervals from these 4
    trials); the method-level rows, of 6 splits, keep theirs."""
    from workbench.cli.app import main
    from workbench.study.paired import min_units

    monkeypatch.setenv("COLUMNS", "200")  # one table row per line
    data = tmp_path / "s.parquet"
    assert main(["simulate", "--strategy", "CS1", "--trials", "12", "-o", str(data)]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(data), "--n-components", "2", "--samples", "0", "--no-efficiency", "--horizon", "1",
                 "--test-size", "0.34", "-o", str(tmp_path / "r.csv")]) == 0
    out = capsys.readouterr().out
    n = pd.read_csv(tmp_path / "r.csv")["trial"].nunique()
    assert n < min_units()
    words = f"no interval ({n} test trials; {min_units()} needed)"
    fitted = out.split("These fitted models on these test trials")[1].splitlines()
    rows = [line for line in fitted if line.startswith("CS1 ")]
    assert len(rows) == 3 and all(words in r and " %]" not in r for r in rows), rows
    inputs = out.split("proposed vs the better model with no pilot (paired)")[1].splitlines()
    rows = [line for line in inputs if line.startswith("CS1 ")][:2]
    assert len(rows) == 2 and all(words in r for r in rows), rows
    assert " %]" in out.split("Methods (refitted on every split")[1].split("These fitted models")[0]


def test_a_mismatch_in_a_late_digit_prints_its_entry_apart_from_the_closest_costs():
    # the demo's CS1: "u1 on x -0.0947 [-0.0947, -0.0947], softer than its -0.0947" -- four equal numbers read as a
    # contradiction where the entry departs from the closest diagonal cost's in its fourth digit
    import re

    from workbench.study.weights import PartFit

    k0 = -0.094712
    closest = SimpleNamespace(shown=np.array([True]), k_hat=np.array([k0 + 2.1e-5]), k_closest=np.array([k0]),
                              mismatch_lo=np.array([1.2e-5]), mismatch_hi=np.array([3.0e-5]))
    words = PartFit(("x",), ("u1",), 3.0, 0, float("nan"), None, closest, 19.0, 0).mismatch_words()
    entry, lo, hi, its = (float(v) for v in re.search(
        r"u1 on x (\S+) \[(\S+), (\S+)\], softer than its (\S+)", words).groups())
    assert entry != its and lo != hi, words
    assert lo <= entry <= hi and abs(its - k0) < abs(entry - k0), words
