"""The page's simulation is the plant's: the same steps and the same end rules as the server's, bit for bit."""

from __future__ import annotations

import json

import numpy as np
import pytest

from workbench.collect.task import OUTCOMES, outcome, reason, replay, step, task_spec
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_trial

from .conftest import LANDING_PILOT, pilot_gain, pilot_u


def test_task_spec_is_the_plant():
    s = planar_quadrotor()
    spec = task_spec(s)
    assert np.array_equal(np.array(spec["A"]), s.A) and np.array_equal(np.array(spec["B"]), s.B)
    assert spec["dt"] == s.dt and spec["max_steps"] == round(spec["time_limit_s"] / s.dt)
    json.dumps(spec)  # what the page receives


def test_python_step_agrees_with_the_plant():
    s, spec = planar_quadrotor(), task_spec()
    rng = np.random.default_rng(1)
    for _ in range(50):
        x, u = rng.normal(size=6), rng.uniform(-1, 1, 2)
        assert np.allclose(step(spec["A"], spec["B"], x.tolist(), u.tolist()), s.step(x, u), rtol=0, atol=1e-12)


def test_replay_ends_where_the_simulator_ends():
    """A simulated landing's inputs replayed through the task give its states and its outcome."""
    spec = task_spec()
    for seed in range(3):
        d = simulate_trial("CS1", np.random.default_rng(seed))
        xs, end, k = replay(spec, d.x[0], d.u)
        assert end == d.meta["outcome"] and k == len(d) - 1
        assert np.allclose(xs, d.x, atol=1e-9)


@pytest.mark.parametrize("held", [1, 5])
def test_the_scripted_landing_pilot_lands_from_anywhere_in_the_start_box(held):
    """The browser tests' landing pilot (conftest.LANDING_PILOT) lands: from a grid over the start box, its reads
    held ``held`` steps (a slow display: a frame runs up to 5 physics steps on one read, static/sim.js). A pilot
    that crashes leaves a fit step and ``workbench fit`` no trial (they take landed training trials)."""
    spec, K = task_spec(), pilot_gain()
    i = spec["index"]
    ends = []
    for sx in np.linspace(*spec["start"]["x"], 9):
        for sy in np.linspace(*spec["start"]["y"], 3):
            x, k, u = [0.0] * len(spec["state_names"]), 0, None
            x[i["x"]], x[i["y"]] = float(sx), float(sy)
            while (end := outcome(spec, x, k)) is None:
                if k % held == 0:
                    u = pilot_u(K, LANDING_PILOT["y_ref"], np.array(x), k, LANDING_PILOT["wobble"]).tolist()
                x = step(spec["A"], spec["B"], x, u)
                k += 1
            ends.append((end, reason(spec, x, end)))
    assert all(end == "landed" for end, _ in ends), [why for end, why in ends if end != "landed"]


@pytest.fixture(scope="module")
def sim_page(browser, tmp_path_factory):
    from workbench.collect.protocol import load_protocol
    from workbench.collect.server import Server, make_app
    from workbench.collect.session import Session

    server = Server(make_app(Session(tmp_path_factory.mktemp("s") / "session", load_protocol(
        "paper_single_subject"))), port=0).start()
    page = browser.new_page()
    page.goto(f"{server.url}static/index.html")
    page.evaluate("async () => { window.sim = await import('/static/sim.js'); "
                  "window.spec = (await (await fetch('/api/config')).json()).task; }")
    yield page
    page.close()
    server.stop()


def test_page_and_server_step_the_same_bits(sim_page):
    spec = task_spec()
    rng = np.random.default_rng(2)
    x = [float(v) for v in rng.normal(size=6)]
    us = rng.uniform(-1, 1, (200, 2)).tolist()
    page = sim_page.evaluate("([x, us]) => { const out = []; for (const u of us) { x = sim.step(spec.A, spec.B, x, u);"
                             " out.push(x); } return out; }", [x, us])
    ours = []
    for u in us:
        x = step(spec["A"], spec["B"], x, u)
        ours.append(x)
    assert np.array_equal(np.array(page), np.array(ours))  # equal, not close: the same sums in the same order


def test_page_and_server_end_trials_by_the_same_rules(sim_page):
    spec = task_spec()
    rng = np.random.default_rng(3)
    states = np.column_stack([rng.uniform(-3.5, 3.5, 400), rng.uniform(-0.2, 3.8, 400), rng.normal(0, 0.1, 400),
                              rng.normal(0, 0.1, 400), rng.normal(0, 0.1, 400), rng.normal(0, 1, 400)])
    states[:100, 1] = -0.01  # on the ground: landed or crashed, by pad, speed and attitude
    ks = rng.integers(0, spec["max_steps"] + 2, 400)
    page = sim_page.evaluate("([xs, ks]) => xs.map((x, j) => sim.outcome(spec, x, ks[j]))",
                             [states.tolist(), ks.tolist()])
    ours = [outcome(spec, x, int(k)) for x, k in zip(states.tolist(), ks, strict=True)]
    assert page == ours
    assert set(ours) >= {None, *OUTCOMES}  # every rule was exercised
    # and give each end the same reason, in the same words (what the subject reads, what the trial records)
    ended = [(x, o) for x, o in zip(states.tolist(), ours, strict=True) if o is not None]
    page_why = sim_page.evaluate("cases => cases.map(([x, o]) => sim.reason(spec, x, o))", ended)
    assert page_why == [reason(spec, x, o) for x, o in ended]
    assert {w.split(":")[0] for w in page_why} == {"landed", "crashed", "left the area", "out of time"}


