"""The testbed in a real browser (Debian's Chromium through Playwright): scripted subjects on a virtual gamepad and
on the keyboard fly a protocol; what is recorded is what they did."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from workbench.collect.session import HIDDEN
from workbench.data.dataset import is_dataset, load_demonstrations

from .conftest import (
    LANDING_PILOT,
    calibrate,
    calibrated,
    new_page,
    pilot_gain,
    pilot_js,
    register,
    rerun_entities,
    write_protocol,
)

REPO = Path(__file__).resolve().parents[2]


def _fly_next(page, timeout_s: float = 40.0) -> None:
    """On a trial's screen: Space starts it; returns once the page has saved it (the progress line moved on)."""
    page.wait_for_selector("#screen-task:not([hidden])")
    before = page.inner_text("#progress")
    page.keyboard.press("Space")
    page.wait_for_function("b => document.querySelector('#progress').textContent !== b", arg=before,
                           timeout=timeout_s * 1000)
    assert page.inner_text("#error") == ""


def _pad_said(page, xs: np.ndarray) -> np.ndarray:
    """The axes the scripted pad returned in each recorded state."""
    return np.array(page.evaluate("xs => xs.map(x => window.__padLog[JSON.stringify(x)] || null)", xs.tolist()))


def test_a_gamepad_subject_flies_a_protocol_and_the_inputs_are_the_pads(browser, serve, tmp_path):
    """The default suite's one browser flight: consent, a calibration done in full, a briefing, one trial with
    the time limit stated, the pad read at the display rate with every read recorded, the outcome's reason after
    the last trial."""
    path = write_protocol(tmp_path / "p.toml", [{"message": {"title": "Briefing", "text": "Read this."}},
                                                {"label": "CS1", "instructions": "Land.", "trials": 1}])
    path.write_text(path.read_text() + '[input]\nexpo = 0.3\n')
    run = serve(path)
    context, page = new_page(browser, gamepad=True)
    try:
        rest = [0.0, 0.12, -0.09, 0.0]  # the sticks' axes (2 and 1) rest off centre, by more than a dead zone
        register(page, run.url, "pad01", rest=rest)
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(20.0), -6.0)}; }}")  # a quick descent
        page.wait_for_selector("#screen-message:not([hidden])")
        assert page.inner_text("#message-title") == "Briefing"
        page.keyboard.press("Space")
        page.wait_for_function("() => document.querySelector('#message-title').textContent === 'Block: CS1'")
        page.keyboard.press("Space")
        page.wait_for_selector("#screen-task:not([hidden])")
        assert "within 30 s" in page.inner_text("#task-overlay")
        _fly_next(page)  # one trial: the order of several is test_session's and the slow tests' (default suite: fast)
        page.wait_for_selector("#summary:not([hidden])")
        ds = load_demonstrations(run.out)
        (d,) = ds
        assert f"Your last trial: Crashed ({d.meta['outcome_reason']})" in page.inner_text("#message-text")
        reads = _mcap_inputs(run.out, d.id, ("step", "raw_u1", "raw_u2"), topic="/input/reads")
        steps = reads[:, 0].astype(int)
        assert len(reads) >= len(d) and set(steps) <= set(range(len(d)))  # every display-rate read, recorded
        last = np.array([reads[steps <= k][-1, 1:] for k in range(len(d))])  # the rule: the latest read
        assert np.array_equal(d.u, calibrated(last, d.meta["calibration"]))
        assert d.meta["input"]["expo"] == 0.3 == d.meta["calibration"]["expo"]
        assert [d.meta["trial"] for d in ds] == [1] and {d.meta["subject"] for d in ds} == {"pad01"}
        for d in ds:
            cal = d.meta["calibration"]
            assert cal["kind"] == "gamepad" and d.meta["device"]["id"] == "Scripted pad (test)"
            assert np.allclose(cal["offsets"], rest, atol=1e-12)  # measured, recorded
            assert cal["deadzone"] == min(0.3, 3 * cal["rest_noise"]) and cal["confirmed"] == [True, True]
            said = _pad_said(page, d.x)
            raw = said[:, cal["axes"]]
            mcap_raw = _mcap_inputs(run.out, d.id)
            assert np.array_equal(mcap_raw[:, 2:], raw)  # the raw sticks recorded are the pad's, exactly
            assert np.array_equal(d.u, calibrated(raw, cal))  # and the inputs are their calibration
            assert ((np.abs(d.u) > 0) & (np.abs(d.u) < 1)).any()  # not only saturated or zero inputs
            full = np.abs(raw) == 1  # the stick at an end of its range: full input, whatever the rest offset
            assert full.any() and np.array_equal(d.u[full], (raw * cal["signs"])[full])
            assert d.meta["timing"]["physics_steps"] == len(d) and "dropped_steps" in d.meta["timing"]
            sampled = _mcap_inputs(run.out, d.id, ("sampled_s",))[:, 0]  # when the page read each step's sticks
            assert sampled[0] == 0 and (np.diff(sampled) >= 0).all()
            assert sampled[-1] == d.meta["timing"]["wall_duration_s"] > 0.5 * d.t[-1]
    finally:
        context.close()


