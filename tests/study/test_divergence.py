"""A rollout that diverges is said, not scored (workbench.study.divergence): the question is whether a model whose
loop lies outside the unit circle gets an RMSE of its blow-up printed and averaged as a comparison number."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from workbench.defaults import DIVERGED_FACTOR
from workbench.method.stability import Stability
from workbench.models import IOCOnlyModel
from workbench.sim.landing import simulate_landings
from workbench.study import evaluate as ev
from workbench.study.divergence import diverged, notes, scored, verdict_lines
from workbench.study.input_prediction import input_lines, input_scores
from workbench.study.paired import paired_differences
from workbench.study.scores import cell, heldout_scores, score_lines


@pytest.fixture(scope="module")
def fitted(quadrotor):
    train = simulate_landings("CS2", n_trials=6, seed=11)
    test = simulate_landings("CS2", n_trials=3, seed=12)
    return IOCOnlyModel(quadrotor, timing="none").fit(train), test


def _with_loop(model, scale):
    """The model with its gain scaled (a negative scale pushes the loop outside the unit circle) and ρ̂ of that
    loop as its stability, with an interval that holds 1: a model fit keeps ("not distinguishable")."""
    out = copy.deepcopy(model)
    out.K_ = scale * model.K_
    rho = float(np.max(np.abs(np.linalg.eigvals(model.plant.A + model.plant.B @ out.K_))))
    half = abs(rho - 1.0) + 0.01
    out.stability_ = Stability(rho=rho, lo=rho - half, hi=rho + half, verdict="not distinguishable")
    return out, rho


def test_the_rule_is_the_recorded_range_times_the_factor():
    rng = np.random.default_rng(3)
    x_rec = rng.normal(size=(50, 4))
    centre = 0.5 * (x_rec.max(axis=0) + x_rec.min(axis=0))
    reach = np.linalg.norm(x_rec - centre, axis=1).max()
    direction = np.array([0.6, 0.0, 0.8, 0.0])  # a unit vector
    inside = np.vstack([x_rec[:5], centre + 0.99 * DIVERGED_FACTOR * reach * direction])
    outside = np.vstack([x_rec[:5], centre + 1.01 * DIVERGED_FACTOR * reach * direction])
    assert not diverged(inside, x_rec)
    assert diverged(outside, x_rec)
    assert not diverged(outside, x_rec, idx=(1, 3))  # the states it left on are not scored
    assert diverged(np.vstack([x_rec[:5], np.full(4, np.nan)]), x_rec)
    assert not diverged(x_rec + 1.0, np.zeros_like(x_rec))  # recorded states without a range: no verdict


def test_a_diverging_rollout_is_said_in_place_of_its_scores_and_left_out_of_the_statistics(fitted):
    model, test = fitted
    bad, rho = _with_loop(model, -0.3)
    assert 1.0 < rho < 1.1  # slightly outside, and "not distinguishable" by its interval
    n_steps = 150
    growth = rho ** n_steps
    assert growth > DIVERGED_FACTOR  # over this horizon its slow mode outgrows the data's range
    table = ev.compare({"proposed": bad, "ioc_only": model}, test, n_steps=n_steps, starts=20)
    label = str(test[0].label)
    said = notes(table)
    assert set(said) == {(label, "proposed")}
    note = said[(label, "proposed")]
    assert note == f"diverges (ρ̂ {rho:.4g} [{bad.stability_.lo:.3g}, {bad.stability_.hi:.3g}])"

    scores = heldout_scores(table)
    mine = scores[scores["method"] == "proposed"]
    assert mine["value"].isna().all() and (mine["note"] == note).all()
    theirs = scores[scores["method"] == "ioc_only"]
    assert np.isfinite(theirs["value"]).all() and (theirs["note"] == "").all()
    assert all(cell(r) == note for r in mine.itertuples(index=False))
    assert any(note in line for line in score_lines(scores, label))
    # the pilot's input: one step ahead it never rolls out, so it keeps its number; over the horizon it is said
    inputs = input_scores(table)
    step = inputs[(inputs["method"] == "proposed") & (inputs["metric"] == "input_step")].iloc[0]
    horizon = inputs[(inputs["method"] == "proposed") & (inputs["metric"] == "input_horizon")].iloc[0]
    assert np.isfinite(step["value"]) and step["note"] == ""
    assert horizon["note"] == note
    assert any(note in line for line in input_lines(inputs, label))

    # the statistics: compared on the raw rows it would be "worse by" its blow-up; it is left out instead
    assert paired_differences(table, "rmse_position", "proposed", ["ioc_only"], n_boot=200)
    assert paired_differences(scored(table), "rmse_position", "proposed", ["ioc_only"], n_boot=200) == []
    kept = scored(table)
    assert not kept[(kept["method"] == "proposed") & kept["metric"].str.startswith("rmse_")].shape[0]
    assert kept[(kept["method"] == "proposed") & (kept["metric"] == "input_step")].shape[0] == len(test)
    (line,) = verdict_lines(table, {"proposed": "the proposed model"})
    assert line.startswith(f"On {label}, the proposed model's mean rollout {note}")
    assert note in line and f"×{DIVERGED_FACTOR:g}" in line


def test_a_loop_slightly_outside_whose_rollout_stays_in_range_keeps_its_number(fitted):
    model, test = fitted
    bad, rho = _with_loop(model, 0.1)
    assert rho > 1.0 and rho ** ev.N_STEPS < DIVERGED_FACTOR  # ρ̂ alone does not decide: the rollout does
    table = ev.compare({"proposed": bad, "ioc_only": model}, test, n_steps=ev.N_STEPS, starts=20)
    assert notes(table) == {}
    scores = heldout_scores(table)
    assert np.isfinite(scores["value"]).all() and (scores["note"] == "").all()
    assert scored(table) is table


def test_a_rollout_that_diverges_beside_a_loop_judged_stable_says_both(fitted):
    # log_86 (a PX4 POSCTL flight) printed "diverges (ρ̂ 0.9864 [0.981, 0.992])": a reader sees a stable loop called
    # diverging. The rule is the rollout's range, so both stand; the note says so instead of leaving a contradiction.
    model, test = fitted
    bad, rho = _with_loop(model, -0.3)
    bad.stability_ = Stability(rho=0.5 * rho, lo=0.4 * rho, hi=0.6 * rho, verdict="stable")
    assert bad.stability_.hi < 1.0
    table = ev.compare({"proposed": bad, "ioc_only": model}, test, n_steps=150, starts=20)
    note = notes(table)[(str(test[0].label), "proposed")]
    s = bad.stability_
    assert note == f"diverges though its loop is stable (ρ̂ {s.rho:.4g} [{s.lo:.3g}, {s.hi:.3g}])"
