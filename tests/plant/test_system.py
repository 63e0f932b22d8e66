"""The plant: the paper's quadrotor entry by entry, Assumptions 1–2, and identification."""

from __future__ import annotations

import numpy as np
import pytest

from workbench import Demonstration, DemonstrationSet, LinearSystem
from workbench.errors import ModelError
from workbench.plant.system import planar_quadrotor


def test_planar_quadrotor_matches_paper_entry_by_entry():
    dt, g, (k1, k2, k3), mass, Ix = 0.05, 9.8, (-0.1, -1.0, -30.0), 0.25, 0.01
    # eq. (31): A = I6 + dt * [...]; written out row by row as printed in the paper
    A = np.eye(6) + dt * np.array(
        [
            [0, 0, 0, 1, 0, 0],
            [0, 0, 0, 0, 1, 0],
            [0, 0, 0, 0, 0, 1],
            [0, 0, g, 0, 0, 0],
            [0, 0, 0, 0, k1, 0],
            [0, 0, k2, 0, 0, k3],
        ]
    )
    # eq. (32)
    B = dt * np.array([[0, 0], [0, 0], [0, 0], [0, 0], [0, 1 / mass], [1 / Ix, 0]])
    sys_ = planar_quadrotor()
    for i in range(6):
        for j in range(6):
            assert sys_.A[i, j] == pytest.approx(A[i, j], abs=1e-15), (i, j)
        for j in range(2):
            assert sys_.B[i, j] == pytest.approx(B[i, j], abs=1e-15), (i, j)
    assert sys_.dt == dt and sys_.state_names == ("x", "y", "phi", "xdot", "ydot", "phidot")
    assert sys_.input_names == ("u1", "u2")
    np.testing.assert_array_equal(sys_.clip(np.array([3.0, -2.0])), [1.0, -1.0])


def test_not_stabilizable_names_the_mode():
    A = np.diag([1.2, 0.5, 0.3])
    B = np.array([[0.0], [1.0], [1.0]])  # the unstable mode 1.2 is unreachable
    with pytest.raises(ModelError, match=r"not stabilizable.*λ = 1\.2"):
        LinearSystem(A, B, 0.1)
    # the same unreachable mode, but stable: stabilizable
    LinearSystem(np.diag([0.9, 0.5, 0.3]), B, 0.1)


def test_rank_and_shape_errors():
    A = np.eye(3) * 0.5
    with pytest.raises(ModelError, match=r"rank B = 1"):
        LinearSystem(A, np.array([[1.0, 2.0], [2.0, 4.0], [0.0, 0.0]]), 0.1)
    with pytest.raises(ModelError, match=r"fewer inputs than states"):
        LinearSystem(A, np.eye(3), 0.1)
    with pytest.raises(ModelError, match=r"A must be square"):
        LinearSystem(np.zeros((3, 2)), np.ones((3, 1)), 0.1)
    with pytest.raises(ModelError, match=r"A\[1, 1\] is not finite"):
        LinearSystem(np.diag([0.5, np.nan, 0.5]), np.ones((3, 1)), 0.1)


def test_identify_recovers_a_simulated_plant():
    rng = np.random.default_rng(0)
    true = planar_quadrotor()
    K = np.array([[-0.05, 0, -0.8, -0.08, 0, -0.005], [0, -0.4, 0, 0, -0.9, 0]])
    demos = []
    for j in range(5):
        x = np.zeros((200, 6))
        u = np.zeros((200, 2))
        x[0] = rng.normal(size=6)
        for k in range(199):
            u[k] = K @ x[k] + 0.3 * rng.normal(size=2)  # excitation
            x[k + 1] = true.A @ x[k] + true.B @ u[k]
        u[-1] = K @ x[-1]
        demos.append(Demonstration(0.05 * np.arange(200), x, u, {"id": f"e{j}"}))
    ds = DemonstrationSet(demos, true.state_names, true.input_names, 0.05)
    est = LinearSystem.identify(ds)
    rel_A = np.linalg.norm(est.A - true.A) / np.linalg.norm(true.A)
    rel_B = np.linalg.norm(est.B - true.B) / np.linalg.norm(true.B)
    print(f"identify: relative error A {rel_A:.2e}, B {rel_B:.2e}, residual {est.fit_residual:.2e}")
    assert rel_A <= 1e-6 and rel_B <= 1e-6
    assert est.fit_residual < 1e-9


