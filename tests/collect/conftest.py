"""Fixtures of the testbed's tests: a session server in this process, Debian's Chromium driven by Playwright, and a
scripted subject on a virtual gamepad (``navigator.getGamepads`` overridden by an init script).

The browser is the distribution's (``/usr/bin/chromium``, installed by ``.ci/run``); Playwright never downloads
one. Without it the browser tests are skipped on a user's machine and fail in CI.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from workbench.collect.protocol import load_protocol
from workbench.collect.server import Server, make_app
from workbench.collect.session import Session
from workbench.plant.system import planar_quadrotor

CHROMIUM = os.environ.get("WORKBENCH_CHROMIUM") or shutil.which("chromium") or "/usr/bin/chromium"

# A scripted pad: the sticks a deterministic pilot asks for in the page's current state (read from the page's
# window.collect hook), the axes it returned logged by the state they were returned for, so a test can check
# that what the page recorded is exactly what the pad said.
PAD_SCRIPT = """
(() => {
  const buttons = Array.from({ length: 17 }, () => ({ pressed: false, touched: false, value: 0 }));
  const pad = { id: "Scripted pad (test)", index: 0, connected: true, mapping: "standard", timestamp: 0,
                axes: [0, 0, 0, 0], buttons, vibrationActuator: null };
  window.__padLog = {};
  window.__pilot = null;
  navigator.getGamepads = () => {
    const c = window.collect, trial = c && c.trial;
    let axes = [0, 0, 0, 0];
    if (window.__pilot && trial && !trial.ended) axes = window.__pilot(trial.x, trial.k);
    else if (window.__axes) axes = window.__axes.slice();  // a stick held on the calibration screen
    // a worn pad: at rest its axes read window.__rest, not 0 (what the calibration screen measures), and at full
    // deflection still ±1 (the ends of the axis's range)
    const worn = (v, r) => (Math.abs(v) === 1 ? v : r + v * (v >= 0 ? 1 - r : 1 + r));
    if (window.__rest) axes = axes.map((v, j) => worn(v, window.__rest[j]));
    if (window.__pilot && trial && !trial.ended) window.__padLog[JSON.stringify(trial.x)] = axes.slice();
    pad.axes = axes; pad.timestamp = performance.now();
    return [{ ...pad, axes: axes.slice() }, null, null, null];
  };
})();
"""


def pilot_gain(r_thrust: float = 100.0) -> np.ndarray:
    """An LQR gain for the plant (``u = K x``): a stabilizing scripted pilot, from a computation, not a copy."""
    s = planar_quadrotor()
    Q, R = np.diag([1.0, 1.0, 1.0, 1.0, 4.0, 0.01]), np.diag([20.0, r_thrust])
    P = scipy.linalg.solve_discrete_are(s.A, s.B, Q, R)
    return -np.linalg.solve(R + s.B.T @ P @ s.B, s.B.T @ P @ s.A)


def pilot_js(K: np.ndarray, y_ref: float, wobble: float = 0.1) -> str:
    """The scripted pilot as a page function ``(x, k) -> axes``: :func:`pilot_u` put on a standard pad's axes
    (angular acceleration on axis 2, thrust on axis 1, up negative)."""
    return f"""(x, k) => {{
      const K = {json.dumps(K.tolist())}, ref = [0, {y_ref}, 0, 0, 0, 0];
      const u = K.map((row, i) => row.reduce((s, a, j) => s + a * (x[j] - ref[j]), 0)
                                  + {wobble} * Math.sin((i ? 0.5 : 0.3) * k));
      const c = u.map((v) => Math.max(-1, Math.min(1, v)));
      return [0, -c[1], c[0], 0];
    }}"""


def pilot_u(K: np.ndarray, y_ref: float, x: np.ndarray, k: int, wobble: float = 0.1) -> np.ndarray:
    """What :func:`pilot_js` asks for at step ``k`` in state ``x``: ``u = clip(K (x − ref) + wobble sin(ω k))``,
    ``ref`` the state ``y_ref`` high (ω = 0.3, 0.5 per step: the inputs vary, as a person's do)."""
    ref = np.array([0.0, y_ref, 0.0, 0.0, 0.0, 0.0])
    return np.clip(K @ (np.asarray(x) - ref) + wobble * np.sin(np.array([0.3, 0.5]) * k), -1.0, 1.0)


# A pilot that lands (touches down slower than the task's landing speed, flat, on the pad): it aims 5 cm below the
# ground with a small wobble. Aiming lower or wobbling more touches down faster than the landing speed (aiming
# 0.3 m below, the pilot crashed at 0.16-0.20 m/s every time); test_task checks this one lands from the start box.
LANDING_PILOT = {"y_ref": -0.05, "wobble": 0.02}


def calibrated(raw: np.ndarray, cal: dict) -> np.ndarray:
    """The page's calibration (static/input.js ``calibrate``) applied to raw axis readings."""
    out = np.zeros_like(raw)
    for i in range(raw.shape[1]):
        off = cal["offsets"][cal["axes"][i]]
        d = raw[:, i] - off
        travel = np.where(d >= 0, 1 - off, 1 + off)
        v = cal["signs"][i] * np.where(travel > 0, d / np.where(travel > 0, travel, 1.0), 0.0)
        a, dz, e = np.abs(v), cal["deadzone"], cal.get("expo", 0.0)
        m = np.minimum(1.0, (a - dz) / (1 - dz))
        out[:, i] = np.where(a <= dz, 0.0, np.sign(v) * ((1 - e) * m + e * m * m * m))
    return out


@pytest.fixture(scope="session")
def browser():
    if not Path(CHROMIUM).is_file():
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"CI must have Chromium at {CHROMIUM} (.ci/run installs it)")
        pytest.skip(f"no Chromium at {CHROMIUM}")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=["--no-sandbox"])
        yield b
        b.close()


