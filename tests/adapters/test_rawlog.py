"""Issue 20 (points 2–5): the raw log, firmware generations of field names, drafted mappings, errors that name
the cause. Logs are written by the project's own writers (ULog, tlog) from simulated flights."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from pymavlink import mavutil

import adapters
from adapters.draft import draft_mapping
from adapters.explain import explain
from adapters.formats import ulog
from adapters.mapping import load_mapping
from adapters.modes import mode_number
from adapters.rawlog import raw_log
from adapters.writer import demo_streams, layout
from workbench.errors import DataError
from workbench.sim.landing import simulate_landings

PAUSE = 2.0


@pytest.fixture(scope="module")
def flights():
    return simulate_landings("CS1", 2, seed=3)


def _generation(k: int):
    """px4_manual with the k-th alternative of every channel that has one (0: v1.10–v1.13, 1: older or newer)."""
    m = load_mapping("px4_manual").for_format("ulog")
    chans = []
    for ch in m.channels:
        v = ch.variants[min(k, len(ch.variants) - 1)]
        # a string list gives one channel whose selector has alternative sources: take the k-th source
        sources = v.selector.sources
        chans.append(replace(v, selector=replace(v.selector, source=sources[min(k, len(sources) - 1)],
                                                 alternatives=())))
    return replace(m, channels=tuple(chans))


def _px4_log(path, flights, generation: int, *, armed: bool = True, version: str = "v1.12.3"):
    streams = demo_streams(flights, _generation(generation), epoch=0.0, pause=PAUSE)
    spans = layout(flights, 0.0, PAUSE)
    t = np.arange(0.0, spans[-1][1] + 1.0, 0.5)
    in_flight = np.zeros(t.size, dtype=bool)
    for a, b in spans:
        in_flight |= (t >= a) & (t <= b)
    streams["vehicle_status"] = pd.DataFrame({
        "t": t, "nav_state": np.where(in_flight, 15, 5).astype(np.uint8),  # STAB in flight, AUTO_RTL between
        "arming_state": np.full(t.size, 2 if armed else 1, dtype=np.uint8)})
    ulog.write(path, streams, info={"sys_name": "PX4", "ver_sw_branch": version})
    return path


@pytest.mark.parametrize("generation", [0, 1])
def test_px4_manual_reads_old_and_new_field_names(flights, tmp_path, generation):
    path = _px4_log(tmp_path / "px4.ulg", flights, generation)
    names = set(adapters.read(path).frames)
    streams = adapters.read(path)
    written = _generation(generation)
    u2 = written.channel("u2")
    frame = streams[u2.selector.source.split(".")[0]]
    assert u2.selector.source.split(".")[1] in frame.columns  # the log has this generation's field, not the other
    ds = adapters.load(path, "px4_manual")
    assert len(ds) == len(flights) and "vehicle_status" in names
    step = int(round(ds.dt / flights.dt))
    for d, original, (a, _) in zip(ds, flights, layout(flights, 0.0, PAUSE), strict=True):
        k = int(round((d.meta["t0"] - a) / flights.dt))  # where the mode span starts inside the written trial
        np.testing.assert_allclose(d.u[:5], original.u[k : k + 5 * step : step], atol=1e-9)


@pytest.mark.parametrize("generation", [0, 1])
def test_map_drafts_a_mapping_that_imports_each_generation(flights, tmp_path, generation):
    path = _px4_log(tmp_path / "px4.ulg", flights, generation, version=["v1.12.3", "v1.8.2"][generation])
    draft = draft_mapping(adapters.read(path), name="mine")
    assert draft.template == "px4_manual" and draft.vehicle.startswith("PX4")
    chosen = dict(draft.chosen)
    assert chosen["u1"] == _generation(generation).channel("u1").selector.source
    toml = tmp_path / "mine.toml"
    toml.write_text(draft.toml)
    ds = adapters.load(path, toml)
    reference = adapters.load(path, "px4_manual")
    assert len(ds) == len(reference)
    # the draft's grid follows the slowest chosen stream; compare on the common start
    np.testing.assert_allclose(ds[0].u[0], reference[0].u[0], atol=1e-9)


def test_never_armed_is_named_by_load_and_inspect(flights, tmp_path):
    path = _px4_log(tmp_path / "px4.ulg", flights, 1, armed=False)
    with pytest.raises(DataError, match="never armed"):
        adapters.load(path, "px4_manual")
    summary = adapters.inspect(path)
    assert summary.armed == () and summary.armed_text == "armed: never armed"
    assert "never armed" in str(summary)


def _quadplane_tlog(path, flights):
    m = load_mapping("arduplane_manual").for_format("tlog")
    streams = demo_streams(flights, m, epoch=1e9, pause=PAUSE)
    spans = layout(flights, 1e9, PAUSE)
    ml = mavutil.mavlink
    modes = [mode_number("arduplane", "QLOITER"), mode_number("arduplane", "CIRCLE")]
    t = np.arange(spans[0][0], spans[-1][1], 1.0)
    custom = np.where(np.arange(t.size) % 2 == 0, modes[0], modes[1])
    for frame in streams.values():
        frame["time_boot_ms"] = np.rint((frame["t"].to_numpy() - 1e9) * 1000.0).astype(np.int64)
    streams["HEARTBEAT"] = pd.DataFrame({"t": t, "type": ml.MAV_TYPE_VTOL_QUADROTOR,
                                         "autopilot": ml.MAV_AUTOPILOT_ARDUPILOTMEGA, "base_mode": 129,
                                         "custom_mode": custom, "system_status": 4, "mavlink_version": 3})
    return adapters.FORMATS["tlog"].write(path, streams)


def test_a_quadplane_with_the_copter_mapping_names_its_modes_and_the_plane_mapping(flights, tmp_path):
    path = _quadplane_tlog(tmp_path / "qp.tlog", flights)
    with pytest.raises(DataError) as err:
        adapters.load(path, "ardupilot_manual")
    text = str(err.value)  # refused before its modes are read with the copter's table
    assert "made for arducopter flight modes" in text and "MAV_TYPE_VTOL_QUADROTOR (arduplane modes)" in text
    assert "--mapping arduplane_manual" in text


def test_no_stick_input_in_the_spans_is_named(flights, tmp_path):
    m = load_mapping("px4_manual").for_format("ulog")
    streams = demo_streams(flights, _generation(0), epoch=0.0, pause=PAUSE)
    spans = layout(flights, 0.0, PAUSE)
    sticks = streams["manual_control_setpoint"]
    # the sticks only in the first half second, the manual mode only from the first second on
    streams["manual_control_setpoint"] = sticks[sticks["t"] < spans[0][0] + 0.5].copy()
    t = np.arange(spans[0][0] + 1.0, spans[-1][1] + 1.0, 0.5)
    streams["vehicle_status"] = pd.DataFrame({"t": t, "nav_state": np.full(t.size, 15, np.uint8),
                                              "arming_state": np.full(t.size, 2, np.uint8)})
    path = ulog.write(tmp_path / "nosticks.ulg", streams)
    with pytest.raises(DataError, match="no stick input in these spans: u1, u2"):
        adapters.load(path, m)


def test_raw_log_holds_every_numeric_field_and_the_texts_params_and_track(external):
    streams = adapters.read(str(external("dronekit_flight.tlog")))
    raw = raw_log(streams)
    by_name = {s.name: s for s in raw.streams}
    for name, frame in streams.frames.items():
        numeric = [c for c in frame.columns if c not in ("t", "sysid", "compid") and frame[c].dtype.kind in "biuf"]
        if numeric:
            s = by_name[name]
            assert list(s.fields) == numeric
            order = np.argsort(frame["t"].to_numpy(), kind="stable")
            np.testing.assert_array_equal(s.values, frame[numeric].to_numpy(np.float64)[order])
    att = by_name["ATTITUDE"]
    assert dict(zip(att.fields, att.units, strict=True))["rollspeed"] == "rad/s"  # MAVLink's own units
    assert len(raw.text) == len(streams["STATUSTEXT"])
    assert dict(raw.parameters).keys() == set(streams["PARAM_VALUE"]["param_id"])
    gpi = streams["GLOBAL_POSITION_INT"]
    fix = gpi["lat"].to_numpy() != 0
    assert raw.track.source == "GLOBAL_POSITION_INT"
    np.testing.assert_allclose(raw.track.lat, gpi["lat"].to_numpy()[fix] * 1e-7)
    assert raw.armed and raw.modes and raw.epoch_clock


def test_ulog_parameters_and_logged_messages_equal_pyulogs(external):
    from pyulog import ULog

    path = str(external("px4_sample_log_small.ulg"))
    ref = ULog(path)
    raw = raw_log(adapters.read(path))
    assert dict(raw.parameters) == ref.initial_parameters
    assert list(raw.text.texts) == [m.message for m in ref.logged_messages]
    assert raw.track is not None and not raw.epoch_clock


def test_explain_keeps_exactly_what_the_import_keeps(external):
    path = str(external("dronekit_flight.tlog"))
    m = load_mapping("ardupilot_manual").for_format("tlog")
    pieces = explain(adapters.read(path), m)
    kept = [p for p in pieces if p[2] == "kept"]
    ds = adapters.load(path, m)
    assert [p[0] for p in kept] == pytest.approx([d.meta["t0"] for d in ds], abs=1e-9)
    assert {p[2] for p in pieces} >= {"kept", "disarmed", "too short"}
    assert all(b >= a for a, b, _, _ in pieces)
    short = [p for p in pieces if p[2] == "too short"]
    assert all(b - a < m.segment.min_duration for a, b, _, _ in short)


@pytest.mark.parametrize("log", ["dronekit_flight.tlog", "px4_sample_log_small.ulg", "erle_copter_83.BIN"])
def test_map_on_the_real_logs_imports_without_edits(tmp_path, log, external):
    draft = draft_mapping(adapters.read(str(external(log))), name="drafted")
    path = tmp_path / "drafted.toml"
    path.write_text(draft.toml)
    ds = adapters.load(str(external(log)), path, allow_still=True)  # the PX4 log has no GPS position
    assert len(ds) == len(adapters.load(str(external(log)), draft.template, allow_still=True))


@pytest.mark.parametrize("style", ["old", "new"])
@pytest.mark.parametrize("vehicle", ["copter", "plane"])
def test_map_drafts_a_mapping_for_each_dataflash_generation(tmp_path, style, vehicle):
    """ArduPilot's onboard logs of two firmware generations (EKF1 / TimeMS; XKF1[0] or NKF1[0] / TimeUS, FMTU)."""
    from adapters.formats.dataflash_write import write_example

    log = write_example(tmp_path / f"{style}_{vehicle}.bin", style, vehicle, seconds=60.0, seed=5)
    draft = draft_mapping(adapters.read(log), name="drafted")
    assert draft.template == ("ardupilot_manual" if vehicle == "copter" else "arduplane_manual")
    path = tmp_path / "drafted.toml"
    path.write_text(draft.toml)
    ds = adapters.load(log, path)
    assert len(ds) >= 1 and set(ds.state_names) == set(adapters.load(log, draft.template).state_names)


