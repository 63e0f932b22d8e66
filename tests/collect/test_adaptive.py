"""The adaptive experiment in a real browser: a scripted subject on a virtual gamepad flies a train block, rests
while the server fits THEIR model on their own landed, not excluded training trials (killed mid-fit, resumed),
then flies assisted by that model. Slow: the subject flies in real time."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from workbench.collect.records import set_exclusion
from workbench.collect.session import HIDDEN
from workbench.collect.task import blend, task_spec
from workbench.data.dataset import load_demonstrations
from workbench.data.digest import set_digest

from .conftest import calibrate, calibrated, consent, new_page, pilot_gain, pilot_js, write_protocol

REPO = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow


def _serve(out: Path, protocol: Path | str, *extra: str) -> tuple[subprocess.Popen, str]:
    """``workbench collect`` in its own process group (killed whole, workers too, as by a power cut)."""
    proc = subprocess.Popen([sys.executable, "-m", "workbench", "collect", "--protocol", str(protocol), "--out",
                             str(out), "--port", "0", "--no-browser", *extra], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE,
                            text=True, cwd=REPO, env={**os.environ, "COLUMNS": "200"}, start_new_session=True)
    line = proc.stdout.readline()
    assert line.startswith("serving http://127.0.0.1:"), line + proc.stderr.read()
    return proc, line.split()[1]


def _step(page, until: str, on_trial=None, timeout_s: float = 60.0) -> None:
    """Go through the session's screens (Space on each, trials flown by the scripted pilot) until ``until``
    (a JS condition) holds."""
    for _ in range(200):
        if page.evaluate(f"() => {until}"):
            return
        page.wait_for_function("() => window.collect.onSpace !== null || "
                               f"({until})", timeout=timeout_s * 1000)
        if page.evaluate(f"() => {until}"):
            return
        on_task = page.is_visible("#screen-task")
        before = page.inner_text("#progress")
        page.keyboard.press("Space")
        if on_task:
            page.wait_for_function("b => document.querySelector('#progress').textContent !== b", arg=before,
                                   timeout=timeout_s * 1000)
            assert page.inner_text("#error") == ""
            if on_trial is not None:
                on_trial()
        else:
            page.wait_for_timeout(150)
    raise AssertionError(f"never reached {until}")


def test_train_fit_assist_with_the_subjects_own_model_killed_during_the_fit(browser, tmp_path):
    protocol = write_protocol(tmp_path / "assisted.toml", [
        {"label": "CS1", "instructions": "Land.", "trials": 5, "held_out": 1},
        {"fit": {"label": "CS1", "from": "train", "min_trials": 3, "break_s": 1}},
        {"label": "CS1", "instructions": "Land with help.", "trials": 2, "role": "test", "assist": "blend",
         "blend": 0.3}])
    out = tmp_path / "session"
    proc, url = _serve(out, protocol)
    excluded: list[str] = []

    def exclude_the_first_landed_train_trial() -> None:
        if excluded:
            return
        for d in load_demonstrations(out):
            if d.meta["role"] == "train" and d.meta["outcome"] == "landed":
                set_exclusion(out, d.id, True, "the subject sneezed")  # the experimenter's call, mid-session
                excluded.append(d.id)
                return

    context, page = new_page(browser, gamepad=True)
    try:
        consent(page, url, "s01")
        calibrate(page)
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(100.0), -0.05)}; }}")  # lands in ~9 s
        _step(page, "window.collect.status && window.collect.status.next.kind === 'fit'",
              on_trial=exclude_the_first_landed_train_trial)
        page.wait_for_function("() => document.querySelector('#message-status').textContent.includes('Preparing')")
        record = out / HIDDEN / "models" / "s01" / "CS1.json"
        assert not record.exists()
        os.killpg(proc.pid, signal.SIGKILL)  # the server and its fit's worker die mid-fit
        proc.wait(timeout=10)
    finally:
        context.close()
    assert not record.exists() and excluded
    proc, url = _serve(out, protocol)  # the same session, resumed
    context, page = new_page(browser, gamepad=True)
    try:
        page.goto(f"{url}?subject=s01")
        page.wait_for_selector("#resume-note:not([hidden])")
        calibrate(page)
        page.wait_for_function("() => document.querySelector('#message-status').textContent.includes('ready')",
                               timeout=120_000)
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(100.0), -0.05)}; }}")
        _step(page, "!document.querySelector('#summary').hidden")
        end_text = page.inner_text("#message-text")
    finally:
        context.close()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    assert "Your last trial:" in end_text  # the last trial's outcome, with its reason, on the end screen
    ds = load_demonstrations(out)
    fit = json.loads(record.read_text())
    model_file = out / HIDDEN / "models" / "s01" / "CS1.npz"
    # the model is this subject's, fitted on their landed, not excluded training trials, checked on the held-out
    trained = ds.filter(lambda d: d.meta["label"] == "CS1" and d.meta["role"] == "train"
                        and d.meta["outcome"] == "landed" and not d.meta["excluded"])
    assert fit["train_ids"] == trained.ids and excluded[0] not in fit["train_ids"] and len(trained) >= 3
    assert fit["data_digest"] == set_digest(trained) and fit["digest"] == hashlib.sha256(
        model_file.read_bytes()).hexdigest()
    held = [d.id for d in ds if d.meta["role"] == "test" and not d.meta.get("assist")]
    assert [h["id"] for h in fit["held_out"]] == held and fit["held_out_error"] > 0
    assisted = [d for d in ds if d.meta.get("assist")]
    assert len(assisted) == 2
    spec = task_spec()
    for d in assisted:
        a = d.meta["assist"]
        assert a["kind"] == "blend" and a["model"] == {"source": "fit", "digest": fit["digest"],
                                                       "data_digest": fit["data_digest"]}
        pilot = np.array(d.meta["pilot_u"])
        law = np.array([blend(spec, a["K"], a["alpha"], x, p) for x, p in zip(d.x.tolist(), pilot.tolist(),
                                                                               strict=True)])
        assert np.array_equal(d.u, law) and not np.array_equal(d.u, pilot)  # the pilot's own input kept apart
        from .test_browser import _mcap_inputs

        raw = _mcap_inputs(out, d.id)[:, 2:]
        assert np.array_equal(pilot, calibrated(raw, d.meta["calibration"]))  # and it is the pad's
    from workbench.models import load_model

    assert np.array_equal(np.array(assisted[0].meta["assist"]["K"]), load_model(model_file).K_)
    assert "model of CS1 fitted on" in stdout and "held-out rmse_position" in stdout, stdout + stderr
