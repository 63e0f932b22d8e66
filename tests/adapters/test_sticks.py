"""Sticks by their role (adapters/sticks.py): the channel the log's own RC map gives a stick, and the check that the
mapped stick moves with the attitude it commands.

Every 2014 – early-2015 Erle PXF log has ``RCMAP_ROLL = 2, RCMAP_PITCH = 1``; a mapping that read channel 1 as the
roll stick modelled the pitch stick against the roll-plane states (erlerobot/logs pxf/copter/10-11-2014/104.BIN:
C1 correlates −0.80 with ATT.DesPitch and +0.03 with DesRoll). The logs here are written by the project's writers
with the roll stick on channel 2 and the pitch stick on channel 1, as there.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest
from pymavlink import mavutil

import adapters
from adapters import sticks
from adapters.formats import dataflash_write
from adapters.mapping import load_mapping
from adapters.modes import mode_number
from adapters.streams import Streams
from adapters.writer import demo_streams, layout
from workbench.errors import DataError, MappingError
from workbench.sim.landing import simulate_landings

EPOCH, PAUSE = 1_704_067_200.0, 2.0


def _pwm(stick: np.ndarray) -> np.ndarray:
    return np.rint(1500 + 400 * np.clip(stick, -1, 1)).astype(np.int16)


def _copter_bin(tmp_path, name: str, rcmap: dict[str, float] | None, roll_on: int, seconds: float = 40.0):
    """An ArduCopter 3.2-style log whose roll stick (the one ATT.DesRoll follows) is RC channel ``roll_on`` and
    whose pitch stick (DesPitch) is the other of 1 and 2; ``rcmap``: the RCMAP_* parameters it logs."""
    streams, options = dataflash_write.example_streams("old", "copter", seconds=seconds, seed=3)
    rc, att = streams["RCIN"], streams["ATT"]
    rng = np.random.default_rng(7)
    t = rc["t"].to_numpy()
    roll_stick = np.sin(t / 1.7) * np.cos(t / 5.3) + rng.normal(0, 0.05, t.size)
    pitch_stick = np.sin(t / 2.9 + 1.0) + rng.normal(0, 0.05, t.size)
    pitch_on = 3 - roll_on
    rc[f"C{roll_on}"], rc[f"C{pitch_on}"] = _pwm(roll_stick), _pwm(-pitch_stick)  # pitch channel reversed
    ta = att["t"].to_numpy()
    held = np.searchsorted(t, ta, side="right") - 1
    ok = held >= 0
    att.loc[ok, "DesRoll"] = np.round(30 * roll_stick[held[ok]] + rng.normal(0, 1, ok.sum()), 2)
    att.loc[ok, "DesPitch"] = np.round(30 * pitch_stick[held[ok]] + rng.normal(0, 1, ok.sum()), 2)
    if rcmap:
        parm = streams["PARM"]
        extra = pd.DataFrame({"t": parm["t"].iloc[0], "Name": list(rcmap), "Value": np.float32(list(rcmap.values()))})
        streams["PARM"] = pd.concat([parm, extra], ignore_index=True)
    return dataflash_write.write(tmp_path / name, streams, **options), streams


def _held(rc: pd.DataFrame, column: str, ds) -> list[np.ndarray]:
    """The PWM stick of ``column`` held (zero-order) on each demonstration's grid, as the pwm transform maps it."""
    t = rc["t"].to_numpy()
    out = []
    for d in ds:
        at = np.searchsorted(t, d.meta["t0"] + d.t + 1e-9, side="right") - 1
        out.append((rc[column].to_numpy(np.float64)[at] - 1500.0) / 500.0)
    return out


def test_a_bin_with_rcmap_roll_2_reads_the_roll_stick_from_channel_2(tmp_path):
    path, streams = _copter_bin(tmp_path, "rcmap2.bin", {"RCMAP_ROLL": 2, "RCMAP_PITCH": 1}, roll_on=2)
    ds = adapters.load(path, "ardupilot_manual")
    assert len(ds) >= 2
    u1 = ds.input_names.index("u1")
    for d, expected, wrong in zip(ds, _held(streams["RCIN"], "C2", ds), _held(streams["RCIN"], "C1", ds),
                                  strict=True):
        np.testing.assert_allclose(d.u[:, u1], expected, atol=1e-12)
        assert not np.allclose(d.u[:, u1], wrong)
    note = ds[0].meta["sticks"]
    assert "u1 (roll) = RCIN.C2 (RCMAP_ROLL = 2)" in note and "u2 (throttle) = RCIN.C3" in note
    assert float(re.search(r"u1 moves with ATT\.DesRoll \(r = ([+-][\d.]+)\)", note).group(1)) > 0.9