def join(session: Session, subject: str, fields: dict | None = None, confirm: bool = False) -> dict:
    """Register a subject who agreed to the session's consent text (what the page sends)."""
    return session.register(subject, fields or {}, {"sha256": session.protocol.consent_sha256}, confirm)


def _toml(value) -> str:
    if isinstance(value, dict):  # an inline table
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    return json.dumps(value)


def write_protocol(path: Path, blocks: list[dict], **top) -> Path:
    """A small protocol file for a test."""
    lines = [f'title = "{top.get("title", "Test protocol")}"', 'consent = "A test session."']
    for key in ("counterbalance", "time_limit_s", "subjects"):
        if key in top:
            lines.append(f"{key} = {json.dumps(top[key])}")
    if "breaks" in top:
        lines += ["[breaks]", *(f"{k} = {json.dumps(v)}" for k, v in top["breaks"].items())]
    for b in blocks:
        lines.append("[[blocks]]")
        lines += [f"{k} = {_toml(v)}" for k, v in b.items()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


class Running:
    """A session served in this process (the experimenter's page open with ``key``)."""

    def __init__(self, out: Path, protocol, key: str = "test-key", **session) -> None:
        self.session = Session(out, protocol, **session)
        self.server = Server(make_app(self.session, key=key), port=0).start()
        self.url = self.server.url
        self.key = key
        self.out = out


@pytest.fixture
def serve(tmp_path):
    running = []

    def start(protocol, out: Path | None = None, **session) -> Running:
        p = load_protocol(protocol) if isinstance(protocol, str | Path) else protocol
        r = Running(out or tmp_path / "session", p, **session)
        running.append(r)
        return r

    yield start
    for r in running:
        r.server.stop()


def new_page(browser, gamepad: bool, viewport: tuple[int, int] = (1100, 760)):
    context = browser.new_context(viewport={"width": viewport[0], "height": viewport[1]})
    context.set_default_timeout(60_000)  # a shared machine under load: a wait's deadline, not a speed check
    if gamepad:
        context.add_init_script(PAD_SCRIPT)
    return context, context.new_page()


@contextlib.contextmanager
def opened_page(browser, gamepad: bool, viewport: tuple[int, int] = (1100, 760)):
    """:func:`new_page`'s page, its browser context closed on leaving (a new browser for each subject)."""
    context, page = new_page(browser, gamepad, viewport)
    try:
        yield page
    finally:
        context.close()


def consent(page, url: str, subject: str) -> None:
    """The consent screen (the ID given in the link), agreed; the subject form's fields (if any) left empty."""
    page.goto(f"{url}?subject={subject}")
    page.wait_for_selector("#screen-consent:not([hidden])")
    page.click("#consent-agree")
    page.wait_for_selector("#screen-subject:not([hidden]), #screen-calibration:not([hidden])")
    if page.is_visible("#subject-continue"):
        page.click("#subject-continue")


def calibrate(page, rest: list[float] | None = None) -> None:
    """The calibration screen done as a subject does it: a gamepad's rest measured (its axes resting at ``rest``)
    and both sticks assigned by moving them and confirmed; or each arrow key tapped."""
    page.wait_for_selector("#screen-calibration:not([hidden])")
    if page.is_visible("#pad-steps"):
        page.evaluate("rest => { window.__rest = rest; }", rest)
        page.click("#measure-rest")
        page.wait_for_function("() => document.querySelector('#rest-result').textContent.includes('dead zone')")
        for i, axes in ((1, [0, 0, 1, 0]), (2, [0, -1, 0, 0])):  # right stick right; left stick up
            page.click(f"#assign-u{i}")  # then the stick is moved and held
            page.wait_for_function(f"() => document.querySelector('#axis-u{i}').textContent.includes('now')")
            page.evaluate("axes => { window.__axes = axes; }", axes)
            page.wait_for_selector(f"#confirm-u{i}:not([hidden])")
            page.evaluate("() => { window.__axes = null; }")
            page.click(f"#confirm-u{i}")
    else:
        for key in ("ArrowLeft", "ArrowRight", "ArrowUp", "ArrowDown"):
            page.keyboard.press(key)
    page.wait_for_function("() => document.querySelector('#calibration-next').textContent.includes('Space')")
    page.keyboard.press("Space")


def register(page, url: str, subject: str, rest: list[float] | None = None) -> None:
    """Consent, the subject form and the calibration screen, as a subject does them."""
    consent(page, url, subject)
    calibrate(page, rest)


def rerun_entities(mcap: Path, rrd: Path) -> set[str]:
    """The entity paths rerun's own MCAP loader makes of a file (what ``rerun FILE.mcap`` shows)."""
    import rerun as rr
    from rerun.chunk import RrdReader

    rec = rr.RecordingStream("workbench-collect-test")
    rec.save(rrd)
    rec.log_file_from_path(mcap)
    rec.flush()
    rec.disconnect()
    return {str(chunk.entity_path) for chunk in RrdReader(rrd).stream()}
