"""``workbench view LOG`` without ``--mapping``: the vehicle's shipped mapping, said, as import/fit/evaluate use
it, so the first view shows the flight's states (the raw tabs beside them); ``--raw`` shows the log alone."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from pymavlink import mavutil
from rerun.chunk import RrdReader

import adapters
from adapters.mapping import load_mapping
from adapters.modes import mode_number
from adapters.writer import demo_streams
from workbench.cli import main
from workbench.errors import DataError
from workbench.sim.landing import simulate_landings

EPOCH, PAUSE = 1_704_067_200.0, 2.0


@pytest.fixture(scope="module")
def copter_tlog(tmp_path_factory):
    """Two landings flown in STABILIZE by an ArduCopter (its HEARTBEATs name the vehicle), as a tlog."""
    ds = simulate_landings("CS1", 2, seed=3)
    streams = demo_streams(ds, load_mapping("ardupilot_manual").for_format("tlog"), epoch=EPOCH, pause=PAUSE)
    for frame in streams.values():
        frame["time_boot_ms"] = np.rint((frame["t"].to_numpy() - EPOCH) * 1000.0).astype(np.int64)
    ml = mavutil.mavlink
    t = streams["ATTITUDE"]["t"].to_numpy()[::50]
    streams["HEARTBEAT"] = pd.DataFrame({
        "t": t, "type": ml.MAV_TYPE_QUADROTOR, "autopilot": ml.MAV_AUTOPILOT_ARDUPILOTMEGA,
        "base_mode": ml.MAV_MODE_FLAG_SAFETY_ARMED | ml.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        "custom_mode": mode_number("arducopter", "STABILIZE"), "system_status": 4, "mavlink_version": 3})
    return adapters.FORMATS["tlog"].write(tmp_path_factory.mktemp("view") / "copter.tlog", streams)


def _paths(rrd) -> set[str]:
    return {str(c.entity_path) for c in RrdReader(rrd).stream()}


def test_view_without_a_mapping_uses_the_vehicles_and_says_which(copter_tlog, tmp_path, capsys):
    chosen, _ = adapters.choose_mapping(copter_tlog)
    assert chosen == "ardupilot_manual"  # the log's HEARTBEATs name an ArduCopter
    out = tmp_path / "v.rrd"
    assert main(["view", str(copter_tlog), "--save", str(out)]) == 0
    said = capsys.readouterr().out
    assert f"mapping {chosen}" in said
    paths = _paths(out)
    demos = adapters.load(copter_tlog, chosen)
    # the flight's states per demonstration (previously only the raw streams), and the raw tabs beside them
    assert len(demos) and {f"/demos/{d.id}/states/{s}" for d in demos for s in demos.state_names} <= paths
    assert any(p.startswith("/log/streams/") for p in paths)


def test_view_raw_shows_the_log_alone(copter_tlog, tmp_path):
    out = tmp_path / "raw.rrd"
    assert main(["view", str(copter_tlog), "--raw", "--save", str(out), "-q"]) == 0
    paths = _paths(out)
    assert any(p.startswith("/log/streams/") for p in paths)
    assert not [p for p in paths if p.startswith("/demos")]


def test_view_of_a_log_no_mapping_makes_demonstrations_of_shows_it_raw_with_the_cause(copter_tlog, tmp_path,
                                                                                          capsys):
    # the same flight never armed: the mapping makes no demonstration; the log still opens, the cause said
    streams = adapters.read_streams(copter_tlog)
    streams["HEARTBEAT"]["base_mode"] = mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    log = adapters.FORMATS["tlog"].write(tmp_path / "disarmed.tlog", streams)
    with pytest.raises(DataError) as cause:
        adapters.load(log, "ardupilot_manual")
    out = tmp_path / "d.rrd"
    assert main(["view", str(log), "--save", str(out)]) == 0
    assert str(cause.value) in capsys.readouterr().err
    paths = _paths(out)
    assert any(p.startswith("/log/streams/") for p in paths) and not [p for p in paths if p.startswith("/demos")]
