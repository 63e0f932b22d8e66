"""Calibration at 1σ/2σ/3σ without saturated inputs, judged against the sampling spread."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import scipy.stats

from workbench.data.demonstrations import Demonstration
from workbench.study.calibration import calibration_check, calibration_counts, saturated


class _Band:
    """A stand-in model: input mean 0 and standard deviation ``sigma`` at every state."""

    def __init__(self, sigma, u_min=None, u_max=None):
        self.sigma = sigma
        self.plant = SimpleNamespace(m=1, input_names=("u1",), u_min=u_min, u_max=u_max)

    def input_distribution(self, X, x0, target):
        n = len(X)
        return np.zeros((n, 1)), np.full((n, 1, 1), self.sigma**2)

    def input_distribution_along(self, demo, target=None):  # each input given the trial before it (no timing here)
        return self.input_distribution(demo.x, demo.x[0], target)


def _demos(rng, scale, n_trials=20, n=200, rho=0.0, limit=None):
    out = []
    for i in range(n_trials):
        e = rng.standard_normal(n)
        w = np.empty(n)
        w[0] = e[0]
        for k in range(1, n):  # AR(1) with unit variance: samples within a trial are correlated
            w[k] = rho * w[k - 1] + np.sqrt(1 - rho**2) * e[k]
        u = scale * w
        if limit is not None:
            u = np.clip(u, -limit, limit)
        out.append(Demonstration(np.arange(n) * 0.05, np.zeros((n, 1)), u[:, None], {"id": f"t{i}"}))
    return out


def test_a_calibrated_band_passes_and_a_narrow_one_is_called_narrow():
    rng = np.random.default_rng(7)
    ok = calibration_check(calibration_counts(_Band(1.0), _demos(rng, 1.0, rho=0.9)))
    narrow = calibration_check(calibration_counts(_Band(1.0), _demos(rng, 1.6, rho=0.9)))
    assert (ok["verdict"] == "fits").all(), ok
    assert narrow.set_index("n_sigma").loc[1.0, "verdict"] == "too narrow"
    # the effective count shrinks with the correlation: an AR(1) indicator keeps (1 − ρ)/(1 + ρ) of the samples
    n_eff = ok.set_index("n_sigma").loc[1.0, "n_eff"]
    assert 0.02 * 4000 < n_eff < 0.3 * 4000
    # the sampling range is the binomial interval of the nominal share over N_eff samples
    row = ok.set_index("n_sigma").loc[1.0]
    k = int(round(row["n_eff"]))
    assert row["lo"] * k == scipy.stats.binom.interval(0.95, k, row["nominal"])[0]


def test_inputs_at_their_limits_are_flagged_and_left_out_of_the_score():
    rng = np.random.default_rng(8)
    demos = _demos(rng, 1.0, n_trials=10, limit=1.2)
    at_limit = np.concatenate([np.abs(d.u) >= 1.2 for d in demos])
    declared = saturated(demos, _Band(1.0, u_min=np.array([-1.2]), u_max=np.array([1.2])).plant)
    pinned = saturated(demos, _Band(1.0).plant)  # no declared limits: the stick pinned at its travel's ends
    np.testing.assert_array_equal(np.concatenate(declared), at_limit)
    np.testing.assert_array_equal(np.concatenate(pinned), at_limit)
    check = calibration_check(calibration_counts(_Band(1.0), demos)).set_index("n_sigma")
    assert check.loc[1.0, "saturated"] == at_limit.mean()
    free = np.concatenate([np.abs(d.u[:, 0])[np.abs(d.u[:, 0]) < 1.2] for d in demos])
    assert check.loc[1.0, "coverage_free"] == (free <= 1.0).mean()
