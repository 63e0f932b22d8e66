"""A mapping's integrated state (``x = { integrate = "xdot" }``): the position a turning vehicle's heading frame
holds, kept consistent with the plant's kinematic row ``x[k+1] = x[k] + dt·xdot[k]``."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import adapters
from adapters.mapping import load_mapping
from adapters.pipeline import build
from adapters.streams import Streams
from adapters.transforms import TRANSFORMS
from workbench.errors import MappingError

YAW_RATE = 0.5  # rad/s: a steady pirouette
SPEED = 3.0  # m/s east, straight: the flight does not turn, the vehicle does


def _kinematic_residual(d, names, dt: float) -> tuple[float, float]:
    """RMS of ``x[k+1] − x[k] − dt·xdot[k]`` over a demonstration, and the RMS of ``dt·xdot`` it compares with."""
    x, v = d.x[:, names.index("x")], d.x[:, names.index("xdot")]
    step = np.diff(d.t) * v[:-1]
    return float(np.sqrt(np.mean((np.diff(x) - step) ** 2))), float(np.sqrt(np.mean(step**2)))


def _rotated_position_residual(t, north, east, heading, dt: float) -> float:
    """The same residual for the position rotated into the heading frame (what the mappings used to map)."""
    right = TRANSFORMS["heading_right"].forward
    cols = np.column_stack([heading, north, east])
    p = right(cols, {"yaw_scale": 1.0})
    v = right(np.column_stack([heading, np.gradient(north, t), np.gradient(east, t)]), {"yaw_scale": 1.0})
    return float(np.sqrt(np.mean((np.diff(p) - np.diff(t) * v[:-1]) ** 2)))


def _px4_pirouette(seconds: float = 30.0, hz: float = 50.0) -> tuple[Streams, dict[str, np.ndarray]]:
    """A PX4 ULog's streams: flown in MANUAL, east at :data:`SPEED` in a straight line while yawing at
    :data:`YAW_RATE`, rolling and climbing a little (so that no channel is still)."""
    t = np.arange(int(seconds * hz)) / hz
    heading = np.angle(np.exp(1j * YAW_RATE * t))  # wrapped to (−π, π], as PX4 logs it
    north, east = np.zeros_like(t), SPEED * t
    z = -10.0 - np.sin(0.2 * t)
    roll = 0.1 * np.sin(0.7 * t)
    q = {"q[0]": np.cos(roll / 2), "q[1]": np.sin(roll / 2), "q[2]": 0.0 * t, "q[3]": 0.0 * t}
    frames = {
        "vehicle_local_position": pd.DataFrame({"t": t, "heading": heading, "x": north, "y": east, "z": z,
                                                "vx": 0.0 * t, "vy": SPEED + 0.0 * t, "vz": -0.2 * np.cos(0.2 * t)}),
        "vehicle_attitude": pd.DataFrame({"t": t, **q}),
        "vehicle_angular_velocity": pd.DataFrame({"t": t, "xyz[0]": 0.07 * np.cos(0.7 * t), "xyz[1]": 0.0 * t,
                                                  "xyz[2]": YAW_RATE + 0.0 * t}),
        "manual_control_setpoint": pd.DataFrame({"t": t, "y": roll / 0.6, "z": 0.5 + 0.1 * np.sin(0.2 * t)}),
        "vehicle_status": pd.DataFrame({"t": t[::25], "nav_state": 0.0, "arming_state": 2.0}),
    }
    streams = Streams("pirouette.ulg", "ulog", frames, counts={k: len(v) for k, v in frames.items()})
    return streams, {"t": t, "north": north, "east": east, "heading": heading}


def test_a_yawing_px4_flight_maps_a_position_its_velocity_integrates_to():
    streams, truth = _px4_pirouette()
    m = load_mapping("px4_manual").for_format("ulog")
    ds = build(streams, m)
    # the flight is one that tells the designs apart: the position rotated into the turning heading frame breaks
    # the kinematic row by a good part of a step (its rate is v_right − ψ̇·p_forward)
    old = _rotated_position_residual(truth["t"], truth["north"], truth["east"], truth["heading"], m.dt)
    for d in ds:
        residual, step = _kinematic_residual(d, ds.state_names, m.dt)
        assert old > 0.5 * step
        # the mapped position holds it to the rounding of the sums
        assert residual <= 1e-9 * step
        assert d.x[0, ds.state_names.index("x")] == 0.0  # from 0 at the demonstration's start: no goal is implied


def test_a_yawing_arducopter_dataflash_flight_maps_a_position_its_velocity_integrates_to(tmp_path):
    from adapters.formats import dataflash_write

    streams, options = dataflash_write.example_streams("old", "copter", seconds=30.0, seed=3)
    ekf = streams["EKF1"]
    t = ekf["t"].to_numpy()
    heading = np.mod(np.degrees(YAW_RATE * (t - t[0])), 360.0)
    ekf["Yaw"] = np.round(heading, 2)
    s = t - t[0]
    ekf["VN"], ekf["VE"] = np.float32(0.0), (SPEED + 0.5 * np.sin(0.3 * s)).astype(np.float32)
    ekf["PN"], ekf["PE"] = np.float32(0.0), (SPEED * s + (1.0 - np.cos(0.3 * s)) / 0.6).astype(np.float32)
    gps = streams["GPS"]  # the GPS says what the EKF does
    gps["Spd"], gps["GCrs"] = np.interp(gps["t"], t, ekf["VE"].to_numpy(np.float64)), 90.0
    path = dataflash_write.write(tmp_path / "pirouette.bin", streams, **options)
    ds = adapters.load(path, "ardupilot_manual")
    m = load_mapping("ardupilot_manual").for_format("dataflash")
    old = _rotated_position_residual(t, ekf["PN"].to_numpy(np.float64), ekf["PE"].to_numpy(np.float64),
                                     np.radians(ekf["Yaw"].to_numpy(np.float64)), m.dt)
    assert len(ds)
    for d in ds:
        residual, step = _kinematic_residual(d, ds.state_names, m.dt)
        assert old > 0.5 * step and residual <= 1e-9 * step


MAPPING = """
dt = 0.1
states = ["p", "v"]
inputs = ["u"]
[channels]
p = {integrate}
v = {{ source = "S.v", scale = 2.0 }}
u = "T.stick"
"""


def _load(tmp_path, integrate: str = '{ integrate = "v" }'):
    path = tmp_path / "m.toml"
    path.write_text(MAPPING.format(integrate=integrate))
    return load_mapping(path)


def test_an_integrated_state_restarts_from_zero_in_each_piece(tmp_path):
    m = _load(tmp_path)
    assert m.channel("p").integrates == "v" and m.channel("p").selector == m.channel("v").selector
    t = np.arange(0.0, 10.0, 0.1)
    v = np.where(t < 5.0, 1.0, -0.5) + 0.1 * np.sin(t)
    keep = (t < 4.0) | (t > 6.0)  # a 2 s silence of every channel: two pieces
    frames = {"S": pd.DataFrame({"t": t[keep], "v": v[keep]}), "T": pd.DataFrame({"t": t, "stick": np.sin(t)})}
    ds = build(Streams("log.bin", "test", frames, counts={k: len(f) for k, f in frames.items()}), m)
    assert len(ds) == 2
    for d in ds:
        p, rate = d.x[:, 0], d.x[:, 1]
        assert p[0] == 0.0
        np.testing.assert_allclose(np.diff(p), np.diff(d.t) * rate[:-1], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(("integrate", "message"), [
    ('{ integrate = "u" }', r"channels\.p\.integrate: must name another state"),
    ('{ integrate = "p" }', r"channels\.p\.integrate: must name another state"),
    ('{ integrate = "v", source = "S.p" }', r"channels\.p: integrate stands alone.*drop \['source'\]"),
])
def test_an_integrate_entry_is_checked(tmp_path, integrate, message):
    with pytest.raises(MappingError, match=message):
        _load(tmp_path, integrate)


def test_an_integrated_position_drops_the_log_frames_goal(tmp_path):
    """A goal is a position in the log's frame; relative to a position integrated from 0 it would be made up."""
    m = _load(tmp_path)
    t = np.arange(0.0, 5.0, 0.1)
    frames = {"S": pd.DataFrame({"t": t, "v": np.sin(t)}), "T": pd.DataFrame({"t": t, "stick": np.cos(t)}),
              "STATUSTEXT": pd.DataFrame({"t": [0.0], "text": ["wb target[0]=3 target[1]=0"]})}
    path = tmp_path / "goal.toml"
    path.write_text(MAPPING.format(integrate='{ integrate = "v" }') + '[meta]\ntext = "STATUSTEXT.text"\n')
    with_goal = build(Streams("log.bin", "test", frames, counts={k: len(f) for k, f in frames.items()}),
                      load_mapping(path))
    assert "target" not in with_goal[0].meta
    assert with_goal[0].meta["skipped"]["targets (a position is integrated from 0 per demonstration)"] == 1
    del m


def test_the_draft_of_a_dataflash_log_integrates_its_heading_frame_velocity(tmp_path):
    # `workbench map` drafts from the shipped template: its x is the integral line, not the velocity's sources
    from adapters.draft import draft_mapping
    from adapters.formats.dataflash_write import write_example

    path = write_example(tmp_path / "copter.bin", "new", "copter", seconds=30.0, seed=2)
    draft = draft_mapping(adapters.read(path))
    lines = draft.toml.splitlines()
    (x,) = [ln for ln in lines if ln.startswith("x = ")]
    assert x.startswith('x = { integrate = "xdot" }') and "chosen over" not in x
    mapping = tmp_path / "draft.toml"
    mapping.write_text(draft.toml)
    assert load_mapping(mapping).for_format("dataflash").channel("x").integrates == "xdot"
