"""The rerun recordings: read the .rrd back and check entity paths, row counts and values against the model.

Every expected number is computed here from the demonstrations and the fitted model (``model.variability``,
``model.predict``), never copied from a run. No test here opens a viewer (``test_viewer_real.py`` does); every
chunk of every kind of recording the CLI writes is read back and must have rows, because a chunk without rows
crashes the rerun 0.41 viewer while ``rerun rrd verify`` passes.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from rerun.blueprint.components import LinkAxis
from rerun.chunk import RrdReader

from workbench import viewer
from workbench.errors import DataError, WorkbenchError
from workbench.models import HumanBehaviorModel, IOCOnlyModel
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings
from workbench.viewer import columns, objective, output, replay, replay_blueprint, session, style
from workbench.viewer.tabs.objective import log_models

from ..rrd import blueprint_names, read_rrd
from . import viewer_recordings

recordings = viewer_recordings.load()  # one shared instance, so test_viewer_real.py reuses the same recordings

HORIZON = 15
SAMPLES = 40
STARTS = (0, 25)

rr.set_strict_mode(True)  # a bad call must fail the test, not log a warning


def series(entities, path: str, column: str = "Scalars:scalars") -> tuple[np.ndarray, np.ndarray]:
    """(time, values) of a temporal entity, sorted by time; values (rows, width)."""
    e = entities[path]
    t = np.asarray(e["time"], dtype=float)
    v = np.asarray(e[column], dtype=float)
    order = np.argsort(t, kind="stable")
    return t[order], v[order]


def rrd_verify(path: Path) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("rerun")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "rerun"]
    return subprocess.run([*cmd, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    plant = planar_quadrotor()
    demos = simulate_landings("CS1", 8, seed=3) + simulate_landings("CS2", 4, seed=3)
    cs1 = demos.by_label("CS1")
    model = HumanBehaviorModel(plant, n_components=3, noise_folds=0).fit(cs1)  # the noise scale's CV: not here
    ioc = IOCOnlyModel(plant).fit(cs1)
    focus = cs1[1].id
    path = tmp_path_factory.mktemp("viewer") / "session.rrd"
    _, session = viewer.record_session(
        path, demos, models={"CS1": model}, baselines={"CS1": {"ioc_only": ioc}}, focus=[focus],
        n_steps=HORIZON, samples=SAMPLES, starts=STARTS, seed=7,
    )
    return {"demos": demos, "model": model, "ioc": ioc, "focus": focus, "path": path, "session": session,
            "entities": read_rrd(path)}


def test_rrd_verifies(setup):
    result = rrd_verify(setup["path"])
    assert result.returncode == 0, result.stderr


def test_entity_paths_and_row_counts(setup):
    ents, demos = setup["entities"], setup["demos"]
    for d in demos:
        for s in demos.state_names:
            t, v = series(ents, f"/demos/{d.id}/states/{s}")
            assert len(t) == len(d)
        for u in demos.input_names:
            t, v = series(ents, f"/demos/{d.id}/inputs/{u}")
            assert len(t) == len(d)
        assert f"/scene/demos/{d.id}/path" in ents
        assert len(ents[f"/scene/demos/{d.id}/vehicle"]["time"]) == len(d)
    for p in ("/scene/ground", "/scene/pad", "/scene/starts", "/models/CS1/K", "/models/CS1/Q", "/models/CS1/R",
              "/models/CS1/S", "/models/CS1/summary"):
        assert p in ents, p
    # only the strategy with a model gets variability; CS2 has none
    cs2 = next(d for d in demos if d.label == "CS2")
    assert not any(k.startswith(f"/demos/{cs2.id}/variability") for k in ents)
    for start in STARTS:
        for method, column in (("proposed", "Scalars:scalars"), ("ioc_only", "Scalars:scalars"),
                               ("proposed_band", "Measurements:values")):
            for s in demos.state_names:
                t, _ = series(ents, f"/demos/{setup['focus']}/predictions/from_{start}/{method}/{s}", column)
                assert len(t) == HORIZON + 1
        assert f"/scene/predictions/{setup['focus']}/from_{start}/proposed" in ents


def test_states_inputs_and_time_columns(setup):
    ents, demos = setup["entities"], setup["demos"]
    d = demos[2]
    for j, s in enumerate(demos.state_names):
        t, v = series(ents, f"/demos/{d.id}/states/{s}")
        np.testing.assert_allclose(t, d.t - d.t[0], atol=1e-9)
        np.testing.assert_array_equal(v[:, 0], d.x[:, j])
    steps = np.asarray(ents[f"/demos/{d.id}/inputs/u1"]["step"])
    np.testing.assert_array_equal(np.sort(steps), np.arange(len(d)))
    # inputs are drawn as a zero-order hold
    style = ents[f"/demos/{d.id}/inputs/u1"]
    assert any(style[k] for k in style if k.startswith("static:SeriesLines:interpolation_mode"))


def test_logged_gmr_equals_model_variability(setup):
    ents, demos, model = setup["entities"], setup["demos"], setup["model"]
    for d in demos.by_label("CS1"):
        mu, Sigma = model.variability(d.x, x0=d.x[0], target=d.target)
        sigma = np.sqrt(np.diagonal(Sigma, axis1=1, axis2=2))
        w = d.u - d.x @ model.K_.T
        for j, u in enumerate(demos.input_names):
            base = f"/demos/{d.id}/variability/{u}"
            _, w_logged = series(ents, f"{base}/w")
            np.testing.assert_allclose(w_logged[:, 0], w[:, j], rtol=0, atol=1e-12)
            _, m1 = series(ents, f"{base}/gmr", "Measurements:values")
            _, v1 = series(ents, f"{base}/gmr", "Measurements:variances")
            _, v3 = series(ents, f"{base}/gmr_3sigma", "Measurements:variances")
            np.testing.assert_allclose(m1[:, 0], mu[:, j], rtol=1e-12, atol=1e-14)
            np.testing.assert_allclose(v1[:, 0], sigma[:, j] ** 2, rtol=1e-12, atol=1e-16)
            np.testing.assert_allclose(v3[:, 0], 9 * sigma[:, j] ** 2, rtol=1e-12, atol=1e-16)
            outside = np.flatnonzero(np.abs(w[:, j] - mu[:, j]) > 3 * sigma[:, j])
            t_out = np.asarray(ents[f"{base}/outside_3sigma"]["time"])
            np.testing.assert_allclose(np.sort(t_out), (d.t - d.t[0])[outside], atol=1e-9)


def test_logged_predictions_equal_model_predict(setup):
    ents, demos, model, ioc = setup["entities"], setup["demos"], setup["model"], setup["ioc"]
    d = next(x for x in demos if x.id == setup["focus"])
    for start in STARTS:
        base = f"/demos/{d.id}/predictions/from_{start}"
        expected = {
            "proposed": model.predict(d.x[start], HORIZON, target=d.target, task_x0=d.x[0]),
            "ioc_only": ioc.predict(d.x[start], HORIZON, target=d.target, task_x0=d.x[0]),
        }
        mc = model.predict(d.x[start], HORIZON, target=d.target, task_x0=d.x[0], samples=SAMPLES, seed=7)
        for j, s in enumerate(demos.state_names):
            for method, pred in expected.items():
                t, v = series(ents, f"{base}/{method}/{s}")
                np.testing.assert_allclose(v[:, 0], pred.x[:, j], rtol=1e-12, atol=1e-12)
                np.testing.assert_allclose(t, d.t[start] - d.t[0] + demos.dt * np.arange(HORIZON + 1), atol=1e-9)
            # the band is drawn as an area: value ± √variance spans the Monte Carlo percentiles
            _, mid = series(ents, f"{base}/proposed_band/{s}", "Measurements:values")
            _, var = series(ents, f"{base}/proposed_band/{s}", "Measurements:variances")
            np.testing.assert_allclose(mid[:, 0] - np.sqrt(var[:, 0]), mc.x_lower[:, j], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(mid[:, 0] + np.sqrt(var[:, 0]), mc.x_upper[:, j], rtol=1e-9, atol=1e-12)
        # the plane of flight from the roles, up drawn up on rerun's y-down screen
        across, up = demos.roles.resolve(demos.state_names).plane
        strip = ents[f"/scene/predictions/{d.id}/from_{start}/proposed"]["static:LineStrips2D:strips"][0]
        x = expected["proposed"].x
        np.testing.assert_allclose(np.asarray(strip[0]), np.column_stack([x[:, across], -x[:, up]]), atol=1e-6)


def test_model_tensors(setup):
    ents, model = setup["entities"], setup["model"]
    K = ents["/models/CS1/K"]["static:Tensor:data"][0][0]
    np.testing.assert_allclose(np.asarray(K["buffer"], dtype=float).reshape(model.K_.shape), model.K_)
    Q = ents["/models/CS1/Q"]["static:Tensor:data"][0][0]
    n = model.plant.n
    np.testing.assert_allclose(np.asarray(Q["buffer"], dtype=float).reshape(n, n),
                               model.objective_.M_normalized[:n, :n])
    text = ents["/models/CS1/summary"]["static:TextDocument:text"][0][0]
    assert f"{model.objective_.alpha:.4g}" in text


def test_blueprint_has_the_five_tabs(setup):
    assert RrdReader(setup["path"]).blueprints(), "the recording carries no default blueprint"
    names = blueprint_names(setup["path"])
    # the model was fitted on every CS1 trial: its tab says the focus trial is in-sample
    where = " (in-sample)" if setup["focus"] in setup["model"].train_ids_ else ""
    for tab in ("scene", "states", "inputs & variability", f"predictions · {setup['focus']}{where}", "objective"):
        assert tab in names, (tab, names)


def test_the_scene_carries_a_key_of_the_strategies_colors(setup):
    # the scene's tracks are colored by strategy and no key view stands beside it: the scene draws its own key
    demos, ents = setup["demos"], setup["entities"]
    key = ents["/scene/key"]
    names = list(key["static:Points2D:labels"][0])
    assert names == ["CS1", "CS2"]
    for name, packed in zip(names, np.ravel(key["static:Points2D:colors"][0]), strict=True):
        d = demos.by_label(name)[0]
        (line,) = np.ravel(ents[f"/demos/{d.id}/states/{demos.state_names[0]}"]["static:SeriesLines:colors"][0])
        assert packed == line  # the key's color is the one its tracks and plots are drawn in


def test_measurements_fallback_logs_two_lines(tmp_path, setup, monkeypatch):
    monkeypatch.setattr(session, "HAS_MEASUREMENTS", False)
    demos, model = setup["demos"], setup["model"]
    d = demos[0]
    rec = viewer.new_recording()
    path = tmp_path / "fallback.rrd"
    with viewer.open_output(rec, save=path):
        viewer.SessionLogger(rec, demos).log_variability(d, model)
    ents = read_rrd(path)
    mu, Sigma = model.variability(d.x, x0=d.x[0], target=d.target)
    sigma = np.sqrt(np.diagonal(Sigma, axis1=1, axis2=2))
    _, band = series(ents, f"/demos/{d.id}/variability/u2/gmr_3sigma")
    np.testing.assert_allclose(band[:, 0], mu[:, 1] - 3 * sigma[:, 1], rtol=1e-12)
    np.testing.assert_allclose(band[:, 1], mu[:, 1] + 3 * sigma[:, 1], rtol=1e-12)


def test_replay_streams_online_predictions(tmp_path, setup):
    demos, model = setup["demos"], setup["model"]
    d = demos[0]
    path = tmp_path / "replay.rrd"
    rec = viewer.new_recording()
    horizon = 6
    with viewer.open_output(rec, save=path) as out:
        stats = replay(d, model, rec, state_names=demos.state_names, input_names=demos.input_names, wait=False,
                       n_steps=horizon)
        out.blueprint = replay_blueprint([d.id], demos.state_names, demos.input_names)
    assert rrd_verify(path).returncode == 0
    ents = read_rrd(path)
    assert stats.n_steps == len(d)
    t, x = series(ents, f"/demos/{d.id}/states/x")
    np.testing.assert_array_equal(x[:, 0], d.x[:, 0])
    mean, cov = model.input_distribution_along(d)  # K̂x + μ(x), Σ(x); with the pilot's timing, given the trial before
    for j, u in enumerate(demos.input_names):
        _, v = series(ents, f"/demos/{d.id}/online/{u}/gmr", "Measurements:values")
        _, var = series(ents, f"/demos/{d.id}/online/{u}/gmr", "Measurements:variances")
        np.testing.assert_allclose(v, np.column_stack([mean[:, j], mean[:, j]]), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(var, np.column_stack([cov[:, j, j], 9 * cov[:, j, j]]), rtol=1e-10, atol=1e-14)
        inside = np.abs(d.u[:, j] - mean[:, j]) <= 3 * np.sqrt(cov[:, j, j])
        assert stats.coverage_3sigma[j] == pytest.approx(inside.mean())
    # the forecast of state k + H made at sample k, stamped at k + H
    _, ends = series(ents, f"/demos/{d.id}/online/rollout_end/y")
    steps = np.sort(np.asarray(ents[f"/demos/{d.id}/online/rollout_end/y"]["step"]))
    np.testing.assert_array_equal(steps, np.arange(len(d)) + horizon)
    for k in (0, len(d) // 2, len(d) - 1):
        past = model.pasts(d, [k])
        expected = model.predict(d.x[k], horizon, target=d.target, task_x0=d.x[0],
                                 past=None if past is None else past[0]).x[-1, 1]
        assert ends[k, 0] == pytest.approx(expected, rel=1e-10, abs=1e-12)
    assert np.isfinite(stats.realtime_factor) and stats.realtime_factor > 0


def test_replay_paces_to_wall_time(setup):
    """With an injected clock: at speed 2 the replay sleeps until (t_k − t_0) / 2 after its start."""
    demos, model = setup["demos"], setup["model"]
    d = demos[0]
    now = [100.0]
    sleeps: list[float] = []

    def sleep(s: float) -> None:
        sleeps.append(s)
        now[0] += s

    rec = viewer.new_recording()
    rec.memory_recording()
    replay(d, model, rec, speed=2.0, n_steps=0, clock=lambda: now[0], sleep=sleep)
    # the clock only moves by sleeping, so the sleeps add up to the trial's duration at twice real time
    assert sum(sleeps) == pytest.approx((d.t[-1] - d.t[0]) / 2.0)
    assert len(sleeps) == len(d) - 1


def test_bad_arguments_are_clear_errors(setup):
    demos, model = setup["demos"], setup["model"]
    rec = viewer.new_recording()
    with pytest.raises(WorkbenchError, match="exactly one output"):
        viewer.open_output(rec, save="a.rrd", spawn=True)
    with pytest.raises(DataError, match="start index"):
        viewer.SessionLogger(rec, demos).log_predictions(demos[0], {"proposed": model}, start=10_000)
    with pytest.raises(DataError, match="speed"):
        replay(demos[0], model, rec, speed=0.0)
    with pytest.raises(DataError, match="no demonstration"):
        viewer.log_session(rec, demos, models=model, focus=["nope"])


# -- every recording the CLI writes ------------------------------------------------------------------------------
KINDS = ("demo", "view", "view_model", "replay", "flight")


def _recording(kind: str) -> Path:
    return recordings.cli_recording(kind)


@pytest.mark.parametrize("kind", [*KINDS, "plane_raw", "plane", "live_silent"])
def test_rerun_verifies_every_cli_recording(kind):
    """``rerun rrd verify`` deserializes every column: a null where rerun expects a value (a mode lane's null
    state) fails it, though the viewer opens the file."""
    result = rrd_verify(_recording(kind))
    assert result.returncode == 0, result.stdout + result.stderr


def test_a_flights_mode_lane_holds_no_null_state():
    import adapters

    lane = read_rrd(_recording("plane"))["/flight/mode"]
    ds = adapters.load(recordings.workdir() / "quadplane.tlog", "arduplane_manual")
    order = np.argsort(np.asarray(lane["time"], dtype=float), kind="stable")
    states = [lane["StateChange:state"][k] for k in order]
    states = [s[0] if s else None for s in states]
    # each segment's mode from its start, then the state that says no segment is flown
    assert len(ds) >= 2 and states == [s for d in ds for s in (d.meta["mode"], style.NO_TRIAL_STATE)]
    assert style.NO_TRIAL_STATE in lane["static:StateConfiguration:values"][0]


@pytest.mark.parametrize("kind", KINDS)
def test_no_chunk_of_a_cli_recording_is_empty(kind):
    """Two chunks without rows on one timeline crash the rerun 0.41 viewer; every chunk of every store must have
    rows (recording and blueprint)."""
    reader = RrdReader(_recording(kind))
    n_chunks = 0
    for store in [*reader.recordings(), *reader.blueprints()]:
        for chunk in reader.stream(store=store):
            n_chunks += 1
            assert chunk.num_rows > 0, f"{kind}: empty chunk at {chunk.entity_path}"
    assert n_chunks > 0


def test_the_guard_drops_a_send_without_rows(tmp_path, setup):
    rec = viewer.new_recording()
    path = tmp_path / "guard.rrd"
    empty = np.array([], dtype=np.float64)
    with viewer.open_output(rec, save=path):
        sent = columns.send_columns(rec, "nothing", [rr.TimeColumn("time", duration=empty)],
                                    rr.Scalars.columns(scalars=empty))
        kept = columns.send_columns(rec, "something", [rr.TimeColumn("time", duration=[0.0, 1.0])],
                                    rr.Scalars.columns(scalars=[1.0, 2.0]))
    assert (sent, kept) == (False, True)
    ents = read_rrd(path)
    assert "/nothing" not in ents and len(ents["/something"]["time"]) == 2
    # an input of a trial without a single sample outside 3σ gets its style but no rows (it was an empty chunk)
    ents, model, none_outside = setup["entities"], setup["model"], 0
    for d in setup["demos"].by_label("CS1"):
        mu, Sigma = model.variability(d.x, x0=d.x[0], target=d.target)
        outside = np.abs(model.residuals(d) - mu) > 3 * np.sqrt(np.diagonal(Sigma, axis1=1, axis2=2))
        for j, u in enumerate(setup["demos"].input_names):
            assert len(ents[f"/demos/{d.id}/variability/{u}/outside_3sigma"]["time"]) == outside[:, j].sum()
            none_outside += not outside[:, j].any()
    assert none_outside > 0, "no input without outliers: the case the guard exists for is not exercised"


def test_each_kind_of_recording_has_its_own_application_id():
    expected = {"demo": "workbench_study", "view": "workbench_log", "view_model": "workbench_session",
                "replay": "workbench_replay", "flight": "workbench_log", "plane": "workbench_log",
                "plane_raw": "workbench_log_raw", "live_silent": "workbench_live"}
    found = {}
    for kind, path in recordings.cli_recordings().items():
        reader = RrdReader(path)
        ids = {s.application_id for s in [*reader.recordings(), *reader.blueprints()]}
        assert len(ids) == 1, (kind, ids)
        found[kind] = ids.pop()
    assert found == {k: v for k, v in expected.items() if k in found}
    assert len({found["demo"], found["view"], found["replay"]}) == 3


def test_a_flight_is_drawn_on_its_own_clock_one_color_per_segment():
    from adapters import inspect, load

    path = _recording("flight")
    ds = load(recordings.FLIGHT_LOG, mapping="ardupilot_manual")
    log_start = inspect(recordings.FLIGHT_LOG).t_start  # the clock `workbench inspect` prints its modes on
    ents = read_rrd(path)
    colors = set()
    for d in ds:
        t, x = series(ents, f"/demos/{d.id}/states/{ds.state_names[0]}")
        np.testing.assert_allclose(t, d.meta["t0"] - log_start + d.t - d.t[0], atol=1e-6)
        colors.add(tuple(ents[f"/demos/{d.id}/states/{ds.state_names[0]}"]["static:SeriesLines:colors"][0]))
    assert len(colors) == len(ds)
    # segments follow each other on the log's clock
    starts = sorted(d.meta["t_start"] for d in ds)
    assert starts[0] >= 0 and all(b > a for a, b in zip(starts, starts[1:], strict=False))
    # no landing target declared: the scene is the flown tracks only, no pad
    assert "/scene/pad" not in ents and all(f"/scene/demos/{d.id}/path" in ents for d in ds)
    assert len(ents["/flight/mode"]["time"]) == 2 * len(ds)  # each segment's mode, then its end
    names = blueprint_names(path)
    assert "scene" in names and "states" in names and "objective" not in names
    assert not any(n.startswith("predictions") for n in names)
    # the plots span the log (its segments start minutes in): a time axis with a range is not globally linked,
    # which rerun 0.41 would draw around the cursor at 0 instead, empty
    axes = _time_axes(path)
    ranged = [a for a in axes.values() if a.get("TimeAxis:view_range")]
    assert ranged and not any(a.get("TimeAxis:link") in ([LinkAxis.LinkToGlobal.value], LinkAxis.LinkToGlobal.value)
                              for a in ranged)


def _time_axes(path: Path) -> dict[str, dict]:
    """Per view of the recording's blueprint, its time axis' logged components."""
    reader = RrdReader(path)
    axes: dict[str, dict] = defaultdict(dict)
    for chunk in reader.stream(store=reader.blueprints()[0]):
        if str(chunk.entity_path).endswith("/TimeAxis"):
            row = chunk.to_record_batch().to_pylist()[-1]
            axes[str(chunk.entity_path)].update({k: v for k, v in row.items() if k.startswith("TimeAxis:")})
    return axes


def test_a_plant_without_roles_has_plots_but_no_scene(tmp_path, setup):
    demos = setup["demos"].with_roles(None)
    path = tmp_path / "noroles.rrd"
    _, logged = viewer.record_session(path, demos, models={"CS1": setup["model"]}, focus=[setup["focus"]],
                                      n_steps=HORIZON, samples=0)
    ents = read_rrd(path)
    assert not any(k.startswith("/scene") for k in ents)
    assert not logged.scene and logged.predictions
    d = demos[0]
    t, v = series(ents, f"/demos/{d.id}/states/x")
    np.testing.assert_array_equal(v[:, 0], d.x[:, 0])
    names = blueprint_names(path)
    assert "scene" not in names and any(n.startswith("predictions") for n in names)


def test_heatmaps_of_two_models_share_one_diverging_scale(tmp_path, setup):
    model, ioc = setup["model"], setup["ioc"]
    demos = setup["demos"]
    rec = viewer.new_recording()
    path = tmp_path / "objective.rrd"
    with viewer.open_output(rec, save=path):
        log_models(viewer.SessionLogger(rec, demos), {"CS1": model, "IOC": ioc})
    ents = read_rrd(path)
    vmax = max(np.abs(model.K_).max(), np.abs(ioc.K_).max())
    for name, m in (("CS1", model), ("IOC", ioc)):
        img = ents[f"/models/{name}/heatmap/K/cells"]["static:Image:buffer"][0][0]
        rgb = np.asarray(img, dtype=np.uint8).reshape(*m.K_.shape, 3)
        # blue below zero, red above, white at zero, on the one scale ±vmax of both models
        np.testing.assert_array_equal(rgb, objective.colors(m.K_, vmax))
        i, j = np.unravel_index(np.argmax(m.K_), m.K_.shape)
        assert rgb[i, j, 0] > rgb[i, j, 2]
        i, j = np.unravel_index(np.argmin(m.K_), m.K_.shape)
        assert rgb[i, j, 2] > rgb[i, j, 0]
        labels = ents[f"/models/{name}/heatmap/K/values"]["static:Points2D:labels"][0]
        # every value but the zeros (a white cell reads as 0; their gray label boxes hid the colours)
        assert labels == [t for v in m.K_.ravel() if (t := objective.value_text(v, vmax)) != "0"]
        assert ents[f"/models/{name}/heatmap/K/cols"]["static:Points2D:labels"][0] == list(demos.state_names)
        assert ents[f"/models/{name}/heatmap/K/rows"]["static:Points2D:labels"][0] == list(demos.input_names)
    white = objective.colors(np.zeros((1, 1)), 1.0)[0, 0]
    assert white.min() > 240


# -- the command's outputs -----------------------------------------------------------------------------------------
def _workbench(*argv: str, env: dict[str, str], cwd: Path | None = None, timeout: float = 120):
    return subprocess.run([sys.executable, "-m", "workbench", *argv], capture_output=True, text=True, env=env,
                          cwd=cwd, timeout=timeout)


def _headless_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PATH"] = "/usr/bin:/bin"  # the venv's bin is not on PATH: the viewer must be found beside the python
    env.update(extra)
    return env


def _spawn_port_free() -> None:
    if output._listening(9876):
        pytest.skip("a rerun viewer already listens on 127.0.0.1:9876; --spawn would reuse it")


def test_spawn_without_a_display_is_one_clear_line_not_a_hang(tmp_path):
    _spawn_port_free()
    recordings.cli_recordings()
    demos = recordings.workdir() / "demo" / "demos.parquet"
    result = _workbench("view", str(demos), "--spawn", env=_headless_env(), timeout=60)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "display" in lines[0], result.stderr


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="an unreachable X display is a Linux notion")
def test_spawn_with_a_viewer_that_cannot_open_a_window_fails_fast(tmp_path):
    if not Path(sys.executable).with_name("rerun").exists():
        pytest.skip("no rerun viewer beside this python")
    _spawn_port_free()
    recordings.cli_recordings()
    demos = recordings.workdir() / "demo" / "demos.parquet"
    # a display that does not exist: the viewer starts, listens, then dies opening its window
    result = _workbench("view", str(demos), "--spawn", env=_headless_env(DISPLAY=":977"), timeout=90)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "could not open a window" in lines[0], result.stderr


def test_the_viewer_is_found_beside_python_without_path(monkeypatch):
    monkeypatch.setenv("PATH", "")
    exe = Path(sys.executable).with_name("rerun")
    expected = [str(exe)] if exe.exists() else [sys.executable, "-m", "rerun"]
    assert output.rerun_executable() == expected


def test_default_outputs_go_under_out(tmp_path):
    recordings.cli_recordings()
    work = recordings.workdir()
    demos, model = work / "demo" / "demos.parquet", work / "demo" / "models" / "CS1.npz"
    env = _headless_env()
    view = _workbench("view", str(demos), "-q", env=env, cwd=tmp_path)
    assert view.returncode == 0, view.stderr
    replayed = _workbench("replay", str(demos), "--model", str(model), "--no-wait", "--horizon", "0", "-q",
                          env=env, cwd=tmp_path)
    assert replayed.returncode == 0, replayed.stderr
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*.rrd")) == [
        "out/demos.replay.rrd", "out/demos.rrd"]


def test_flight_modes_get_one_color_each_and_lanes_end_with_their_trial(tmp_path, setup):
    demos = setup["demos"][:3]
    modes = [["STABILIZE", "ALT_HOLD"], ["LOITER"], ["ALT_HOLD"]]
    for d, names in zip(demos, modes, strict=True):
        d.meta["modes"] = {"t": list(np.linspace(0.0, d.t[-1] - d.t[0], len(names), endpoint=False)), "mode": names}
    path = tmp_path / "modes.rrd"
    try:
        viewer.record_session(path, demos, clock="trial")
    finally:
        for d in demos:
            d.meta.pop("modes")
    ents = read_rrd(path)
    lanes = [ents[f"/demos/{d.id}/mode"] for d in demos]
    config = lanes[0]
    values = config["static:StateConfiguration:values"][0]
    colors = config["static:StateConfiguration:colors"][0]
    assert sorted(values) == sorted(["ALT_HOLD", "LOITER", "STABILIZE", style.NO_TRIAL_STATE])
    assert len(set(colors)) == len(values)
    assert all(lane["static:StateConfiguration:colors"][0] == colors for lane in lanes)  # same mode, same color
    for d, lane, names in zip(demos, lanes, modes, strict=True):
        states = [s[0] if s else None for s in lane["StateChange:state"]]
        assert states == [*names, style.NO_TRIAL_STATE]  # a state of its own (not null) closes the lane
        assert max(lane["time"]) == pytest.approx(d.t[-1] - d.t[0])


def test_a_legend_goes_to_the_corner_without_data():
    t = np.linspace(0.0, 3.0, 61)
    falling = 1.0 - t / 3.0  # from the top left to the bottom right: both other corners are free
    assert session.quiet_corner([(t, falling)], (0.0, 3.0), (0.0, 1.0)) in ("RightTop", "LeftBottom")
    rising = t / 3.0
    assert session.quiet_corner([(t, rising)], (0.0, 3.0), (0.0, 1.0)) in ("LeftTop", "RightBottom")
    high = np.full_like(t, 0.95)
    assert session.quiet_corner([(t, high)], (0.0, 3.0), (0.0, 1.0)) == "LeftBottom"


def test_the_scene_key_stays_clear_of_the_scale_bar_in_a_narrow_scene(tmp_path):
    # a vertical descent: the view is shown as wide as it is tall, the bar follows the larger extent, and the key's
    # points must neither sit on the bar nor on each other
    from dataclasses import replace

    demos = simulate_landings("CS1", 2, seed=5) + simulate_landings("CS2", 2, seed=5)
    i_x = demos.state_names.index("x")
    narrow = [replace(d, x=d.x * np.where(np.arange(d.x.shape[1]) == i_x, 0.01, 1.0)) for d in demos]
    demos = demos.with_demos(narrow)
    path = tmp_path / "narrow.rrd"
    viewer.record_session(path, demos)
    ents = read_rrd(path)
    key = np.asarray(ents["/scene/key"]["static:Points2D:positions"][0], dtype=float).reshape(-1, 2)
    bar = np.asarray(ents["/scene/scale"]["static:LineStrips2D:strips"][0][0], dtype=float).reshape(-1, 2)
    length = bar[1, 0] - bar[0, 0]
    height = abs(bar[0, 1] - key[0, 1])
    assert height > 0.05 * length  # above the bar, not on it
    assert np.min(np.diff(key[:, 0])) > 0.2 * length  # apart from each other, on the bar's scale


def test_a_writer_that_stops_while_saving_is_a_named_error_and_leaves_no_file(tmp_path, monkeypatch):
    rec = viewer.new_recording()
    path = tmp_path / "full.rrd"

    def failing_flush(self, *args, **kwargs):  # what rerun raises when its writer thread cannot write (disk full)
        raise RuntimeError("File-writer thread shut down prematurely")

    monkeypatch.setattr(rr.RecordingStream, "flush", failing_flush)
    with pytest.raises(WorkbenchError, match=r"full\.rrd: the recording could not be written"):  # previous main:
        with viewer.open_output(rec, save=path):                                             # the RuntimeError
            rec.log("x", rr.Scalars(1.0))
    assert not path.exists() and not [p for p in tmp_path.iterdir()]
