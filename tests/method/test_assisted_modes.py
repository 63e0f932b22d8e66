"""A gain that does not bring the position back, from segments flown in a mode where the autopilot holds the
position (ArduCopter LOITER, ALT_HOLD; PX4 POSCTL, ALTCTL), names that mode as the likely cause."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from pymavlink import mavutil

import adapters
from adapters.mapping import load_mapping
from adapters.modes import AUTOPILOT_HOLDS, mode_number
from adapters.writer import demo_streams
from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.errors import ModelError
from workbench.method.gain import estimate_gain
from workbench.plant.system import LinearSystem
from workbench.sim.landing import simulate_landings

EPOCH = 1_704_067_200.0


def _copter_tlog(path, mode: str):
    ds = simulate_landings("CS1", 2, seed=3)
    streams = demo_streams(ds, load_mapping("ardupilot_manual").for_format("tlog"), epoch=EPOCH, pause=2.0)
    for frame in streams.values():
        frame["time_boot_ms"] = np.rint((frame["t"].to_numpy() - EPOCH) * 1000.0).astype(np.int64)
    ml = mavutil.mavlink
    streams["HEARTBEAT"] = pd.DataFrame({
        "t": streams["ATTITUDE"]["t"].to_numpy()[::50], "type": ml.MAV_TYPE_QUADROTOR,
        "autopilot": ml.MAV_AUTOPILOT_ARDUPILOTMEGA,
        "base_mode": ml.MAV_MODE_FLAG_SAFETY_ARMED | ml.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        "custom_mode": mode_number("arducopter", mode), "system_status": 4, "mavlink_version": 3})
    return adapters.FORMATS["tlog"].write(path, streams)


@pytest.mark.parametrize("mode", ["LOITER", "STABILIZE"])
def test_import_tags_the_segments_whose_autopilot_holds_states(tmp_path, mode):
    ds = adapters.load(_copter_tlog(tmp_path / "f.tlog", mode), "ardupilot_manual")
    assert len(ds) and all(d.meta["mode"] == mode for d in ds)
    assert all(d.meta.get("autopilot_holds") == AUTOPILOT_HOLDS.get(mode) for d in ds)


def _unstable_demos(modes, seed, states=("x", "xdot")):
    """A double integrator whose "pilot" pushes the position away (positive feedback): not stabilizing, the slow
    mode on the position and its velocity."""
    A, B = np.array([[1.0, 0.1], [0.0, 1.0]]), np.array([[0.0], [0.1]])
    rng = np.random.default_rng(seed)
    demos = []
    for j, mode in enumerate(modes):
        x, u = np.empty((30, 2)), np.empty((30, 1))
        x[0] = rng.normal(size=2)
        for k in range(30):
            u[k] = np.array([0.5, 0.5]) @ x[k] + 0.1 * rng.normal()
            if k + 1 < 30:
                x[k + 1] = A @ x[k] + B @ u[k]
        meta = {"id": f"d{j}", "mode": mode}
        if mode in AUTOPILOT_HOLDS:
            meta["autopilot_holds"] = AUTOPILOT_HOLDS[mode]
        demos.append(Demonstration(np.arange(30) * 0.1, x, u, meta=meta))
    return A, B, demos


@pytest.mark.parametrize(("vertical", "mode", "named"), [
    (None, "LOITER", True),      # LOITER holds the horizontal position: the slow mode lies on it
    ("x", "ALT_HOLD", True),     # the state is the altitude, which ALT_HOLD holds
    (None, "ALT_HOLD", False),   # ALT_HOLD holds the altitude, not this horizontal position: not the cause
])
def test_an_assisted_mode_is_named_only_where_it_holds_the_states_of_the_slow_mode(vertical, mode, named):
    from workbench.data.roles import Roles

    A, B, demos = _unstable_demos([mode, mode, "STABILIZE"], seed=0)
    roles = Roles(position=("x",), velocity=("xdot",), vertical=vertical)
    plant = LinearSystem(A, B, dt=0.1, state_names=("x", "xdot"), input_names=("u",), roles=roles)
    ds = DemonstrationSet(demos, ("x", "xdot"), ("u",), dt=0.1, roles=roles)
    with pytest.raises(ModelError, match="not stabilizing") as exc:
        estimate_gain(ds, plant)
    message = str(exc.value)
    assert ("Likely cause: 2 of 3 demonstrations were flown in a mode whose autopilot" in message) == named
    assert (mode in message) == named


def test_without_roles_no_mode_is_named():
    # which states a mode holds is known from the plant's roles; without them the mode explains nothing
    A, B, demos = _unstable_demos(["LOITER", "LOITER", "STABILIZE"], seed=0)
    plant = LinearSystem(A, B, dt=0.1, state_names=("x", "xdot"), input_names=("u",))
    ds = DemonstrationSet(demos, ("x", "xdot"), ("u",), dt=0.1)
    with pytest.raises(ModelError, match="not stabilizing") as exc:
        estimate_gain(ds, plant)
    assert "autopilot" not in str(exc.value)


@pytest.mark.parametrize(("vertical", "named"), [("x", True), (None, False)])
def test_a_model_fitted_on_assisted_segments_names_the_mode_by_the_same_rule(vertical, named):
    # the models fit the gain on the pilot's view of the demonstrations: the flight mode must come along, and the
    # refusal (judged with its interval) names ALT_HOLD only where the slow mode lies on the altitude
    from workbench.data.roles import Roles
    from workbench.models import IOCOnlyModel

    A, B, demos = _unstable_demos(["ALT_HOLD"] * 3, seed=1)
    roles = Roles(position=("x",), velocity=("xdot",), vertical=vertical)
    plant = LinearSystem(A, B, dt=0.1, state_names=("x", "xdot"), input_names=("u",), roles=roles)
    ds = DemonstrationSet(demos, ("x", "xdot"), ("u",), dt=0.1, roles=roles)
    with pytest.raises(ModelError, match=r"not stabilizing.*interval \[1\.") as exc:
        IOCOnlyModel(plant, gain_method="direct", task="zero@x,xdot").fit(ds)
    assert ("3 of 3 demonstrations were flown in a mode whose autopilot" in str(exc.value)) == named