@pytest.mark.parametrize("style", ["old", "new"])
def test_dataflash_events_and_errors_are_named(tmp_path, style):
    """EV ids and ERR subsystem/code pairs read as ArduPilot names them (the raw view said "EV: event 10")."""
    from adapters.events import ERROR_SUBSYSTEMS, EVENTS
    from adapters.formats.dataflash_write import write_example

    streams = adapters.read(write_example(tmp_path / f"{style}.bin", style, "copter", seconds=20.0, seed=1))
    text = raw_log(streams).text
    ev = [x for x, src in zip(text.texts, text.sources, strict=True) if src == "EV"]
    assert ev == [EVENTS[int(i)] for i in streams.frames["EV"]["Id"]]
    assert "ARMED" in ev and "DISARMED" in ev
    err = [(x, lv) for x, lv, src in zip(text.texts, text.levels, text.sources, strict=True) if src == "ERR"]
    codes = list(zip(streams.frames["ERR"]["Subsys"], streams.frames["ERR"]["ECode"], strict=True))
    assert len(err) == len(codes)
    for (x, level), (sub, code) in zip(err, codes, strict=True):
        assert x.startswith(ERROR_SUBSYSTEMS[int(sub)] + ": ") and "code" not in x
        assert level == ("INFO" if code == 0 else "ERROR")  # a cleared error is not an error


