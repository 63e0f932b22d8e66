"""The plant: a discrete-time linear system ``x[k+1] = A x[k] + B u[k]`` (eq. (1) of the method paper).

The method needs (A, B) known and stabilizable (Assumption 1) with ``rank B = m < n`` (Assumption 2);
:class:`LinearSystem` checks both on construction. :func:`planar_quadrotor` is the paper's landing testbed
(eqs. (31)–(32), counted in order in the LaTeX source); :meth:`LinearSystem.identify` estimates (A, B)
from logs that come without a model.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from workbench.data.roles import ResolvedRoles, Roles
from workbench.defaults import DT_PAPER_S, HORIZON_S
from workbench.errors import DataError, ModelError

if TYPE_CHECKING:
    from workbench.data.demonstrations import DemonstrationSet
    from workbench.plant.identification import IdentificationReport

__all__ = ["LinearSystem", "planar_quadrotor", "is_stabilizable", "PLANAR_QUADROTOR_ROLES"]


def _rank(M: np.ndarray, rtol: float = 1e-10) -> int:
    s = np.linalg.svd(M, compute_uv=False)
    return int((s > rtol * max(M.shape) * (s[0] if s.size else 0.0)).sum()) if s.size and s[0] > 0 else 0


def is_stabilizable(A: np.ndarray, B: np.ndarray, rtol: float = 1e-9) -> tuple[bool, complex | None]:
    """PBH test: (A, B) is stabilizable iff rank [A − λI, B] = n for every eigenvalue |λ| ≥ 1.

    Returns ``(ok, λ)`` with the first offending eigenvalue, or ``None``.
    """
    n = A.shape[0]
    for lam in np.linalg.eigvals(A):
        if abs(lam) >= 1 - 1e-12 and _rank(np.hstack([A - lam * np.eye(n), B]).astype(complex), rtol) < n:
            return False, complex(lam)
    return True, None


@dataclass(frozen=True, eq=False)
class LinearSystem:
    """A validated discrete-time linear plant ``x[k+1] = A x[k] + B u[k]``.

    Parameters
    ----------
    A : (n, n) array
    B : (n, m) array
    dt : float
        Sampling step in seconds.
    state_names, input_names : sequence of str
        Default ``x0…`` and ``u0…``.
    u_min, u_max : (m,) arrays, optional
        Input bounds (e.g. stick limits), used when a prediction clips its inputs.
    fit_residual : float, optional
        For an identified system, the RMS one-step prediction residual of the fit.
    roles : Roles, optional
        Which states are positions, velocities and the heading angle (:mod:`workbench.data.roles`); none by default.
    identification : IdentificationReport, optional
        For a plant from :meth:`identify`: its held-out errors, ρ(A), conditioning and physical checks.
    plant_group : str, optional
        What the pilot's sticks command in this plant (:mod:`workbench.data.plant_groups`: ``"angle"`` for a lean
        angle, ``"velocity+climb"`` for LOITER's …); a plant identified from demonstrations of one group carries it.

    Raises
    ------
    ModelError
        Bad shapes, non-finite entries, (A, B) not stabilizable (Assumption 1), rank B ≠ m or m ≥ n
        (Assumption 2).
    """

    A: np.ndarray
    B: np.ndarray
    dt: float
    state_names: tuple[str, ...] = ()
    input_names: tuple[str, ...] = ()
    u_min: np.ndarray | None = None
    u_max: np.ndarray | None = None
    fit_residual: float | None = field(default=None)
    roles: Roles = field(default_factory=Roles)
    identification: IdentificationReport | None = field(default=None, repr=False)
    plant_group: str | None = None

    def __post_init__(self) -> None:
        A = np.array(self.A, dtype=np.float64)
        B = np.array(self.B, dtype=np.float64)
        if B.ndim == 1:
            B = B.reshape(-1, 1)
        if A.ndim != 2 or A.shape[0] != A.shape[1]:
            raise ModelError(f"A must be square, got shape {A.shape}")
        if B.ndim != 2 or B.shape[0] != A.shape[0]:
            raise ModelError(f"B must have {A.shape[0]} rows like A, got shape {B.shape}")
        for name, M in (("A", A), ("B", B)):
            if not np.isfinite(M).all():
                i, j = np.argwhere(~np.isfinite(M))[0]
                raise ModelError(f"{name}[{i}, {j}] is not finite ({M[i, j]})")
        n, m = B.shape
        if not m < n:
            raise ModelError(f"Assumption 2 needs fewer inputs than states: m = {m}, n = {n}")
        if (r := _rank(B)) != m:
            raise ModelError(f"Assumption 2 needs rank B = m = {m}, but rank B = {r}")
        ok, lam = is_stabilizable(A, B)
        if not ok:
            raise ModelError(
                f"(A, B) is not stabilizable (Assumption 1): the mode λ = {lam:.6g} (|λ| = {abs(lam):.6g}) "
                "cannot be reached by the inputs (PBH test)"
            )
        if not (self.dt > 0 and np.isfinite(self.dt)):
            raise ModelError(f"dt must be a positive finite number, got {self.dt!r}")
        state_names = tuple(self.state_names) or tuple(f"x{i}" for i in range(n))
        input_names = tuple(self.input_names) or tuple(f"u{i}" for i in range(m))
        if len(state_names) != n or len(input_names) != m:
            raise ModelError(
                f"{len(state_names)} state names and {len(input_names)} input names for a plant with n={n}, m={m}"
            )
        bounds = []
        for b in (self.u_min, self.u_max):
            if b is not None:
                b = np.broadcast_to(np.asarray(b, dtype=np.float64), (m,)).copy()
                b.setflags(write=False)
            bounds.append(b)
        if bounds[0] is not None and bounds[1] is not None and not (bounds[0] < bounds[1]).all():
            raise ModelError(f"u_min {bounds[0]} must be below u_max {bounds[1]}")
        A.setflags(write=False)
        B.setflags(write=False)
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)
        object.__setattr__(self, "dt", float(self.dt))
        object.__setattr__(self, "state_names", state_names)
        object.__setattr__(self, "input_names", input_names)
        object.__setattr__(self, "u_min", bounds[0])
        object.__setattr__(self, "u_max", bounds[1])
        roles = self.roles if isinstance(self.roles, Roles) else Roles.from_json(self.roles)
        try:
            roles.check(state_names, "LinearSystem roles")
        except DataError as exc:
            raise ModelError(str(exc)) from None
        object.__setattr__(self, "roles", roles)

    @property
    def r(self) -> ResolvedRoles:
        """The roles as state indices (``r.position``, ``r.velocity``, ``r.heading``, ``r.plane``)."""
        return self.roles.resolve(self.state_names)

    @property
    def n(self) -> int:
        return self.A.shape[0]

    @property
    def m(self) -> int:
        return self.B.shape[1]

    def step(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``A x + B u``, vectorized over leading batch dimensions."""
        return x @ self.A.T + u @ self.B.T

    def clip(self, u: np.ndarray) -> np.ndarray:
        """Inputs clipped to the bounds, where the plant has them."""
        if self.u_min is None and self.u_max is None:
            return u
        return np.clip(u, self.u_min, self.u_max)

    @classmethod
    def identify(
        cls,
        demos: DemonstrationSet,
        *,
        u_min: Sequence[float] | None = None,
        u_max: Sequence[float] | None = None,
        structure: str = "auto",
        horizon_s: float = HORIZON_S,
        translation_invariant: bool = False,
        hold: bool = True,
    ) -> LinearSystem:
        """Least-squares estimate of (A, B) from consecutive samples of every demonstration, with a report.

        Pairs (x[k], u[k]) → x[k+1] are taken within each demonstration, never across two. With
        ``structure="kinematic"`` the position rows are fixed by kinematics, ``p[k+1] = p[k] + dt·v[k]`` for the
        roles' position / velocity pairs (no input moves a position directly), and the other rows are fitted
        (with ``translation_invariant=True`` on everything but the positions, so no state depends on an absolute
        position); ``"free"`` fits every entry of ``[A B]``; demonstrations of different plant groups are refused
        (one plant per kind of stick); ``"auto"`` (the
        default) is kinematic when ``demos.roles`` pair positions with velocities, else free — so data without
        roles are identified as before. The RMS one-step residual on all data is ``fit_residual``; the held-out
        check (leave-one-segment-out, ``horizon_s`` seconds ahead, against persistence), ρ(A), conditioning,
        physical checks and a one-line warning are in ``identification``
        (:class:`~workbench.plant.identification.IdentificationReport`). With ``hold`` (the default) a plant that
        fails a physical check is identified again with the failing entries held at their physics (``A[xdot, φ] =
        g·dt``) and taken unless the held-out segments show it worse (95 % HAC interval; the report's ``fixed:``
        lines), else the report carries the ``contradiction``; ``hold=False`` keeps the least-squares fit as it is
        (``--plant as-fitted``).

        Raises
        ------
        ModelError
            When the data do not excite every state and input direction the fitted rows use, or the structure
            is unknown or needs roles the data lack.
        """
        from workbench.plant.identification import identify_plant

        A, B, residual, report = identify_plant(
            demos, structure=structure, horizon_s=horizon_s, translation_invariant=translation_invariant, hold=hold
        )
        return cls(
            A,
            B,
            demos.dt,
            demos.state_names,
            demos.input_names,
            u_min=u_min,
            u_max=u_max,
            fit_residual=residual,
            roles=demos.roles,
            identification=report,
            plant_group=report.plant_group,
        )


