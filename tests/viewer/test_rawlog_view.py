"""The raw log in rerun (``workbench view LOG --raw``) and ``rerun-loader-workbench`` through rerun's
external data-loader protocol: path in, an rrd stream on stdout, exit code 66 for files it does not handle."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import rerun.blueprint as rrb
from rerun.chunk import RrdReader

import adapters
from adapters.rawlog import raw_log

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_logs" / "landing_s00.tlog"
FLIGHT = REPO.parent / "shared" / "external" / "dronekit_flight.tlog"


def _loader(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench.cli.loader", *args], capture_output=True, cwd=REPO,
                          timeout=120)


def _entities(data: bytes, tmp_path: Path) -> set[str]:
    path = tmp_path / "out.rrd"
    path.write_bytes(data)
    return {str(c.entity_path) for c in RrdReader(path).stream()}


def test_the_loader_is_a_console_script_named_for_rerun():
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    # rerun 0.41 looks for rerun-importer-*, and warns that rerun-loader-* is deprecated (still run)
    assert scripts["rerun-importer-workbench"] == "workbench.cli.loader:run"
    assert scripts["rerun-loader-workbench"] == "workbench.cli.loader:run"


def test_loader_streams_a_tlog_under_the_given_prefix(tmp_path):
    r = _loader(str(SAMPLE), "--application-id", "app", "--recording-id", "rec-1", "--entity-path-prefix", "pre",
                "--time_sequence", "frame=3")
    assert r.returncode == 0, r.stderr.decode()
    paths = _entities(r.stdout, tmp_path)
    raw = raw_log(adapters.read(SAMPLE))
    expected = {f"/pre/log/streams/{s.name}" for s in raw.streams}
    assert expected <= paths
    assert "/pre/log/messages" in paths and "/pre/log/mode" in paths
    assert not [p for p in paths if p.startswith("/log")]  # everything under the prefix


@pytest.mark.parametrize("name, text", [("notes.txt", "just some words\n"), ("table.csv", "a,b\n1,2\n")])
def test_loader_declines_files_it_does_not_handle(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    r = _loader(str(path), "--recording-id", "x")
    assert r.returncode == 66 and r.stdout == b""
    r = _loader(str(tmp_path / "missing.tlog"))
    assert r.returncode == 66


@pytest.mark.slow
def test_loader_static_logs_only_the_timeless_part(tmp_path):
    r = _loader(str(FLIGHT), "--static")
    assert r.returncode == 0, r.stderr.decode()
    paths = _entities(r.stdout, tmp_path)
    assert "/log/parameters" in paths and not [p for p in paths if p.startswith("/log/streams")]


@pytest.mark.slow
def test_view_raw_is_the_raw_view(tmp_path):
    out = tmp_path / "raw.rrd"
    r = subprocess.run([sys.executable, "-m", "workbench", "view", str(FLIGHT), "--raw", "--save", str(out)],
                       capture_output=True, text=True, cwd=REPO, timeout=300)
    assert r.returncode == 0, r.stderr
    paths = {str(c.entity_path) for c in RrdReader(out).stream()}
    raw = raw_log(adapters.read(FLIGHT))
    assert {f"/log/streams/{s.name}" for s in raw.streams} <= paths
    assert {"/log/mode", "/log/armed", "/log/messages", "/log/gps/vehicle", "/log/parameters"} <= paths
    assert not [p for p in paths if p.startswith("/demos")]  # the log alone, no mapping's states
    verify = subprocess.run([str(Path(sys.executable).with_name("rerun")), "rrd", "verify", str(out)],
                            capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr


def _quadplane_raw(tmp_path: Path):
    """The raw log of a QuadPlane tlog written with the project's writer (two landings, a still roll stick)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("_rec", Path(__file__).with_name("viewer_recordings.py"))
    recordings = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(recordings)
    return raw_log(adapters.read(recordings.quadplane_tlog(tmp_path / "qp.tlog")))


def _recorded(raw, out: Path) -> Path:
    """``raw`` logged by the viewer into the recording ``out``."""
    import rerun as rr

    from workbench.viewer.rawlog import log_raw

    rec = rr.RecordingStream("raw_test")
    rec.save(out)
    log_raw(rec, raw)
    rec.flush()
    rec.disconnect()
    return out


def test_a_stream_silent_between_two_flights_is_drawn_with_a_break(tmp_path):
    import numpy as np
    import pyarrow as pa

    from workbench.viewer.rawlog import GAP_S

    raw = _quadplane_raw(tmp_path)
    att = next(s for s in raw.streams if s.name == "ATTITUDE")
    steps = np.diff(att.t)
    gaps = int(np.sum(steps > max(GAP_S, 20 * np.median(steps))))
    assert gaps >= 1  # the pause between the two landings
    rows = []
    for chunk in RrdReader(_recorded(raw, tmp_path / "raw.rrd")).stream():
        if str(chunk.entity_path) == "/log/streams/ATTITUDE" and not chunk.is_static:
            col = chunk.to_record_batch().column("Scalars:scalars")
            rows += [np.asarray(v, dtype=float) for v in pa.array(col).to_pylist()]
    broken = sum(bool(np.isnan(r).all()) for r in rows)
    assert broken == gaps and len(rows) == len(att.t) + gaps


