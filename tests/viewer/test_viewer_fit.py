"""What the viewer tells a user at a glance: a model that does not fit is warned of (terminal and recording),
``view --model`` draws its Monte Carlo band by default, bands never change a line's hue and sit under the scene's
lines, a ULog is drawn on ``inspect``'s clock, and a saved live recording opens like the others.

Expected values are computed here (from the models, ``adapters.inspect``, the style's colors), never copied.
"""

from __future__ import annotations

import colorsys

import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from workbench.viewer import style, verdict
from workbench.viewer.live import LiveLogger, live_blueprint

from ..rrd import blueprint_names, read_rrd
from . import viewer_recordings

recordings = viewer_recordings.load()  # one instance per process: test_viewer.py's recordings


PX4_LOG = recordings.REPO.parent / "shared" / "external" / "px4_sample_log_small.ulg"


def _flat(values: list) -> list:
    """A column's cells, one level of list per row unwrapped."""
    out = []
    for v in values:
        out.extend(v if isinstance(v, list) else [v])
    return out


def _view(capsys, *argv: str) -> str:
    from workbench.cli import main

    code = main(["view", *argv])
    assert code == 0
    return capsys.readouterr().err


@pytest.fixture(scope="module")
def demo_files():
    recordings.cli_recordings()
    d = recordings.workdir() / "demo"
    return d / "demos.parquet", d / "models" / "CS1.npz"


def test_a_model_on_data_of_another_dt_is_warned_in_the_terminal_and_the_recording(tmp_path, capsys, demo_files):
    from workbench.data.dataset import load_demonstrations
    from workbench.models.factory import load_model

    demos, model_path = demo_files
    model = load_model(model_path)
    coarse = load_demonstrations(demos).by_label("CS1").resample(2 * model.plant.dt)
    coarse_path = tmp_path / "coarse.parquet"
    coarse.save(coarse_path)
    out = tmp_path / "wrong.rrd"
    err = _view(capsys, str(coarse_path), "--model", str(model_path), "--resample", "--samples", "0",
                "--save", str(out), "-q")
    expected = verdict.mismatches(model, coarse.state_names, coarse.input_names, coarse.roles, None,
                                  source_dt=coarse.dt)
    assert expected, "the dt mismatch must be found"
    printed = [line for line in err.splitlines() if line.startswith("warning: model")]
    assert len(printed) == 1 and expected[0] in printed[0] and "does not fit" in printed[0], err
    logged = _flat(read_rrd(out)["/warnings"]["static:TextLog:text"])
    assert logged == [printed[0].removeprefix("warning: ")]
    # the first view's title says it, and the objective tab carries the verdict
    names = blueprint_names(out)
    assert any(n.startswith("⚠ MODEL") and "DOES NOT FIT" in n for n in names), names
    assert "/models/" + model_path.stem + "/verdict" in read_rrd(out)


def test_a_model_on_data_of_other_roles_is_warned_in_the_terminal_and_the_recording(tmp_path, capsys, demo_files):
    from dataclasses import replace

    from workbench.data.dataset import load_demonstrations
    from workbench.data.demonstrations import DemonstrationSet
    from workbench.models.factory import load_model

    demos, model_path = demo_files
    model = load_model(model_path)
    cs1 = load_demonstrations(demos).by_label("CS1")
    # the same names and dt, but another vehicle's roles: the heading is not declared (another mapping)
    other = DemonstrationSet(list(cs1), cs1.state_names, cs1.input_names, cs1.dt,
                             roles=replace(cs1.roles, heading=None))
    assert other.roles != model.plant.roles
    path = tmp_path / "other_roles.parquet"
    other.save(path)
    out = tmp_path / "roles.rrd"
    err = _view(capsys, str(path), "--model", str(model_path), "--samples", "0", "--save", str(out), "-q")
    expected = verdict.mismatches(model, other.state_names, other.input_names, load_demonstrations(path).roles, None)
    assert [m for m in expected if "roles" in m], "the roles mismatch must be found"
    printed = [line for line in err.splitlines() if line.startswith("warning: model")]
    assert len(printed) == 1 and all(m in printed[0] for m in expected), err
    assert "roles" in printed[0]
    logged = _flat(read_rrd(out)["/warnings"]["static:TextLog:text"])
    assert logged == [printed[0].removeprefix("warning: ")]
    assert any(n.startswith("⚠ MODEL") and "DOES NOT FIT" in n for n in blueprint_names(out))


def test_view_with_a_model_draws_the_band_by_default_and_a_fitting_model_is_not_warned(tmp_path, capsys, demo_files):
    from workbench.cli.view import VIEW_SAMPLES

    demos, model_path = demo_files
    out = tmp_path / "model.rrd"
    err = _view(capsys, str(demos), "--model", f"CS1={model_path}", "--horizon", "1", "--save", str(out), "-q")
    assert "warning: model" not in err, err
    ents = read_rrd(out)
    bands = [p for p in ents if "/proposed_band/" in p]
    scene = [p for p in ents if p.startswith("/scene/predictions/") and p.endswith("proposed_band")]
    assert bands and scene
    assert VIEW_SAMPLES > 0 and f"default {VIEW_SAMPLES}" in _help("view")


