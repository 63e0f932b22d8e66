"""The default gain: instrumental variables where their instruments are relevant, least squares otherwise."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.data.demonstrations import Demonstration
from workbench.method.gain import IV_MIN_RELEVANCE, choose_gain
from workbench.models import HumanBehaviorModel
from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import OperatorProfile, simulate_landings

G = 9.8


def _cs1_attitude_row() -> np.ndarray:
    """The CS1 pilot's attitude loop near the pad, linearized from its cascade (sim/landing.py): phi_des from the
    velocity error, itself from the position; u1 = k_phi (phi_des − phi) − k_phidot phidot."""
    p = OperatorProfile()
    return np.array([-p.k_phi * p.k_vel * p.k_pos / G, 0, -p.k_phi, -p.k_phi * p.k_vel / G, 0, -p.k_phidot])


@pytest.mark.parametrize("seed", [11, 12])
def test_default_gain_is_iv_and_removes_the_closed_loop_bias_on_cs1(seed):
    system = planar_quadrotor()
    ds = simulate_landings("CS1", 30, seed=seed)
    kw = {"fit_objective": False, "noise_folds": 0, "n_components": 2}
    default = HumanBehaviorModel(system, **kw).fit(ds)
    direct = HumanBehaviorModel(system, gain_method="direct", **kw).fit(ds)
    assert default.gain_choice_.method == default.gain_method_ == "iv"
    assert "relevant" in default.gain_choice_.reason and direct.gain_choice_.method == "direct"
    truth = _cs1_attitude_row()
    err = {name: np.linalg.norm(m.K_[0] - truth) / np.linalg.norm(truth) for name, m in
           (("iv", default), ("direct", direct))}
    print(f"\nCS1 seed {seed}: attitude row off by {err['direct']:.0%} (direct), {err['iv']:.0%} (iv)")
    assert err["iv"] < 0.5 * err["direct"]


def test_the_fallback_to_direct_says_why():
    system = planar_quadrotor()
    ds = simulate_landings("CS1", 6, seed=13, time_limit=4.0)
    # every trial from one start: the instruments (start state × time) cannot move every state direction
    x0 = ds[0].x[0]
    same = [Demonstration(d.t, d.x - d.x[0] + x0, d.u, d.meta) for d in ds]
    K, choice = choose_gain(same, system)
    assert choice.method == "direct" and choice.reason.startswith("fallback from iv")
    assert f"{IV_MIN_RELEVANCE:g}" in choice.reason or "rank" in choice.reason
    np.testing.assert_array_equal(K, choose_gain(same, system, "direct")[0])
