"""``workbench map``'s drafts (adapters/draft.py): every source checked against the log before the draft is given,
and text from the log written as TOML strings, never as syntax.

An outside attack put a 62-byte firmware string holding a newline and a ``clock`` line into a log: the draft
wrote it into a comment unescaped, the line became active, and importing with that draft doubled every duration.
"""

from __future__ import annotations

import tomllib

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.draft import draft_mapping, toml_string
from adapters.formats import dataflash_write

BENIGN = "ArduCopter V3.2.1 (36b405fb)"
HOSTILE = [
    # the attack: a whole line that doubles every duration (on the previous main: trials of 13.5 s instead of 6.7 s)
    'ArduCopter\nclock = { field = "TimeMS", scale = 0.002 }\n#',
    'ArduCopter V3\nclock = { field = "TimeMS", scale = 0.002 }',
    'ArduCopter "V3" \\ end\\',
    "ArduCopter ] [segment]\ngap = 99.0",
    'ArduCopter """ x\r\ndt = 10.0\r',
    "ArduCopter ✓ 😀 \u202e LTR \u2028 \x7f \x1b[31m \t",
    "ArduCopter\n[channels]\nx = 'GPS.Lat'",
]


def _log(tmp_path, name: str, firmware: str):
    streams, options = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    options["firmware"] = firmware
    return dataflash_write.write(tmp_path / name, streams, **options)


def _active(toml: str) -> list[str]:
    """The lines that are not comments or blank."""
    return [ln for ln in toml.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]


@pytest.fixture(scope="module")
def benign(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("benign")
    log = _log(tmp, "benign.bin", BENIGN)
    draft = draft_mapping(adapters.read(log), name="drafted")
    path = tmp / "drafted.toml"
    path.write_text(draft.toml)
    return draft, adapters.load(log, path)


@pytest.mark.parametrize("firmware", HOSTILE, ids=range(len(HOSTILE)))
def test_a_hostile_firmware_string_stays_text_in_the_draft(tmp_path, benign, firmware):
    assert len(firmware.encode()) <= 64  # a DataFlash MSG holds 64 bytes
    log = _log(tmp_path, "hostile.bin", firmware)
    assert adapters.read(log).info["firmware"] == firmware  # the log carries it as written
    draft = draft_mapping(adapters.read(log), name="drafted")
    parsed, reference = tomllib.loads(draft.toml), tomllib.loads(benign[0].toml)
    # the firmware string round-trips as the description's text, and nothing else of the draft changes
    assert parsed["description"] == f"drafted for {firmware} from ardupilot_manual"
    assert {k: v for k, v in parsed.items() if k != "description"} == \
           {k: v for k, v in reference.items() if k != "description"}
    active = [ln for ln in _active(draft.toml) if not ln.startswith("description = ")]
    assert active == [ln for ln in _active(benign[0].toml) if not ln.startswith("description = ")]
    assert len(draft.toml.splitlines()) == len(benign[0].toml.splitlines())  # no line added by the string
    # importing with it gives the benign draft's trials: no duration doubled
    path = tmp_path / "drafted.toml"
    path.write_text(draft.toml)
    ds = adapters.load(log, path)
    assert [d.duration for d in ds] == [d.duration for d in benign[1]] and ds.dt == benign[1].dt


def test_toml_strings_round_trip_any_text():
    rng = np.random.default_rng(0)
    pool = ['"', "\\", "\n", "\r", "\t", "\x00", "\x1f", "\x7f", "]", "'", "#", "=", "\u2028", "😀", "é", "a", "\ud800"]
    for _ in range(300):
        text = "".join(rng.choice(pool, size=int(rng.integers(0, 12))))
        value = toml_string(text)
        assert "\n" not in value and "\r" not in value
        assert tomllib.loads(f"k = {value}\n")["k"] == text.replace("\ud800", "\ufffd")


def test_a_mode_field_the_log_lacks_is_never_drafted(tmp_path):
    # ArduCopter V3.3-dev's Loiter_RTL.bin (erlerobot/logs): MODE has Mode, ThrCrs and no ModeNum; the draft wrote
    # MODE.ModeNum and importing the log with its own draft failed
    streams, options = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    streams["MODE"] = streams["MODE"].drop(columns=["ModeNum"]).assign(ThrCrs=np.int16(500))
    options["formats"]["MODE"] = "Mh"
    log = dataflash_write.write(tmp_path / "v33.bin", streams, **options)
    assert "ModeNum" not in adapters.read(log)["MODE"].columns
    draft = draft_mapping(adapters.read(log), name="drafted")
    assert tomllib.loads(draft.toml)["segment"]["mode"]["source"] == "MODE.Mode"
    path = tmp_path / "drafted.toml"
    path.write_text(draft.toml)
    assert len(adapters.load(log, path)) == len(adapters.load(log, "ardupilot_manual"))


def test_the_draft_names_sticks_by_role_through_the_log_s_rc_map(tmp_path):
    streams, options = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    parm = streams["PARM"]
    row = pd.DataFrame({"t": [parm["t"].iloc[0]], "Name": ["RCMAP_ROLL"], "Value": [np.float32(2)]})
    streams["PARM"] = pd.concat([parm, row], ignore_index=True)
    log = dataflash_write.write(tmp_path / "rcmap.bin", streams, **options)
    draft = draft_mapping(adapters.read(log), name="drafted")
    parsed = tomllib.loads(draft.toml)
    assert parsed["rc_map"] == "ardupilot" and parsed["channels"]["u1"]["source"] == "RCIN.C{roll}"
    assert parsed["setpoints"]["u1"] == "ATT.DesRoll"
    path = tmp_path / "drafted.toml"
    path.write_text(draft.toml)
    assert "u1 (roll) = RCIN.C2 (RCMAP_ROLL = 2)" in adapters.load(log, path)[0].meta["sticks"]


def test_the_draft_keeps_the_template_s_touchdown_rule(tmp_path):
    # erle_pxf_copter_6-11-2014_GPS_issues1.BIN: the draft had no [segment] landing, so importing with it kept the
    # ground time the shipped ardupilot_manual drops (7 demonstrations, 745 samples, against 6 and 602)
    streams, options = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    ev = streams["EV"]
    t0 = float(ev["t"].iloc[0])
    # take-off (NOT_LANDED) 2 s into the first armed span, touchdown (LAND_COMPLETE) 10 s later, inside kept modes
    extra = pd.DataFrame({"t": [t0 + 2.0, t0 + 12.0], "Id": np.array([28, 18], ev["Id"].dtype)})
    streams["EV"] = pd.concat([ev, extra], ignore_index=True).sort_values("t", kind="stable", ignore_index=True)
    log = dataflash_write.write(tmp_path / "landed.bin", streams, **options)
    draft = draft_mapping(adapters.read(log), name="drafted")
    shipped = adapters.load_mapping("ardupilot_manual").for_format("dataflash").segment.landing.flag
    landing = tomllib.loads(draft.toml)["segment"]["landing"]
    assert landing["source"] == shipped.selector.source
    assert (landing["on"], landing["off"]) == (list(shipped.on), list(shipped.off))
    path = tmp_path / "drafted.toml"
    path.write_text(draft.toml)
    ours, theirs = adapters.load(log, path), adapters.load(log, "ardupilot_manual")
    spans = [(d.t[0], d.t[-1]) for d in theirs]
    assert [(d.t[0], d.t[-1]) for d in ours] == spans and len(spans) > 0
