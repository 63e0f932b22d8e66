"""Task frames (task parameters) of the task-parameterized GMM.

A frame ``p`` is an affine coordinate system ``(T^p, b^p)`` acting on a data point ``xi = [x; w]`` of
dimension ``D = n + m``. The data are observed in frame ``p`` as ``Z^p = (T^p)^{-1} (xi - b^p)``, eq. (28) of
the method paper, with ``T^p`` block-diagonal over input and output, eq. (29). Counting ``\\begin{equation}``
in the paper's LaTeX in order, these are eqs. (28)-(29) (labels ``eq:state_frame``, ``eq:T_b``); the quadrotor
study's frames (start and end of the demonstration, the end frame rotated by the final attitude) are
eqs. (33)-(34) (labels ``eq:simulation_TP_b``, ``eq:simulation_TP_T_phi``). The paper writes
``T^1 = I_2`` and ``T^2 = R(phi_N)`` as 2x2 matrices; here they act on the position block and are the identity
elsewhere, so every ``T^p`` is D x D.

Frames are computed per demonstration from its own data (start = first state, goal = last state, or the
demonstration's known target when there is one) and, for a new situation, from the task (start state, target).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from workbench.errors import ModelError
from workbench.frozen import readonly

__all__ = [
    "Frame",
    "FrameSpec",
    "FRAME_KINDS",
    "identity_frame",
    "start_frame",
    "goal_frame",
    "frames_for_demo",
    "frames_for_task",
    "project",
]

#: The frame kinds a :class:`FrameSpec` may name.
FRAME_KINDS = ("identity", "start", "goal")

# T^p must be safely invertible: Z^p = (T^p)^{-1}(xi - b^p) amplifies errors by cond(T^p).
_MAX_COND = 1e12


@dataclass(frozen=True, eq=False)
class Frame:
    """One task frame ``(T, b)``: an invertible linear map and an origin, eqs. (28)-(29).

    Parameters
    ----------
    T : ndarray, shape (D, D)
        Invertible linear transformation ``T^p`` (a rotation, scaling, shear, ...).
    b : ndarray, shape (D,)
        Origin ``b^p`` of the frame.

    Raises
    ------
    ModelError
        If the shapes disagree, an entry is not finite, or ``T`` is singular (condition number above 1e12).
    """

    T: np.ndarray
    b: np.ndarray

    def __post_init__(self) -> None:
        try:
            T = np.asarray(self.T, dtype=float)
            b = np.asarray(self.b, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ModelError(f"Frame: T and b must be numeric arrays ({exc})") from None
        if b.ndim != 1 or b.size == 0:
            raise ModelError(f"Frame: b must be a non-empty 1-D vector, got shape {b.shape}")
        D = b.shape[0]
        if T.shape != (D, D):
            raise ModelError(f"Frame: T must have shape ({D}, {D}) to match b of length {D}, got {T.shape}")
        if not np.all(np.isfinite(T)):
            raise ModelError("Frame: T contains non-finite values")
        if not np.all(np.isfinite(b)):
            raise ModelError("Frame: b contains non-finite values")
        cond = np.linalg.cond(T)
        if not np.isfinite(cond) or cond > _MAX_COND:
            raise ModelError(
                f"Frame: T is singular or nearly so (condition number {cond:.3g} > {_MAX_COND:.0e})"
            )
        object.__setattr__(self, "T", readonly(T))
        object.__setattr__(self, "b", readonly(b))

    @property
    def dim(self) -> int:
        """Dimension ``D`` of the data the frame acts on."""
        return int(self.b.shape[0])

    def to_local(self, xi: np.ndarray) -> np.ndarray:
        """Observe global data points in this frame: ``Z = T^{-1}(xi - b)``, eq. (28).

        Uses a linear solve, so it is exact for any invertible ``T`` (not only rotations).

        Parameters
        ----------
        xi : ndarray, shape (N, D) or (D,)

        Returns
        -------
        Z : ndarray, same shape as ``xi``
        """
        xi = np.asarray(xi, dtype=float)
        if xi.shape[-1] != self.dim:
            raise ModelError(
                f"Frame.to_local: data have {xi.shape[-1]} columns, the frame acts on {self.dim}"
            )
        return np.linalg.solve(self.T, (xi - self.b).T).T

    def to_global(self, z: np.ndarray) -> np.ndarray:
        """Map frame coordinates back to global ones: ``xi = T z + b`` (inverse of eq. (28))."""
        z = np.asarray(z, dtype=float)
        return z @ self.T.T + self.b


def project(xi: np.ndarray, frames: Sequence[Frame]) -> np.ndarray:
    """Observe data points in every frame, eq. (28).

    Parameters
    ----------
    xi : ndarray, shape (N, D)
    frames : sequence of P :class:`Frame`

    Returns
    -------
    Z : ndarray, shape (N, P, D)
        ``Z[:, p] = (T^p)^{-1} (xi - b^p)``.
    """
    xi = np.asarray(xi, dtype=float)
    return np.stack([f.to_local(xi) for f in frames], axis=1)


def identity_frame(D: int) -> Frame:
    """The global frame: ``T = I``, ``b = 0``."""
    if int(D) < 1:
        raise ModelError(f"identity_frame: dimension must be >= 1, got {D}")
    return Frame(np.eye(int(D)), np.zeros(int(D)))


def _state_vector(x: np.ndarray, what: str) -> np.ndarray:
    try:
        v = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(f"{what}: state must be a numeric vector") from None
    if v.ndim != 1 or v.size == 0:
        raise ModelError(f"{what}: state must be a non-empty 1-D vector, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ModelError(f"{what}: state contains non-finite values")
    return v


def start_frame(x0: np.ndarray, m: int) -> Frame:
    """Start frame of eq. (33): ``b = [x_0; 0_m]``, ``T = I``.

    Parameters
    ----------
    x0 : ndarray, shape (n,)
        Initial state of the demonstration or task.
    m : int
        Number of inputs (output block of ``xi``), whose origin stays at zero.
    """
    x0 = _state_vector(x0, "start_frame")
    if int(m) < 0:
        raise ModelError(f"start_frame: number of inputs must be >= 0, got {m}")
    D = x0.size + int(m)
    return Frame(np.eye(D), np.concatenate([x0, np.zeros(int(m))]))


def goal_frame(
    x_goal: np.ndarray,
    m: int,
    phi: float | None = None,
    position_idx: tuple[int, int] | None = None,
) -> Frame:
    """Goal frame of eqs. (33)-(34): ``b = [x_N; 0_m]``, ``T`` = rotation by ``phi`` on the position block.

    Parameters
    ----------
    x_goal : ndarray, shape (n,)
        Final state ``x_N`` (the recorded last state, or the known target of the task).
    m : int
        Number of inputs.
    phi : float or None
        Rotation angle ``phi_N`` (radians) applied to the two coordinates ``position_idx``; ``None`` or 0
        means no rotation (``T = I``).
    position_idx : (int, int)
        Indices of the planar position coordinates the rotation acts on (the plant's ``roles.plane``);
        required with ``phi``.
    """
    x_goal = _state_vector(x_goal, "goal_frame")
    if int(m) < 0:
        raise ModelError(f"goal_frame: number of inputs must be >= 0, got {m}")
    D = x_goal.size + int(m)
    T = np.eye(D)
    if phi is not None:
        phi = float(phi)
        if not np.isfinite(phi):
            raise ModelError("goal_frame: rotation angle phi is not finite")
        if position_idx is None or len(position_idx) != 2:
            raise ModelError(
                f"goal_frame: a rotation by phi needs position_idx, the two position states it turns, "
                f"got {position_idx}"
            )
        i, j = (int(k) for k in position_idx)
        if not (0 <= i < x_goal.size and 0 <= j < x_goal.size and i != j):
            raise ModelError(
                f"goal_frame: position_idx {tuple(position_idx)} must name two distinct state coordinates "
                f"in [0, {x_goal.size})"
            )
        c, s = np.cos(phi), np.sin(phi)
        T[i, i], T[i, j], T[j, i], T[j, j] = c, -s, s, c
    return Frame(T, np.concatenate([x_goal, np.zeros(int(m))]))


@dataclass(frozen=True)
class FrameSpec:
    """Which frames a TP-GMM uses, by name, and how to build them from a demonstration or a task.

    Parameters
    ----------
    kinds : tuple of str
        Frame names in order, each one of ``"identity"``, ``"start"``, ``"goal"``. The paper's quadrotor study
        uses ``("start", "goal")``, eq. (33).
    angle_index : int or None
        Index into the goal state of the angle ``phi_N`` by which the goal frame is rotated, eq. (34) (the
        plant's heading role). ``None`` means no rotation.
    position_idx : (int, int) or ()
        The two state coordinates the goal rotation acts on (the plant's ``roles.plane``); needed only with
        ``angle_index``.
    """

    kinds: tuple[str, ...] = ("start", "goal")
    angle_index: int | None = None
    position_idx: tuple[int, ...] = field(default=())

    def __post_init__(self) -> None:
        kinds = (self.kinds,) if isinstance(self.kinds, str) else tuple(self.kinds)
        if not kinds:
            raise ModelError("FrameSpec: at least one frame kind is needed")
        bad = [k for k in kinds if k not in FRAME_KINDS]
        if bad:
            raise ModelError(f"FrameSpec: unknown frame kind(s) {bad}; known kinds are {list(FRAME_KINDS)}")
        object.__setattr__(self, "kinds", kinds)
        object.__setattr__(self, "position_idx", tuple(int(i) for i in self.position_idx))
        if self.angle_index is not None:
            object.__setattr__(self, "angle_index", int(self.angle_index))
            if len(self.position_idx) != 2:
                raise ModelError(
                    f"FrameSpec: a goal rotation (angle_index {self.angle_index}) needs the two position states it "
                    f"turns as position_idx, got {self.position_idx}"
                )

    @classmethod
    def coerce(cls, spec: FrameSpec | str | Sequence[str]) -> FrameSpec:
        """Accept a :class:`FrameSpec`, one frame name, or a sequence of names."""
        if isinstance(spec, FrameSpec):
            return spec
        if isinstance(spec, str):
            return cls((spec,))
        return cls(tuple(spec))

    @property
    def n_frames(self) -> int:
        return len(self.kinds)

    def build(self, x0: np.ndarray, x_goal: np.ndarray | None, n_inputs: int) -> list[Frame]:
        """Frames for one situation given its start state and goal state (eqs. (33)-(34))."""
        x0 = _state_vector(x0, "FrameSpec.build (start)")
        n = x0.size
        if x_goal is not None:
            x_goal = _state_vector(x_goal, "FrameSpec.build (goal)")
            if x_goal.size != n:
                raise ModelError(f"FrameSpec.build: goal has {x_goal.size} entries, the state has {n}")
        frames: list[Frame] = []
        for kind in self.kinds:
            if kind == "identity":
                frames.append(identity_frame(n + int(n_inputs)))
            elif kind == "start":
                frames.append(start_frame(x0, n_inputs))
            else:
                if x_goal is None:
                    raise ModelError("FrameSpec.build: a 'goal' frame needs a goal state (target)")
                phi = None
                if self.angle_index is not None:
                    if not 0 <= self.angle_index < n:
                        raise ModelError(
                            f"FrameSpec.build: angle_index {self.angle_index} is outside the state (n={n})"
                        )
                    phi = x_goal[self.angle_index]
                frames.append(goal_frame(x_goal, n_inputs, phi=phi, position_idx=self.position_idx))
        return frames


def frames_for_demo(
    spec: FrameSpec | str | Sequence[str],
    x: np.ndarray,
    n_inputs: int,
    target: np.ndarray | None = None,
) -> list[Frame]:
    """Frames of one demonstration, computed from its own data, eq. (33).

    Parameters
    ----------
    spec : FrameSpec or frame names
    x : ndarray, shape (N, n)
        The demonstration's states; the start frame sits at ``x[0]``.
    n_inputs : int
        Number of inputs ``m`` (``D = n + m``).
    target : ndarray, shape (n,), optional
        Known goal state (e.g. ``meta["target"]``); defaults to the last recorded state ``x[-1]``.

    Returns
    -------
    list of Frame
    """
    spec = FrameSpec.coerce(spec)
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[0] == 0:
        raise ModelError(f"frames_for_demo: states must be a non-empty (N, n) array, got shape {x.shape}")
    goal = x[-1] if target is None else np.asarray(target, dtype=float)
    return spec.build(x[0], goal, n_inputs)


def frames_for_task(
    spec: FrameSpec | str | Sequence[str],
    x0: np.ndarray,
    target: np.ndarray | None,
    n_inputs: int,
) -> list[Frame]:
    """Frames of a new situation, from its start state and its target (a full n-vector goal state).

    For a test trial the goal frame sits at the known target (the landing pad), not at a recorded state.
    """
    return FrameSpec.coerce(spec).build(x0, target, n_inputs)
