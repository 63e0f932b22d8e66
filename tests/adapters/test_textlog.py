"""The raw view's text messages (adapters/textlog.py): declared by each format, every text-only MCAP topic among
them, and values that are no numbers (NaN, ±inf, null, text) shown as they are, never a Python exception.

An outside attack found ``view`` exiting 3 with a raw Python exception on NaN, ±inf, null or text in event and
error messages (16 of 72 calls), and an MCAP holding only ``std_msgs/String`` topics showing "0 streams", its
1,246 messages nowhere.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.formats import FORMATS, dataflash_write
from adapters.formats.base import Format
from adapters.rawlog import raw_log

ODD = [10.0, np.nan, np.inf, -np.inf, 3.5, 11.0]


def _string_bag(path, n: int):
    """A ROS 2 MCAP of one std_msgs/String topic and nothing else (CDR, as rosbag2 records it)."""
    from mcap_ros2.writer import Writer

    with open(path, "wb") as f:
        writer = Writer(f)
        schema = writer.register_msgdef("std_msgs/msg/String", "string data")
        for i in range(n):
            stamp = 1_700_000_000_000_000_000 + i * 50_000_000
            writer.write_message("/chatter", schema, {"data": f"hello {i}"}, log_time=stamp, publish_time=stamp)
        writer.finish()
    return path


def test_a_text_only_mcap_topic_is_in_the_raw_view_s_messages(tmp_path):
    path = _string_bag(tmp_path / "chatter.mcap", 37)
    raw = raw_log(adapters.read(path))
    assert raw.streams == ()  # no number to plot
    assert len(raw.text) == 37 and set(raw.text.sources) == {"/chatter"}
    assert list(raw.text.texts) == [f"hello {i}" for i in range(37)]
    assert (np.diff(raw.text.t) > 0).all()


def test_the_ros2_talker_bag_shows_its_topic_beside_rosout(external):
    streams = adapters.read(external("rosbag2_talker.mcap"))
    raw = raw_log(streams)
    topic = [x for x, s in zip(raw.text.texts, raw.text.sources, strict=True) if s == "/topic"]
    assert topic == streams["/topic"]["data"].tolist() and len(topic) == streams.counts["/topic"]
    assert raw.text.sources.count("/rosout") == streams.counts["/rosout"]


def test_every_format_declares_its_text_and_the_raw_view_lists_none():
    import ast
    from pathlib import Path

    from adapters import rawlog

    tree = ast.parse(Path(rawlog.__file__).read_text())
    docstrings = {id(n.body[0].value) for n in ast.walk(tree) if isinstance(n, ast.Module | ast.FunctionDef |
                  ast.ClassDef) and n.body and isinstance(n.body[0], ast.Expr)}
    strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
               and id(n) not in docstrings}
    assert not strings & {"STATUSTEXT", "MSG", "ERR", "EV", "/rosout", "text", "Message", "msg"}
    declaring = {name for name, f in FORMATS.items() if type(f).text_messages is not Format.text_messages}
    assert declaring == {"tlog", "ulog", "dataflash", "mcap"}


def _dataflash_with_odd_values(tmp_path):
    streams, options = dataflash_write.example_streams("old", "copter", seconds=10.0, seed=3)
    streams["EV"] = pd.DataFrame({"t": streams["EV"]["t"].iloc[0] + np.arange(len(ODD)),
                                  "Id": np.array(ODD, np.float32)})
    streams["ERR"] = pd.DataFrame({"t": streams["ERR"]["t"].iloc[0] + np.arange(3),
                                   "Subsys": np.array([np.nan, 16, np.inf], np.float32),
                                   "ECode": np.array([2, np.nan, 0], np.float32)})
    streams["MODE"]["ModeNum"] = np.array([0, np.nan, 2, np.inf, 0], np.float32)
    options["formats"].update(EV="f", ERR="ff", MODE="Mf")
    return dataflash_write.write(tmp_path / "odd.bin", streams, **options)


def test_non_finite_event_and_error_values_are_shown_as_such(tmp_path):
    raw = raw_log(adapters.read(_dataflash_with_odd_values(tmp_path)))
    shown = dict.fromkeys(zip(raw.text.sources, raw.text.texts, strict=True))
    events = [t for s, t in shown if s == "EV"]
    assert events == ["ARMED", "event nan", "event inf", "event -inf", "event 3.5", "DISARMED"]
    assert [t for s, t in shown if s == "ERR"] == ["subsystem nan, code 2", "subsystem 16, code nan",
                                                   "subsystem inf, code 0"]
    assert "nan" in {m.mode for m in raw.modes}


def test_null_and_text_severities_in_an_mcap_are_shown_as_such(tmp_path):
    # the workbench's own MCAP writer writes JSON null for NaN
    n = 6
    rosout = pd.DataFrame({"t": 1.7e9 + np.arange(n), "level": [20.0, np.nan, np.inf, -np.inf, 40.0, 1e300],
                           "msg": [f"line {i}" for i in range(n)]})
    ev = pd.DataFrame({"t": 1.7e9 + np.arange(n), "Id": ODD})  # an EV topic in an MCAP is numbers, not events
    path = FORMATS["mcap"].write(tmp_path / "odd.mcap", {"/rosout": rosout, "EV": ev})
    raw = raw_log(adapters.read(path))
    rows = [(lv, x) for lv, x, s in zip(raw.text.levels, raw.text.texts, raw.text.sources, strict=True)
            if s == "/rosout"]
    assert rows == [("INFO", "line 0"), ("INFO", "line 1"), ("INFO", "line 2"), ("INFO", "line 3"),
                    ("ERROR", "line 4"), ("INFO", "line 5")]
    assert "EV" not in raw.text.sources and any(s.name == "EV" for s in raw.streams)


@pytest.mark.slow
def test_view_of_logs_with_odd_event_values_exits_0(tmp_path):
    path = _dataflash_with_odd_values(tmp_path)
    out = subprocess.run([sys.executable, "-m", "workbench", "view", str(path), "--save", str(tmp_path / "v.rrd")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr and "Error" not in out.stderr.replace("error:", "")


def test_heartbeat_fields_that_are_no_numbers_break_no_summary(tmp_path):
    # an MCAP (or any format) holding a HEARTBEAT stream whose fields are null or text: inspect and view read its
    # modes; on the previous main: "TypeError: int() argument must be … not 'NoneType'", exit 3
    n = 6
    hb = pd.DataFrame({"t": 1.7e9 + np.arange(n), "type": np.array([2, None, "q", np.nan, 2, 2], dtype=object),
                       "autopilot": [3] * n, "base_mode": [np.nan, 129, 129, None, 1, 1],
                       "custom_mode": np.array(["x", 0, np.inf, 0, 0, None], dtype=object)})
    path = FORMATS["mcap"].write(tmp_path / "hb.mcap", {"HEARTBEAT": hb})
    summary = adapters.inspect(path)
    assert [m.mode for m in summary.modes] == ["nan", "STABILIZE", "nan"]
    # the vehicle's rows are those of a type it names (2): their base_mode is NaN, 1, 1 — never armed
    assert summary.armed_text == "armed: never armed"
    raw_log(adapters.read(path))