def _mcap_inputs(out: Path, trial_id: str, fields: tuple[str, ...] = ("u1", "u2", "raw_u1", "raw_u2"),
                 topic: str = "/trial/input") -> np.ndarray:
    from mcap.reader import make_reader

    with open(out / HIDDEN / "mcap" / trial_id.split("-")[0] / f"{trial_id}.mcap", "rb") as f:
        rows = [json.loads(m.data) for _, c, m in make_reader(f).iter_messages(topics=[topic])]
    return np.array([[r[k] for k in fields] for r in rows])


def _mcap_events(out: Path, trial_id: str) -> list[tuple[str, str]]:
    from mcap.reader import make_reader

    with open(out / HIDDEN / "mcap" / trial_id.split("-")[0] / f"{trial_id}.mcap", "rb") as f:
        return [(e["kind"], e["code"]) for e in (json.loads(m.data) for _, c, m in
                                                  make_reader(f).iter_messages(topics=["/input/events"]))]


@pytest.mark.slow
def test_a_keyboard_subject_flies_and_the_keys_and_ramp_are_recorded(browser, serve, tmp_path):
    run = serve(write_protocol(tmp_path / "p.toml", [{"label": "CS2", "instructions": "Land.", "trials": 1}]))
    context, page = new_page(browser, gamepad=False)
    try:
        register(page, run.url, "kb01")
        page.wait_for_selector("#screen-message:not([hidden])")
        page.keyboard.press("Space")
        page.wait_for_selector("#screen-task:not([hidden])")
        page.keyboard.press("Space")
        page.keyboard.down("ArrowLeft")
        page.wait_for_timeout(150)
        page.keyboard.up("ArrowLeft")
        page.keyboard.down("ArrowDown")  # full thrust down: it reaches the ground in about a second
        page.wait_for_selector("#summary:not([hidden])", timeout=30_000)
        page.keyboard.up("ArrowDown")
        (d,) = load_demonstrations(run.out)
        assert d.meta["device"]["kind"] == "keyboard" and d.meta["outcome"] in ("crashed", "left the domain")
        events = _mcap_events(run.out, d.id)
        assert events[:3] == [("keydown", "ArrowLeft"), ("keyup", "ArrowLeft"), ("keydown", "ArrowDown")]
        raw = _mcap_inputs(run.out, d.id)[:, 2:]
        assert set(np.unique(raw)) <= {-1.0, 0.0, 1.0} and (raw[:, 0] == -1).any() and (raw[:, 1] == -1).any()
        n, level, ramped = d.meta["device"]["ramp_steps"], np.zeros(2), []
        assert d.meta["device"]["ramp_per_step"] == 1 / n
        for r in raw:  # the stated ramp: one step of 1/n a physics step toward the keys' direction
            level = level + np.sign(r * n - level)
            ramped.append(level / n)
        assert np.array_equal(d.u, np.array(ramped))
    finally:
        context.close()


def _serve_cli(out: Path, protocol: str, *extra: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "workbench", "collect", "--protocol", protocol, "--out", str(out),
                             "--port", "0", "--no-browser", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=REPO, env={**os.environ, "COLUMNS": "200"})
    line = proc.stdout.readline()
    assert line.startswith("serving http://127.0.0.1:"), line + proc.stderr.read()
    return proc, line.split()[1]


