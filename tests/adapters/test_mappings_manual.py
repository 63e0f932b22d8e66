"""Manual-flight mappings and ``inspect`` on real and written logs: mode names per vehicle type, mean rates, tilt."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from pymavlink import mavutil

import adapters
from adapters.mapping import load_mapping
from adapters.modes import MODE_TABLES, heartbeat_table, mode_number
from adapters.streams import Streams
from adapters.summary import summarize
from adapters.transforms import TRANSFORMS
from adapters.writer import demo_streams, layout
from workbench.errors import DataError
from workbench.sim.landing import simulate_landings

EPOCH, PAUSE = 1_704_067_200.0, 2.0


@pytest.fixture(scope="module")
def flights():
    return simulate_landings("CS1", 2, seed=3)


def _heartbeats(spans, modes, *, autopilot: int, mav_type: int) -> pd.DataFrame:
    """The vehicle's HEARTBEATs at 1 Hz in ``modes`` per span (RTL between), and a ground station's at 1 Hz."""
    rtl = mode_number(heartbeat_table(autopilot, mav_type), "RTL") or 0
    rows = []
    for (a, b), mode in zip(spans, modes, strict=True):
        rows += [(t, mav_type, autopilot, 129, mode) for t in np.arange(a, b, 1.0)]
        rows.append((b + PAUSE / 2, mav_type, autopilot, 1, rtl))
    rows += [(t + 0.3, 6, 8, 0, 0) for t in np.arange(spans[0][0], spans[-1][1], 1.0)]  # MAV_TYPE_GCS, INVALID
    t, kind, ap, base, custom = (np.array(c) for c in zip(*sorted(rows), strict=True))
    return pd.DataFrame({"t": t, "type": kind, "autopilot": ap, "base_mode": base, "custom_mode": custom,
                         "system_status": 4, "mavlink_version": 3})


def _write_tlog(path, ds, mapping: str, heartbeats: pd.DataFrame):
    streams = demo_streams(ds, load_mapping(mapping).for_format("tlog"), epoch=EPOCH, pause=PAUSE)
    for frame in streams.values():  # an autopilot booted at the epoch stamps its messages
        frame["time_boot_ms"] = np.rint((frame["t"].to_numpy() - EPOCH) * 1000.0).astype(np.int64)
    streams["HEARTBEAT"] = heartbeats
    return adapters.FORMATS["tlog"].write(path, streams)


def _assert_mean_rates(path, summary):
    frames = adapters.read_streams(path)
    for s in summary.streams:
        t = frames[s.name]["t"].to_numpy()
        if len(t) > 1:
            span = t.max() - t.min()
            assert s.rate_hz == pytest.approx((len(t) - 1) / span, rel=1e-9), s.name
        if len(t) > 10:  # (count − 1) and count differ by more than 10 % only for a handful of messages
            assert s.rate_hz == pytest.approx(len(t) / span, rel=0.10), s.name


# ------------------------------------------------------------------------------------------- mode tables


def test_mode_tables_are_pymavlinks():
    assert MODE_TABLES["arducopter"] == mavutil.mode_mapping_acm
    assert MODE_TABLES["arduplane"] == mavutil.mode_mapping_apm
    assert MODE_TABLES["ardurover"] == mavutil.mode_mapping_rover
    assert MODE_TABLES["ardusub"] == mavutil.mode_mapping_sub
    for number, name in MODE_TABLES["px4"].items():
        assert mavutil.interpret_px4_mode(0, number) == name
    ml = mavutil.mavlink
    assert heartbeat_table(ml.MAV_AUTOPILOT_ARDUPILOTMEGA, ml.MAV_TYPE_QUADROTOR) == "arducopter"
    assert heartbeat_table(ml.MAV_AUTOPILOT_ARDUPILOTMEGA, ml.MAV_TYPE_FIXED_WING) == "arduplane"
    for vtol in (ml.MAV_TYPE_VTOL_QUADROTOR, ml.MAV_TYPE_VTOL_TILTROTOR, ml.MAV_TYPE_VTOL_RESERVED4):
        assert heartbeat_table(ml.MAV_AUTOPILOT_ARDUPILOTMEGA, vtol) == "arduplane"
    assert heartbeat_table(ml.MAV_AUTOPILOT_ARDUPILOTMEGA, ml.MAV_TYPE_GROUND_ROVER) == "ardurover"
    assert heartbeat_table(ml.MAV_AUTOPILOT_ARDUPILOTMEGA, ml.MAV_TYPE_SUBMARINE) == "ardusub"
    assert heartbeat_table(ml.MAV_AUTOPILOT_PX4, ml.MAV_TYPE_QUADROTOR) == "px4"
    assert heartbeat_table(ml.MAV_AUTOPILOT_INVALID, ml.MAV_TYPE_GCS) is None


def test_shipped_manual_mappings_keep_the_pilot_flown_modes():
    def kept(name, fmt):
        rule = load_mapping(name).for_format(fmt).segment.mode
        return {MODE_TABLES[rule.names][k] for k in rule.keep}

    assert kept("ardupilot_manual", "tlog") == {"STABILIZE", "ALT_HOLD", "LOITER", "POSHOLD", "ACRO"}
    assert kept("arduplane_manual", "tlog") == {"MANUAL", "FBWA", "QSTABILIZE", "QHOVER", "QLOITER"}
    assert {"MANUAL", "POSCTL", "ALTCTL"} <= kept("px4_manual", "ulog")
    assert {"MANUAL", "POSCTL", "ALTCTL"} <= kept("px4_manual", "tlog")
    for name in ("ardupilot_manual", "arduplane_manual", "px4_manual"):
        roles = load_mapping(name).roles
        assert roles.position and roles.velocity and roles.heading, name


# --------------------------------------------------------------------------------------- inspect, rates


def test_a_bursty_stream_reads_at_its_mean_rate_not_its_burst_rate():
    # 4 messages per second arriving in bursts 10 ms apart: 1 / median gap would say 100 Hz
    t = (np.arange(60)[:, None] + 0.01 * np.arange(4)[None, :]).ravel()
    s = summarize(Streams("burst.tlog", "tlog", {"VFR_HUD": pd.DataFrame({"t": t, "alt": 0.0})}, {"VFR_HUD": t.size}))
    assert s.streams[0].rate_hz == pytest.approx((t.size - 1) / (t[-1] - t[0]))
    assert s.streams[0].rate_hz == pytest.approx(4.0, rel=0.02)


def test_inspect_names_plane_modes_by_the_vtol_heartbeat_and_gives_mean_rates(flights, tmp_path):
    spans = layout(flights, EPOCH, PAUSE)
    table = MODE_TABLES["arduplane"]
    modes = [mode_number("arduplane", "FBWA"), mode_number("arduplane", "QHOVER")]
    ml = mavutil.mavlink
    hb = _heartbeats(spans, modes, autopilot=ml.MAV_AUTOPILOT_ARDUPILOTMEGA, mav_type=ml.MAV_TYPE_VTOL_QUADROTOR)
    path = _write_tlog(tmp_path / "quadplane.tlog", flights, "arduplane_manual", hb)
    summary = adapters.inspect(path)
    names = [m.mode for m in summary.modes]
    assert names[0] == table[modes[0]] == "FBWA" and "QHOVER" in names and "RTL" in names
    assert "VTOL_QUADROTOR" in summary.vehicle
    fbwa = summary.modes[0]
    assert fbwa.duration == pytest.approx(spans[0][1] - spans[0][0], abs=1.0)  # up to the HEARTBEAT period
    assert "FBWA" in str(summary) and f"({fbwa.duration:.1f} s)" in str(summary)
    _assert_mean_rates(path, summary)
    # the shipped mapping cuts the same flight into its two pilot-flown spans, named
    ds = adapters.load(path, "arduplane_manual")
    assert [d.meta["mode"] for d in ds] == ["FBWA", "QHOVER"]
    for d, original in zip(ds, flights, strict=True):
        assert d.duration == pytest.approx(original.duration, abs=ds.dt)
        step = int(round(ds.dt / flights.dt))
        np.testing.assert_allclose(d.x[:5], original.x[: 5 * step : step], atol=1e-5)  # tilt round trip


def test_the_same_mode_number_is_named_by_the_vehicle_type(flights, tmp_path):
    spans = layout(flights, EPOCH, PAUSE)
    ml = mavutil.mavlink
    number = mode_number("arduplane", "FBWA")
    copter = _heartbeats(spans, [number, number], autopilot=ml.MAV_AUTOPILOT_ARDUPILOTMEGA,
                         mav_type=ml.MAV_TYPE_QUADROTOR)
    summary = adapters.inspect(_write_tlog(tmp_path / "copter.tlog", flights, "ardupilot_manual", copter))
    assert summary.modes[0].mode == MODE_TABLES["arducopter"][number] != "FBWA"


def test_px4_over_mavlink_modes_are_px4_custom_modes(flights, tmp_path):
    spans = layout(flights, EPOCH, PAUSE)
    ml = mavutil.mavlink
    modes = [mode_number("px4", "POSCTL"), mode_number("px4", "MANUAL")]
    hb = _heartbeats(spans, modes, autopilot=ml.MAV_AUTOPILOT_PX4, mav_type=ml.MAV_TYPE_QUADROTOR)
    path = _write_tlog(tmp_path / "px4.tlog", flights, "px4_manual", hb)
    summary = adapters.inspect(path)
    assert [m.mode for m in summary.modes][:2] == ["POSCTL", "RTL"]
    ds = adapters.load(path, "px4_manual")
    assert [d.meta["mode"] for d in ds] == ["POSCTL", "MANUAL"]


def test_real_logs_mean_rates_and_mode_spans(external):
    path = external("dronekit_flight.tlog")
    summary = adapters.inspect(path)
    _assert_mean_rates(path, summary)
    rate = {s.name: s for s in summary.streams}
    # 290 parameter requests in 58 s: a few per second, not the thousands 1 / median gap said
    assert rate["PARAM_REQUEST_READ"].rate_hz < 10
    assert "QUADROTOR" in summary.vehicle
    assert all(m.duration >= 0 for m in summary.modes)
    assert sum(m.duration for m in summary.modes if m.mode == "STABILIZE") > 600
    px4 = adapters.inspect(external("px4_sample_log_small.ulg"))
    assert "MANUAL" in {m.mode for m in px4.modes}


# ------------------------------------------------------------------------------------------------ tilt


def _rotation(roll, pitch, yaw):
    def rx(a):
        return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])

    def ry(a):
        return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])

    def rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    return rz(yaw) @ ry(pitch) @ rx(roll)


def test_tilt_east_is_the_thrust_axis_angle_in_the_east_up_plane():
    rng = np.random.default_rng(1)
    angles = np.column_stack([rng.uniform(-0.5, 0.5, 50), rng.uniform(-0.5, 0.5, 50), rng.uniform(-np.pi, np.pi, 50)])
    tilt = TRANSFORMS["euler_tilt_east"].forward(angles, {})
    for (r, p, y), a in zip(angles, tilt, strict=True):
        thrust = _rotation(r, p, y) @ np.array([0.0, 0.0, -1.0])  # NED
        assert np.tan(a) == pytest.approx(thrust[1] / -thrust[2], rel=1e-9, abs=1e-12)
    # heading north the tilt is the roll; heading east a nose-down pitch leans east
    np.testing.assert_allclose(TRANSFORMS["euler_tilt_east"].forward(np.array([[0.2, 0.0, 0.0]]), {}), [0.2])
    np.testing.assert_allclose(TRANSFORMS["euler_tilt_east"].forward(np.array([[0.0, -0.2, np.pi / 2]]), {}), [0.2])


def test_tilt_east_rate_is_the_derivative_of_the_tilt():
    # integrate the attitude under constant body rates and compare the rate with finite differences
    p, q, r = 0.4, -0.3, 1.1
    dt, n = 1e-4, 2000
    R = _rotation(0.1, -0.05, 0.7)
    omega = np.array([[0, -r, q], [r, 0, -p], [-q, p, 0]])
    rows = []
    for _ in range(n):
        roll, pitch, yaw = np.arctan2(R[2, 1], R[2, 2]), -np.arcsin(R[2, 0]), np.arctan2(R[1, 0], R[0, 0])
        rows.append([roll, pitch, yaw, p, q])
        R = R @ (np.eye(3) + omega * dt + omega @ omega * dt**2 / 2)
    v = np.array(rows)
    tilt = TRANSFORMS["euler_tilt_east"].forward(v[:, :3], {})
    rate = TRANSFORMS["euler_tilt_east_rate"].forward(v, {})
    np.testing.assert_allclose(np.gradient(tilt, dt)[1:-1], rate[1:-1], rtol=1e-3, atol=1e-5)


def test_workbench_inspect_prints_the_plane_modes_with_durations(flights, tmp_path, capsys):
    from workbench.cli import main

    spans = layout(flights, EPOCH, PAUSE)
    ml = mavutil.mavlink
    modes = [mode_number("arduplane", "QSTABILIZE"), mode_number("arduplane", "QLOITER")]
    hb = _heartbeats(spans, modes, autopilot=ml.MAV_AUTOPILOT_ARDUPILOTMEGA, mav_type=ml.MAV_TYPE_FIXED_WING)
    path = _write_tlog(tmp_path / "plane.tlog", flights, "arduplane_manual", hb)
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    summary = adapters.inspect(path)
    first = summary.modes[0]
    assert "flight modes (MAV_AUTOPILOT_ARDUPILOTMEGA MAV_TYPE_FIXED_WING)" in out
    assert f"QSTABILIZE 0.0–{first.duration:.1f} s ({first.duration:.1f} s)" in out and "QLOITER" in out


def test_a_multi_field_source_names_the_missing_field(tmp_path):
    from workbench.errors import MappingError

    text = tmp_path / "m.toml"
    text.write_text('dt = 0.2\nstates = ["phi", "v"]\ninputs = ["u"]\n[channels]\n'
                    'phi = { source = "ATTITUDE.roll,pitch,yawz", transform = "euler_tilt_east" }\n'
                    'v = "ATTITUDE.rollspeed"\nu = "ATTITUDE.pitchspeed"\n')
    frame = pd.DataFrame({"t": np.arange(30) * 0.1, "roll": 0.1, "pitch": 0.0, "yaw": 0.0, "rollspeed": 0.0,
                          "pitchspeed": 0.0})
    streams = Streams("a.tlog", "tlog", {"ATTITUDE": frame}, {"ATTITUDE": 30})
    with pytest.raises(MappingError, match=r"no field 'yawz'.*nearest: yaw"):
        adapters.build(streams, load_mapping(text).for_format("tlog"))


@pytest.mark.parametrize("style", ["old", "new"])
@pytest.mark.parametrize(("vehicle", "mapping"), [("copter", "ardupilot_manual"), ("plane", "arduplane_manual")])
def test_the_shipped_ardupilot_mappings_read_dataflash_logs_of_each_generation(tmp_path, style, vehicle, mapping):
    """The `[dataflash]` channels name EKF1 (3.x), NKF1 and XKF1[0] (4.x); the first present wins."""
    from adapters.formats.dataflash_write import write_example

    path = write_example(tmp_path / f"{style}_{vehicle}.bin", style, vehicle, seconds=60.0, rate=1.0, seed=4)
    streams = adapters.read_streams(path)
    ds = adapters.load(path, mapping=mapping)
    assert len(ds) >= 1
    roll = streams["ATT"]["Roll"].to_numpy()
    t_att = streams["ATT"]["t"].to_numpy()
    d = ds[0]
    # phi is ATT.Roll in radians, sampled on the grid: compare with the log interpolated at the demo's times
    expected = np.deg2rad(np.interp(d.t + d.meta["t0"], t_att, roll))
    np.testing.assert_allclose(d.x[:, ds.state_names.index("phi")], expected, atol=1e-6)


def test_the_real_dataflash_log_imports_with_the_shipped_copter_mapping(external):
    path = external("erle_copter_83.BIN")
    # its EKF1 velocity does not follow its GPS's (bench/real_logs.md): import names that; the viewer shows the log
    with pytest.raises(DataError, match=r"EKF1 velocity does not follow the GPS velocity \(GPS Spd, GCrs\)"):
        adapters.load(path, mapping="ardupilot_manual")
    ds = adapters.load(path, mapping="ardupilot_manual", allow_still=True)
    modes = {d.meta.get("mode") for d in ds}
    assert len(ds) >= 1 and modes <= {"STABILIZE", "ALT_HOLD", "LOITER"}
    # the mode lane of `inspect` and the demonstrations agree on the pilot-flown modes the log has
    assert modes & {"STABILIZE", "ALT_HOLD"}


def _copter_bin(tmp_path, name, edit):
    from adapters.formats import dataflash_write

    streams, options = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    edit(streams, options)
    return dataflash_write.write(tmp_path / name, streams, **options)


def test_a_position_that_never_moves_is_named_at_import(tmp_path):
    # An ArduCopter flown without GPS logs EKF1.PN/PE as 0.0 throughout (erlerobot/logs pxf/copter/6-3-2014/5.BIN);
    # the fit used to stop at "the data excite only 7 of 8 directions" instead of saying so. The shipped mapping's x
    # is the integral of its velocity (issue 41), so the position is checked where a mapping reads one: here the
    # EKF's east position.
    def no_gps(streams, options):
        streams["EKF1"]["PN"] = 0.0
        streams["EKF1"]["PE"] = 0.0

    path = _copter_bin(tmp_path, "no_gps.bin", no_gps)
    m = load_mapping("ardupilot_manual")
    assert m.for_format("dataflash").channel("x").integrates == "xdot"
    mapping = tmp_path / "east.toml"  # the DataFlash channels with the EKF's east position for x
    with open(m.path, encoding="utf-8") as f:
        mapping.write_text(f.read().replace('x = { integrate = "xdot" }', 'x = "EKF1.PE"'))
    with pytest.raises(DataError, match=r"x constant 0 in all \d+ samples \(EKF1\.PE\) — no position source"):
        adapters.load(path, str(mapping))
    looked = adapters.load(path, str(mapping), allow_still=True)  # the viewer still shows it
    assert len(looked) and "no GPS position" in looked[0].meta["still"]


def test_the_shipped_mapping_reads_a_mode_message_without_modenum(tmp_path):
    # ArduCopter firmware before ModeNum logs MODE with Mode alone; `workbench map` knew it, the mapping did not
    def mode_only(streams, options):
        streams["MODE"] = streams["MODE"].drop(columns=["ModeNum"])
        options["formats"] = {**options["formats"], "MODE": "M"}

    path = _copter_bin(tmp_path, "mode_only.bin", mode_only)
    reference = _copter_bin(tmp_path, "reference.bin", lambda s, o: None)
    got, expected = adapters.load(path, "ardupilot_manual"), adapters.load(reference, "ardupilot_manual")
    assert [d.meta["mode"] for d in got] == [d.meta["mode"] for d in expected]
    assert sum(len(d.t) for d in got) == sum(len(d.t) for d in expected)


def test_a_mapping_for_another_vehicle_is_refused_naming_the_log_vehicle_and_the_mapping_that_fits(flights, tmp_path):
    # An ArduRover flown in MANUAL (custom mode 0): the copter mapping's table reads 0 as STABILIZE and imported
    # the drive as a copter's manual flight without a word; a plane's log against the copter mapping likewise.
    ml = mavutil.mavlink
    spans = layout(flights, EPOCH, PAUSE)
    rover = _write_tlog(tmp_path / "rover.tlog", flights, "ardupilot_manual",
                        _heartbeats(spans, [mode_number("ardurover", "MANUAL")] * len(spans),
                                    autopilot=ml.MAV_AUTOPILOT_ARDUPILOTMEGA, mav_type=ml.MAV_TYPE_GROUND_ROVER))
    with pytest.raises(DataError, match=r"mapping 'ardupilot_manual' is made for arducopter flight modes, but this "
                                        r"log is from .*MAV_TYPE_GROUND_ROVER \(ardurover modes\)"):
        adapters.load(rover, "ardupilot_manual")
    plane = _write_tlog(tmp_path / "plane.tlog", flights, "arduplane_manual",
                        _heartbeats(spans, [mode_number("arduplane", "FBWA")] * len(spans),
                                    autopilot=ml.MAV_AUTOPILOT_ARDUPILOTMEGA, mav_type=ml.MAV_TYPE_FIXED_WING))
    with pytest.raises(DataError, match=r"the shipped mapping 'arduplane_manual' is made for it"):
        adapters.load(plane, "ardupilot_manual")
    # without a mapping, the one made for the vehicle is chosen and said
    assert adapters.choose_mapping(plane)[0] == "arduplane_manual"
    assert len(adapters.load(plane, adapters.choose_mapping(plane)[0])) == len(flights)


def test_both_planar_channels_of_a_real_copter_flight_are_physics(external):
    # a copter flies both planes: the roll plane (ardupilot_manual) and the pitch plane (ardupilot_manual_pitch)
    # each identify a tilt -> velocity response within a factor 2 of g·dt on the real ArduCopter telemetry log
    from workbench.plant.choice import choose_plant

    log = external("dronekit_flight.tlog")
    for name in ("ardupilot_manual", "ardupilot_manual_pitch"):
        plant = choose_plant(adapters.load(log, name), "identify")
        (check,) = plant.identification.checks
        assert check.within(), (name, str(check))