def test_a_bin_without_rcmap_parameters_reads_the_default_and_says_so(tmp_path):
    path, _ = _copter_bin(tmp_path, "default.bin", None, roll_on=1)
    ds = adapters.load(path, "ardupilot_manual")
    assert "u1 (roll) = RCIN.C1 (RCMAP_ROLL not in the log: ArduPilot's default 1)" in ds[0].meta["sticks"]


def test_a_mapped_channel_that_does_not_move_with_the_commanded_roll_is_stopped(tmp_path):
    # the log says RCMAP_ROLL = 1 (a stale parameter), but DesRoll follows channel 2
    path, streams = _copter_bin(tmp_path, "stale.bin", {"RCMAP_ROLL": 1, "RCMAP_PITCH": 2}, roll_on=2)
    with pytest.raises(DataError) as info:
        adapters.load(path, "ardupilot_manual")
    message = str(info.value)
    assert "\n" not in message
    assert "u1 reads RCIN.C1 (the roll stick by RCMAP_ROLL = 1), which does not move with ATT.DesRoll" in message
    assert "the stick is on RCIN.C2" in message
    # the correlations printed are the channels' own over the kept segments
    looked = adapters.load(path, "ardupilot_manual", allow_still=True)
    assert looked[0].meta["still"] == message
    att, rc = streams["ATT"], streams["RCIN"]
    inside = np.zeros(len(att), dtype=bool)
    for d in looked:
        if sticks.commands_setpoint(d.meta["plant_group"]):  # not LOITER: there the position controller leans
            inside |= (att["t"] >= d.meta["t0"]) & (att["t"] <= d.meta["t0"] + d.t[-1])
    ta = att["t"].to_numpy()[inside]
    held = np.searchsorted(rc["t"].to_numpy(), ta, side="right") - 1
    desired = att["DesRoll"].to_numpy()[inside]
    r = {c: np.corrcoef(rc[c].to_numpy(np.float64)[held], desired)[0, 1] for c in ("C1", "C2")}
    printed = re.search(r"correlation ([+-][\d.]+) over the (\d+) samples .* RCIN\.C2 correlates ([+-][\d.]+)", message)
    assert float(printed.group(1)) == pytest.approx(r["C1"], abs=0.006)
    assert float(printed.group(3)) == pytest.approx(r["C2"], abs=0.006)
    assert int(printed.group(2)) == inside.sum()
    # a copy of the mapping that reads channel 2 imports it
    text = open(load_mapping("ardupilot_manual").path).read()
    copy = tmp_path / "c2.toml"
    copy.write_text(text.replace('"RCIN.C{roll}"', '"RCIN.C2"'))
    assert len(adapters.load(path, copy))


def test_segments_where_the_autopilot_commands_the_attitude_are_not_judged(tmp_path):
    # erlerobot/logs pxf/copter/22-12-2014/37.BIN: in LOITER the position controller's DesRoll turns with the
    # heading and correlated -0.83 with the yaw stick (C4), over a DesRoll spread three times ALT_HOLD's; pooled
    # over every kept segment, the roll stick (C2, +0.95 in ALT_HOLD) was called the wrong channel
    path, streams = _copter_bin(tmp_path, "loiter.bin", {"RCMAP_ROLL": 2, "RCMAP_PITCH": 1}, roll_on=2, seconds=100.0)
    modes = adapters.read(path).info["flight_modes"]
    loiter = [(a, b) for name, a, b in modes if name == "LOITER"]
    assert loiter
    rc, att = streams["RCIN"], streams["ATT"]
    ta = att["t"].to_numpy()
    yaw = np.sin(rc["t"].to_numpy() / 0.9)
    rc["C4"] = _pwm(yaw)
    for a, b in loiter:
        inside = (ta >= a) & (ta <= b)
        held = np.searchsorted(rc["t"].to_numpy(), ta[inside], side="right") - 1
        att.loc[inside, "DesRoll"] = np.round(-90 * yaw[held], 2)
    options = dataflash_write.example_streams("old", "copter", seconds=100.0, seed=3)[1]
    path = dataflash_write.write(tmp_path / "loiter.bin", streams, **options)
    ds = adapters.load(path, "ardupilot_manual")
    assert "LOITER" in {d.meta["mode"] for d in ds}
    r = float(re.search(r"u1 moves with ATT\.DesRoll \(r = ([+-][\d.]+)\)", ds[0].meta["sticks"]).group(1))
    assert r > 0.9  # judged on the STABILIZE and ALT_HOLD segments, where the stick commands the lean


