"""The real causes a mapped flight cannot give a plant's physics: an estimated velocity that does not follow the
log's own GPS velocity, a log without any GPS stream (dead reckoning), and a vehicle that flipped.

Each built on a synthetic ArduCopter DataFlash log (:func:`adapters.formats.dataflash_write.example_streams`, whose
GPS ground speed and course follow its EKF's velocity, as a real log's do) with one thing changed.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.formats import dataflash_write
from adapters.gps import MOTION_OVER_ACCURACY
from adapters.mapping import load_mapping
from workbench.errors import DataError, ModelError


def _copter_bin(tmp_path, name, edit=None, seconds=30.0):
    streams, options = dataflash_write.example_streams("old", "copter", seconds=seconds, seed=3)
    if edit is not None:
        edit(streams, options)
    return dataflash_write.write(tmp_path / name, streams, **options), streams


def _own_gps(streams, options):
    """A GPS velocity of its own, drawn apart from the EKF's: the EKF does not follow it."""
    rng = np.random.default_rng(11)
    n = len(streams["GPS"])
    streams["GPS"]["Spd"] = np.round(rng.uniform(0, 5, n), 2)
    streams["GPS"]["GCrs"] = np.round(rng.uniform(0, 360, n), 2)


def _explained(streams, ds) -> float:
    """1 − Σ|v − v_gps|² / Σ|v_gps − mean|² over the GPS samples inside the demonstrations (north and east)."""
    gps, ekf = streams["GPS"], streams["EKF1"]
    tg = gps["t"].to_numpy()
    course = np.deg2rad(gps["GCrs"].to_numpy(np.float64))
    g = np.column_stack([gps["Spd"] * np.cos(course), gps["Spd"] * np.sin(course)])
    inside = np.zeros(tg.size, dtype=bool)
    for d in ds:
        inside |= (tg >= d.meta["t0"]) & (tg <= d.meta["t0"] + d.t[-1])
    tg, g = tg[inside], g[inside]
    v = np.column_stack([np.interp(tg, ekf["t"], ekf[k]) for k in ("VN", "VE")])
    return 1.0 - float(((v - g) ** 2).sum()) / float(((g - g.mean(axis=0)) ** 2).sum())


def test_the_example_log_s_ekf_follows_its_gps_and_imports(tmp_path):
    path, streams = _copter_bin(tmp_path, "clean.bin")
    ds = adapters.load(path, "ardupilot_manual")
    assert len(ds) and not ds[0].meta.get("still") and not ds[0].meta.get("flipped")
    assert _explained(streams, ds) > 0.9  # the GPS velocity is the EKF's, up to the log's rounding


def test_an_ekf_velocity_that_does_not_follow_the_gps_is_named_at_import(tmp_path):
    # erle_copter_83.BIN: EKF1.VN/VE correlate 0.2 / 0.6 with the GPS's own velocity, and the identified plant's
    # A[xdot, phi] came out 0.2 of g·dt; the fit then stopped at "the gain is not stabilizing"
    path, streams = _copter_bin(tmp_path, "wandering.bin", _own_gps)
    with pytest.raises(DataError, match=r"EKF1 velocity does not follow the GPS velocity \(GPS Spd, GCrs\)") as info:
        adapters.load(path, "ardupilot_manual")
    message = str(info.value)
    assert "\n" not in message and "the estimator is not converged or not the one that flew" in message
    looked = adapters.load(path, "ardupilot_manual", allow_still=True)  # the viewer shows it, with the cause
    assert looked[0].meta["still"] == message
    explained = _explained(streams, looked)
    assert explained < 0
    assert float(re.search(r"it explains (-?[\d.]+) of", message).group(1)) == pytest.approx(explained, abs=0.006)


