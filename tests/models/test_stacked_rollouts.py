"""Mean rollouts of several tasks in one batch (``HumanBehaviorModel._stacked_policy``, the held-out scores of
cross-validation and the method-level splits) give each start exactly what its own task's rollout gives it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from workbench.models import GMROnlyModel, HumanBehaviorModel
from workbench.plant.system import planar_quadrotor
from workbench.sim.operators import SLOW_PILOT, LQROperator, lqr_operator_demos


@pytest.mark.parametrize("timing", [(0.15, 0.05), "none", "gmr-only"])
def test_stacked_mean_rollouts_are_the_task_by_task_ones(timing):
    quad = planar_quadrotor()
    op = LQROperator(**SLOW_PILOT, delay_s=0.15, lag_s=0.05)
    train, test = lqr_operator_demos(op, 6, seed=3, plant=quad), lqr_operator_demos(op, 3, seed=4, plant=quad)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if timing == "gmr-only":
            model, timing = GMROnlyModel(quad, n_components=2, noise_folds=0).fit(train), "none"
        else:
            model = HumanBehaviorModel(quad, n_components=2, fit_objective=False, noise_folds=0,
                                       gain_method="direct", timing=timing).fit(train)
    x0s, goals, task_x0s, steps, pasts = [], [], [], [], []
    for d in test:  # three tasks, one start alone in its task and two sharing one
        starts = [0, 7] if d is not test[1] else [5]
        x0s += [d.x[s] for s in starts]
        goals += [d.target] * len(starts)
        task_x0s += [d.x[0]] * len(starts)
        steps += starts
        pasts += model.pasts(d, starts) or [None] * len(starts)
    assert (model._timing() is not None) == (timing != "none")
    pasts = pasts if timing != "none" else None
    args = (np.array(x0s), 20, np.array(goals))
    kw = {"task_x0s": np.array(task_x0s), "task_steps": steps, "pasts": pasts}
    together = model.predict_many(*args, **kw)
    alone = [model.predict_many(args[0][i : i + 1], 20, args[2][i : i + 1], task_x0s=kw["task_x0s"][i : i + 1],
                                task_steps=steps[i : i + 1], pasts=None if pasts is None else pasts[i : i + 1])[0]
             for i in range(len(x0s))]
    assert model._stacked_policy([(d.x[0], d.target) for d in test], [2, 1, 2]) is not None
    for a, b in zip(together, alone, strict=True):
        # the same operations row by row; a batch of one row multiplies through another BLAS path (last bits)
        np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.u, b.u, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.Sigma_u, b.Sigma_u, rtol=0, atol=1e-12)
    # and the held-out error moves the rollouts: the stacked policy is not the first task's for every row
    assert np.abs(together[0].x - together[-1].x).max() > 1e-3