def test_a_stick_that_never_moves_its_setpoint_gives_no_verdict(tmp_path):
    # the example log's sticks are noise that no setpoint follows: no channel reaches a large correlation
    streams, options = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    path = dataflash_write.write(tmp_path / "noise.bin", streams, **options)
    ds = adapters.load(path, "ardupilot_manual")
    assert "u1: no stick moves ATT.DesRoll in the kept segments (r = " in ds[0].meta["sticks"]  # r ≈ 0: no stop


def _still_roll_bin(tmp_path, name: str, dead_zones: bool):
    """beastayyg's sample.bin in small: the roll and pitch sticks held at 1511 and 1514 µs, the yaw stick within
    3 µs of 1509 but moving with ATT.DesRoll; ``dead_zones``: the log holds RC1/RC4 _DZ 20 around _TRIM 1500."""
    path, streams = _copter_bin(tmp_path, name, {"RCMAP_ROLL": 1, "RCMAP_PITCH": 2}, roll_on=1)
    rc, att = streams["RCIN"], streams["ATT"]
    held = np.searchsorted(rc["t"].to_numpy(), att["t"].to_numpy(), side="right") - 1
    lean = (rc["C1"].to_numpy(np.float64) - 1500.0) / 400.0
    rc["C4"] = np.rint(1509 + 1.5 * lean).astype(np.int16)  # -1 … +1 of the stick: 1508 … 1510 µs
    att.loc[held >= 0, "DesRoll"] = np.round(30 * lean[held[held >= 0]], 2)
    rc["C1"], rc["C2"] = np.int16(1511), np.int16(1514)  # the sample's roll and pitch sticks: never moved
    if dead_zones:
        parm = streams["PARM"]
        names = ["RC1_DZ", "RC1_TRIM", "RC4_DZ", "RC4_TRIM"]
        extra = pd.DataFrame({"t": parm["t"].iloc[0], "Name": names, "Value": np.float32([20, 1500, 20, 1500])})
        streams["PARM"] = pd.concat([parm, extra], ignore_index=True)
    options = dataflash_write.example_streams("old", "copter", seconds=40.0, seed=3)[1]
    return dataflash_write.write(tmp_path / name, streams, **options)


def test_a_channel_inside_its_dead_zone_is_not_named_as_the_stick(tmp_path):
    # beastayyg/ardupilot-log-diagnosis sample.bin stopped with "the stick is on RCIN.C4": a yaw stick 3 µs off
    # centre, inside its 20 µs dead zone, correlated -0.80 with DesRoll while the roll stick never moved
    without = _still_roll_bin(tmp_path, "no_dz.bin", dead_zones=False)
    with pytest.raises(DataError, match=r"the stick is on RCIN\.C4"):  # without the log's zones: as before
        adapters.load(without, "ardupilot_manual")
    path = _still_roll_bin(tmp_path, "dz.bin", dead_zones=True)
    try:
        note = adapters.load(path, "ardupilot_manual")[0].meta["sticks"]
    except DataError as e:  # a later check may stop it; not the stick check
        assert "the stick is on" not in str(e)
        note = adapters.load(path, "ardupilot_manual", allow_still=True)[0].meta["sticks"]
    assert "u1: no stick moves ATT.DesRoll in the kept segments (RCIN.C1 stays inside its dead zone, RC1_DZ = 20 " \
           "around RC1_TRIM = 1500)" in note


