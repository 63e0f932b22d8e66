"""Live prediction: the online path equals the offline import and replay, survives a bad link, and runs over UDP.

Every expected value comes from the offline path (``adapters.load`` of the same frames written as a tlog, the
model's ``input_distribution`` / ``residuals`` / ``predict`` on the imported demonstrations) or from counting what
a test injected; the end-to-end test goes through the real CLI (``workbench live`` and ``workbench replay --to``)
over UDP on 127.0.0.1.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import struct
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

import adapters
from adapters.link.mavlink import open_link, tlog_frames
from workbench.errors import ModelError, WorkbenchError
from workbench.live.predictor import OnlinePredictor
from workbench.models import HumanBehaviorModel
from workbench.plant.system import planar_quadrotor

from ..rrd import read_rrd

REPO = Path(__file__).resolve().parents[2]
TLOG = REPO / "sample_logs" / "landing_s00.tlog"
WB = [sys.executable, "-m", "workbench"]
HORIZON = 20  # 1 s at dt = 0.05 s


# -- helpers -----------------------------------------------------------------------------------------------------
def write_tlog(path: Path, records) -> Path:
    """Raw (time, frame) records as a tlog: 8-byte big-endian µs timestamp, then the frame as received."""
    path.write_bytes(b"".join(struct.pack(">Q", int(round(t * 1e6))) + bytes(f) for t, f in records))
    return path


def online(model, records, mapping="planar_quadrotor", **kwargs):
    pr = OnlinePredictor(model, mapping, **kwargs)
    preds = []
    for t, frame in records:
        pr.feed(frame, arrival=t)
        preds += pr.pop()
    return pr, preds


def by_demo(preds):
    out = defaultdict(list)
    for p in preds:
        out[p.demo_id].append(p)
    return out


def assert_equal_to_offline(model, demo, steps, *, rollout_at=()):
    """A live segment's steps against the imported demonstration and the model's offline predictions."""
    n = len(steps)
    assert n >= 2
    np.testing.assert_array_equal(np.array([p.x for p in steps]), demo.x[:n])
    np.testing.assert_array_equal(np.array([p.u for p in steps]), demo.u[:n])
    np.testing.assert_array_equal(steps[0].x0, demo.x[0])
    assert [p.k for p in steps] == list(range(n))
    if demo.target is None:
        assert steps[0].target is None
    else:
        np.testing.assert_array_equal(steps[0].target, demo.target)
    # (with the pilot's timing: each input given the segment before it, as live carries it)
    mean, cov = (a[:n] for a in model.input_distribution_along(demo))
    np.testing.assert_allclose(np.array([p.u_mean for p in steps]), mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array([p.u_cov for p in steps]), cov, rtol=0, atol=1e-12)
    w = model.residuals(demo)[:n]
    np.testing.assert_allclose(np.array([p.w for p in steps]), w, rtol=0, atol=1e-12)
    for k in rollout_at:
        past = model.pasts(demo, [k])
        expected = model.predict(demo.x[k], HORIZON, target=demo.target, task_x0=demo.x[0],
                                 past=None if past is None else past[0]).x
        np.testing.assert_allclose(steps[k].rollout_x, expected, rtol=0, atol=1e-12)


# -- fixtures ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def records():
    return list(tlog_frames(TLOG))


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    ds = adapters.load(TLOG, mapping="planar_quadrotor")
    model = HumanBehaviorModel(planar_quadrotor(), n_components=3, noise_folds=0).fit(ds.by_label("CS1"))
    path = tmp_path_factory.mktemp("live") / "cs1.npz"
    model.save(path)
    return ds, model, path


def first_demos(ds, records, n):
    """The records of the first ``n`` demonstrations (up to the next one's start)."""
    end = ds[n].meta["t0"]
    return [(t, f) for t, f in records if t < end - 1e-6]


# -- the online path equals the offline one ------------------------------------------------------------------
def test_online_steps_equal_the_offline_import_and_predictions(fitted, records):
    ds, model, _ = fitted
    part = first_demos(ds, records, 4)
    pr, preds = online(model, part, horizon_s=1.0)
    got = by_demo(preds)
    assert list(got) == ds.ids[:4]
    for d in ds[:4]:
        assert len(got[d.id]) == len(d)
        assert got[d.id][0].meta["label"] == d.label
        assert_equal_to_offline(model, d, got[d.id], rollout_at=(0, len(d) // 2, len(d) - 1))
    assert pr.stats.n_segments == 4
    assert pr.stats.rejected == {}
    # step(): the newest step, once; step(t): the newest completed step at or before a time, None when it is older
    # than the mapping's gap
    last = preds[-1]
    first = pr.step()
    assert first is not None and (first.k, first.demo_id) == (last.k, last.demo_id) and pr.step() is None
    assert pr.step(last.t).k == last.k and pr.step(last.t + 10.0) is None


def test_a_bad_link_is_counted_and_changes_nothing(fitted, records):
    ds, model, _ = fitted
    part = first_demos(ds, records, 2)
    rng = np.random.default_rng(7)
    intruder = mav.MAVLink(None, srcSystem=2, srcComponent=1)
    fed, injected = [], defaultdict(int)
    i = 0
    while i < len(part):
        t, frame = part[i]
        if i % 97 == 13 and i + 1 < len(part) and part[i + 1][0] == t:  # two frames of one instant, swapped
            fed += [part[i + 1], (t, frame)]
            injected["out of order"] += 1
            i += 2
            continue
        fed.append((t, frame))
        if i % 50 == 7:
            garbage = bytes(rng.integers(0, 0xFC, int(rng.integers(1, 60)), dtype=np.uint8))  # no magic byte
            fed.append((t, garbage))
            injected["garbage bytes"] += len(garbage)
        if i % 70 == 11:
            broken = bytearray(frame)
            broken[-3] ^= 0x5A  # the payload's last byte: the checksum no longer matches
            fed.append((t, bytes(broken)))
            injected["CRC failures"] += 1
        if i % 90 == 17:
            fed.append((t, frame[: len(frame) - 5]))
            injected["truncated frames"] += 1
        if i % 40 == 3:
            fed.append((t, frame))
            injected["duplicates"] += 1
        if i % 60 == 29:  # another vehicle, flying somewhere else
            wild = intruder.local_position_ned_encode(int(t * 1000) % 2**32, *rng.normal(size=6))
            fed.append((t, wild.pack(intruder)))
            intruder.seq = (intruder.seq + 1) % 256  # pack() alone does not count
            injected["other systems"] += 1
        i += 1
    pr, preds = online(model, fed)
    counts = pr.stats.counts
    for cause, n in injected.items():
        assert counts.get(cause, 0) == n, cause
    got = by_demo(preds)
    assert list(got) == ds.ids[:2]
    for d in ds[:2]:
        assert len(got[d.id]) == len(d)
        assert_equal_to_offline(model, d, got[d.id])


def test_a_byte_stream_cut_anywhere_gives_the_same_steps(fitted, records):
    """TCP and serial links deliver bytes, not frames: chunks cut at random places, frames split across them."""
    ds, model, _ = fitted
    part = first_demos(ds, records, 1)
    stream = b"".join(f for _, f in part)
    cuts = np.sort(np.random.default_rng(5).choice(np.arange(1, len(stream)), size=len(part) // 2, replace=False))
    pr = OnlinePredictor(model, "planar_quadrotor")
    preds = []
    for chunk in np.split(np.frombuffer(stream, dtype=np.uint8), cuts):
        pr.feed(chunk.tobytes(), datagram=False)
        preds += pr.pop()
    assert pr.stats.rejected == {}
    got = by_demo(preds)
    assert list(got) == [ds[0].id] and len(got[ds[0].id]) == len(ds[0])
    assert_equal_to_offline(model, ds[0], got[ds[0].id])


def test_pymavlink_messages_pushed_by_a_users_loop_give_the_same_steps(fitted, records):
    """``push(msg)``: what a loop that reads the link with pymavlink itself hands over (BAD_DATA included)."""
    ds, model, _ = fitted
    part = first_demos(ds, records, 1)
    parser = mav.MAVLink(None)
    parser.robust_parsing = True
    pr = OnlinePredictor(model, "planar_quadrotor")
    preds = []
    for i, (t, frame) in enumerate(part):
        data = frame if i % 100 != 50 else b"\x01\x02\x03" + frame  # now and then a few bad bytes first
        for msg in parser.parse_buffer(data) or []:
            pr.push(msg, arrival=t)
        preds += pr.pop()
    assert pr.stats.counts["garbage bytes"] == 3 * sum(1 for i in range(len(part)) if i % 100 == 50)
    got = by_demo(preds)
    assert list(got) == [ds[0].id] and len(got[ds[0].id]) == len(ds[0])
    assert_equal_to_offline(model, ds[0], got[ds[0].id])


def test_the_arrival_clock_is_the_tlogs_clock(fitted, records):
    """``clock="arrival"``: samples timed by when they arrived, which is what a tlog records (its "log" clock)."""
    ds, model, _ = fitted
    pr, preds = online(model, first_demos(ds, records, 1), clock="arrival")
    got = by_demo(preds)
    assert list(got) == [ds[0].id] and len(got[ds[0].id]) == len(ds[0])
    assert_equal_to_offline(model, ds[0], got[ds[0].id])
    np.testing.assert_array_equal([p.t for p in got[ds[0].id]], ds[0].meta["t0"] + ds[0].t)


def test_a_gap_longer_than_the_mappings_ends_the_segment_as_offline(fitted, records, tmp_path):
    ds, model, _ = fitted
    part = first_demos(ds, records, 1)
    t0 = part[0][0]
    cut = [(t, f) for t, f in part if not (t0 + 3.0 < t < t0 + 3.5)]  # 0.5 s of silence > gap 0.25 s
    offline = adapters.load(write_tlog(tmp_path / "gap.tlog", cut), mapping="planar_quadrotor")
    assert len(offline) == 2  # the offline import splits there too: "<id>.1" and "<id>.2"
    _, preds = online(model, cut)
    got = by_demo(preds)
    base = ds[0].id
    assert list(got) == [base, f"{base}.2"]
    for live_id, d in zip(got, offline, strict=True):
        assert len(got[live_id]) == len(d)
        assert_equal_to_offline(model, d, got[live_id])


MODE_MAPPING = """
name = "quadrotor_by_mode"
dt = 0.05
states = ["x", "y", "phi", "xdot", "ydot", "phidot"]
inputs = ["u1", "u2"]
[channels]
x = "LOCAL_POSITION_NED.y"
y = { source = "LOCAL_POSITION_NED.z", transform = "ned_up" }
phi = "ATTITUDE.roll"
xdot = "LOCAL_POSITION_NED.vy"
ydot = { source = "LOCAL_POSITION_NED.vz", transform = "ned_up" }
phidot = "ATTITUDE.rollspeed"
u1 = { source = "MANUAL_CONTROL.y", scale = 0.001 }
u2 = { source = "MANUAL_CONTROL.z", scale = 0.001 }
[segment]
gap = 0.25
min_duration = 0.1
mode = { source = "HEARTBEAT.custom_mode", names = "arducopter", keep = ["STABILIZE"] }
armed = { source = "HEARTBEAT.base_mode", bitmask = 128 }
"""


def test_mode_and_armed_rules_segment_as_offline(fitted, records, tmp_path):
    """HEARTBEATs switch to ALT_HOLD for a while and disarm for a while: the same pieces as the offline import."""
    _, model, _ = fitted
    mapping = tmp_path / "by_mode.toml"
    mapping.write_text(MODE_MAPPING)
    part = [(t, f) for t, f in records if t < records[0][0] + 23.0]  # ends in the pause after a trial
    t0 = part[0][0]
    parser = mav.MAVLink(None)
    parser.robust_parsing = True
    packer = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    changed = []
    for t, frame in part:
        msg = parser.parse_buffer(frame)[0]
        if msg.get_type() == "HEARTBEAT" and (3.0 <= t - t0 < 5.0 or 15.0 <= t - t0 < 17.0):
            if t - t0 < 10:
                msg.custom_mode = 2  # ALT_HOLD: not a kept mode
            else:
                msg.base_mode &= ~128  # disarmed
            packer.seq = msg.get_seq()
            frame = msg.pack(packer, force_mavlink1=False)
        changed.append((t, frame))
    offline = adapters.load(write_tlog(tmp_path / "modes.tlog", changed), mapping=str(mapping))
    _, preds = online(model, changed, mapping=str(mapping))
    got = by_demo(preds)
    assert len(got) == len(offline) >= 4
    for live_id, d in zip(got, offline, strict=True):
        assert len(got[live_id]) == len(d), live_id
        np.testing.assert_array_equal(np.array([p.x for p in got[live_id]]), d.x)
        np.testing.assert_array_equal(np.array([p.u for p in got[live_id]]), d.u)
        assert got[live_id][0].meta.get("mode") == d.meta.get("mode") == "STABILIZE"


def test_the_landing_rule_ends_each_flight_at_touchdown_as_offline(fitted, records, tmp_path):
    _, model, _ = fitted
    mapping = tmp_path / "landing.toml"
    rules = MODE_MAPPING.index("mode = {")
    mapping.write_text(MODE_MAPPING[:rules] + 'landing = { state = "y", below = 0.3 }\n')
    part = [(t, f) for t, f in records if t < records[0][0] + 35.0]
    offline = adapters.load(write_tlog(tmp_path / "land.tlog", part), mapping=str(mapping))
    _, preds = online(model, part, mapping=str(mapping))
    got = by_demo(preds)
    assert len(got) == len(offline) >= 3
    y = list(offline.state_names).index("y")
    for live_id, d in zip(got, offline, strict=True):
        steps = got[live_id]
        assert len(steps) == len(d)
        np.testing.assert_array_equal(np.array([p.x for p in steps]), d.x)
        np.testing.assert_array_equal(steps[0].x0, d.x[0])
        if live_id != list(got)[-1]:  # the last flight was cut by the end of the records, not by touchdown
            assert d.x[-1, y] <= 0.3 < d.x[-2, y]


def test_a_silent_link_is_reported_once_and_resumes(fitted, records):
    _, model, _ = fitted
    now = [0.0]
    pr = OnlinePredictor(model, "planar_quadrotor", silence=2.0, now=lambda: now[0])
    for _, frame in records[:40]:
        pr.feed(frame)
    assert pr.poll() == []
    now[0] = 2.5
    events = pr.poll()
    assert [e.kind for e in events] == ["silent"]
    now[0] = 9.0
    assert pr.poll() == []  # reported once
    assert pr.stats.silent and pr.stats.silences == 1
    for _, frame in records[40:60]:
        pr.feed(frame)
    assert [e.kind for e in pr.poll()] == ["resumed"]
    assert not pr.stats.silent


def test_a_link_that_never_sends_is_silent_from_the_start_and_says_since_when(fitted):
    from workbench.viewer.live import link_state

    _, model, _ = fitted
    start = 1_700_000_000.0
    now = [start]
    pr = OnlinePredictor(model, "planar_quadrotor", silence=2.0, now=lambda: now[0])
    now[0] = start + 1.0
    assert pr.poll() == [] and "waiting" in link_state(pr.stats)  # quiet, not yet past the silence threshold
    now[0] = start + 3.0
    events = pr.poll()
    assert [e.kind for e in events] == ["silent"] and "since listening began" in events[0].text
    st = pr.stats
    assert not st.heard and st.quiet_since == start and st.quiet_for == pytest.approx(3.0)
    text = link_state(st)
    assert "receiving" not in text and time.strftime("%H:%M:%S", time.localtime(start)) in text, text


def test_model_and_mapping_must_agree(fitted, tmp_path):
    _, model, _ = fitted
    other = tmp_path / "other.toml"
    other.write_text(MODE_MAPPING.replace('inputs = ["u1", "u2"]', 'inputs = ["u2", "u1"]'))
    with pytest.raises(ModelError, match="inputs"):
        OnlinePredictor(model, str(other))
    with pytest.raises(WorkbenchError, match="not a link"):
        open_link(str(TLOG))


def test_live_prediction_runs_without_rerun():
    code = "import sys, workbench.live.predictor; print('rerun' in sys.modules, 'workbench.viewer' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.split() == ["False", "False"]


# -- end to end: the real CLI over UDP -------------------------------------------------------------------------
def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def live_run(fitted, tmp_path_factory):
    """``workbench live`` on a UDP port while ``workbench replay --to`` sends the sample tlog at 10×, and this
    test sends garbage, broken frames and another vehicle's messages to the same port in between."""
    _, _, model_path = fitted
    out = tmp_path_factory.mktemp("live_cli")
    port = free_udp_port()
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    live = subprocess.Popen(
        [*WB, "live", f"udpin:127.0.0.1:{port}", "--mapping", "planar_quadrotor", "--model", str(model_path),
         "--save", str(out / "live.rrd"), "--duration", "9"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=out,
    )
    replay = None
    injected: dict[str, int] = defaultdict(int)
    try:
        line = live.stdout.readline()  # "listening on …": the port is bound
        assert "listening on" in line, line + live.stderr.read()
        replay = subprocess.Popen([*WB, "replay", str(TLOG), "--to", f"udpout:127.0.0.1:{port}", "--speed", "10"],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=out)
        rng = np.random.default_rng(3)
        intruder = mav.MAVLink(None, srcSystem=7, srcComponent=1)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for i in range(30):
                time.sleep(0.15)
                garbage = bytes(rng.integers(0, 0xFC, 40, dtype=np.uint8))
                s.sendto(garbage, ("127.0.0.1", port))
                injected["garbage bytes"] += len(garbage)
                hb = intruder.heartbeat_encode(2, 3, 129, 0, 4).pack(intruder)
                intruder.seq += 1  # pack() alone does not count: a real sender's frames differ in seq
                pos = intruder.local_position_ned_encode(i, *rng.normal(size=6)).pack(intruder)
                intruder.seq += 1
                s.sendto(hb, ("127.0.0.1", port))
                s.sendto(pos, ("127.0.0.1", port))
                injected["other systems"] += 2
                broken = bytearray(pos)
                broken[-3] ^= 0x33
                s.sendto(bytes(broken), ("127.0.0.1", port))
                injected["CRC failures"] += 1
        stdout, stderr = live.communicate(timeout=60)
    finally:
        for proc in (live, replay):
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait()
    return {"code": live.returncode, "stdout": line + stdout, "stderr": stderr, "rrd": out / "live.rrd",
            "injected": dict(injected)}


def test_live_cli_predictions_equal_the_offline_replay(fitted, live_run):
    ds, model, _ = fitted
    assert live_run["code"] == 0, live_run["stderr"]
    ents = read_rrd(live_run["rrd"], static=False)
    by_id = {d.id: d for d in ds}
    checked = 0
    for path, cols in ents.items():
        m = re.fullmatch(r"/demos/(.+)/online/(u\d)/gmr", path)
        if m is None:
            continue
        d, j = by_id[m.group(1)], ds.input_names.index(m.group(2))
        steps = np.asarray(cols["step"], dtype=int)
        values = np.asarray(cols["Measurements:values"], dtype=float)[:, 0]
        variances = np.asarray(cols["Measurements:variances"], dtype=float)[:, 0]
        mean, cov = model.input_distribution_along(d)  # what `replay --model` streams (given the trial before)
        np.testing.assert_allclose(values, mean[steps, j], rtol=0, atol=1e-9)
        np.testing.assert_allclose(variances, cov[steps, j, j], rtol=1e-9, atol=1e-15)
        state = ents[f"/demos/{m.group(1)}/states/x"]
        np.testing.assert_array_equal(np.asarray(state["Scalars:scalars"], dtype=float)[:, 0],
                                      d.x[np.asarray(state["step"], dtype=int), 0])
        checked += len(steps)
    assert checked >= 2 * 400  # at 10× for 9 s: several trials, thousands of steps; never a vacuous check
    assert re.search(r"(\d+) steps in (\d+) segment", live_run["stdout"])


def test_live_timing_lines_break_between_segments(live_run):
    # one NaN row just before each segment's first step after the first: no line drawn across the pause
    ents = read_rrd(live_run["rrd"], static=False)
    firsts = sorted(float(np.min(np.asarray(c["link_time"], dtype=float)))
                    for p, c in ents.items() if re.fullmatch(r"/demos/[^/]+/states/x", p))
    assert len(firsts) >= 2
    for path in ("/live/compute_ms", "/live/latency_ms"):
        t = np.asarray(ents[path]["link_time"], dtype=float)
        v = np.asarray(ents[path]["Scalars:scalars"], dtype=float)[:, 0]
        gaps = np.sort(t[np.isnan(v)])
        assert len(gaps) == len(firsts) - 1
        np.testing.assert_allclose(gaps, np.asarray(firsts[1:]) - 1e-6, atol=1e-7)


def test_live_cli_predictions_equal_the_replay_commands_recording(fitted, live_run, tmp_path):
    """The same steps as ``workbench replay LOG --model M`` streams, read back from both recordings."""
    ds, _, model_path = fitted
    live = read_rrd(live_run["rrd"], static=False)
    ids = [d.id for d in ds if f"/demos/{d.id}/online/u1/gmr" in live][:2]
    assert len(ids) == 2
    r = subprocess.run([*WB, "replay", str(TLOG), "--model", str(model_path), "--demo", *ids, "--no-wait",
                        "--horizon", "0", "--save", str(tmp_path / "replay.rrd")],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    offline = read_rrd(tmp_path / "replay.rrd", static=False)
    for demo_id in ids:
        for u in ds.input_names:
            path = f"/demos/{demo_id}/online/{u}/gmr"
            on = dict(zip(live[path]["step"], live[path]["Measurements:values"], strict=True))
            off = dict(zip(offline[path]["step"], offline[path]["Measurements:values"], strict=True))
            assert set(on) <= set(off) and len(on) >= 100
            steps = sorted(on)
            np.testing.assert_allclose([on[k] for k in steps], [off[k] for k in steps], rtol=0, atol=1e-9)


def test_live_cli_survives_and_counts_a_bad_link(live_run):
    assert live_run["code"] == 0, live_run["stderr"]
    line = next(x for x in live_run["stdout"].splitlines() if x.startswith("link: "))
    counts = dict(re.findall(r"([a-zA-Z][a-zA-Z ()]+?) (\d+)(?:,|$)", line.removeprefix("link: ").strip()))
    for cause, n in live_run["injected"].items():
        if cause == "garbage bytes" and "shed (backlog)" in counts:  # a slow machine fell behind: junk shed unparsed
            assert int(counts.get(cause, 0)) <= n, (cause, counts)
        else:
            assert int(counts.get(cause, 0)) == n, (cause, counts)


def test_live_recording_verifies(live_run):
    exe = Path(sys.executable).with_name("rerun")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "rerun"]
    result = subprocess.run([*cmd, "rrd", "verify", str(live_run["rrd"])], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


def test_ctrl_c_ends_live_with_a_complete_recording(fitted, records, tmp_path):
    _, _, model_path = fitted
    port = free_udp_port()
    live = subprocess.Popen(
        [*WB, "live", f"udpin:127.0.0.1:{port}", "--model", str(model_path), "--save", str(tmp_path / "c.rrd")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        assert "listening on" in live.stdout.readline()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for _, frame in records[:400]:
                s.sendto(frame, ("127.0.0.1", port))
                time.sleep(0.001)
        time.sleep(1.0)
        live.send_signal(signal.SIGINT)
        stdout, stderr = live.communicate(timeout=60)
    finally:
        if live.poll() is None:
            live.kill()
    assert live.returncode == 0, stderr
    assert "interrupted" in stdout
    n_steps = int(re.search(r"(\d+) steps in", stdout).group(1))
    assert n_steps > 0
    ents = read_rrd(tmp_path / "c.rrd", static=False)
    logged = sum(len(c["step"]) for path, c in ents.items() if path.endswith("/states/x"))
    assert logged == n_steps  # every completed step is in the recording


def test_replay_needs_a_model_or_a_link(tmp_path):
    r = subprocess.run([*WB, "replay", str(TLOG)], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 2 and "--to CONNECTION" in r.stderr  # a usage error, as argparse's
    r = subprocess.run([*WB, "replay", str(REPO / "sample_logs" / "landing_s01.mcap"), "--to", "udpout:127.0.0.1:9"],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 1 and "not a MAVLink telemetry log" in r.stderr


def test_an_integrated_state_restarts_at_each_segment_as_offline(fitted, records, tmp_path):
    # a mapping's `x = { integrate = "xdot" }` (issue 41): live sums the velocity step by step from 0 at each
    # segment's start, as the offline import does per piece; the gap splits the flight in two
    ds, model, _ = fitted
    shipped = REPO / "adapters" / "mappings" / "planar_quadrotor.toml"
    text = shipped.read_text(encoding="utf-8")
    assert text.count('x = "LOCAL_POSITION_NED.y"') == 1
    mapping = tmp_path / "integrated.toml"
    mapping.write_text(text.replace('x = "LOCAL_POSITION_NED.y"', 'x = { integrate = "xdot" }'))
    part = first_demos(ds, records, 1)
    t0 = part[0][0]
    cut = [(t, f) for t, f in part if not (t0 + 3.0 < t < t0 + 3.5)]
    offline = adapters.load(write_tlog(tmp_path / "gap.tlog", cut), mapping=str(mapping))
    assert len(offline) == 2
    _, preds = online(model, cut, mapping=str(mapping))
    got = by_demo(preds)
    for live_id, d in zip(got, offline, strict=True):
        assert d.x[0, 0] == 0.0 and np.ptp(d.x[:, 0]) > 0  # the integral, from 0 in each segment
        assert_equal_to_offline(model, d, got[live_id])