@pytest.mark.slow
def test_killing_server_and_browser_mid_trial_loses_only_that_trial(browser, tmp_path):
    protocol = write_protocol(tmp_path / "p.toml", [{"label": "CS1", "instructions": "Land.", "trials": 3}])
    out = tmp_path / "session"
    proc, url = _serve_cli(out, str(protocol))
    context, page = new_page(browser, gamepad=True)
    try:
        register(page, url, "s01")
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(), -0.15)}; }}")  # a slow descent
        page.wait_for_selector("#screen-message:not([hidden])")
        page.keyboard.press("Space")
        _fly_next(page)
        page.keyboard.press("Space")  # the second trial starts …
        page.wait_for_function("() => window.collect.trial && window.collect.trial.k > 20")
        proc.send_signal(signal.SIGKILL)  # … and the server dies under it
        proc.wait(timeout=10)
        page.wait_for_timeout(300)
    finally:
        context.close()  # and the browser goes too
    visible = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()
                     and not any(part.startswith(("_", ".")) for part in p.relative_to(out).parts))
    assert visible == ["subject=s01/s01-000-CS1-train.parquet"]
    assert is_dataset(out) and len(load_demonstrations(out)) == 1
    proc, url = _serve_cli(out, str(protocol))  # a new server resumes the folder
    context, page = new_page(browser, gamepad=True)
    try:
        page.goto(f"{url}?subject=s01")
        page.wait_for_selector("#resume-note:not([hidden])")
        assert "1 of 3 trials are done" in page.inner_text("#resume-note")
        calibrate(page)  # the sticks checked again
        page.wait_for_selector("#screen-task:not([hidden])")
        assert "trial 2 of 3" in page.inner_text("#task-label")
        status = json.loads(page.evaluate("async () => JSON.stringify(await (await fetch('/api/subject/s01')).json())"))
        assert status["next"]["slot"] == 1 and status["trials_done"] == 1
    finally:
        context.close()
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)


@pytest.mark.slow
def test_a_scripted_paper_single_subject_session_fits_evaluates_and_opens_in_rerun(browser, tmp_path):
    """The shipped protocol, shortened by its flags: 2 labels × (train + test) trials that evaluate compares."""
    from workbench.cli import main

    out = tmp_path / "session"
    proc, url = _serve_cli(out, "paper_single_subject", "--max-trials", "2", "--max-pause", "1")
    context, page = new_page(browser, gamepad=True)
    try:
        register(page, url, "s01")
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(), **LANDING_PILOT)}; }}")
        while True:
            page.wait_for_selector("#screen-message:not([hidden]), #screen-task:not([hidden])")
            if page.is_visible("#summary"):
                break
            if page.is_visible("#screen-task"):
                _fly_next(page)
                continue
            page.wait_for_function("() => window.collect.onSpace !== null", timeout=5000)
            page.keyboard.press("Space")
            page.wait_for_timeout(100)
    finally:
        context.close()
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10)
    ds = load_demonstrations(out)
    count = {}
    for d in ds:
        count[(d.meta["label"], d.meta["role"])] = count.get((d.meta["label"], d.meta["role"]), 0) + 1
    assert count == {("CS1", "train"): 2, ("CS2", "train"): 2, ("CS1", "test"): 2, ("CS2", "test"): 2}
    # fit and evaluate take a session's landed trials: a pilot that crashed would leave them none
    assert {d.meta["outcome"] for d in ds} == {"landed"}, [d.meta["outcome_reason"] for d in ds]
    assert main(["fit", str(out), "--label", "CS1", "--n-components", "1", "--bootstrap", "0",
                 "-o", str(tmp_path / "cs1.npz")]) == 0
    table = tmp_path / "results.csv"
    assert main(["evaluate", str(out), "--n-components", "1", "--samples", "0", "--no-efficiency",
                 "-o", str(table)]) == 0
    import pandas as pd

    results = pd.read_csv(table)
    assert set(results["label"]) == {"CS1", "CS2"} and "proposed" in set(results["method"])
    assert len(set(results["method"])) >= 3  # compared with its baselines
    # the MCAP opens in rerun: its loader turns the trial's channels into entities
    mcap = next((out / HIDDEN / "mcap" / "s01").glob("*.mcap"))
    assert {"/trial/input", "/trial/state", "/input/events"} <= rerun_entities(mcap, tmp_path / "trial.rrd")