def _help(command: str) -> str:
    from workbench.cli.parser import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return sub.choices[command].format_help()


def test_the_band_verdict_judges_coverage_against_its_sampling_spread():
    from scipy.stats import binom

    from workbench.study.calibration import band_verdict

    nominal, n = verdict.NOMINAL_1SIGMA, 2000
    lo, hi = (np.asarray(binom.interval(0.95, n, nominal)) / n).tolist()
    words = band_verdict([nominal, lo - 0.01, hi + 0.01, float("nan")], nominal, n)
    assert list(words) == ["fits", "too narrow", "too wide", ""]
    # 3σ: a band of other data misses most samples; one a little narrow misses a few more than nominal
    n3 = 300
    lo3 = binom.interval(0.95, n3, verdict.NOMINAL_3SIGMA)[0] / n3
    assert str(band_verdict(lo3 - 0.005, verdict.NOMINAL_3SIGMA, n3)) == "too narrow"
    assert str(band_verdict(0.97, verdict.NOMINAL_3SIGMA, n3)) == "too narrow"
    assert str(band_verdict(0.85, verdict.NOMINAL_3SIGMA, n3)) == "does not fit"


def _hue_shift(line: tuple[int, int, int], band: tuple[int, int, int], alpha: float) -> float:
    """Degrees the hue of ``line`` turns under a fill of ``band`` at ``alpha`` (rerun draws fills over lines)."""
    a = np.asarray(line, float) / 255
    b = a + alpha * (np.asarray(band, float) / 255 - a)
    h0, h1 = colorsys.rgb_to_hsv(*a)[0], colorsys.rgb_to_hsv(*b)[0]
    d = abs(h0 - h1) * 360
    return min(d, 360 - d)


def test_bands_keep_line_colors_and_sit_under_the_scene_lines(setup_session):
    ents = setup_session
    # every time-series band, in the session, is drawn in the one neutral band tint
    band_colors = set()
    for cols in ents.values():
        for key in ("static:Measurements:colors",):
            band_colors.update(int(c) for c in _flat(cols.get(key, [])))
    packed = int(style.packed(style.BAND_COLOR)[0])
    assert band_colors == {packed}
    # rerun draws a fill over the lines: a neutral tint turns no method's hue, a colored one would
    for method in ("proposed", "ioc_only", "gmr_only", "persistence"):
        for alpha in (0.1, 0.2, 0.3):
            assert _hue_shift(style.method_color(method), style.BAND_COLOR, alpha) < 5.0
    assert _hue_shift(style.method_color("ioc_only"), style.light(style.method_color("persistence"), 0.45), 0.3) > 5.0
    # in the scene, draw order is honored: the envelope is under every track and prediction line
    band_orders = [o for p, c in ents.items() if p.endswith("_band") and p.startswith("/scene/")
                   for o in _flat(c["static:LineStrips2D:draw_order"])]
    line_orders = [o for p, c in ents.items() if p.startswith("/scene/") and not p.endswith("_band")
                   and "static:LineStrips2D:draw_order" in c and not p.endswith("/ground")
                   for o in _flat(c["static:LineStrips2D:draw_order"])]
    assert band_orders and line_orders and max(band_orders) < min(line_orders)


@pytest.fixture(scope="module")
def setup_session():
    return read_rrd(recordings.cli_recordings()["view_model"])


def test_a_ulog_is_drawn_on_the_clock_of_inspect(tmp_path, capsys):
    if not PX4_LOG.is_file():
        pytest.skip(f"{PX4_LOG} is absent")
    import adapters

    out = tmp_path / "px4.rrd"
    _view(capsys, str(PX4_LOG), "--mapping", "px4_manual", "--save", str(out), "-q")
    summary = adapters.inspect(PX4_LOG)
    ds = adapters.load(PX4_LOG, mapping="px4_manual", allow_still=True)  # no GPS: the view shows it all the same
    ents = read_rrd(out)
    for d in ds:
        t = np.sort(np.asarray(ents[f"/demos/{d.id}/states/{ds.state_names[0]}"]["time"], float))
        np.testing.assert_allclose(t, d.meta["t0"] - summary.t_start + d.t - d.t[0], atol=1e-6)
        # inside the flight-mode span inspect prints for this segment's mode, to a grid step
        spans = [(m.start - summary.t_start, m.end - summary.t_start) for m in summary.modes
                 if m.mode == d.meta.get("mode")]
        assert any(a - ds.dt <= t[0] and t[-1] <= b + ds.dt for a, b in spans), (t[0], t[-1], spans)
    # the raw streams beside the mapped segments are on the same clock: each starts where inspect starts it
    first = {s.name: s.t_start for s in summary.streams}
    for name in ("vehicle_local_position", "manual_control_setpoint"):
        t_raw = np.asarray(ents[f"/log/streams/{name}"]["time"], float)
        assert t_raw.min() == pytest.approx(first[name] - summary.t_start, abs=1e-6), name