@pytest.mark.parametrize("top", [0.01, 0.8])
def test_too_little_motion_is_its_own_cause(tmp_path, top):
    # a vehicle standing (0.01 m/s) and a 28 s hover whose GPS speed never passes 0.8 m/s; the hover was called "the
    # estimator is not converged or not the one that flew". The line states the threshold and the measured maximum,
    # and calls nothing noise: 0.8 m/s is eight times the receiver's accuracy (it said "the receiver's noise")
    rng = np.random.default_rng(4)

    def hover(streams, options):
        n = len(streams["GPS"])
        streams["GPS"]["Spd"] = np.round(rng.uniform(0, top, n), 2)
        streams["GPS"]["GCrs"] = np.round(rng.uniform(0, 360, n), 2)

    path, streams = _copter_bin(tmp_path, "hover.bin", hover)
    with pytest.raises(DataError, match=r"too little motion to identify the plant: the GPS speed \(GPS Spd, GCrs\) "
                                        r"never passes 1 m/s in the kept segments") as info:
        adapters.load(path, "ardupilot_manual")
    message = str(info.value)
    assert "not converged" not in message and "\n" not in message
    looked = adapters.load(path, "ardupilot_manual", allow_still=True)
    gps = streams["GPS"]
    inside = np.zeros(len(gps), dtype=bool)
    for d in looked:
        inside |= (gps["t"] >= d.meta["t0"]) & (gps["t"] <= d.meta["t0"] + d.t[-1])
    fastest = float(gps["Spd"][inside].max())
    assert f"at most {fastest:.2g} m/s over {int(inside.sum())} GPS samples" in message
    accuracy = load_mapping("ardupilot_manual").for_format("dataflash").reference.accuracy
    assert (f"(the threshold: {MOTION_OVER_ACCURACY:g} times the receiver's {accuracy:g} m/s velocity accuracy)"
            in message)
    assert "noise" not in message


def test_a_log_without_any_gps_stream_is_named_dead_reckoning(tmp_path):
    # erlerobot/logs pxf/copter/30-3-2015/72.BIN: no GPS message at all, yet EKF1's position and velocity move
    def no_gps(streams, options):
        del streams["GPS"]

    path, _ = _copter_bin(tmp_path, "no_gps.bin", no_gps)
    assert "GPS" not in adapters.read(path).frames
    with pytest.raises(DataError, match=r"the log has no GPS stream \(GPS\.Spd,GCrs.*\), yet x, y, xdot, ydot move: "
                                        r"the estimator dead-reckons"):
        adapters.load(path, "ardupilot_manual")
    assert "dead-reckons" in adapters.load(path, "ardupilot_manual", allow_still=True)[0].meta["still"]


def test_a_flip_cuts_its_segment_and_drops_the_flight_after_it(tmp_path):
    # erlerobot/logs pxf/copter/15-12-2014/16.BIN: ATT.Roll reaches -177°; the flight after it is a crash
    _copter_bin(tmp_path, "clean.bin", seconds=60.0)
    first = adapters.load(tmp_path / "clean.bin", "ardupilot_manual")[0]
    start, end = first.meta["t0"], first.meta["t0"] + first.t[-1]
    at = end - 1.0  # the flip, a second before the segment's end: the piece before it is longer than min_duration
    upside_down = -170.0

    def flip(streams, options):
        att = streams["ATT"]
        att.loc[att["t"] >= at, "Roll"] = upside_down

    path, streams = _copter_bin(tmp_path, "flip.bin", flip, seconds=60.0)
    ds = adapters.load(path, "ardupilot_manual")
    assert len(ds) == 1  # the segments after the flip start upside down: dropped
    kept = ds[0]
    assert kept.meta["t0"] == pytest.approx(start)
    # cut at the first grid step beyond 90°: the roll interpolated between the ATT samples either side of the flip
    step = float(np.median(np.diff(streams["ATT"]["t"]))) + (kept.t[1] - kept.t[0])
    assert at - step - 1e-9 < kept.meta["t0"] + kept.t[-1] < at
    phi = kept.x[:, ds.state_names.index("phi")]
    assert np.abs(phi).max() <= math.pi / 2
    note = kept.meta["flipped"]
    assert f"reaches {upside_down:.0f}° — the vehicle flipped" in note
    assert re.search(r"the STABILIZE segment from [\d.]+ s cut at [\d.]+ s: phi \(ATT\.Roll\)", note)
    assert "the ALT_HOLD segment from" in note and "dropped" in note


