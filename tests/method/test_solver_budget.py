"""SCS, the fallback where Clarabel fails, gets a short try (issue 41 §5: a default fit on a real log within 30 s), and
the second stage (a tie-break on the α-optimal face) a shorter one: 200,000 iterations (≈ 20 s) never passed the
checks on real flights' gains."""

from __future__ import annotations

import numpy as np

import workbench.method.inverse_lqr_sdp as sdp
from workbench.plant.system import planar_quadrotor


def test_the_second_stage_runs_scs_on_a_shorter_budget_than_the_first(monkeypatch):
    sys_ = planar_quadrotor()
    problem = sdp.InverseLQR(sys_.A, sys_.B, solvers=["SCS"])
    problem._build()
    seen = {}

    def solve(self, **kwargs):  # record what each stage asks SCS for, solve nothing
        seen[self is problem._stage2] = kwargs
        return None

    monkeypatch.setattr(sdp.cp.Problem, "solve", solve)
    problem._K.value = np.zeros((sys_.m, sys_.n))
    problem._run(problem._stage1, "SCS", 1)
    problem._run(problem._stage2, "SCS", 2)
    stage1, stage2 = seen[False]["max_iters"], seen[True]["max_iters"]
    assert stage1 == sdp._SOLVER_OPTIONS["SCS"]["max_iters"]
    assert stage2 == sdp._STAGE2_OPTIONS["SCS"]["max_iters"] < stage1
    assert seen[True]["eps_abs"] == seen[False]["eps_abs"]  # the same accuracy asked, fewer iterations allowed
