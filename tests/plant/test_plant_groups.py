"""A plant per kind of stick (issue 41 §2): segments are grouped by what the stick commands in their flight mode, each
group gets its own plant, physics check and model, and ArduPlane's MANUAL is a plant of its own.

The logs are written here, DataFlash files of a simulated vehicle flown in each mode (:mod:`workbench.sim.modes`),
whose stick responses are known; every expected number is computed from that simulated truth."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.formats import dataflash_write
from adapters.mapping import load_mapping
from adapters.modes import AUTOPILOT_HOLDS, MODE_TABLES, STICKS, mode_number, plant_group
from adapters.writer import demo_streams, layout
from workbench.cli import main
from workbench.data.plant_groups import PLANT_GROUPS, by_plant_group, select_plant_group
from workbench.errors import DataError, ModelError
from workbench.models.storage import load_model
from workbench.plant.physics import stick_responses
from workbench.plant.system import LinearSystem
from workbench.sim.modes import ModeVehicle, fly

DT = 0.1  # the shipped DataFlash mappings' grid
VEHICLE = ModeVehicle()


def _write_bin(path, groups, *, mapping: str, firmware: str, table: str, seconds: float = 25.0):
    """A DataFlash log of the vehicle flown in each group's mode in turn (two segments each), as ``mapping`` reads
    it: its states' messages, a MODE message at each segment's start, and a GPS whose velocity is the EKF's."""
    parts = [fly(VEHICLE, g, seed=i, n=2, seconds=seconds, dt=DT) for i, g in enumerate(groups)]
    ds = parts[0].with_demos([d for p in parts for d in p])
    epoch, pause = 5.0, 3.0
    streams = demo_streams(ds, load_mapping(mapping).for_format("dataflash"), epoch=epoch, pause=pause)
    numbers = [mode_number(table, d.meta["mode"]) for d in ds]
    streams["MODE"] = pd.DataFrame({"t": [a for a, _ in layout(ds, epoch, pause)], "Mode": numbers,
                                    "ModeNum": numbers})
    ekf = streams["EKF1"]
    if "VN" not in ekf:  # a mapping with the east velocity alone (the plane's): the vehicle flies east-west
        ekf["VN"] = 0.0
    streams["GPS"] = pd.DataFrame({"t": ekf["t"], "Status": 3, "Spd": np.hypot(ekf["VN"], ekf["VE"]),
                                   "GCrs": np.degrees(np.arctan2(ekf["VE"], ekf["VN"])) % 360})
    return dataflash_write.write(path, streams, firmware=firmware)


@pytest.fixture(scope="module")
def copter_bin(tmp_path_factory):
    """An ArduCopter flown in STABILIZE (the stick commands a lean angle), then LOITER (a velocity)."""
    return _write_bin(tmp_path_factory.mktemp("groups") / "stabilize_loiter.bin", ["angle", "velocity+climb"],
                      mapping="ardupilot_manual", firmware="ArduCopter V4.5.7 (2a3dc4b7)", table="arducopter")


def _close(got, truth, rel=0.1):
    assert [(r.input, r.state) for r in got] == [(r.input, r.state) for r in truth]
    for g, t in zip(got, truth, strict=True):
        assert g.per_full_stick == pytest.approx(t.per_full_stick, rel=rel), (str(g), str(t))
        assert g.time_constant_s == pytest.approx(t.time_constant_s, rel=rel), (str(g), str(t))


def test_every_mode_of_the_stick_table_is_a_mode_of_its_autopilot_and_a_known_group():
    for table, modes in STICKS.items():
        assert set(modes) <= set(MODE_TABLES[table].values()), table
        assert set(modes.values()) <= set(PLANT_GROUPS), table
    # the autopilot-held states are read off the same table: a velocity stick holds the position, a climb-rate
    # throttle the altitude
    assert "position" in AUTOPILOT_HOLDS["LOITER"] and "altitude" in AUTOPILOT_HOLDS["LOITER"]
    assert "altitude" in AUTOPILOT_HOLDS["ALT_HOLD"] and "position" not in AUTOPILOT_HOLDS["ALT_HOLD"]
    assert "STABILIZE" not in AUTOPILOT_HOLDS and "MANUAL" not in AUTOPILOT_HOLDS
    assert plant_group("arducopter", "ALT_HOLD") == "angle+climb" and plant_group("arduplane", "MANUAL") == "surface"
    assert plant_group("arducopter", "RTL") == "mode RTL"  # a mode the table does not know: a plant of its own


