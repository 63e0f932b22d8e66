"""An ArduPlane 4.x log starts on arming, after its ``EV`` ARMED: it holds no arming event, yet ``STAT.Armed`` is 1 in
every ``STAT`` message (PyFlightCoach/FlightData's center_0003.bin and pilot_0004.BIN, ArduPlane V4.2.3). The
shipped plane mapping's armed rule falls back to that held flag where the log holds no arming event, and
``inspect`` says the same; before, both logs stopped with "never armed", which was not the cause.

A log whose logging left the sticks out (those two logs hold no ``RCIN`` and no ``IMU`` message) stops naming the
pilot's inputs first, with every other channel the log lacks.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.formats import dataflash_write
from adapters.mapping import load_mapping
from workbench.errors import DataError, MappingError

SET_HOME = 25  # ArduPilot LogEvent SET_HOME: an event that says nothing about arming


def _plane(tmp_path, name, armed=None, drop=(), events=((3.0, SET_HOME),)):
    """The example ArduPlane 4.x log with no ARM message and ``events`` [(time from the start, EV id)] (one
    non-arming event by default); ``armed`` the STAT.Armed value per STAT message (None: no STAT stream);
    ``drop`` streams left out (not declared)."""
    streams, options = dataflash_write.example_streams("new", "plane", seconds=60.0, seed=5)
    t0 = float(streams["ATT"]["t"].iloc[0])
    del streams["ARM"]
    streams["EV"] = pd.DataFrame({"t": [t0 + a for a, _ in events], "Id": np.array([i for _, i in events], np.uint8)})
    if armed is not None:
        t = t0 + np.arange(len(armed)) * (60.0 / len(armed))
        streams["STAT"] = pd.DataFrame(
            {"t": t, "isFlying": np.ones(len(armed), np.uint8), "Armed": np.asarray(armed, np.uint8)}
        )
        options["formats"] = {**options["formats"], "STAT": "BB"}
        options["units"] = {**options["units"], "STAT": {"isFlying": "-", "Armed": "-"}}
        options["multipliers"] = {**options["multipliers"], "STAT": {"isFlying": "-", "Armed": "-"}}
    for s in drop:  # the stream and its instances (IMU[0], IMU[1])
        for k in [k for k in streams if k == s or k.startswith(f"{s}[")]:
            del streams[k]
    return dataflash_write.write(tmp_path / name, streams, **options), t0


def test_a_plane_log_without_arming_events_is_armed_by_its_held_stat_flag(tmp_path):
    path, t0 = _plane(tmp_path, "stat_armed.bin", armed=[1] * 300)
    ds = adapters.load(path, "arduplane_manual")
    assert len(ds) >= 1
    summary = adapters.inspect(path)
    assert summary.armed and summary.armed[0][0] == pytest.approx(t0, abs=1e-6)
    assert summary.armed_text != "armed: never armed"


def test_the_held_flag_decides_where_it_says_disarmed(tmp_path):
    n = 300
    armed = np.zeros(n, np.uint8)
    armed[n // 3 : 2 * n // 3] = 1  # armed over the middle third only
    path, t0 = _plane(tmp_path, "stat_middle.bin", armed=armed)
    stat_t = t0 + np.arange(n) * (60.0 / n)
    lo, hi = stat_t[n // 3], stat_t[2 * n // 3]
    ds = adapters.load(path, "arduplane_manual")
    assert len(ds)
    for d in ds:
        assert lo - 1e-6 <= d.meta["t0"] and d.meta["t0"] + d.t[-1] <= hi + 1e-6
    np.testing.assert_allclose(adapters.inspect(path).armed, [(lo, hi)], atol=1e-6)


def test_a_held_flag_that_never_says_armed_is_never_armed_by_that_flag(tmp_path):
    path, _ = _plane(tmp_path, "stat_never.bin", armed=[0] * 120)
    with pytest.raises(
        DataError,
        match=r"never armed: STAT \(STAT\.Armed\) says the vehicle was disarmed in all "
        r"120 message\(s\)",
    ):
        adapters.load(path, "arduplane_manual")
    assert adapters.inspect(path).armed_text == "armed: never armed"


def test_without_the_held_flag_a_log_without_arming_events_is_still_never_armed(tmp_path):
    path, _ = _plane(tmp_path, "no_stat.bin")
    with pytest.raises(DataError, match=r"never armed: the log records arming as events"):
        adapters.load(path, "arduplane_manual")


def test_arming_events_decide_over_the_held_flag(tmp_path):
    # the flag says armed throughout, the one ARMED event from 10 s: where the log holds events, they decide
    path, t0 = _plane(tmp_path, "events.bin", armed=[1] * 300, events=[(10.0, 10)])
    ds = adapters.load(path, "arduplane_manual")
    assert len(ds) and min(d.meta["t0"] for d in ds) >= t0 + 10.0 - 1e-6


def test_a_log_without_the_sticks_names_the_pilot_s_inputs_first(tmp_path):
    path, _ = _plane(tmp_path, "no_sticks.bin", armed=[1] * 300, drop=("RCIN", "IMU"))
    with pytest.raises(MappingError) as err:
        adapters.load(path, "arduplane_manual")
    text = str(err.value)
    assert "the pilot's inputs u1, u2 are not in this log" in text
    assert text.index("'u1'") < text.index("phidot")
    assert "also not in it: u2 (RCIN.C3), phidot (IMU.GyrX or IMU[0].GyrX)" in text


def test_a_held_fallback_belongs_to_an_event_rule(tmp_path):
    base = 'name = "m"\ndt = 0.1\nstates = ["x"]\ninputs = ["u"]\n[channels]\nx = "A.x"\nu = "A.u"\n[segment]\n'

    def parse(armed: str):
        path = tmp_path / "m.toml"
        path.write_text(base + f"armed = {armed}\n")
        return load_mapping(path)

    good = parse('{ source = "EV.Id", on = [10], off = [11], held = { source = "STAT.Armed", equals = 1 } }')
    assert good.segment.armed.held is not None and good.segment.armed.held.equals == 1
    assert any(s.source == "STAT.Armed" for s in good.selectors())
    with pytest.raises(MappingError, match=r"segment\.armed\.held"):
        parse('{ source = "STAT.Armed", equals = 1, held = { source = "X.y" } }')
    with pytest.raises(MappingError, match=r"segment\.armed\.held"):
        parse('{ source = "EV.Id", on = [10], off = [11], held = { source = "EV.Id", on = [1], off = [2] } }')