def test_a_flight_flipped_throughout_says_so_in_one_line(tmp_path):
    def flipped(streams, options):
        streams["ATT"]["Roll"] = 175.0

    path, _ = _copter_bin(tmp_path, "flipped.bin", flipped)
    with pytest.raises(DataError, match=r"no demonstration left once cut at the vehicle's flips") as info:
        adapters.load(path, "ardupilot_manual")
    assert "\n" not in str(info.value) and "reaches 175°" in str(info.value)


def test_the_fit_names_a_plant_that_fails_its_physics_check_first(tmp_path):
    # erle_copter_83.BIN's plant: A[xdot, phi] a fifth of g·dt; the fit said only "the gain is not stabilizing"
    from dataclasses import replace
    from types import SimpleNamespace

    from workbench.cli.model import _physics_first
    from workbench.data.plant_groups import select_plant_group
    from workbench.plant.choice import choose_plant
    from workbench.plant.identification import PhysicalCheck

    path, _ = _copter_bin(tmp_path, "clean.bin")
    stabilize = select_plant_group(adapters.load(path, "ardupilot_manual"), "angle")  # one plant per kind of stick
    report = choose_plant(stabilize, "identify").identification
    (check,) = report.checks
    weak = PhysicalCheck(check.name, check.expected / 5, check.expected, check.note)
    passing = SimpleNamespace(identification=replace(report, checks=(replace(weak, value=check.expected),)))
    failing = SimpleNamespace(identification=replace(report, checks=(weak,)))
    assert passing.identification.physics_failure == ""
    failure = failing.identification.physics_failure
    assert failure.startswith(f"{check.name} is {weak.ratio:.2g} × g·dt") and "likely cause" in failure
    error = ModelError("the gain is not stabilizing: ρ = 1.02")
    assert _physics_first(passing, error) == str(error)
    line = _physics_first(failing, error)
    assert line.startswith(f"the identified plant is not physics: {check.name} is {weak.ratio:.2g} × g·dt")
    assert line.endswith(str(error)) and "\n" not in line


def test_the_viewer_shows_such_a_log_with_the_cause_beside_its_states(tmp_path):
    from ..rrd import key_texts

    path, _ = _copter_bin(tmp_path, "wandering.bin", _own_gps)
    ds = adapters.load(path, "ardupilot_manual", allow_still=True)
    texts = key_texts(ds, tmp_path / "v.rrd")
    cause = ds[0].meta["still"].split(": mapping 'ardupilot_manual': ", 1)[1]
    assert any(f"**not for fitting**: {cause}" in t for t in texts), texts


@pytest.mark.parametrize("follows", [True, False])
@pytest.mark.parametrize(("mapping", "vehicle", "table", "mode"), [
    ("ardupilot_manual", "MAV_TYPE_QUADROTOR", "arducopter", "STABILIZE"),
    ("arduplane_manual", "MAV_TYPE_FIXED_WING", "arduplane", "FBWA")])