def test_identify_refuses_unexcited_data():
    x = np.zeros((50, 6))
    x[:, 0] = np.linspace(0, 1, 50)
    ds = DemonstrationSet([Demonstration(0.05 * np.arange(50), x, np.zeros((50, 2)), {"id": "flat"})],
                          planar_quadrotor().state_names, ("u1", "u2"), 0.05)
    with pytest.raises(ModelError, match=r"excite only \d+ of 8"):
        LinearSystem.identify(ds)


# ------------------------------------------------------------------------------ identification with physics


def _closed_loop(plant: LinearSystem, K: np.ndarray, n_demos: int = 5, n: int = 200, seed: int = 0, noise=0.3):
    rng = np.random.default_rng(seed)
    demos = []
    for j in range(n_demos):
        x = np.zeros((n, plant.n))
        u = np.zeros((n, plant.m))
        x[0] = rng.normal(size=plant.n)
        for k in range(n - 1):
            u[k] = K @ x[k] + noise * rng.normal(size=plant.m)  # excitation
            x[k + 1] = plant.A @ x[k] + plant.B @ u[k]
        u[-1] = K @ x[-1]
        demos.append(Demonstration(plant.dt * np.arange(n), x, u, {"id": f"e{j}"}))
    return DemonstrationSet(demos, plant.state_names, plant.input_names, plant.dt, roles=plant.roles)


def test_kinematic_identification_fixes_the_position_rows_and_recovers_the_papers_plant():
    true = planar_quadrotor()
    K = np.array([[-0.05, 0, -0.8, -0.08, 0, -0.005], [0, -0.4, 0, 0, -0.9, 0]])
    ds = _closed_loop(true, K)
    est = LinearSystem.identify(ds)  # roles pair positions with velocities: kinematic by default
    rep = est.identification
    assert rep.structure == "kinematic" and est.roles == true.roles
    r = est.r
    for p, v in zip(r.position, r.velocity, strict=True):
        row = np.zeros(true.n)
        row[p], row[v] = 1.0, ds.dt
        np.testing.assert_array_equal(est.A[p], row)  # exactly kinematic, not approximately
        np.testing.assert_array_equal(est.B[p], 0.0)  # no direct input → position term
    np.testing.assert_allclose(est.A, true.A, atol=1e-9)
    assert rep.position_pull < 1e-9  # the paper's plant does not depend on where it is
    invariant = LinearSystem.identify(ds, translation_invariant=True)
    others = [i for i in range(true.n) if i not in r.position]
    np.testing.assert_array_equal(invariant.A[np.ix_(others, r.position)], 0.0)  # by construction
    assert invariant.identification.position_pull == 0.0
    np.testing.assert_allclose(invariant.A, true.A, atol=1e-9)
    np.testing.assert_allclose(est.B, true.B, atol=1e-9)
    # held out, the exact plant predicts exactly; persistence does not
    assert rep.horizon_score < 1e-6 < rep.horizon_score_persistence
    assert rep.one_step_score < 1e-6 < rep.one_step_score_persistence
    # the lateral velocity integrates the tilt (eq. (31)): one more eigenvalue on the unit circle, not unstable
    assert rep.n_integrators == 2 and rep.spectral_radius_beyond_integrators == pytest.approx(1.0, abs=1e-9)
    (check,) = rep.checks
    assert check.value == pytest.approx(true.A[r.velocity[0], r.heading])
    assert check.ratio == pytest.approx(9.8 / 9.80665) and check.within()
    assert rep.warning is None
    assert "kinematic" in str(rep) and "A[xdot, phi]" in str(rep)


def test_structure_default_and_errors():
    true = planar_quadrotor()
    K = np.array([[-0.05, 0, -0.8, -0.08, 0, -0.005], [0, -0.4, 0, 0, -0.9, 0]])
    ds = _closed_loop(true, K, n_demos=3, n=80)
    bare = DemonstrationSet(list(ds), ds.state_names, ds.input_names, ds.dt)  # no roles
    assert LinearSystem.identify(bare).identification.structure == "free"
    assert LinearSystem.identify(ds, structure="free").identification.structure == "free"
    with pytest.raises(ModelError, match="needs roles that pair position"):
        LinearSystem.identify(bare, structure="kinematic")
    with pytest.raises(ModelError, match="unknown structure"):
        LinearSystem.identify(ds, structure="physics")