PLANAR_QUADROTOR_ROLES = Roles(
    position=("x", "y"),
    velocity=("xdot", "ydot"),
    heading="phi",
    vertical="y",
    units={"x": "m", "y": "m", "phi": "rad", "xdot": "m/s", "ydot": "m/s", "phidot": "rad/s", "u1": "stick",
           "u2": "stick"},
)


def planar_quadrotor(
    dt: float = DT_PAPER_S,
    g: float = 9.8,
    k: tuple[float, float, float] = (-0.1, -1.0, -30.0),
    mass: float = 0.25,
    Ix: float = 0.01,
) -> LinearSystem:
    """The paper's linearized planar quadrotor, eqs. (31)–(32) of the method paper (`simulator_dynamics_A`, `_B`).

    State ``[x, y, phi, xdot, ydot, phidot]`` (m, m, rad, m/s, m/s, rad/s; y up, gravity compensated),
    input ``[u1, u2]`` = [angular acceleration, thrust] in [−1, 1]²; ``k = (k1, k2, k3)`` are the inner
    stabilizing loop's parameters.
    """
    k1, k2, k3 = k
    Ac = np.zeros((6, 6))
    Ac[0, 3] = Ac[1, 4] = Ac[2, 5] = 1.0
    Ac[3, 2] = g
    Ac[4, 4] = k1
    Ac[5, 2], Ac[5, 5] = k2, k3
    Bc = np.zeros((6, 2))
    Bc[4, 1] = 1.0 / mass
    Bc[5, 0] = 1.0 / Ix
    return LinearSystem(
        np.eye(6) + dt * Ac,
        dt * Bc,
        dt,
        ("x", "y", "phi", "xdot", "ydot", "phidot"),
        ("u1", "u2"),
        u_min=np.array([-1.0, -1.0]),
        u_max=np.array([1.0, 1.0]),
        roles=PLANAR_QUADROTOR_ROLES,
    )