def test_ground_time_is_cut_before_the_stick_check_and_the_fit(tmp_path):
    # beastayyg log_0038 (ArduCopter 3.4.6) stopped with "the stick is on RCIN.C3": 16 of its 29 kept STABILIZE s
    # are on the ground, where the attitude target follows the measured attitude, not the stick. EV NOT_LANDED (28)
    # says when it took off and LAND_COMPLETE (18) when it was down again; LAND_COMPLETE_MAYBE (17) is no landing
    # (ArduCopter clears it without an event when the vehicle climbs away)
    path, streams = _copter_bin(tmp_path, "ground.bin", {"RCMAP_ROLL": 1, "RCMAP_PITCH": 2}, roll_on=1)
    rc, att, ev = streams["RCIN"], streams["ATT"], streams["EV"]
    armed = float(ev["t"].iloc[0])  # ARMED, in the first STABILIZE span
    took_off, maybe, landed = armed + 6.0, armed + 11.0, armed + 17.0
    ta = att["t"].to_numpy()
    held = np.searchsorted(rc["t"].to_numpy(), ta, side="right") - 1
    throttle = np.sin(rc["t"].to_numpy() / 0.7)
    rc["C3"] = _pwm(throttle)
    for a, b in ((armed, took_off), (landed, np.inf)):  # on the ground DesRoll moves with anything but the roll stick
        ground = (ta >= a) & (ta < b) & (held >= 0)
        att.loc[ground, "DesRoll"] = np.round(-90 * throttle[held[ground]], 2)
    extra = pd.DataFrame({"t": [took_off, maybe, landed], "Id": np.array([28, 17, 18], np.uint8)})
    streams["EV"] = pd.concat([ev, extra], ignore_index=True).sort_values("t", kind="stable").reset_index(drop=True)
    options = dataflash_write.example_streams("old", "copter", seconds=40.0, seed=3)[1]
    path = dataflash_write.write(tmp_path / "ground.bin", streams, **options)
    ds = adapters.load(path, "ardupilot_manual")  # it stopped with "the stick is on RCIN.C3"
    r = float(re.search(r"u1 moves with ATT\.DesRoll \(r = ([+-][\d.]+)\)", ds[0].meta["sticks"]).group(1))
    assert r > 0.9
    # only the air is kept, on the log's clock as the reader puts the events on it
    events = adapters.read(path).frames["EV"]
    at = dict(zip(events["Id"].astype(int), events["t"].astype(float), strict=False))
    starts, ends = [d.meta["t0"] for d in ds], [d.meta["t0"] + d.t[-1] for d in ds]
    assert min(starts) >= at[28] and max(ends) <= at[18]
    assert any(a < at[17] < b for a, b in zip(starts, ends, strict=True))  # no cut at LAND_COMPLETE_MAYBE


def test_manual_modes_flown_only_on_the_ground_are_named(tmp_path):
    # beastayyg sample.bin, peterbarker_3: armed in STABILIZE on the ground, the take-off in AUTO (here RTL); once
    # the ground time is cut nothing is left, and the line says so (it said "no stick input in these spans: u1, u2")
    path, streams = _copter_bin(tmp_path, "ground_only.bin", {"RCMAP_ROLL": 1, "RCMAP_PITCH": 2}, roll_on=1)
    ev = streams["EV"]
    modes = streams["MODE"]
    rtl = float(modes["t"][modes["ModeNum"] == mode_number("arducopter", "RTL")].iloc[0])
    extra = pd.DataFrame({"t": [rtl + 0.5], "Id": np.array([28], np.uint8)})  # NOT_LANDED: the take-off, in RTL
    streams["EV"] = pd.concat([ev, extra], ignore_index=True).sort_values("t", kind="stable").reset_index(drop=True)
    options = dataflash_write.example_streams("old", "copter", seconds=40.0, seed=3)[1]
    path = dataflash_write.write(tmp_path / "ground_only.bin", streams, **options)
    with pytest.raises(DataError) as info:
        adapters.load(path, "ardupilot_manual")
    message = str(info.value)
    assert "\n" not in message and "no stick input" not in message
    found = re.search(r"on the ground through ([\d.]+) of the ([\d.]+) s armed in", message)
    ground, total = float(found.group(1)), float(found.group(2))
    # in the air in a kept mode only from the last STABILIZE to the last DISARMED, on the reader's clock
    read = adapters.read(path).frames
    air = float(read["EV"]["t"][read["EV"]["Id"] == 11].iloc[-1]) - float(read["MODE"]["t"].iloc[-1])
    assert total - ground == pytest.approx(air, abs=0.15) and 0 < air < 5
    assert "(EV.Id = 18 LAND_COMPLETE on landing, 28 NOT_LANDED on take-off); its " in message
    assert "s in the air there leave no piece of min_duration = 5 s" in message


