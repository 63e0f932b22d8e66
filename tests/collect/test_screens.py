"""Every page of the testbed as a subject and an experimenter see it, at 1280×720 and 1920×1080 (headless
Chromium): screenshots to look at (``WORKBENCH_SCREENS=DIR`` keeps them), and the checks that can be made of them
— nothing wider than the window, the trial's overlay and the task's numbers inside it. Slow: real flights and a
real fit."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from workbench.collect.fitting import in_process

from .conftest import calibrate, join, opened_page, pilot_gain, pilot_js, write_protocol
from .test_session import flown

pytestmark = pytest.mark.slow
SIZES = ((1280, 720), (1920, 1080))


def _protocol(tmp_path: Path) -> Path:
    path = write_protocol(tmp_path / "screens.toml", [
        {"message": {"title": "Briefing", "text": "Land on the pad, gently.\n\nStrategy CS1: across first, then "
                     "down. The experimenter answers your questions now."}},
        {"label": "CS1", "instructions": "Strategy CS1: first fly horizontally until you are above the pad, then "
                                         "descend straight down.", "trials": 3, "held_out": 1},
        {"fit": {"label": "CS1", "min_trials": 2, "break_s": 2}},
        {"label": "CS1", "instructions": "With your model's path shown.", "trials": 1, "role": "test",
         "assist": "show"},
        {"label": "CS1", "instructions": "With your model's help.", "trials": 1, "role": "test", "assist": "blend",
         "blend": 0.3}], title="Quadrotor landing: assisted by your own model", breaks={"between_blocks_s": 2},
        subjects=["s01", "s02", "s03"])
    path.write_text(path.read_text() + '[[fields]]\nname = "age"\nlabel = "Age (years)"\ntype = "number"\n'
                    '[[fields]]\nname = "hand"\nlabel = "Dominant hand"\ntype = "choice"\n'
                    'choices = ["right", "left", "either"]\n')
    return path


class Shots:
    def __init__(self, folder: Path) -> None:
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        self.names: list[str] = []

    def __call__(self, page, name: str) -> None:
        """``name`` at both sizes; the page is no wider than the window at either."""
        for w, h in SIZES:
            page.set_viewport_size({"width": w, "height": h})
            page.wait_for_timeout(150)
            page.screenshot(path=str(self.folder / f"{name}-{w}x{h}.png"))
            wide = page.evaluate("() => document.documentElement.scrollWidth - window.innerWidth")
            assert wide <= 0, f"{name} at {w}x{h} is {wide} px wider than the window"
            if page.is_visible("#task-overlay:not(:empty)"):
                box = page.locator("#task-overlay").bounding_box()
                assert box["y"] >= 0 and box["y"] + box["height"] <= h, f"{name}: the overlay leaves the window"
        self.names.append(name)


def _to_the_task(page, on_instructions=None) -> None:
    """Space past a message to the next block's instructions ("Block …"; ``on_instructions()`` there), and Space
    again to its task screen."""
    page.keyboard.press("Space")
    page.wait_for_function("() => document.querySelector('#message-title').textContent.startsWith('Block')")
    if on_instructions is not None:
        on_instructions()
    page.keyboard.press("Space")
    page.wait_for_selector("#screen-task:not([hidden])")


def test_every_page_at_two_sizes(browser, serve, tmp_path):
    shots = Shots(Path(os.environ.get("WORKBENCH_SCREENS") or tmp_path / "screens"))
    preparing_shown = threading.Event()

    def held_fit(fn, task):
        """The fit step's fit, run once the page has shown it preparing. The server starts the fit when s02's last
        training trial is written, before their page is open; unheld, the fit ended before the page came in a
        process that had fitted before (2 trials in about a second), "Preparing" never showed and its wait timed
        out."""
        preparing_shown.wait(timeout=180)
        return in_process(fn, task)

    run = serve(_protocol(tmp_path), runner=held_fit)
    s = run.session
    with opened_page(browser, gamepad=True) as page:
        page.goto(f"{run.url}?subject=s01")
        page.wait_for_selector("#screen-consent:not([hidden])")
        shots(page, "01-consent")
        page.click("#consent-agree")
        page.wait_for_selector("#screen-subject:not([hidden])")
        page.fill("input[name=age]", "34")
        shots(page, "02-subject-fields")
        page.click("#subject-continue")
        page.wait_for_selector("#screen-calibration:not([hidden])")
        shots(page, "03-calibration-gamepad")
        page.click("#measure-rest")
        page.wait_for_function("() => document.querySelector('#rest-result').textContent.includes('dead zone')")
        page.click("#assign-u1")
        page.wait_for_function("() => document.querySelector('#axis-u1').textContent.includes('now')")
        page.evaluate("() => { window.__axes = [0, 0, 1, 0]; }")
        page.wait_for_selector("#confirm-u1:not([hidden])")
        page.evaluate("() => { window.__axes = null; }")
        shots(page, "04-calibration-confirm")
        page.click("#confirm-u1")
        page.click("#assign-u2")
        page.wait_for_function("() => document.querySelector('#axis-u2').textContent.includes('now')")
        page.evaluate("() => { window.__axes = [0, -1, 0, 0]; }")
        page.wait_for_selector("#confirm-u2:not([hidden])")
        page.evaluate("() => { window.__axes = null; }")
        page.click("#confirm-u2")
        shots(page, "05-calibration-done")
        page.keyboard.press("Space")
        page.wait_for_function("() => document.querySelector('#message-title').textContent === 'Briefing'")
        shots(page, "06-briefing")
        _to_the_task(page, lambda: shots(page, "07-instructions"))
        shots(page, "08-trial-before-start")
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(100.0), -0.05)}; }}")
        page.keyboard.press("Space")
        page.wait_for_function("() => window.collect.trial && window.collect.trial.k > 60")
        shots(page, "09-trial-in-flight")
        page.wait_for_function("() => window.collect.onSpace !== null && !window.collect.trial", timeout=60_000)
        shots(page, "10-trial-after-landing")
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(20.0), -6.0)}; }}")  # a crash
        page.keyboard.press("Space")
        page.wait_for_function("() => window.collect.status.next.trial === 3", timeout=60_000)
        shots(page, "11-trial-after-crash")

    # a repeated ID in a new browser, a declined consent, a subject without a gamepad
    with opened_page(browser, gamepad=False) as page:
        page.goto(run.url)
        page.wait_for_selector("#screen-consent:not([hidden])")
        page.fill("#subject-id", "s01")
        page.click("#consent-agree")
        page.wait_for_selector("#screen-subject:not([hidden])")
        page.click("#subject-continue")
        page.wait_for_selector("#confirm-box:not([hidden])")
        shots(page, "12-repeated-id")
        page.click("#confirm-no")
        page.fill("#subject-id", "s03")
        page.click("#consent-decline")
        page.wait_for_function("() => document.querySelector('#message-title').textContent === 'Thank you'")
        shots(page, "13-declined")
        page.goto(f"{run.url}?subject=s09")
        page.click("#consent-agree")
        page.click("#subject-continue")
        page.wait_for_selector("#confirm-box:not([hidden])")
        shots(page, "14-undeclared-id")
        page.click("#confirm-yes")
        page.wait_for_selector("#screen-calibration:not([hidden])")
        shots(page, "15-calibration-keyboard")

    # a subject whose training trials are in: the fit break, the assisted trials, the end
    join(s, "s02", {"age": 28})
    for item in s.plan("s02"):
        if item.kind == "trial" and item.assist == "none":
            s.write_trial(flown(s, "s02", item.slot, y_ref=-0.05))
        elif item.kind in ("message", "instructions"):
            s.advance("s02", item.key)
        if item.kind == "fit":
            break
    with opened_page(browser, gamepad=True) as page:
        page.goto(f"{run.url}?subject=s02")
        calibrate(page)
        page.wait_for_function("() => document.querySelector('#message-status').textContent.includes('Preparing')")
        shots(page, "16-fit-break-preparing")
        preparing_shown.set()
        page.wait_for_function("() => document.querySelector('#message-keys').textContent.includes('Space')",
                               timeout=120_000)
        shots(page, "17-fit-break-ready")
        _to_the_task(page)
        shots(page, "18-assisted-show")
        page.evaluate(f"() => {{ window.__pilot = {pilot_js(pilot_gain(100.0), -0.05)}; }}")
        page.keyboard.press("Space")
        page.wait_for_function("() => document.querySelector('#message-title').textContent === 'Break'",
                               timeout=60_000)
        shots(page, "19-break")
        page.wait_for_function("() => window.collect.onSpace !== null", timeout=10_000)
        _to_the_task(page)
        shots(page, "20-assisted-blend")
        page.keyboard.press("Space")
        page.wait_for_selector("#summary:not([hidden])", timeout=60_000)
        shots(page, "21-end")

    with opened_page(browser, gamepad=False) as page:
        page.goto(f"{run.url}experimenter?key={run.key}")
        page.wait_for_function("() => document.querySelectorAll('.subject').length >= 2")
        shots(page, "22-experimenter")
        # the experimenter excludes a trial from the page, with a note
        row = page.locator("tr", has_text="s02-001-CS1-train")
        row.locator("input[type=text]").fill("the subject sneezed")
        row.locator("input[type=checkbox]").check()
        row.locator("button").click()
        page.wait_for_selector("tr.excluded")
        shots(page, "23-experimenter-excluded")
    from workbench.data.dataset import load_demonstrations

    excluded = {d.id: d.meta["exclusion_note"] for d in load_demonstrations(run.out) if d.meta["excluded"]}
    assert excluded == {"s02-001-CS1-train": "the subject sneezed"}
    assert len(shots.names) == 23