def test_a_saved_live_recording_opens_collapsed_paused_and_every_event_has_a_link_time(tmp_path):
    saved = live_blueprint(["seg-1"], ["x", "y"], ["u1"])
    assert saved.collapse_panels is True
    assert saved.time_panel.play_state == "paused" and saved.time_panel.timeline == "link_time"
    watched = live_blueprint(["seg-1"], ["x", "y"], ["u1"], following=True)
    assert watched.time_panel.play_state == "following"
    # the link's timing plots over the whole session, not ±30 s around the paused cursor at its start
    spanned = live_blueprint(["seg-1"], ["x", "y"], ["u1"], span=(3.0, 90.0))
    timing = [v for v in _views(spanned.root_container) if str(getattr(v, "name", "")).endswith("[ms]")]
    assert len(timing) == 2
    for v in timing:
        (r,) = v.properties["TimeAxis"].view_range.as_arrow_array().to_pylist()
        assert r["start"] < 3e9 < 90e9 < r["end"] < 100e9  # nanoseconds on the link's clock
    silent = live_blueprint([], ["x", "y"], ["u1"])  # nothing received: the first tab explains why
    assert silent.collapse_panels is True
    from workbench.live.predictor import LiveEvent

    path = tmp_path / "live.rrd"
    rec = rr.RecordingStream("workbench_live_test")
    rec.save(path)
    logger = LiveLogger(rec, ["x", "y"], ["u1"])
    logger.event(LiveEvent("silent", 123.0, "no data for 2 s; waiting for the link"))
    rec.flush()
    rec.disconnect()
    ents = read_rrd(path)
    events = ents["/live/events"]
    assert len(events["link_time"]) == len(events["TextLog:text"]) == 2
    assert "link_time" in ents["/live/status"]
    assert RrdReader(path).recordings()


def test_a_saved_live_recording_opens_at_the_vehicles_first_state_not_at_link_time_0(tmp_path):
    """The vehicle's clock is its time since boot: what came before the first state (the waiting lines, a link
    event) was stamped at link time 0, so a saved file opened minutes before any data. Held back, the event is
    stamped at the first state and the placeholders are dropped; nothing on the link timeline precedes the data."""
    from workbench.live.predictor import LiveEvent, LivePrediction

    path = tmp_path / "live.rrd"
    rec = rr.RecordingStream("workbench_live_test")
    rec.save(path)
    logger = LiveLogger(rec, ["x", "y"], ["u1"], plane=(0, 1, None), watched=False)
    logger.event(LiveEvent("heard", 0.0, "heartbeat from system 1"))
    first = 312.5  # s since the vehicle booted
    for k in range(3):
        logger.log(LivePrediction("flight-000", 0, k, first + 0.05 * k, 0.05 * k, np.zeros(2), np.zeros(1),
                                  np.zeros(2), None, np.zeros(1), np.eye(1), None, None, None, None, None, 0.05))
    logger.flush()
    logger.finish()
    rec.flush()
    rec.disconnect()
    ents = read_rrd(path)
    stamps = [t for e in ents.values() for t in _flat(e.get("link_time", [])) if t is not None]
    assert stamps and min(stamps) == first
    assert "heartbeat from system 1" in _flat(ents["/live/events"]["TextLog:text"])
    assert "/scene/live/waiting" not in ents or not _flat(ents["/scene/live/waiting"].get("Points2D:labels", []))


def test_a_silent_live_recording_shows_the_port_it_waits_on_and_a_scene_to_wait_in():
    ents = read_rrd(recordings.cli_recording("live_silent"))
    status = _flat(ents["/live/status"]["TextDocument:text"])[-1]
    port = next(w for w in status.split() if w.startswith("udpin:")).rstrip(":")
    assert "**waiting**" in status and "receiving" not in status
    waiting = ents["/scene/live/waiting"]
    label = _flat(waiting["Points2D:labels"])[0]
    assert "waiting for the vehicle's first state" in label and port in label
    assert min(waiting["link_time"]) == 0.0  # where a saved live file opens
    for static in ("/scene/live/ground", "/scene/live/scale"):  # planar_quadrotor's plane is a side view
        assert ents[static]["static:LineStrips2D:strips"], static


def test_the_scale_bar_follows_the_larger_extent_of_the_plane():
    from workbench.viewer.scene import scale_bar

    # a vertical descent: 2 cm across, 1.1 m down; the view shows it as wide as tall, so the bar is ~a fifth of 1.1 m
    ends, text = scale_bar(([-0.01, 0.01], [0.1, 1.2]), "m")
    length = float(ends[1, 0] - ends[0, 0])
    assert 1.1 / 10 <= length <= 1.1 / 2 and text == f"{length:g} m"
    # across and down alike: the same rule either way round
    wide, _ = scale_bar(([0.0, 1.1], [0.0, 0.02]), "m")
    assert float(wide[1, 0] - wide[0, 0]) == length


def _views(container):
    """Every view and container under a blueprint container, depth first."""
    for c in getattr(container, "contents", None) or []:
        yield c
        yield from _views(c)