def test_poshold_s_stick_commands_a_lean_angle_and_its_autopilot_holds_the_position():
    # ArduCopter's PosHold / FlowHold: "the pilot stick inputs directly control the vehicle's lean angle", the throttle
    # as in AltHold, and the autopilot brakes and holds the position once the sticks are centred: the stick's kind is
    # ALT_HOLD's, the plant (vehicle and autopilot) is not, so neither is pooled with ALT_HOLD nor with LOITER
    for mode in ("POSHOLD", "FLOWHOLD"):
        group = PLANT_GROUPS[plant_group("arducopter", mode)]
        assert (group.lateral, group.throttle) == ("angle", "climb"), mode
        assert group.holds == AUTOPILOT_HOLDS[mode], mode  # read off the group, as every other mode's
        assert "position" in group.holds and "altitude" in group.holds, mode
    assert "position" not in PLANT_GROUPS[plant_group("arducopter", "ALT_HOLD")].holds
    assert plant_group("arducopter", "POSHOLD") != plant_group("arducopter", "ALT_HOLD")
    assert plant_group("arducopter", "POSHOLD") != plant_group("arducopter", "LOITER")  # a velocity stick


def test_the_readme_and_the_glossary_name_every_plant_group_and_both_mode_tables():
    # a group a mode table gives (FBWB's and a PX4 plane's ALTCTL `bank+climb`, SPORT's `rate+climb`) is a name
    # `fit -o` writes into a file name and `--plant-group` takes: the README and the glossary list each, and both
    # tables (the README said "one table, adapters.modes.STICKS" after FIXED_WING_STICKS was added)
    from pathlib import Path

    from adapters.modes import FIXED_WING_STICKS

    repo = Path(__file__).resolve().parents[2]
    readme = (repo / "README.md").read_text(encoding="utf-8")
    glossary = next(line for line in (repo / "docs" / "architecture.md").read_text(encoding="utf-8").splitlines()
                    if line.startswith("| plant group |"))
    used = {g for table in (*STICKS.values(), *FIXED_WING_STICKS.values()) for g in table.values()}
    assert used <= set(PLANT_GROUPS)
    for name in PLANT_GROUPS:
        assert f"`{name}`" in readme, name
        assert f"`{name}`" in glossary, name
    for table in ("adapters.modes.STICKS", "adapters.modes.FIXED_WING_STICKS"):
        assert table in readme and table in glossary, table


def test_a_log_flown_in_two_modes_gives_a_plant_per_group_with_what_each_stick_commands(copter_bin):
    ds = adapters.load(copter_bin, "ardupilot_manual")
    assert [(d.meta["mode"], d.meta["plant_group"]) for d in ds] == [("STABILIZE", "angle")] * 2 + [
        ("LOITER", "velocity+climb")] * 2
    with pytest.raises(ModelError, match=r"one plant per kind of stick.*angle: 2 segments \(STABILIZE.*"
                                         r"velocity\+climb: 2 segments \(LOITER"):
        LinearSystem.identify(ds)
    for group, part in by_plant_group(ds).items():
        plant = LinearSystem.identify(part)
        assert plant.plant_group == group
        (check,) = plant.identification.checks
        assert check.within(), str(check)  # a lean accelerates the vehicle in both modes
        _close(plant.identification.responses, VEHICLE.truth(group, DT))
        assert f"plant group {group}" in str(plant.identification)
    # why: one plant pooled over both modes (what the previous main identified) gets the velocity stick wrong
    pooled = LinearSystem.identify(ds.with_demos([d.with_meta(plant_group=None) for d in ds]))
    velocity = stick_responses(pooled.A, pooled.B, pooled.r, pooled.roles, pooled.state_names, pooled.input_names, DT,
                               "velocity+climb")[0]
    truth = VEHICLE.truth("velocity+climb", DT)[0]
    assert abs(velocity.per_full_stick / truth.per_full_stick - 1) > 0.5, (str(velocity), str(truth))