@pytest.mark.slow
def test_the_experimenters_view_shows_live_tracks_predictions_outcomes_and_a_summary(browser, tmp_path):
    from rerun.chunk import RrdReader

    from workbench.cli import main

    demos, model = tmp_path / "demos.parquet", tmp_path / "cs1.npz"
    assert main(["simulate", "--strategy", "CS1", "--trials", "6", "-o", str(demos)]) == 0
    assert main(["fit", str(demos), "--n-components", "1", "--bootstrap", "0", "-o", str(model)]) == 0
    protocol = write_protocol(tmp_path / "p.toml", [{"label": "CS1", "instructions": "Land.", "trials": 1}])
    out, rrd = tmp_path / "session", tmp_path / "view.rrd"
    proc, url = _serve_cli(out, str(protocol), "--save", str(rrd), "--model", f"CS1={model}")
    context, page = new_page(browser, gamepad=True)
    try:
        register(page, url, "s01")
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(20.0), -1.5)}; }}")
        page.wait_for_selector("#screen-message:not([hidden])")
        page.keyboard.press("Space")
        _fly_next(page)
    finally:
        context.close()
        proc.send_signal(signal.SIGINT)
        stdout, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0 and "s01: 1 of 1 trials (CS1 train" in stdout
    (d,) = load_demonstrations(out)
    entities = {}
    for chunk in RrdReader(rrd).stream():
        entities[str(chunk.entity_path)] = entities.get(str(chunk.entity_path), 0) + chunk.num_rows
    assert {"/live/s01/vehicle", "/live/s01/prediction", f"/trials/s01/{d.id}", "/outcomes", "/summary"} <= set(
        entities), sorted(entities)
    assert entities["/live/s01/vehicle"] == len(d)  # every step of the trial was seen live


@pytest.mark.slow
def test_assisted_blocks_show_the_models_path_and_blend_by_the_stated_law(browser, tmp_path):
    from workbench.cli import main
    from workbench.collect.task import blend, task_spec

    demos, model = tmp_path / "demos.parquet", tmp_path / "cs1.npz"
    assert main(["simulate", "--strategy", "CS1", "--trials", "6", "-o", str(demos)]) == 0
    assert main(["fit", str(demos), "--n-components", "1", "--bootstrap", "0", "-o", str(model)]) == 0
    protocol = write_protocol(tmp_path / "p.toml", [
        {"label": "CS1", "instructions": "Follow the line.", "trials": 1, "assist": "show"},
        {"label": "CS1", "instructions": "Fly with help.", "trials": 1, "assist": "blend", "blend": 0.5}])
    out = tmp_path / "session"
    proc, url = _serve_cli(out, str(protocol), "--model", f"CS1={model}")
    context, page = new_page(browser, gamepad=True)
    try:
        register(page, url, "s01")
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(20.0), -1.5)}; }}")
        for _ in range(2):
            page.wait_for_selector("#screen-message:not([hidden])")
            page.keyboard.press("Space")
            page.wait_for_selector("#screen-task:not([hidden])")
            status = page.evaluate("() => window.collect.status.next")
            guide = page.evaluate("() => document.querySelector('#task-overlay').textContent")
            assert "Assisted" in guide
            _fly_next(page)
    finally:
        context.close()
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=30)
    shown, blended = load_demonstrations(out)
    assert shown.meta["assist"]["kind"] == "show" and np.array_equal(shown.u, np.array(shown.meta["pilot_u"]))
    assert status["help"]["kind"] == "blend"
    spec, help_ = task_spec(), blended.meta["assist"]
    pilot = np.array(blended.meta["pilot_u"])
    law = np.array([blend(spec, help_["K"], help_["alpha"], x, p) for x, p in zip(blended.x.tolist(),
                                                                                  pilot.tolist(), strict=True)])
    assert np.array_equal(blended.u, law) and not np.array_equal(blended.u, pilot)
    raw = _mcap_inputs(out, blended.id)[:, 2:]
    assert np.array_equal(pilot, calibrated(raw, blended.meta["calibration"]))  # the pilot's own, from the pad


@pytest.mark.slow
def test_practice_runs_for_its_duration_and_stays_out_of_the_dataset(browser, serve, tmp_path):
    path = write_protocol(tmp_path / "p.toml", [{"label": "CS1", "instructions": "Land.", "trials": 1}])
    path.write_text(path.read_text() + "[practice]\nduration_s = 2\nrecorded = true\n")
    run = serve(path)
    context, page = new_page(browser, gamepad=True)
    try:
        register(page, run.url, "s01")
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(20.0), -1.5)}; }}")
        page.wait_for_selector("#screen-task:not([hidden])")
        assert "Practice" in page.inner_text("#task-label")
        page.keyboard.press("Space")  # one practice landing (longer than the practice's 2 s)
        page.wait_for_function("() => document.querySelector('#task-overlay').textContent.includes('Practice is over')",
                               timeout=30_000)
        page.keyboard.press("Space")
        page.wait_for_selector("#screen-message:not([hidden])")  # the block's instructions
        assert page.inner_text("#message-title") == "Block: CS1"
    finally:
        context.close()
    practice = list((run.out / HIDDEN / "practice" / "s01").glob("*.parquet"))
    assert len(practice) == 1 and not is_dataset(run.out)  # kept, but not among the trials fit and evaluate read