def test_fields_zero_throughout_are_hidden_by_default(tmp_path):
    import numpy as np

    raw = _quadplane_raw(tmp_path)
    rc = next(s for s in raw.streams if s.name == "RC_CHANNELS")
    zero = [f for k, f in enumerate(rc.fields) if not np.any(rc.values[:, k] != 0)]
    moving = [f for k, f in enumerate(rc.fields) if np.ptp(rc.values[:, k]) > 0 and "time" not in f]
    assert zero and moving  # unused channels, and the throttle the writer moved
    for chunk in RrdReader(_recorded(raw, tmp_path / "raw.rrd")).stream():
        if str(chunk.entity_path) == "/log/streams/RC_CHANNELS" and chunk.is_static:
            shown = chunk.to_record_batch().column("SeriesLines:visible_series").to_pylist()[0]
    by_field = dict(zip(rc.fields, shown, strict=True))
    assert not any(by_field[f] for f in zero) and all(by_field[f] for f in moving)


def test_the_lanes_span_where_the_data_is_not_a_stray_message():
    from workbench.viewer.rawlog import LoggedRaw, bulk_span, raw_views

    # a 7 s flight logged at 250 Hz, one message at 0 s and one at 1174 s (as the PX4 sample log has)
    s = LoggedRaw("log", "x.ulg", streams=["attitude", "test_motor", "mission"], armed=True,
                  rows={"attitude": 1750, "test_motor": 1, "mission": 1},
                  spans={"attitude": (20.3, 27.3), "test_motor": (0.0, 0.0), "mission": (1174.0, 1174.0)},
                  span=(0.0, 1174.0))
    assert bulk_span(s) == (20.3, 27.3)
    # a log whose streams all carry data spans them all
    even = LoggedRaw("log", "x.tlog", streams=["a", "b"], rows={"a": 100, "b": 50},
                     spans={"a": (0.0, 10.0), "b": (5.0, 30.0)}, span=(0.0, 30.0))
    assert bulk_span(even) == (0.0, 30.0)
    (tab,) = [t for t in raw_views(s) if getattr(t, "name", "") == "raw streams"]
    lanes = [v for v in _views(tab) if isinstance(v, rrb.StateTimelineView)]
    (r,) = lanes[0].properties["TimeAxis"].view_range.as_arrow_array().to_pylist()
    assert 19e9 < r["start"] < 20.3e9 and 27.3e9 < r["end"] < 29e9  # nanoseconds


def _views(container):
    for c in getattr(container, "contents", None) or []:
        yield c
        yield from _views(c)


def _series(path: Path, entity: str):
    import numpy as np
    import pyarrow as pa

    t, v = [], []
    for chunk in RrdReader(path).stream():
        if str(chunk.entity_path) == entity and not chunk.is_static:
            batch = chunk.to_record_batch()
            t += list(batch.column("time").cast(pa.int64()).to_numpy() / 1e9)
            v += [np.asarray(x, dtype=float)[0] for x in batch.column("Scalars:scalars").to_pylist()]
    return np.asarray(t), np.asarray(v)


def test_a_raw_log_opens_on_the_pilots_screen_attitude_in_degrees_and_named_sticks(tmp_path):
    """The first tab: one plot per angle in degrees with its setpoint, the sticks named from RCMAP_*; the map is
    zoomed to the track's extent."""
    import numpy as np

    from workbench.viewer.rawlog import map_zoom, pilot_views

    raw = _quadplane_raw(tmp_path)
    att = next(s for s in raw.streams if s.name == "ATTITUDE")
    out = _recorded(raw, tmp_path / "raw.rrd")
    t, roll = _series(out, "/log/pilot/roll/actual")
    finite = np.isfinite(roll)
    np.testing.assert_allclose(roll[finite], np.degrees(att.values[:, att.fields.index("roll")]), rtol=1e-12)
    params = dict(raw.parameters)
    rc = next(s for s in raw.streams if s.name == "RC_CHANNELS")
    channel = int(params.get("RCMAP_THROTTLE", 3))
    _, throttle = _series(out, "/log/pilot/sticks/throttle")
    thr = throttle[np.isfinite(throttle)]
    np.testing.assert_array_equal(thr, rc.values[:, rc.fields.index(f"chan{channel}_raw")])
    import rerun as rr

    from workbench.viewer.rawlog import LoggedRaw, log_raw, raw_views

    logged = log_raw(rr.RecordingStream("raw_test2"), raw)
    assert isinstance(logged, LoggedRaw) and logged.pilot["angles"] == ["roll", "pitch", "yaw"]
    tabs = raw_views(logged)
    assert tabs[0].name == pilot_views(logged.pilot, logged, logged.zoom)[0].name == "pilot"
    names = [getattr(v, "name", "") for v in _views(tabs[0])]
    assert any(str(n).startswith("roll [°]") for n in names) and any("sticks" in str(n) for n in names)
    if raw.track is not None:
        span = max(np.ptp(raw.track.lon), np.ptp(raw.track.lat))
        assert logged.zoom == map_zoom(raw) and 2 ** logged.zoom * 256 * span / 360 < 2000