def test_a_tlog_s_local_velocity_is_checked_against_gps_raw_int(tmp_path, follows, mapping, vehicle, table, mode):
    # the tlog side of ardupilot_manual / arduplane_manual: LOCAL_POSITION_NED.vx,vy (the EKF's ground velocity,
    # a plane's too) against GPS_RAW_INT.vel (cm/s), cog (cdeg)
    from pymavlink import mavutil

    from adapters.mapping import load_mapping
    from adapters.modes import mode_number
    from adapters.writer import demo_streams
    from workbench.sim.landing import simulate_landings

    epoch = 1_704_067_200.0
    ds = simulate_landings("CS1", 2, seed=3)
    streams = demo_streams(ds, load_mapping(mapping).for_format("tlog"), epoch=epoch, pause=2.0)
    for frame in streams.values():
        frame["time_boot_ms"] = np.rint((frame["t"].to_numpy() - epoch) * 1000.0).astype(np.int64)
    rng = np.random.default_rng(5)
    local = streams["LOCAL_POSITION_NED"]
    local["vx"] = rng.normal(0.0, 1.0, len(local))  # north: the simulated flight has only its east velocity
    gps = local.iloc[::2]
    vn, ve = gps["vx"].to_numpy(), gps["vy"].to_numpy()
    if not follows:
        vn, ve = rng.permutation(vn), rng.permutation(ve)
    streams["GPS_RAW_INT"] = pd.DataFrame({
        "t": gps["t"].to_numpy(), "time_usec": gps["time_boot_ms"].to_numpy() * 1000, "fix_type": 3,
        "vel": np.rint(100 * np.hypot(vn, ve)).astype(np.int64),
        "cog": np.rint(100 * np.mod(np.degrees(np.arctan2(ve, vn)), 360.0)).astype(np.int64) % 36000})
    ml = mavutil.mavlink
    streams["HEARTBEAT"] = pd.DataFrame({
        "t": streams["ATTITUDE"]["t"].to_numpy()[::50], "type": getattr(ml, vehicle),
        "autopilot": ml.MAV_AUTOPILOT_ARDUPILOTMEGA,
        "base_mode": ml.MAV_MODE_FLAG_SAFETY_ARMED | ml.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        "custom_mode": mode_number(table, mode), "system_status": 4, "mavlink_version": 3})
    path = adapters.FORMATS["tlog"].write(tmp_path / "f.tlog", streams)
    _draft_acts_as_shipped(path, tmp_path)  # `workbench map`'s draft checks the same
    if follows:
        assert len(adapters.load(path, mapping)) == len(ds)
    else:
        with pytest.raises(DataError, match=r"LOCAL_POSITION_NED velocity does not follow the GPS velocity "
                                            r"\(GPS_RAW_INT vel, cog\)"):
            adapters.load(path, mapping)


# ------------------------------------------------------------------------------ arduplane_manual's reference


def _plane_bin(tmp_path, name, style, own_gps):
    """An ArduPlane DataFlash log (old: EKF1 / GPS, new: NKF1[k] / GPS[0]), its GPS velocity its own if asked."""
    streams, options = dataflash_write.example_streams(style, "plane", seconds=60.0, seed=3)
    gps = "GPS" if style == "old" else "GPS[0]"
    if own_gps:
        rng = np.random.default_rng(11)
        n = len(streams[gps])
        streams[gps]["Spd"] = rng.uniform(0, 5, n).astype(np.float32)
        streams[gps]["GCrs"] = rng.uniform(0, 360, n).astype(np.float32)
    return dataflash_write.write(tmp_path / name, streams, **options)


@pytest.mark.parametrize("style", ["old", "new"])
def test_a_plane_s_ekf_velocity_is_checked_against_its_dataflash_gps(tmp_path, style):
    # arduplane_manual's states are the EKF's ground velocity (not the airspeed): the GPS's is their reference
    assert len(adapters.load(_plane_bin(tmp_path, "follows.bin", style, False), "arduplane_manual"))
    ekf = "EKF1" if style == "old" else "NKF1"
    gps = "GPS" if style == "old" else r"GPS\[0\]"
    with pytest.raises(DataError, match=rf"{ekf}(\[0\])? velocity does not follow the GPS velocity \({gps} Spd"):
        adapters.load(_plane_bin(tmp_path, "own.bin", style, True), "arduplane_manual")


def test_a_plane_dataflash_log_without_gps_is_named_dead_reckoning(tmp_path):
    streams, options = dataflash_write.example_streams("old", "plane", seconds=60.0, seed=3)
    del streams["GPS"]
    path = dataflash_write.write(tmp_path / "no_gps.bin", streams, **options)
    with pytest.raises(DataError, match=r"the log has no GPS stream .* the estimator dead-reckons"):
        adapters.load(path, "arduplane_manual")


# ----------------------------------------------------------------------------- a drafted mapping's reference