def test_a_log_without_landed_events_keeps_its_spans(tmp_path):
    # a firmware that logs no landed events, or a flight that never lands in its log, says nothing about the ground
    path, streams = _copter_bin(tmp_path, "air.bin", {"RCMAP_ROLL": 1, "RCMAP_PITCH": 2}, roll_on=1)
    assert not streams["EV"]["Id"].isin([17, 18, 28]).any()
    ds = adapters.load(path, "ardupilot_manual")
    assert min(d.meta["t0"] for d in ds) < float(streams["EV"]["t"].iloc[0]) + 1.0  # from arming, as before


# -------------------------------------------------------------------------------------------------- tlog


def _tlog(tmp_path, name: str, rcmap: dict[str, float], status=None, between: str = "STABILIZE") -> tuple:
    """A tlog of simulated flights through ardupilot_manual, the roll stick on RC channel 2 (where ``rcmap`` says
    it is), the pitch stick on channel 1, NAV_CONTROLLER_OUTPUT's desired roll following the roll stick; ``status``
    gives the HEARTBEATs' system_status from their times (default: MAV_STATE_ACTIVE, 4, throughout); the flights
    are flown in STABILIZE, the pauses between them in ``between``."""
    flights = simulate_landings("CS1", 2, seed=3)
    numbers = {"roll": int(rcmap.get("RCMAP_ROLL", 1)), "throttle": 3}
    m = sticks._substitute(load_mapping("ardupilot_manual").for_format("tlog"), numbers, ())
    streams = demo_streams(flights, m, epoch=EPOCH, pause=PAUSE)
    for frame in streams.values():
        frame["time_boot_ms"] = np.rint((frame["t"].to_numpy() - EPOCH) * 1000.0).astype(np.int64)
    rc = streams["RC_CHANNELS"]
    roll_pwm = rc["chan2_raw"].to_numpy(np.float64)
    rng = np.random.default_rng(5)
    rc["chan1_raw"] = _pwm(np.sin(rc["t"].to_numpy() / 2.3))  # the pitch stick, which the roll plane never sees
    streams["NAV_CONTROLLER_OUTPUT"] = pd.DataFrame({
        "t": rc["t"], "nav_roll": 30 * (roll_pwm - 1500) / 500 * (1 + rng.normal(0, 0.1, len(rc))),
        "nav_pitch": 0.0, "nav_bearing": 0, "target_bearing": 0, "wp_dist": 0, "alt_error": 0.0,
        "aspd_error": 0.0, "xtrack_error": 0.0})
    spans = layout(flights, EPOCH, PAUSE)
    ml = mavutil.mavlink
    stab = mode_number("arducopter", "STABILIZE")
    other = mode_number("arducopter", between)
    hb = [(t, stab if a <= t <= b else other, 129) for a, b in spans for t in np.arange(a - 1.0, b + 1.0, 1.0)]
    hb_t = np.array([h[0] for h in hb])
    streams["HEARTBEAT"] = pd.DataFrame({"t": [h[0] for h in hb], "type": ml.MAV_TYPE_QUADROTOR,
                                         "autopilot": ml.MAV_AUTOPILOT_ARDUPILOTMEGA, "base_mode": [h[2] for h in hb],
                                         "custom_mode": [h[1] for h in hb], "mavlink_version": 3,
                                         "system_status": 4 if status is None else status(hb_t)})
    streams["PARAM_VALUE"] = pd.DataFrame({"t": EPOCH - 5.0, "param_id": list(rcmap),
                                           "param_value": np.float32(list(rcmap.values())), "param_type": 9,
                                           "param_count": len(rcmap), "param_index": np.arange(len(rcmap))})
    path = adapters.FORMATS["tlog"].write(tmp_path / name, streams)
    return path, flights


