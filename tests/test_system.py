"""The plant: the paper's quadrotor entry by entry, Assumptions 1–2, and identification."""

from __future__ import annotations

import numpy as np
import pytest

from workbench import Demonstration, DemonstrationSet, LinearSystem
from workbench.errors import ModelError
from workbench.system import planar_quadrotor


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


def test_identify_recovers_a_simulated_system():
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
