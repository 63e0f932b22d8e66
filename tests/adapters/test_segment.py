"""Segmentation (adapters/segment.py) and clocks (adapters/clock.py), alone and through the pipeline."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.clock import stream_times
from adapters.mapping import ClockSpec, load_mapping
from adapters.segment import Span, demo_spans, flag_spans, intersect, mode_spans, split_at_landing
from adapters.writer import demo_streams, layout


def test_demo_spans_are_runs_of_one_value():
    t = np.arange(8.0)
    spans = demo_spans(t, np.array([0, 0, 0, np.nan, 1, 1, 2, 2]))
    assert [(s.start, s.end, s.meta["demo"]) for s in spans] == [(0, 2, "0"), (4, 5, "1"), (6, 7, "2")]
    text = demo_spans(t[:4], np.array(["a", "a", None, "b"], dtype=object))
    assert [(s.start, s.end, s.meta["demo"]) for s in text] == [(0, 1, "a"), (3, 3, "b")]


def test_flag_and_mode_spans_hold_until_the_next_report():
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    assert [(s.start, s.end) for s in flag_spans(t, [0, 1, 1, 0, 1])] == [(1, 3), (4, math.inf)]
    spans = mode_spans(t, np.array([0.0, 0, 5, 0, 2]), keep=(0, 2), table="arducopter")
    assert [(s.start, s.end, s.meta["mode"]) for s in spans] == [(0, 2, "STABILIZE"), (3, 4, "STABILIZE"),
                                                                 (4, math.inf, "ALT_HOLD")]


def test_intersection_of_span_lists():
    a = [Span(0, 10, {"mode": "M"}), Span(20, 30, {"mode": "N"})]
    b = [Span(5, 25, {"demo": "1"})]
    assert intersect(a, b) == [Span(5, 10, {"mode": "M", "demo": "1"}), Span(20, 25, {"mode": "N", "demo": "1"})]


def test_split_at_landing_keeps_the_touchdown_sample():
    y = np.array([1.0, 0.5, 0.0, -0.01, 0.0, 0.3, 0.6, 0.2, -0.1])
    ranges, on_ground = split_at_landing(y, below=0.0)
    assert ranges == [(0, 3), (5, 9)]
    assert on_ground == 2


def test_vehicle_clock_is_anchored_on_the_log_clock_per_boot():
    rng = np.random.default_rng(0)
    boot = np.r_[np.arange(10.0, 20.0, 0.5), np.arange(1.0, 6.0, 0.5)]  # reboot after 20 samples
    true_log = np.r_[100.0 + np.arange(20) * 0.5, 130.0 + np.arange(10) * 0.5]
    arrival = true_log + 0.3 + rng.uniform(0, 0.05, 30)  # radio latency and jitter
    frame = pd.DataFrame({"t": arrival, "time_boot_ms": boot * 1000})
    t = stream_times(ClockSpec("time_boot_ms", 0.001), frame)
    np.testing.assert_allclose(np.diff(t[:20]), 0.5)  # spacing from the vehicle: no jitter
    np.testing.assert_allclose(np.diff(t[20:]), 0.5)
    assert abs(np.median(t - arrival)) < 0.05  # placed on the arrival clock
    np.testing.assert_array_equal(stream_times(ClockSpec(), frame), arrival)
    no_field = pd.DataFrame({"t": arrival})
    np.testing.assert_array_equal(stream_times(ClockSpec("time_boot_ms", 0.001), no_field), arrival)


def _tlog_with_heartbeats(ds, path):
    from workbench.cli.sample_logs import EPOCH, PAUSE, _heartbeats

    m = load_mapping("planar_quadrotor").for_format("tlog")
    streams = demo_streams(ds, m, epoch=EPOCH, pause=PAUSE)
    streams["HEARTBEAT"] = _heartbeats(ds)
    adapters.FORMATS["tlog"].write(path, streams)
    return path


@pytest.mark.parametrize(
    "rules",
    [
        'mode = { source = "HEARTBEAT.custom_mode", names = "arducopter", keep = ["STABILIZE"] }\n'
        'armed = { source = "HEARTBEAT.base_mode", bitmask = 128 }',
        'landing = { state = "y", below = 0.0 }',
        "",  # gaps alone: the pause between trials
    ],
)
def test_mode_armed_landing_and_gap_rules_find_the_same_demonstrations(rules, small_set, tmp_path):
    path = _tlog_with_heartbeats(small_set, tmp_path / "hb.tlog")
    channels = load_mapping("planar_quadrotor").raw["tlog"]["channels"]
    lines = ['dt = 0.05', 'states = ["x", "y", "phi", "xdot", "ydot", "phidot"]', 'inputs = ["u1", "u2"]',
             "[channels]"]
    for name, value in channels.items():
        if isinstance(value, str):
            lines.append(f'{name} = "{value}"')
        else:
            inner = ", ".join(f'{k} = "{v}"' if isinstance(v, str) else f"{k} = {v}" for k, v in value.items())
            lines.append(f"{name} = {{ {inner} }}")
    lines += ["[segment]", "gap = 0.25", "min_duration = 0.1", rules]
    mapping = tmp_path / "rules.toml"
    mapping.write_text("\n".join(lines) + "\n")
    ds = adapters.load(path, mapping)
    assert [len(d) for d in ds] == [len(d) for d in small_set]
    starts = [s for s, _ in layout(small_set, 1_704_067_200.0, 2.0)]
    np.testing.assert_allclose([d.meta["t0"] for d in ds], starts, atol=1e-6)
    if "mode" in rules:
        assert {d.meta["mode"] for d in ds} == {"STABILIZE"}