def test_a_tlog_with_rcmap_roll_2_reads_the_roll_stick_from_channel_2(tmp_path):
    path, flights = _tlog(tmp_path, "rcmap2.tlog", {"RCMAP_ROLL": 2.0, "RCMAP_PITCH": 1.0})
    ds = adapters.load(path, "ardupilot_manual")
    assert len(ds) == len(flights)
    u1 = ds.input_names.index("u1")
    for d, original in zip(ds, flights, strict=True):
        step = int(round(ds.dt / flights.dt))
        # the stick round trip through an int16 PWM (1 µs = 0.002 of the stick)
        np.testing.assert_allclose(d.u[:-1, u1], original.u[: (d.u.shape[0] - 1) * step: step, u1], atol=0.0011)
    note = ds[0].meta["sticks"]
    assert "u1 (roll) = RC_CHANNELS.chan2_raw (RCMAP_ROLL = 2)" in note
    assert "u1 moves with NAV_CONTROLLER_OUTPUT.nav_roll" in note


def test_a_tlog_whose_rcmap_names_the_wrong_channel_is_stopped(tmp_path):
    path, _ = _tlog(tmp_path, "stale.tlog", {"RCMAP_ROLL": 2.0})
    text = open(load_mapping("ardupilot_manual").path).read()
    copy = tmp_path / "c1.toml"
    copy.write_text(text.replace('"RC_CHANNELS.chan{roll}_raw"', '"RC_CHANNELS.chan1_raw"'))
    with pytest.raises(DataError, match=r"u1 reads RC_CHANNELS\.chan1_raw, which does not move with "
                                        r"NAV_CONTROLLER_OUTPUT\.nav_roll.*the stick is on RC_CHANNELS\.chan2_raw"):
        adapters.load(path, copy)


def test_a_tlog_s_ground_time_is_cut_by_the_heartbeat_s_landed_state(tmp_path):
    # ArduCopter's HEARTBEAT says STANDBY (3) while its land detector says landed and ACTIVE (4) in the air; a
    # failsafe's CRITICAL (5) hides it and says nothing. No tlog we have carries EXTENDED_SYS_STATE (checked with
    # pymavlink on dronekit_flight, eaics_flight, uavlogviewer_fork_sample and uavlogviewer_vtol); dronekit_flight's
    # heartbeats say STANDBY while armed for 12 s of its STABILIZE flights
    path, flights = _tlog(tmp_path, "air.tlog", {"RCMAP_ROLL": 2.0})
    spans = layout(flights, EPOCH, PAUSE)
    (a0, b0), (_, b1) = spans[0], spans[1]
    took_off, critical, landed = a0 + 3.0, (a0 + b0) / 2, b1 - 3.0

    def status(t: np.ndarray) -> np.ndarray:
        s = np.where((t < took_off) | (t >= landed), 3, 4)
        s[np.argmin(np.abs(t - critical))] = 5  # a failsafe in flight: no landing
        return s

    ground, _ = _tlog(tmp_path, "ground.tlog", {"RCMAP_ROLL": 2.0}, status=status)
    before = adapters.load(path, "ardupilot_manual")
    ds = adapters.load(ground, "ardupilot_manual")
    assert len(ds) == len(before) == 2
    starts = [d.meta["t0"] for d in ds]
    ends = [d.meta["t0"] + d.t[-1] for d in ds]
    hb_t = np.array(sorted(t for a, b in spans for t in np.arange(a - 1.0, b + 1.0, 1.0)))
    first_active = float(hb_t[np.searchsorted(hb_t, took_off)])  # the heartbeat that first says ACTIVE
    assert first_active - ds.dt <= starts[0] and before[0].meta["t0"] < took_off - 1.0
    assert starts[0] < critical < ends[0]  # the CRITICAL heartbeat cut nothing
    assert ends[1] <= float(hb_t[np.searchsorted(hb_t, landed)]) < before[1].meta["t0"] + before[1].t[-1]
    # heartbeats that never say STANDBY or ACTIVE say nothing about the ground: every span kept
    hidden, _ = _tlog(tmp_path, "hidden.tlog", {"RCMAP_ROLL": 2.0}, status=lambda t: np.full(t.size, 5))
    kept = adapters.load(hidden, "ardupilot_manual")
    assert [d.meta["t0"] for d in kept] == [d.meta["t0"] for d in before]
    # a tlog armed in STABILIZE only on the ground says so, the landed state named
    parked, _ = _tlog(tmp_path, "parked.tlog", {"RCMAP_ROLL": 2.0}, status=lambda t: np.full(t.size, 3))
    with pytest.raises(DataError, match=r"no flight to import: the vehicle is on the ground through .* by its landed "
                                        r"events \(HEARTBEAT\.system_status = 3 MAV_STATE_STANDBY on landing, 4 "
                                        r"MAV_STATE_ACTIVE on take-off\)"):
        adapters.load(parked, "ardupilot_manual")