def _draft_acts_as_shipped(path, tmp_path):
    """`workbench map`'s draft of the log holds a [reference], and imports or refuses as its template does."""
    from adapters.draft import draft_mapping

    draft = draft_mapping(adapters.read(path), name="drafted")
    assert "\n[reference]\n" in draft.toml
    toml = tmp_path / "drafted.toml"
    toml.write_text(draft.toml)
    outcomes = []
    for mapping in (draft.template, toml):
        try:
            outcomes.append(len(adapters.load(path, mapping)))
        except DataError as exc:
            # the draft's grid step and segment rules are its own (the log's slowest stream): the numbers may differ
            outcomes.append(re.sub(r"-?\d+(\.\d+)?", "#", str(exc).replace(repr(draft.template), "'drafted'")))
    assert type(outcomes[0]) is type(outcomes[1])
    if isinstance(outcomes[0], str):
        assert outcomes[0] == outcomes[1]
    return outcomes[1]


@pytest.mark.parametrize(("style", "vehicle"), [("old", "copter"), ("new", "plane")])
@pytest.mark.parametrize("case", ["follows", "own", "no_gps"])
def test_a_drafted_mapping_checks_the_velocity_as_the_shipped_one_does(tmp_path, style, vehicle, case):
    streams, options = dataflash_write.example_streams(style, vehicle, seconds=60.0, seed=3)
    gps = "GPS" if style == "old" else "GPS[0]"
    if case == "own":
        rng = np.random.default_rng(11)
        streams[gps]["Spd"] = rng.uniform(0, 5, len(streams[gps])).astype(np.float32)
        streams[gps]["GCrs"] = rng.uniform(0, 360, len(streams[gps])).astype(np.float32)
    elif case == "no_gps":
        del streams[gps]
    outcome = _draft_acts_as_shipped(dataflash_write.write(tmp_path / "f.bin", streams, **options), tmp_path)
    if case == "follows":
        assert isinstance(outcome, int) and outcome > 0
    else:
        assert isinstance(outcome, str)
        assert ("velocity does not follow the GPS velocity" if case == "own" else "dead-reckons") in outcome


# ------------------------------------------------------------------------------------ px4_manual's reference


@pytest.mark.parametrize("topic", ["vehicle_gps_position", "sensor_gps"])  # the receiver's topic before / from v1.14
@pytest.mark.parametrize("follows", [True, False])
def test_a_ulog_s_local_velocity_is_checked_against_its_gps_topic(tmp_path, follows, topic):
    # px4_manual: vehicle_local_position.vx,vy against the receiver's vel_n_m_s, vel_e_m_s (3D fix only)
    from adapters.formats import ulog
    from adapters.mapping import load_mapping
    from adapters.writer import demo_streams, layout
    from workbench.sim.landing import simulate_landings

    flights = simulate_landings("CS1", 2, seed=3)
    streams = demo_streams(flights, load_mapping("px4_manual").for_format("ulog"), epoch=0.0, pause=2.0)
    spans = layout(flights, 0.0, 2.0)
    t = np.arange(0.0, spans[-1][1] + 1.0, 0.5)
    in_flight = np.zeros(t.size, dtype=bool)
    for a, b in spans:
        in_flight |= (t >= a) & (t <= b)
    streams["vehicle_status"] = pd.DataFrame({  # STAB in flight, AUTO_RTL between, armed throughout
        "t": t, "nav_state": np.where(in_flight, 15, 5).astype(np.uint8), "arming_state": np.uint8(2)})
    rng = np.random.default_rng(5)
    local = streams["vehicle_local_position"]
    local["vx"] = rng.normal(0.0, 1.0, len(local)).astype(local["vy"].dtype)  # the simulated flight has no north
    gps = local.iloc[::4]
    vn, ve = gps["vx"].to_numpy(), gps["vy"].to_numpy()
    if not follows:
        vn, ve = rng.permutation(vn), rng.permutation(ve)
    streams[topic] = pd.DataFrame({"t": gps["t"].to_numpy(), "fix_type": np.uint8(3),
                                   "vel_n_m_s": vn.astype(np.float32), "vel_e_m_s": ve.astype(np.float32)})
    path = ulog.write(tmp_path / "f.ulg", streams, info={"sys_name": "PX4", "ver_sw_release": "v1.14.0"})
    _draft_acts_as_shipped(path, tmp_path)  # `workbench map`'s draft checks the same
    if follows:
        assert len(adapters.load(path, "px4_manual")) == len(flights)
    else:
        with pytest.raises(DataError, match=rf"vehicle_local_position velocity does not follow the GPS velocity "
                                            rf"\({topic} vel_n_m_s, vel_e_m_s\)") as info:
            adapters.load(path, "px4_manual")
        assert "\n" not in str(info.value)