def test_unknown_event_and_error_numbers_stay_numbers():
    from adapters.events import error_text, event_name

    assert event_name(250) == "event 250"
    assert error_text(200, 3) == "subsystem 200, code 3"
    assert error_text(16, 77) == "EKFCHECK: code 77"
    assert error_text(16, 2) == "EKFCHECK: BAD_VARIANCE" and error_text(15, 2) == "PARACHUTES: TOO_LOW"
    assert error_text(6, 1) == "FAILSAFE_BATT: FAILSAFE_OCCURRED"
    assert error_text(10, 6, "arducopter").endswith("RTL")  # a flight-mode error's code is the mode refused


def _ulog_data(data: bytes, topic: str) -> list[int]:
    """Offsets of the timestamps of a topic's data messages in a ULog file (header 16 bytes, then messages of
    ``uint16 size, uint8 type, payload``; ``A`` subscribes a message id to a topic, ``D`` carries its data)."""
    import struct

    ids, out, off = set(), [], 16
    while off + 3 <= len(data):
        size, kind = struct.unpack_from("<HB", data, off)
        body = data[off + 3 : off + 3 + size]
        if kind == ord("A") and body[3:].decode() == topic:
            ids.add(struct.unpack_from("<H", body, 1)[0])
        elif kind == ord("D") and struct.unpack_from("<H", body, 0)[0] in ids:
            out.append(off + 5)
        off += 3 + size
    return out


def test_a_bad_stamp_on_vehicle_status_splits_no_flight(flights, tmp_path):
    """One vehicle_status from a pause (AUTO_RTL) stamped into the middle of a flight: the previous main sorted
    it there and cut the flight in two; the mode stream now gets the channels' time-line repair."""
    import struct

    clean = _px4_log(tmp_path / "px4.ulg", flights, 0)
    data = bytearray(clean.read_bytes())
    status = adapters.read(clean, ["vehicle_status"])["vehicle_status"]
    offsets = _ulog_data(bytes(data), "vehicle_status")
    assert len(offsets) == len(status)
    want = adapters.load(clean, "px4_manual")
    k = int(np.flatnonzero(status["nav_state"].to_numpy() == 5)[0])  # the first AUTO_RTL record, before flight 0
    middle = want[1].meta["t0"] + 0.5 * float(want[1].t[-1])
    (stamp,) = struct.unpack_from("<Q", data, offsets[k])
    struct.pack_into("<Q", data, offsets[k], int(round(middle * 1e6)))
    assert stamp != int(round(middle * 1e6))
    bad = tmp_path / "bad" / clean.name
    bad.parent.mkdir()
    bad.write_bytes(bytes(data))
    got = adapters.load(bad, "px4_manual")
    assert [(d.meta["id"], len(d.t)) for d in got] == [(d.meta["id"], len(d.t)) for d in want]