def _double_integrators(a: float) -> LinearSystem:
    """Two axes, position and velocity each; the velocities decay (a < 1) or grow (a > 1)."""
    from workbench.data.roles import Roles

    dt = 0.1
    A = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, a, 0], [0, 0, 0, a]])
    B = np.array([[0, 0], [0, 0], [dt, 0], [0, dt]])
    roles = Roles(position=("px", "py"), velocity=("vx", "vy"))
    return LinearSystem(A, B, dt, ("px", "py", "vx", "vy"), ("ax", "ay"), roles=roles)


def test_an_unstable_plant_is_named_in_the_warning():
    plant = _double_integrators(1.04)
    ds = _closed_loop(plant, np.zeros((2, 4)), n_demos=4, n=60, noise=1.0)
    rep = LinearSystem.identify(ds).identification
    assert rep.spectral_radius_beyond_integrators == pytest.approx(1.04, abs=1e-9)
    assert "unstable beyond its integrators" in rep.warning
    assert rep.checks == ()  # no heading role: no g·dt check
    stable = LinearSystem.identify(_closed_loop(_double_integrators(0.9), np.zeros((2, 4)), n_demos=4, n=60))
    assert stable.identification.warning is None


def test_a_plant_worse_than_persistence_and_an_ill_conditioned_one_are_named():
    # two segments whose state keeps its sign and one whose state flips it every step: left out, each is
    # predicted by a plant fitted on the others, which cannot know its dynamics
    rng = np.random.default_rng(2)
    demos = []
    for j, a in enumerate((0.99, 0.99, -0.99)):
        x = np.zeros((100, 2))
        u = rng.normal(size=(100, 1)) * 1e-3
        x[0] = [1.0, -0.5]
        for k in range(99):
            x[k + 1] = a * x[k] + np.array([1e-3, 0.0]) * u[k, 0]
        demos.append(Demonstration(0.1 * np.arange(100), x, u, {"id": f"s{j}"}))
    rep = LinearSystem.identify(DemonstrationSet(demos, ("a", "b"), ("u",), 0.1), horizon_s=1.0).identification
    assert rep.one_step_score > rep.one_step_score_persistence
    assert "worse than persistence" in rep.warning
    # a state that nearly repeats another: the regressor's columns are almost collinear
    demos = [Demonstration(d.t, np.column_stack([d.x[:, 0], d.x[:, 0] * (1 + 1e-6 * rng.normal(size=len(d)))]),
                           d.u, d.meta) for d in demos]
    rep = LinearSystem.identify(DemonstrationSet(demos, ("a", "b"), ("u",), 0.1), horizon_s=1.0).identification
    assert rep.condition_number > 1e4 and "ill-conditioned" in rep.warning


def test_one_demonstration_is_cut_into_pieces_for_the_held_out_check():
    ds = _closed_loop(_double_integrators(0.9), np.zeros((2, 4)), n_demos=1, n=150)
    rep = LinearSystem.identify(ds, horizon_s=0.5).identification
    assert "contiguous pieces" in rep.validation and rep.n_steps == 5
    assert np.isfinite(rep.horizon_rmse).all() and rep.horizon_score < 1e-6


def test_real_flight_kinematic_plant_from_training_spans(external):
    """The acceptance of issue 9 on the real ArduCopter flight: kinematic rows, no stick → position, g·dt."""
    import adapters

    ds = adapters.load(external("dronekit_flight.tlog"), "ardupilot_manual")
    train, _ = ds.split(0.2, seed=0)
    est = LinearSystem.identify(train, structure="kinematic")
    rep = est.identification
    r = est.r
    for p, v in zip(r.position, r.velocity, strict=True):
        assert est.A[p, p] == 1.0 and est.A[p, v] == train.dt
        assert np.count_nonzero(est.A[p]) == 2 and not est.B[p].any()
    (check,) = rep.checks
    g_dt = 9.80665 * train.dt
    print(f"real flight: {check}; held-out 3 s score plant {rep.horizon_score:.3g} vs persistence "
          f"{rep.horizon_score_persistence:.3g}")
    assert check.expected == pytest.approx(g_dt)
    assert g_dt / 2 <= check.value <= 2 * g_dt
    assert rep.horizon_score < rep.horizon_score_persistence  # the tilt makes the plant worth having
    # the pull toward where the flights were that least squares ascribes to the plant is reported, and small
    assert 0 < rep.position_pull < 0.05 and "absolute position in the other rows" in str(rep)
    strict = LinearSystem.identify(train, structure="kinematic", translation_invariant=True).identification
    assert strict.position_pull == 0.0 and strict.checks[0].within()