@pytest.mark.parametrize("cause", ["own_gps", "no_gps"])
def test_a_stop_for_the_velocity_after_flips_says_how_many_segments_were_cut(tmp_path, cause):
    # the viewer draws the cuts; the terminal's one line must not hide that the flight was cut before the check
    clean = adapters.load(_copter_bin(tmp_path, "clean.bin", seconds=60.0)[0], "ardupilot_manual")
    first = clean[0]
    at = first.meta["t0"] + first.t[-1] - 1.0

    def edit(streams, options):
        att = streams["ATT"]
        att.loc[att["t"] >= at, "Roll"] = -170.0
        if cause == "own_gps":
            _own_gps(streams, options)
        else:
            del streams["GPS"]

    path, _ = _copter_bin(tmp_path, "flip.bin", edit, seconds=60.0)
    with pytest.raises(DataError) as info:
        adapters.load(path, "ardupilot_manual")
    message = str(info.value)
    assert ("does not follow the GPS velocity" if cause == "own_gps" else "dead-reckons") in message
    # as many as the viewer lists: the cut segment and every piece after it that starts upside down
    cuts = adapters.load(path, "ardupilot_manual", allow_still=True)[0].meta["flipped"].split("; the ")
    n = len(cuts)
    assert n >= 2 and "cut at" in cuts[0] and all("dropped" in c for c in cuts[1:])
    assert "\n" not in message and message.endswith(
        f"({n} segment{'s' if n > 1 else ''} cut or dropped at the vehicle's flips before this check: `workbench "
        f"view` shows where)")


@pytest.mark.parametrize("field", ["heading", "yaw"])
def test_a_ulog_flight_that_does_not_point_north_is_read_in_its_heading_frame(tmp_path, field):
    # px4_manual's x and xdot are along the vehicle's right (vehicle_local_position.heading, rad), the frame its body
    # roll accelerates; before, they were east, which the roll accelerates only while the vehicle points north
    # (luk8426/flugdrohne's PX4 v1.14 flights: A[xdot, phi] -0.32 × g·dt). Older firmware logs the heading as
    # vehicle_local_position.yaw (PX4 v1.9.0: YUNEEC/pyulgresample's position.ulg), which was read as east.
    from adapters.formats import ulog
    from adapters.mapping import load_mapping
    from adapters.writer import demo_streams, layout
    from workbench.sim.landing import simulate_landings

    flights = simulate_landings("CS1", 2, seed=4)
    spans = layout(flights, 0.0, 2.0)
    t = np.arange(0.0, spans[-1][1] + 1.0, 0.5)
    in_flight = np.zeros(t.size, dtype=bool)
    for a, b in spans:
        in_flight |= (t >= a) & (t <= b)

    def flown(name, heading):
        """The flights written pointing north, then turned to ``heading`` (rad) with their lateral plane."""
        streams = demo_streams(flights, load_mapping("px4_manual").for_format("ulog"), epoch=0.0, pause=2.0)
        streams["vehicle_status"] = pd.DataFrame({
            "t": t, "nav_state": np.where(in_flight, 15, 5).astype(np.uint8), "arming_state": np.uint8(2)})
        local = streams["vehicle_local_position"]
        # only the velocity: x is its integral (issue 41), and the writer writes no position for it
        for across, north, east in (("vy", "vx", "vy"),):
            right = local[across].to_numpy(dtype=np.float64)  # written along the right at heading 0: east
            local[north] = (-np.sin(heading) * right).astype(local[across].dtype)
            local[east] = (np.cos(heading) * right).astype(local[across].dtype)
        local = local.drop(columns=[c for c in ("heading", "yaw") if c in local])
        local[field] = np.float32(heading)  # no GPS topic: the simulated landings are too slow for its checks
        streams["vehicle_local_position"] = local
        path = ulog.write(tmp_path / name, streams, info={"sys_name": "PX4", "ver_sw_release": "v1.14.0"})
        return adapters.load(path, "px4_manual")

    north, turned = flown("north.ulg", 0.0), flown("turned.ulg", np.deg2rad(-127.0))
    assert len(turned) == len(north) == len(flights)
    for k in (turned.state_names.index("x"), turned.state_names.index("xdot")):
        assert np.ptp(north[0].x[:, k]) > 0.1  # the flights move across
        for a, b in zip(turned, north, strict=True):
            np.testing.assert_allclose(a.x[:, k], b.x[:, k], atol=1e-4)


