"""The bootstrap's resamples try only the solver that solved the point estimate: the fallback chain (SCS iterating
to 200,000 iterations, ~20 s a solve on a real flight's gain) is the point estimate's alone."""

from __future__ import annotations

import warnings

import numpy as np

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.method import bootstrap
from workbench.method.inverse_lqr_sdp import InverseLQR
from workbench.method.objective import forward_gain
from workbench.method.resampling import failure_note
from workbench.plant.system import LinearSystem


def _demos(seed: int = 5, n_trials: int = 5):
    rng = np.random.default_rng(seed)
    A = np.array([[1.0, 0.1], [0.0, 0.95]])
    B = np.array([[0.0], [0.1]])
    plant = LinearSystem(A, B, dt=0.1)
    K = forward_gain(A, B, np.eye(2), np.eye(1), np.zeros((2, 1)))[0]
    demos = []
    for j in range(n_trials):
        x, u = np.zeros((40, 2)), np.zeros((40, 1))
        x[0] = rng.normal(size=2)
        for k in range(40):
            u[k] = K @ x[k] + 0.1 * rng.normal(size=1)
            if k + 1 < 40:
                x[k + 1] = A @ x[k] + B @ u[k]
        demos.append(Demonstration(np.arange(40) * 0.1, x, u, meta={"id": f"d{j}"}))
    return DemonstrationSet(demos, plant.state_names, plant.input_names, dt=0.1), plant


def test_resamples_do_not_fall_back_to_the_point_estimates_other_solvers(monkeypatch):
    # every second stage fails with the first solver (as on real flights' gains): the point estimate goes on to
    # SCS; each resample used to as well (one 20 s SCS solve per resample), and now stops at its stage 1
    ds, plant = _demos()
    original = InverseLQR._run
    scs_calls = []

    def run(self, problem, solver, stage=1):
        if solver != self.solvers[0]:
            scs_calls.append(solver)
            return "infeasible"
        if problem is self._stage2:
            return "infeasible"
        return original(self, problem, solver, stage)

    monkeypatch.setattr(InverseLQR, "_run", run)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = bootstrap(ds, plant, n_boot=12, seed=1)
    point_fallbacks = len(InverseLQR(plant.A, plant.B).solvers) - 1  # the point estimate's stage 2 only
    assert res.objective.solver == InverseLQR(plant.A, plant.B).solvers[0]
    assert res.n_ok == res.n_boot  # the resamples still fit: their stage-1 optimum
    assert len(scs_calls) == point_fallbacks


def test_the_failure_note_names_the_count_and_the_commonest_cause_once_across_numbers():
    failures = [f"resample {i}: the gain is not stabilizing: spectral radius ρ(A + B K) = 1.00{i} ≥ 1"
                for i in range(3)] + ["resample 9: rank(X) = 1 < 2"]
    note = failure_note(failures)
    assert note.startswith("4 resample(s) failed; commonest cause (3): the gain is not stabilizing")
    assert failure_note([]) == ""


def test_a_long_cause_is_printed_whole_not_cut_mid_word():
    from workbench.method.resampling import stop_note

    cause = ("the instruments leave a state direction unexcited: its squared canonical correlation is 0.01 < 0.05, so "
             "the starts of the demonstrations do not move every state (e.g. all start at the same height). Use "
             "more varied start states")
    failures = [f"resample {k}: {cause}" for k in range(3)]
    assert failure_note(failures).endswith("more varied start states")
    assert stop_note(10, 2, failures).endswith("more varied start states")


def test_resamples_on_the_serial_executor_share_one_compiled_problem(monkeypatch):
    # issue 41 §5: the CLI's bootstrap runs one resample per task on the serial executor, and each task compiled the
    # SDP afresh (~0.1 s of cvxpy canonicalization per resample, a second of a default fit on a real log)
    from workbench.method import inverse_lqr_sdp
    from workbench.study.executor import SerialExecutor

    ds, plant = _demos(seed=11)
    inverse_lqr_sdp._CACHE.clear()
    built = []
    original = InverseLQR.__init__

    def counting(self, *args, **kwargs):
        built.append(kwargs.get("solvers"))
        original(self, *args, **kwargs)

    monkeypatch.setattr(InverseLQR, "__init__", counting)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = bootstrap(ds, plant, n_boot=12, seed=0, executor=SerialExecutor())
    assert result.n_boot - result.n_failed > 0
    assert len(built) <= 2, built  # the point estimate's problem and the resamples' one


def test_one_demonstration_gives_no_interval_rather_than_a_zero_width_one():
    # every resample of one trial is that trial: its 'intervals' had zero width (K̂[u1, φ] [1.35, 1.35] on
    # dronekit-la log171's one LOITER segment) and were printed as 95 % intervals
    import pytest

    from workbench.errors import ModelError

    ds, plant = _demos(n_trials=1)
    with pytest.raises(ModelError, match=r"^1 demonstration\(s\): resampling needs two or more"):
        bootstrap(ds, plant, n_boot=5, seed=1)
    two, _ = _demos(n_trials=2)
    res = bootstrap(two, plant, n_boot=5, seed=1)
    assert np.all(res.K_hi > res.K_lo)  # two trials resample into different sets: the interval has width
