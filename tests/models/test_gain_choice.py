"""The default gain: instrumental variables where their instruments are relevant, least squares otherwise."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.method.gain import choose_gain
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
    plant = planar_quadrotor()
    ds = simulate_landings("CS1", 30, seed=seed)
    kw = {"fit_objective": False, "noise_folds": 0, "n_components": 2}
    default = HumanBehaviorModel(plant, **kw).fit(ds)
    direct = HumanBehaviorModel(plant, gain_method="direct", **kw).fit(ds)
    assert default.gain_choice_.method == default.gain_method_ == "iv"
    assert "relevant" in default.gain_choice_.reason and direct.gain_choice_.method == "direct"
    truth = _cs1_attitude_row()
    err = {name: np.linalg.norm(m.K_[0] - truth) / np.linalg.norm(truth) for name, m in
           (("iv", default), ("direct", direct))}
    print(f"\nCS1 seed {seed}: attitude row off by {err['direct']:.0%} (direct), {err['iv']:.0%} (iv)")
    assert err["iv"] < 0.5 * err["direct"]


def test_the_fallback_to_direct_says_why(monkeypatch):
    import workbench.method.gain as gain

    plant = planar_quadrotor()
    ds = simulate_landings("CS1", 8, seed=13)
    _, chosen = choose_gain(ds, plant)
    assert chosen.method == "iv"
    relevance = float(chosen.reason.split("correlation ")[1].split(" ")[0])
    # instruments that must explain more than these starts move every state: "iv" refuses, "direct" steps in
    monkeypatch.setattr(gain, "IV_MIN_RELEVANCE", min(0.99, 2 * relevance))
    K, choice = choose_gain(ds, plant)
    assert choice.method == "direct" and choice.reason.startswith("fallback from iv")
    assert "leave a state direction unexcited" in choice.reason
    np.testing.assert_array_equal(K, choose_gain(ds, plant, "direct")[0])