def test_a_damaged_tlog_does_not_blame_the_damage_for_a_mode_the_log_states(tmp_path):
    # dronekit_flight (1314 CRC failures) said its STABILIZE flights were cut by "data lost to the damage" where the
    # pilot had switched to LOITER, RTL or disarmed: a frame whose checksum fails is dropped, never read garbled, so
    # a mode that reads otherwise in a tlog is the log's own
    path, flights = _tlog(tmp_path, "loiter.tlog", {"RCMAP_ROLL": 2.0}, between="LOITER")
    damaged = tmp_path / "damaged.tlog"
    data = bytearray(path.read_bytes())
    data[len(data) // 4] ^= 0xFF  # the frame this byte falls in fails its checksum: the reader skips it
    damaged.write_bytes(bytes(data))
    ds = adapters.load(damaged, "ardupilot_manual")
    assert len(ds) == len(flights) == 2
    streams = adapters.read(damaged)
    assert sum(streams.skipped.values()) > 0  # the file is damaged
    assert not any("damaged" in d.meta for d in ds), ds[0].meta.get("damaged")


# ---------------------------------------------------------------------------------------- the schema, the map


def test_a_stick_by_role_needs_an_rc_map_and_a_known_role(tmp_path):
    base = ('dt = 0.1\nstates = ["x"]\ninputs = ["u1"]\n[channels]\nx = "A.x"\n')
    for body, match in ((base + 'u1 = "RCIN.C{roll}"\n', r"names the roll stick by its role, but the mapping says "
                                                         r"no rc_map"),
                        ('rc_map = "ardupilot"\n' + base + 'u1 = "RCIN.C{elevator}"\n', r"\{elevator\}.*not a stick"),
                        ('rc_map = "futaba"\n' + base + 'u1 = "RCIN.C{roll}"\n', r"unknown RC map 'futaba'"),
                        ('rc_map = "ardupilot"\n' + base + 'u1 = "RCIN.C{roll}"\n[setpoints]\nx = "ATT.DesRoll"\n',
                         r"setpoints: \['x'\] are not inputs")):
        path = tmp_path / "m.toml"
        path.write_text(body)
        with pytest.raises(MappingError, match=match):
            load_mapping(path)


def test_px4_s_unassigned_stick_is_named():
    m = load_mapping("px4_manual").for_format("tlog")
    streams = Streams("px4.tlog", "tlog", {"PARAM_VALUE": {"t": np.zeros(1), "param_id": np.array(["RC_MAP_ROLL"],
                                                                                                   dtype=object),
                                                           "param_value": np.zeros(1)}})
    with pytest.raises(DataError, match=r"u1 is the roll stick, but the log's RC_MAP_ROLL = 0\.0 is on no RC channel "
                                        r"\(unassigned\)"):
        sticks.resolve(m, streams)
    assert sticks.resolve(load_mapping("px4_manual").for_format("ulog"), streams).sticks == ()  # named fields there


def test_log_parameters_take_the_last_value_sent():
    streams = Streams("p.tlog", "tlog", {"PARAM_VALUE": {"t": np.arange(3.0),
                                                         "param_id": np.array(["RCMAP_ROLL\x00", "A", "RCMAP_ROLL"],
                                                                              dtype=object),
                                                         "param_value": np.array([1.0, 5.0, 2.0])}})
    assert sticks.log_parameters(streams) == {"RCMAP_ROLL": 2.0, "A": 5.0}