def test_a_plane_flown_in_manual_is_imported_and_gets_its_own_plant(tmp_path):
    # the previous main refused it: "no manual mode it keeps (modes MANUAL, …)"
    path = _write_bin(tmp_path / "plane_manual.bin", ["surface"], mapping="arduplane_manual",
                      firmware="ArduPlane V4.5.7 (2a3dc4b7)", table="arduplane")
    ds = adapters.load(path, "arduplane_manual")
    assert {d.meta["mode"] for d in ds} == {"MANUAL"} and {d.meta["plant_group"] for d in ds} == {"surface"}
    plant = LinearSystem.identify(ds)
    (check,) = plant.identification.checks
    assert check.name == "A[phi, phidot]" and check.within(), str(check)  # a plane's bank integrates its roll rate
    _close(plant.identification.responses, VEHICLE.truth("surface", DT))


def test_fit_writes_a_model_per_group_or_the_group_named(copter_bin, tmp_path, capsys):
    out = tmp_path / "m.npz"
    # the GMR-only baseline: what is checked is the routing per plant group, not the proposed model (tested elsewhere)
    assert main(["fit", str(copter_bin), "-o", str(out), "--method", "gmr-only", "--n-components", "1"]) == 0
    said = capsys.readouterr().out
    assert "2 plant groups, a plant and a model for each" in said
    for group in ("angle", "velocity+climb"):
        model = load_model(tmp_path / f"m.{group}.npz")
        assert model.plant.plant_group == group  # the model file keeps its plant's group
        assert f"plant identification (plant group {group}" in said
    assert not out.exists()
    one = tmp_path / "one.npz"
    assert main(["fit", str(copter_bin), "-o", str(one), "--method", "gmr-only", "--n-components", "1",
                 "--plant-group", "velocity+climb"]) == 0
    assert load_model(one).plant.plant_group == "velocity+climb"
    assert main(["fit", str(copter_bin), "-o", str(one), "--plant-group", "rate"]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("error: no demonstration in plant group 'rate'; the groups here: angle: 2 segments")
    # standard output holds one model: several groups are a usage error that names them, before any fit
    assert main(["fit", str(copter_bin), "-o", "-", "--method", "gmr-only", "--n-components", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err == ("error: -o - writes one model, but these demonstrations are 2 plant groups (angle, velocity+climb): "
                   "name one with --plant-group")


def test_selecting_a_group_names_the_groups_there_are(copter_bin):
    ds = adapters.load(copter_bin, "ardupilot_manual")
    assert len(select_plant_group(ds, "angle")) == 2
    with pytest.raises(DataError, match=r"no demonstration in plant group 'surface'; the groups here: angle: 2 "
                                        r"segments \(STABILIZE, 50 s\); velocity\+climb: 2 segments \(LOITER, 50 s\)"):
        select_plant_group(ds, "surface")


def test_view_shows_a_models_plant_group_and_keys_every_group(copter_bin, tmp_path):
    from types import SimpleNamespace

    from workbench.cli.view import _of_plant_group

    from ..rrd import key_texts

    ds = adapters.load(copter_bin, "ardupilot_manual")
    said: list[str] = []
    ctx = SimpleNamespace(say=said.append)
    angle = SimpleNamespace(plant=SimpleNamespace(plant_group="angle"))
    shown = _of_plant_group(ctx, ds, None, [angle])  # a model predicts only where the stick commands what it did
    assert [d.id for d in shown] == [d.id for d in select_plant_group(ds, "angle")]
    assert said == ["showing plant group angle: 2 segments (STABILIZE, 50 s): the model's (--plant-group shows "
                    "another)"]
    assert len(_of_plant_group(ctx, ds, None, [])) == len(ds)  # no model: every segment
    assert len(_of_plant_group(ctx, ds, "velocity+climb", [angle])) == 2  # the group named wins
    # the key names every segment's group
    texts = key_texts(ds, tmp_path / "v.rrd")
    assert any("**plant groups**" in t and "- angle: 2 segments (STABILIZE" in t
               and "- velocity+climb: 2 segments (LOITER" in t for t in texts)


@pytest.mark.slow
def test_view_of_a_model_shows_its_plant_group(copter_bin, tmp_path, capsys):
    from rerun.chunk import RrdReader

    model = tmp_path / "m.npz"
    assert main(["fit", str(copter_bin), "-o", str(model), "--method", "ioc-only", "--bootstrap", "0",
                 "--plant-group", "angle", "-q"]) == 0
    rrd = tmp_path / "v.rrd"
    assert main(["view", str(copter_bin), "--model", str(model), "--samples", "0", "--save", str(rrd)]) == 0
    assert "showing plant group angle: 2 segments (STABILIZE" in capsys.readouterr().out
    ids = {d.id for d in select_plant_group(adapters.load(copter_bin, "ardupilot_manual"), "angle")}
    assert {str(c.entity_path).split("/")[2] for c in RrdReader(rrd).stream()
            if str(c.entity_path).startswith("/demos/")} == ids


@pytest.mark.slow
def test_evaluate_and_report_run_each_group_on_its_own_plant(copter_bin, tmp_path, capsys):
    table = tmp_path / "r.parquet"
    fast = ["--no-efficiency", "--samples", "0", "--n-components", "1"]
    assert main(["evaluate", str(copter_bin), "-o", str(table), *fast]) == 0
    said = capsys.readouterr().out
    for group in ("angle", "velocity+climb"):
        assert f"plant group {group} ({group}: 2 segments" in said
        assert f"plant identification (plant group {group}" in said
        assert (tmp_path / f"r.{group}.parquet").is_file()
    assert said.index("plant group angle (") < said.index("plant identification (plant group angle") < said.index(
        "plant group velocity+climb (")
    out = tmp_path / "report"
    assert main(["report", str(copter_bin), "-o", str(out), "--bootstrap", "0", "--power", "0", *fast]) == 0
    for group in ("angle", "velocity+climb"):
        assert f"(plant group {group})" in (out / group / "report.md").read_text().splitlines()[0]


def test_a_group_whose_intervals_fail_stays_fitted_and_written(copter_bin, tmp_path, capsys, monkeypatch):
    """The model is written before its intervals: a group whose bootstrap cannot be had keeps its model (fit says
    which intervals were not computed and why), and is not counted among the groups not fitted."""
    from workbench.method import resampling

    real = resampling.bootstrap

    def failing_for_velocity(ds, plant, *args, **kwargs):
        if plant.plant_group == "velocity+climb":
            raise ModelError("every resample failed: the gain is not stabilizing")
        return real(ds, plant, *args, **kwargs)

    monkeypatch.setattr(resampling, "bootstrap", failing_for_velocity)
    out = tmp_path / "m.npz"
    assert main(["fit", str(copter_bin), "-o", str(out), "--method", "ioc-only", "--bootstrap", "2"]) == 0
    said = capsys.readouterr()
    warned = [ln for ln in said.err.splitlines() if "intervals not computed" in ln]
    assert len(warned) == 1 and "every resample failed" in warned[0], said.err  # the velocity group's, said once
    assert "not fitted" not in said.err + said.out
    assert "wrote 2 model(s), one per plant group" in said.out
    for group in ("angle", "velocity+climb"):
        assert load_model(tmp_path / f"m.{group}.npz").plant.plant_group == group


def test_a_plane_holding_its_altitude_gets_no_throttle_climb_rate():
    # On a plane in FBWB or a PX4 plane's ALTCTL / POSCTL the pitch stick commands the climb and the throttle the
    # airspeed (FIXED_WING_STICKS): the plant report printed "u2 → ydot climb rate" as for a copter's ALT_HOLD
    from workbench.plant.system import planar_quadrotor

    plant = planar_quadrotor()
    args = (plant.A, plant.B, plant.r, plant.roles, plant.state_names, plant.input_names, plant.dt)
    copter = stick_responses(*args, "angle+climb")
    plane = stick_responses(*args, "bank+climb")
    assert [r.what for r in copter] == ["lean angle", "climb rate"]  # the same plant: the copter's throttle climbs
    assert [r.what for r in plane] == ["bank angle"]
    group = PLANT_GROUPS["bank+climb"]
    assert "airspeed" in group.text and "pitch stick a climb rate" in group.text
    assert "altitude" in AUTOPILOT_HOLDS["FBWB"]  # the autopilot still holds the altitude