@pytest.mark.parametrize(("vehicle_type", "groups"), [(1, {"MANUAL": "angle", "ALTCTL": "angle+climb"}),
                                                      (2, {"MANUAL": "surface", "ALTCTL": "bank+climb"})])
def test_a_px4_plane_s_manual_modes_are_a_plane_s_plants(tmp_path, vehicle_type, groups):
    # one PX4 mode table serves multicopters and planes: vehicle_status.vehicle_type (2: fixed-wing) says which
    # sticks a mode has (docs.px4.io: a plane's MANUAL moves the surfaces, its ALTCTL holds the altitude)
    from adapters.formats import ulog
    from adapters.mapping import load_mapping
    from adapters.writer import demo_streams, layout
    from workbench.sim.landing import simulate_landings

    flights = simulate_landings("CS1", 2, seed=6)
    spans = layout(flights, 0.0, 2.0)
    t = np.arange(0.0, spans[-1][1] + 1.0, 0.5)
    nav = np.full(t.size, 5, np.uint8)  # AUTO_RTL between the flights
    for (a, b), mode in zip(spans, (0, 1), strict=True):  # the first flown in MANUAL, the second in ALTCTL
        nav[(t >= a) & (t <= b)] = mode
    streams = demo_streams(flights, load_mapping("px4_manual").for_format("ulog"), epoch=0.0, pause=2.0)
    streams["vehicle_status"] = pd.DataFrame({"t": t, "nav_state": nav, "arming_state": np.uint8(2),
                                              "vehicle_type": np.uint8(vehicle_type)})
    path = ulog.write(tmp_path / "f.ulg", streams, info={"sys_name": "PX4", "ver_sw_release": "v1.14.0"})
    ds = adapters.load(path, "px4_manual")
    assert {d.meta["mode"]: d.meta["plant_group"] for d in ds} == groups
    assert {d.meta["mode"]: d.meta.get("autopilot_holds", "") for d in ds} == {"MANUAL": "", "ALTCTL": "the altitude"}


@pytest.mark.parametrize("estimate_holds_it", [False, True])
def test_a_gps_velocity_that_holds_one_value_is_judged_in_words_not_by_round_off(tmp_path, estimate_holds_it):
    # a GPS velocity exactly constant in the kept segments: its variance is the mean's round-off (~1e-30), and the
    # share explained came out about -1e30 and refused even an EKF flying that very velocity
    speed, course = 3.7, 33.3

    def constant(streams, options):
        streams["GPS"]["Spd"], streams["GPS"]["GCrs"] = speed, course
        if estimate_holds_it:  # the EKF flies that velocity too, within a hundredth of the receiver's accuracy
            ekf = streams["EKF1"]
            wobble = 1e-3 * np.sin(np.arange(len(ekf)))
            ekf["VN"] = speed * math.cos(math.radians(course)) + wobble
            ekf["VE"] = speed * math.sin(math.radians(course)) + wobble

    path, streams = _copter_bin(tmp_path, "constant.bin", constant)
    north_east = np.full((len(streams["GPS"]), 2), [speed * math.cos(math.radians(course)),
                                                    speed * math.sin(math.radians(course))])
    assert ((north_east - north_east.mean(axis=0)) ** 2).sum() > 0  # the round-off the old check divided by
    if estimate_holds_it:
        ds = adapters.load(path, "ardupilot_manual")
        assert len(ds) and not ds[0].meta.get("still")
        return
    with pytest.raises(DataError, match=r"the GPS velocity \(GPS Spd, GCrs\) holds one value") as info:
        adapters.load(path, "ardupilot_manual")
    message = str(info.value)
    assert "explains" not in message and "\n" not in message
    looked = adapters.load(path, "ardupilot_manual", allow_still=True)
    gps, ekf = streams["GPS"], streams["EKF1"]
    inside = np.zeros(len(gps), dtype=bool)
    for d in looked:
        inside |= (gps["t"] >= d.meta["t0"]) & (gps["t"] <= d.meta["t0"] + d.t[-1])
    tg = gps["t"].to_numpy()[inside]
    v = np.column_stack([np.interp(tg, ekf["t"], ekf[k]) for k in ("VN", "VE")])
    rms = float(np.sqrt(((v - north_east[inside]) ** 2).sum(axis=1).mean()))
    assert f"in all {int(inside.sum())} GPS samples" in message and f"by {rms:.2g} m/s RMS" in message