def test_the_raw_tab_opens_on_the_attitude_never_on_the_parameters():
    """A tlog's busiest stream can be PARAM_VALUE (values to 4e7): the raw tab opens on ATTITUDE instead, and
    without an attitude stream on the busiest stream that is not a parameter or format table."""
    from workbench.viewer.rawlog import LoggedRaw, first_stream

    s = LoggedRaw("log", "x.tlog", streams=["ATTITUDE", "PARAM_VALUE", "VFR_HUD"],
                  rows={"ATTITUDE": 10, "PARAM_VALUE": 500, "VFR_HUD": 20})
    assert s.streams[first_stream(s)] == "ATTITUDE"
    s = LoggedRaw("log", "x.bin", streams=["FMT", "IMU", "PARM", "RCIN"],
                  rows={"FMT": 900, "IMU": 300, "PARM": 800, "RCIN": 40})
    assert s.streams[first_stream(s)] == "IMU"


def test_the_segment_lane_draws_the_ground_time_the_import_cuts(tmp_path):
    """Armed time in a kept mode that the mapping's landed rule puts on the ground is cut by the import: the lane
    draws it as a state of its own, not as "kept" (where the import's cut was invisible) nor as a mode."""
    import numpy as np
    import pandas as pd
    import rerun as rr
    from pymavlink import mavutil

    from adapters import sticks
    from adapters.explain import GROUND, explain
    from adapters.mapping import load_mapping
    from adapters.modes import mode_number
    from adapters.writer import demo_streams, layout
    from workbench import palette
    from workbench.sim.landing import simulate_landings
    from workbench.viewer.rawlog import log_raw

    from ..rrd import read_rrd

    epoch, pause = 1e9, 2.0
    flights = simulate_landings("CS1", 2, seed=3)
    m = sticks._substitute(load_mapping("ardupilot_manual").for_format("tlog"), {"roll": 1, "throttle": 3}, ())
    streams = demo_streams(flights, m, epoch=epoch, pause=pause)
    for frame in streams.values():
        frame["time_boot_ms"] = np.rint((frame["t"].to_numpy() - epoch) * 1000.0).astype(np.int64)
    spans = layout(flights, epoch, pause)
    hb = np.arange(spans[0][0] - 1.0, spans[-1][1] + 1.0, 0.5)
    took_off = spans[0][0] + 3.0  # ArduCopter's HEARTBEAT: STANDBY (3) while landed, ACTIVE (4) in the air
    ml = mavutil.mavlink
    streams["HEARTBEAT"] = pd.DataFrame({"t": hb, "type": ml.MAV_TYPE_QUADROTOR,
                                         "autopilot": ml.MAV_AUTOPILOT_ARDUPILOTMEGA, "base_mode": 129,
                                         "custom_mode": mode_number("arducopter", "STABILIZE"),
                                         "system_status": np.where(hb < took_off, 3, 4), "mavlink_version": 3})
    path = adapters.FORMATS["tlog"].write(tmp_path / "ground.tlog", streams)
    read = adapters.read(path)
    raw = raw_log(read)
    out = tmp_path / "ground.rrd"
    rec = rr.RecordingStream("ground_test")
    rec.save(out)
    logged = log_raw(rec, raw, segments=explain(read, load_mapping("ardupilot_manual").for_format("tlog")))
    rec.flush()
    rec.disconnect()
    assert logged.segments
    lane = read_rrd(out)["/log/segments"]
    order = np.argsort(np.asarray(lane["time"], dtype=float), kind="stable")
    t = np.asarray(lane["time"], dtype=float)[order] + raw.t_start  # back on the log clock
    states = [lane["StateChange:state"][k][0] for k in order]
    # on the ground from the first mapped sample until the first ACTIVE heartbeat, then kept
    first_active = float(hb[hb >= took_off][0])
    ground = [k for k, s in enumerate(states) if s == GROUND]
    assert len(ground) == 1 and t[ground[0]] < took_off - 1.0
    assert states[ground[0] + 1] == "kept" and t[ground[0] + 1] == pytest.approx(first_active, abs=m.dt)
    assert sum(s == "kept" for s in states) == len(adapters.load(path, "ardupilot_manual"))
    config = lane["static:StateConfiguration:values"][0]
    colors = dict(zip(config, lane["static:StateConfiguration:colors"][0], strict=True))
    assert GROUND in config and colors[GROUND] not in {v for k, v in colors.items() if k != GROUND}
    assert palette.LANE_STATES[GROUND] not in palette.MODE_COLORS
    why = [str(x[0] if isinstance(x, list) else x) for x in read_rrd(out)["/log/segments/why"]["TextLog:text"]]
    assert any(f"dropped {first_active - t[ground[0]]:.1f} s: STABILIZE on the ground (by its landed events: "
               "HEARTBEAT.system_status = 3 MAV_STATE_STANDBY on landing, 4 MAV_STATE_ACTIVE on take-off)" in w
               for w in why), why