def test_the_page_and_the_server_calibrate_a_stick_to_the_same_bits(sim_page):
    """Offsets, signs, dead zone and expo: input.js calibrate and checks.calibrate agree to the bit."""
    from workbench.collect.checks import calibrate

    rng = np.random.default_rng(5)
    cases = [[float(r), float(o), float(sg), float(dz), float(e)] for r, o, sg, dz, e in zip(
        rng.uniform(-1, 1, 300), rng.uniform(-0.2, 0.2, 300), rng.choice([-1.0, 1.0], 300),
        rng.choice([0.0, 0.01, 0.05, 0.2], 300), rng.choice([0.0, 0.3, 1.0], 300), strict=True)]
    cases += [[1.0, 0.1, 1.0, 0.05, 0.3], [-1.0, 0.1, -1.0, 0.0, 0.5], [0.1, 0.1, 1.0, 0.0, 0.0]]
    page = sim_page.evaluate("async (cases) => { const input = await import('/static/input.js');"
                             " return cases.map((c) => input.calibrate(...c)); }", cases)
    assert page == [calibrate(*c) for c in cases]


@pytest.mark.parametrize("frame_ms", [10.0, 25.0, 50.0])
def test_physics_runs_at_its_own_rate_whatever_the_display_rate(sim_page, frame_ms):
    """The accumulator: 2 s of frames at 100, 40 or 20 Hz run the same steps and reach the same state."""
    spec = task_spec()
    total_ms = 2000.0
    out = sim_page.evaluate(
        """([frame, total]) => {
             const x0 = [0, 2.8, 0, 0, 0, 0];
             const t = new sim.Trial(spec, x0, (x) => ({ u: [0, -0.2], raw: [0, -0.2] }));
             for (let now = 1000; now <= 1000 + total + 1e-9; now += frame) t.advance(now);
             return { n: t.us.length, late: t.late, dropped: t.skipped, x: t.x };
           }""", [frame_ms, total_ms])
    steps = int(total_ms / (spec["dt"] * 1000))
    assert out["n"] == steps + 1 and out["dropped"] == 0
    x = [0, 2.8, 0, 0, 0, 0]
    for _ in range(steps + 1):  # every recorded sample is stepped on (the trial has not ended)
        x = step(spec["A"], spec["B"], x, [0, -0.2])
    assert out["x"] == x


def test_a_stalled_display_is_counted_not_hidden(sim_page):
    out = sim_page.evaluate(
        """() => {
             const t = new sim.Trial(spec, [0, 2.8, 0, 0, 0, 0], () => ({ u: [0, 0], raw: [0, 0] }));
             t.advance(0); t.advance(16); t.advance(1016);  // a one-second freeze
             return { n: t.us.length, late: t.late, dropped: t.skipped };
           }""")
    # a frame may catch up 5 steps at once (4 of them late); the other steps of the freeze are dropped, counted
    dt_ms = task_spec()["dt"] * 1000
    missed = int(1016 / dt_ms)
    assert out["n"] == 1 + 5 and out["late"] == 4 and out["dropped"] == missed - 5


def test_the_keyboard_ramp_reaches_full_deflection_and_centre_exactly_in_the_stated_steps(sim_page):
    out = sim_page.evaluate(
        """async () => {
             const input = await import('/static/input.js');
             const kb = new input.Keyboard({ add() {} });
             const us = [];
             const hold = (codes, n) => {
               kb.held = new Set(codes);
               for (let j = 0; j < n; j++) us.push(kb.sample().u);
             };
             hold(["ArrowRight", "ArrowUp"], input.KEY_STEPS + 2);  // held past full deflection
             hold(["ArrowLeft"], 2 * input.KEY_STEPS + 1);          // reversed: through 0 to -1
             hold([], input.KEY_STEPS + 1);                         // released
             return { us, n: input.KEY_STEPS, ramp: input.KEY_RAMP };
           }""")
    n, us = out["n"], np.array(out["us"])
    assert out["ramp"] == 1 / n
    # integer levels over n: what a ramp of 1/n a step gives, with 1, 0 and -1 reached exactly
    up = [min(k, n) / n for k in range(1, n + 3)]
    across = [max(n - k, -n) / n for k in range(1, 2 * n + 2)]  # from 1 down through 0 to -1
    back = [min(-n + k, 0) / n for k in range(1, n + 2)]
    assert us[:, 0].tolist() == up + across + back
    assert us[:, 1].tolist() == up + [max(n - k, 0) / n for k in range(1, 3 * n + 3)]