def _mode_span(streams, name):
    """The first span of flight mode ``name`` (ArduCopter's mode number) in the example log's MODE stream."""
    modes = streams["MODE"]
    number = {"STABILIZE": 0, "ALT_HOLD": 2, "LOITER": 5}[name]
    k = int(np.flatnonzero(modes["ModeNum"].to_numpy() == number)[0])
    ends = [*modes["t"].to_numpy()[1:], np.inf]
    return float(modes["t"].iloc[k]), float(ends[k])


@pytest.mark.parametrize("lost", ["no fix", "silent"])
def test_a_segment_flown_without_a_gps_fix_is_dropped_and_named(tmp_path, lost):
    # erle 6-11-2014/GPS_issues2.BIN: 46 s of ALT_HOLD with GPS.Status 0–1 (0 satellites); the EKF dead-reckoned, its
    # speed drifted to 60 m/s against a GPS that read 0, and the plant identified from it had A[xdot, phi] −0.7 × g·dt
    clean_streams, _ = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    a, b = _mode_span(clean_streams, "ALT_HOLD")

    def no_fix(streams, options):
        gps = streams["GPS"]
        inside = (gps["t"] >= a) & (gps["t"] <= b)
        if lost == "no fix":
            gps.loc[inside, "Status"] = 1  # a 2D fix at best: no velocity
        else:
            streams["GPS"] = gps[~inside].reset_index(drop=True)  # the receiver stopped reporting

    clean = adapters.load(_copter_bin(tmp_path, "clean.bin")[0], "ardupilot_manual")
    path, _ = _copter_bin(tmp_path, "no_fix.bin", no_fix)
    ds = adapters.load(path, "ardupilot_manual")
    modes = [d.meta["mode"] for d in ds]
    assert "ALT_HOLD" in [d.meta["mode"] for d in clean] and "ALT_HOLD" not in modes
    assert len(ds) == len(clean) - 1
    note = ds[0].meta["unfixed"]
    assert "\n" not in note and "dropped 1 segment(s) flown without a GPS fix" in note
    said = r"\d+ GPS samples, none with a fix" if lost == "no fix" else "no GPS samples"
    assert re.search(r"the ALT_HOLD segment [\d.]+–[\d.]+ s \(" + said + r"\)", note)
    assert "dead-reckons" in note
    assert not any(d.meta.get("unfixed") for d in clean)


def test_a_flight_without_any_gps_fix_stops_in_one_line(tmp_path):
    # erle 7-9-2014/11.BIN: 9 GPS samples in 900 s, one with a fix; its five STABILIZE segments gave a plant with
    # A[xdot, phi] 0.25 × g·dt, and the fit stopped for that plant's physics
    def no_fix(streams, options):
        streams["GPS"]["Status"] = 0

    path, _ = _copter_bin(tmp_path, "no_fix.bin", no_fix)
    with pytest.raises(DataError, match=r"dropped \d+ segment\(s\) flown without a GPS fix \(GPS\.Status below 3 in "
                                        r"every sample, or no sample\): the STABILIZE segment") as info:
        adapters.load(path, "ardupilot_manual")
    assert "\n" not in str(info.value)
