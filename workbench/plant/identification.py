"""Plant identification with physics in it: (A, B) by least squares, checked on held-out segments.

:meth:`workbench.plant.system.LinearSystem.identify` calls :func:`identify_plant`. Two structures:

``"kinematic"``
    For every position / velocity pair of the roles (:mod:`workbench.data.roles`) the position row is fixed by
    kinematics, ``p[k+1] = p[k] + dt·v[k]`` (no input and no other state enters a position directly), and the
    remaining rows are fitted by least squares. With ``translation_invariant=True`` no other state may depend
    on an absolute position either (as in the paper's plant, eq. (31)), so the positions are exact integrators.
    That is the physics of free flight, but then a pilot who does not hold an absolute position leaves the
    closed loop marginal and the inverse LQR refuses the gain (Assumption 3); by default the fit may keep the
    small pull toward where the flights were, and the report shows how large it is.
``"free"``
    Every entry of ``[A B]`` by least squares, ``min ‖X' − [A B] [X; U]‖_F`` (eq. (1) read as a regression).

Regression pairs ``(x[k], u[k]) → x[k+1]`` never cross two segments. The :class:`IdentificationReport` says
how good the plant is where it was not fitted: one-step and multi-step (the model's horizon) error with every
segment left out in turn (leave-one-segment-out; a log with fewer than three segments is cut into contiguous
pieces first), against persistence (every state held, positions moved on at their recorded velocity); the
spectral radius ρ(A), also without the integrators; the conditioning of the regressor; the physical checks
of the segments' plant group and what each stick commands in it (:mod:`workbench.plant.physics`); and one warning
line when the plant is unstable beyond its integrators, worse than persistence, or ill-conditioned.

A plant that fails a physical check is the wrong vehicle for a pilot model (a lean that does not accelerate the
vehicle as a tilt does). Where the free fit fails one, the plant is identified again as a grey box: each failing
entry held at what physics says it is (``A[xdot, phi] = g·dt``, where the roles name the pair; a plane's
``A[phi, phidot] = dt``) and the rest of its row by least squares. The held plant is the plant unless it predicts the
held-out segments' one-step states of those rows worse than the free fit, judged by the Diebold–Mariano comparison of
the two forecasts' squared errors with a Newey–West interval (:data:`PHYSICS_CI`): then the data contradict the physics
and the report carries one line saying so (``contradiction``), which :func:`workbench.plant.choice.choose_plant`
raises (``--plant as-fitted`` takes the free fit as it is). A held plant says so in the report's ``fixed`` lines.

One plant per kind of stick: demonstrations of different plant groups (:mod:`workbench.data.plant_groups`: a lean
angle in STABILIZE, a velocity in LOITER) are never pooled into one (A, B); identification refuses them, naming the
groups, and the caller identifies each group's plant from its own segments.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from workbench.data.plant_groups import describe_groups, plant_groups
from workbench.data.roles import ResolvedRoles, Roles
from workbench.defaults import HORIZON_S
from workbench.errors import ModelError
from workbench.frozen import readonly
from workbench.plant.physics import GRAVITY, PhysicalCheck, StickResponse, group_checks, stick_responses
from workbench.plant.physics import cause as _cause
from workbench.plant.physics import disagreement as _disagreement

if TYPE_CHECKING:
    from workbench.data.demonstrations import DemonstrationSet

__all__ = [
    "IdentificationReport",
    "PhysicalCheck",
    "StickResponse",
    "identify_plant",
    "resolve_structure",
    "STRUCTURES",
    "GRAVITY",
    "ILL_CONDITIONED",
]

STRUCTURES = ("auto", "kinematic", "free")
#: Condition number of the column-normalized regressor above which the fit is called ill-conditioned.
ILL_CONDITIONED = 1e4
#: |λ| above 1 + this counts as unstable (the paper's plant has eigenvalues exactly on the unit circle).
UNSTABLE_TOL = 1e-6
MIN_SEGMENTS = 3
#: The interval (%) by which a plant held at its physics is judged to predict held-out samples worse than the free fit.
PHYSICS_CI = 95.0


@dataclass(frozen=True, eq=False)
class IdentificationReport:
    """How an identified plant does where it was not fitted (see the module docstring).

    RMSE arrays are per state, in the state's units, pooled over the held-out segments; the ``*_score``
    scalars are the RMSE over all states after dividing each by its standard deviation in the data, so that
    states of different units weigh alike.
    """

    structure: str
    validation: str
    n_segments: int
    n_pairs: int
    dt: float
    n_steps: int
    state_names: tuple[str, ...]
    one_step_rmse: np.ndarray
    one_step_rmse_persistence: np.ndarray
    horizon_rmse: np.ndarray
    horizon_rmse_persistence: np.ndarray
    one_step_score: float
    one_step_score_persistence: float
    horizon_score: float
    horizon_score_persistence: float
    spectral_radius: float
    spectral_radius_beyond_integrators: float
    n_integrators: int
    condition_number: float
    fixed: tuple[str, ...] = ()
    checks: tuple[PhysicalCheck, ...] = ()
    warnings: tuple[str, ...] = ()
    position_pull: float = 0.0  # max |A[i, p]| over positions p and the other rows i (0 when translation invariant)
    plant_group: str | None = None  # what the sticks command in these segments' modes (workbench.data.plant_groups)
    responses: tuple[StickResponse, ...] = ()  # what each stick commands in this plant (workbench.plant.physics)
    #: the free fit's checks where it failed one and the failing entries were held at their physics (else ``()``)
    free_checks: tuple[PhysicalCheck, ...] = ()
    #: one line where the free fit fails a check and the data contradict the physics (see :func:`identify_plant`)
    contradiction: str = ""
    #: why ``--plant auto`` identified data in the paper's layout and step (workbench.plant.choice.paper_reproduces)
    why: str = ""
    #: each state's standard deviation in the data (the scale the scores divide by; ``None``: 1)
    state_scale: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("one_step_rmse", "one_step_rmse_persistence", "horizon_rmse", "horizon_rmse_persistence"):
            object.__setattr__(self, name, readonly(np.asarray(getattr(self, name), dtype=np.float64)))

    @property
    def warning(self) -> str | None:
        """One line naming every problem found, or ``None``."""
        return "identified plant: " + "; ".join(self.warnings) if self.warnings else None

    @property
    def physics_failure(self) -> str:
        """The failed physical checks, each naming its state pair, its ratio to g·dt and the likely cause;
        ``""`` where every check passes (a fit that fails on such a plant fails for this first)."""
        return "; ".join(_disagreement(c) for c in self.checks if not c.within())

    @property
    def held(self) -> tuple[str, ...]:
        """The ``fixed`` lines of the entries held at their physics because the free fit failed their check (the
        kinematic rows' lines, fixed in every kinematic plant, left out); ``()`` for a plant taken as fitted."""
        failed = [c.name for c in self.free_checks if not c.within()]
        return tuple(f for f in self.fixed if any(f.startswith(f"{name} = ") for name in failed))

    @property
    def horizon_s(self) -> float:
        return self.n_steps * self.dt

    def __str__(self) -> str:
        return self.describe()

    def describe(self, warning: bool = True) -> str:
        """The report as lines of text; ``warning=False`` leaves out its warning line, for a caller that gives the
        warning where warnings go (the command line's standard error) and would otherwise print it twice."""
        group = f"plant group {self.plant_group}, " if self.plant_group else ""
        lines = [
            f"plant identification ({group}{self.structure}, dt {self.dt:g} s, {self.n_pairs} sample pairs, "
            f"{self.n_segments} segment{'' if self.n_segments == 1 else 's'}; held out: {self.validation})",
        ]
        lines += [f"  fixed: {f}" for f in self.fixed]
        lines += [f"  not the paper's plant: {self.why}"] if self.why else []
        # said in words, never "nan": persistence has a score wherever a held-out piece lasts the horizon
        horizon = (f"plant {_score_text(self.horizon_score)}, persistence {self.horizon_score_persistence:.3g}"
                   if np.isfinite(self.horizon_score_persistence) else "not scored: no held-out piece lasts that long")
        lines.append(
            f"  normalized held-out RMSE, one step: plant {_score_text(self.one_step_score)}, persistence "
            f"{self.one_step_score_persistence:.3g}; {self.horizon_s:g} s ({self.n_steps} steps): {horizon}"
        )
        width = max(len(s) for s in self.state_names)
        lines.append(f"  {'state':<{width}}  {'1-step':>9}  {'persist.':>9}  {f'{self.horizon_s:g} s':>9}  "
                     f"{'persist.':>9}")
        # a fixed row moves a position on at its recorded velocity, persistence's own rule: at one step the two
        # columns agree by construction ("y 0.02324 0.02324" read as a coincidence)
        fixed = {f.split("[", 1)[0] for f in self.fixed}
        for i, s in enumerate(self.state_names):
            cells = (self.one_step_rmse[i], self.one_step_rmse_persistence[i], self.horizon_rmse[i],
                     self.horizon_rmse_persistence[i])
            scale = 1.0 if self.state_scale is None else float(self.state_scale[i])
            lines.append(f"  {s:<{width}}  " + "  ".join(f"{_rmse_cell(v, scale):>9}" for v in cells)
                         + (" *" if s in fixed else ""))
        if fixed & set(self.state_names):
            lines.append("  * a fixed row: moved on at its recorded velocity, persistence's rule, so one step ahead "
                         "the two agree")
        if self.n_integrators:
            lines.append(f"  absolute position in the other rows: max |A[i, position]| = {self.position_pull:.3g} "
                         "(0 in free-flight physics; a pull the data ascribe to the plant)")
        lines.append(
            f"  ρ(A) = {self.spectral_radius:.6g}; without the {self.n_integrators} integrator(s) "
            f"{self.spectral_radius_beyond_integrators:.6g}; cond of the normalized regressor "
            f"{self.condition_number:.3g}"
        )
        free = {c.name: c for c in self.free_checks if not c.within()}
        lines += [f"  check: {c}" + (f" (held; the free fit's {free[c.name].value:.4g}, ratio "
                                     f"{free[c.name].ratio:.3g})" if c.name in free else "") for c in self.checks]
        lines += [f"  stick: {r}" for r in self.responses]
        if warning and self.warning:
            lines.append(f"  warning: {self.warning}")
        return "\n".join(lines)


def _score_text(v: float) -> str:
    """A normalized score, ``diverges`` where a held-out rollout overflowed."""
    return "diverges" if np.isinf(v) else f"{v:.3g}"


#: An RMSE below this fraction of its state's standard deviation is floating-point rounding, not a prediction error.
ROUNDING = 1e-12


def _rmse_cell(v: float, scale: float = 1.0) -> str:
    """An RMSE in the report's table: ``—`` where not scored, ``diverges`` where the rollout overflowed; 0 where it
    is rounding, below :data:`ROUNDING` of the state's scale ``scale`` (a row the physics fixes exactly, such as the
    position's, leaves 1e-17 of floating-point error; a state measured in small units is not rounding at 1e-13)."""
    if np.isinf(v):
        return "diverges"
    if not np.isfinite(v):
        return "—"
    return "0" if abs(v) < ROUNDING * scale else f"{v:.4g}"


# ----------------------------------------------------------------------------------------------- structure


def _pairs_of(r: ResolvedRoles) -> list[tuple[int, int]]:
    return list(zip(r.position, r.velocity, strict=True)) if r.has_velocity else []


def resolve_structure(structure: str, roles: Roles, state_names: Sequence[str]) -> str:
    """``"kinematic"`` or ``"free"``; ``"auto"`` is kinematic when the roles pair positions with velocities.

    Raises
    ------
    ModelError
        An unknown structure, or ``"kinematic"`` for states without position / velocity roles.
    """
    if structure not in STRUCTURES:
        raise ModelError(f"identify: unknown structure {structure!r}; known: {', '.join(STRUCTURES)}")
    has_pairs = bool(_pairs_of(roles.resolve(state_names))) if roles else False
    if structure == "auto":
        return "kinematic" if has_pairs else "free"
    if structure == "kinematic" and not has_pairs:
        raise ModelError(
            "identify: structure 'kinematic' needs roles that pair position states with velocity states "
            f"(the data's roles: position {list(roles.position)}, velocity {list(roles.velocity)}); "
            "declare them in the mapping's [roles] table or use structure='free'"
        )
    return structure


@dataclass(frozen=True)
class _Layout:
    """Which rows are fixed and which regressor columns the fitted rows use."""

    n: int
    m: int
    dt: float
    pairs: tuple[tuple[int, int], ...]  # (position, velocity) state indices with kinematic rows
    invariant: bool = False  # no row but a position's own depends on an absolute position
    #: entries of ``[A B]`` held at a value physics gives (row, column, value); the rest of their rows is fitted
    held: tuple[tuple[int, int, float], ...] = ()

    @property
    def fixed_rows(self) -> list[int]:
        return [p for p, _ in self.pairs]

    @property
    def free_rows(self) -> list[int]:
        fixed = set(self.fixed_rows)
        return [i for i in range(self.n) if i not in fixed]

    @property
    def columns(self) -> list[int]:
        """Columns of ``[X U]`` the fitted rows regress on: all, or all but the positions (translation invariance)."""
        fixed = set(self.fixed_rows) if self.invariant else set()
        return [j for j in range(self.n + self.m) if j not in fixed]

    def base(self) -> np.ndarray:
        """``[A B]`` with the kinematic rows filled in and zeros elsewhere."""
        AB = np.zeros((self.n, self.n + self.m))
        for p, v in self.pairs:
            AB[p, p] = 1.0
            AB[p, v] = self.dt
        for i, j, value in self.held:
            AB[i, j] = value
        return AB


def _fit(layout: _Layout, Z: np.ndarray, Xn: np.ndarray) -> np.ndarray:
    """Least squares of the free rows, ``min ‖X' − [A B] [X; U]‖_F`` (eq. (1)); a row with held entries regresses
    what they leave, ``x_i[k+1] − Σ_held AB[i, j] z_j[k]``, on its other columns (a grey-box row)."""
    AB = layout.base()
    rows, cols = layout.free_rows, layout.columns
    held_rows = {i for i, _, _ in layout.held}
    plain = [i for i in rows if i not in held_rows]
    if plain:
        theta, *_ = np.linalg.lstsq(Z[:, cols], Xn[:, plain], rcond=None)
        AB[np.ix_(plain, cols)] = theta.T
    for i in sorted(held_rows & set(rows)):
        fixed = [j for r, j, _ in layout.held if r == i]
        own = [j for j in cols if j not in fixed]
        target = Xn[:, i] - Z[:, fixed] @ AB[i, fixed]
        theta, *_ = np.linalg.lstsq(Z[:, own], target, rcond=None)
        AB[i, own] = theta
    return AB


def _rank(M: np.ndarray) -> int:
    s = np.linalg.svd(M, compute_uv=False)
    return int((s > 1e-10 * max(M.shape) * s[0]).sum()) if s.size and s[0] > 0 else 0


def _unexcited(Z: np.ndarray, labels: Sequence[str]) -> str:
    """What the data leave unexcited, for a user: the columns that are 0 throughout, else the combination of columns
    the smallest singular direction of the (column-scaled) regressor is made of."""
    zero = [labels[j] for j in np.flatnonzero(~np.any(Z != 0, axis=0))]
    if zero:
        return f"{', '.join(zero)} never move{'s' if len(zero) == 1 else ''} (0 in every sample)"
    scale = np.sqrt(np.mean(Z**2, axis=0))
    v = np.linalg.svd(Z / scale, full_matrices=False)[2][-1]
    top = np.argsort(-np.abs(v))[:3]
    parts = [f"{v[j]:+.2f}·{labels[j]}" for j in top if abs(v[j]) > 0.1]
    return f"the scaled columns combine to (almost) nothing along {' '.join(parts)}"


def _normalized_cond(M: np.ndarray) -> float:
    scale = np.sqrt(np.mean(M**2, axis=0))
    scale[scale == 0] = 1.0
    return float(np.linalg.cond(M / scale))


# -------------------------------------------------------------------------------------------- validation


def _segments(demos: DemonstrationSet) -> tuple[list[tuple[np.ndarray, np.ndarray]], bool]:
    """The demonstrations as (x, u) segments; fewer than three are cut into contiguous pieces (``True``)."""
    segs = [(d.x, d.u) for d in demos]
    if len(segs) >= MIN_SEGMENTS:
        return segs, False
    total = sum(len(x) for x, _ in segs)
    pieces = []
    for x, u in segs:
        k = max(1, int(round(MIN_SEGMENTS * len(x) / total)))
        for idx in np.array_split(np.arange(len(x)), k):
            if len(idx) >= 2:
                pieces.append((x[idx], u[idx]))
    return pieces, True


def _pairs(segs: Sequence[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    Z = [np.hstack([x[:-1], u[:-1]]) for x, u in segs if len(x) >= 2]
    Xn = [x[1:] for x, _ in segs if len(x) >= 2]
    return np.concatenate(Z), np.concatenate(Xn)


def _errors(A: np.ndarray, B: np.ndarray, x: np.ndarray, u: np.ndarray, h: int) -> tuple[np.ndarray, np.ndarray]:
    """One-step and ``h``-step errors (rows: start samples) of open-loop rollouts with the recorded inputs."""
    one = x[1:] - (x[:-1] @ A.T + u[:-1] @ B.T)
    starts = len(x) - h
    if starts <= 0:
        return one, np.empty((0, x.shape[1]))
    xh = x[:starts].copy()
    for j in range(h):
        xh = xh @ A.T + u[j : j + starts] @ B.T
    return one, x[h : h + starts] - xh


def _rms(errors: list[np.ndarray], n: int) -> np.ndarray:
    e = np.concatenate(errors) if errors else np.empty((0, n))
    if not len(e):
        return np.full(n, np.nan)  # not scored
    with np.errstate(over="ignore", invalid="ignore"):
        rms = np.sqrt(np.mean(e**2, axis=0))
    return np.where(np.isfinite(rms), rms, np.inf)  # scored, and a rollout overflowed (inf − inf is nan): diverges


def _score(rmse: np.ndarray, sigma: np.ndarray) -> float:
    return float(np.sqrt(np.mean((rmse / sigma) ** 2)))


def _beyond_integrators(A: np.ndarray, n_int: int) -> float:
    """The spectral radius once the ``n_int`` eigenvalues closest to 1 (the integrators) are set aside."""
    lam = np.linalg.eigvals(A)
    if n_int:
        lam = lam[np.argsort(np.abs(lam - 1.0))[n_int:]]
    return float(np.abs(lam).max()) if lam.size else 0.0


def identify_plant(
    demos: DemonstrationSet, structure: str = "auto", horizon_s: float = HORIZON_S, translation_invariant: bool = False,
    hold: bool = True,
) -> tuple[np.ndarray, np.ndarray, float, IdentificationReport]:
    """(A, B), the RMS one-step residual of the fit on all data, and the report (see the module docstring).

    Parameters
    ----------
    demos : DemonstrationSet
    structure : {"auto", "kinematic", "free"}
        ``"auto"`` is ``"kinematic"`` when ``demos.roles`` pair positions with velocities, else ``"free"``.
    horizon_s : float
        Seconds of the multi-step check (the model's prediction horizon; the paper's is 3 s).
    translation_invariant : bool
        With ``"kinematic"``: also keep absolute positions out of every other row.
    hold : bool
        Where the fit fails a physical check, identify it again with the failing entries held at their physics and
        take that plant unless the held-out data contradict it (the module docstring); ``False``: the free fit as it
        is (``--plant as-fitted``).

    Raises
    ------
    ModelError
        No demonstrations, an unknown or inapplicable structure, or data that do not excite every direction
        the fitted rows regress on.
    """
    if not len(demos):
        raise ModelError("identify needs at least one demonstration")
    groups = plant_groups(demos)
    if len(groups) > 1:
        # a stick that commands a lean angle in one mode and a velocity in another is two plants, not one
        raise ModelError(
            f"identify: one plant per kind of stick, but these demonstrations span {len(groups)} plant groups "
            f"({describe_groups(demos)}); identify each group's plant from its own segments (`--plant-group`)")
    group = groups[0]
    n, m, dt = demos.n_states, demos.n_inputs, float(demos.dt)
    names = tuple(demos.state_names)
    roles = demos.roles
    structure = resolve_structure(structure, roles, names)
    r = roles.resolve(names) if roles else ResolvedRoles()
    pairs = tuple(_pairs_of(r)) if structure == "kinematic" else ()
    layout = _Layout(n, m, dt, pairs, invariant=translation_invariant)

    Z, Xn = _pairs([(d.x, d.u) for d in demos])
    cols = layout.columns
    rank = _rank(Z[:, cols])
    if rank < len(cols):
        labels = [*names, *demos.input_names]
        raise ModelError(
            f"identify: the data excite only {rank} of {len(cols)} state and input directions "
            f"(cond [X; U] = {np.linalg.cond(Z[:, cols]):.3g}): {_unexcited(Z[:, cols], [labels[j] for j in cols])}; "
            "record more varied demonstrations"
        )
    free = _estimate(demos, layout, Z, Xn, r, structure, horizon_s, translation_invariant, group)
    failed = [c for c in free[3].checks if not c.within() and c.at is not None]
    if not failed or not hold:
        return free[:4]
    # grey box: the entries physics gives held at their value, the rest of their rows by least squares
    held = _estimate(demos, dataclasses.replace(layout, held=tuple((*c.at, c.expected) for c in failed)), Z, Xn, r,
                     structure, horizon_s, translation_invariant, group)
    rows = sorted({c.at[0] for c in failed})
    verdict = _held_vs_free(held[4][:, rows], free[4][:, rows])
    what = ", ".join(names[i] for i in rows)
    if not verdict.worse:
        said = tuple(f"{c.name} = {c.expected:.4g} ({c.note.split(':')[0]}; the free fit's {c.value:.3g} is "
                     f"{c.ratio:.2g} × it) — {verdict.describe(what)}" for c in failed)
        return (*held[:3], dataclasses.replace(held[3], fixed=held[3].fixed + said, free_checks=free[3].checks))
    # one line, the measured facts first (a table cell or a terminal cuts a long line at its end)
    ratios = "; ".join(f"{c.name} is {c.ratio:.2g} × {c.note.split(':')[0]}" for c in failed)
    contradiction = (f"the identified plant is not physics: {ratios}, and held at its physics it predicts the held-out "
                     f"{what} worse ({verdict.describe(what)}): the recorded data contradict the physics, so no pilot "
                     f"model on this plant describes the vehicle; {_cause(failed[0])} (`--plant as-fitted` takes the "
                     "plant as fitted)")
    return (*free[:3], dataclasses.replace(free[3], contradiction=contradiction))


@dataclass(frozen=True)
class _Comparison:
    """The held plant's held-out one-step squared error minus the free plant's, per sample: its mean and interval."""

    mean_held: float
    mean_free: float
    lo: float
    hi: float
    n: int

    @property
    def worse(self) -> bool:
        """The held plant predicts worse beyond the interval (its lower bound above 0); no interval is no verdict."""
        return bool(np.isfinite(self.lo) and self.lo > 0.0)

    @property
    def relative(self) -> tuple[float, float, float]:
        """The held plant's mean squared error relative to the free fit's, ``100 (MSE_held − MSE_free) / MSE_free``
        (%), with the interval of the difference on the same scale (the free fit's MSE taken as known)."""
        scale = 100.0 / self.mean_free if self.mean_free > 0 else float("nan")
        return ((self.mean_held - self.mean_free) * scale, self.lo * scale, self.hi * scale)

    def describe(self, what: str) -> str:
        """The comparison in one clause: both RMSEs, the relative and absolute difference in mean squared error with
        their interval; in words where there is nothing (no held-out sample) or too little (one) to compare by."""
        if self.n == 0:
            return f"no held-out samples of {what} to compare the held and the free plant by"
        rms = f"held-out one-step RMSE of {what} {np.sqrt(self.mean_held):.3g} held, {np.sqrt(self.mean_free):.3g} free"
        if self.n < 2:
            return f"{rms} (too few held-out samples to compare: {self.n})"
        if not np.isfinite(self.lo):
            return f"{rms} (not compared: a held-out prediction diverges)"
        rel, lo, hi = self.relative
        relative = (f"held {_percent(rel)} % MSE [{_percent(lo)} %, {_percent(hi)} %]; " if np.isfinite(rel)
                    else "")  # a free fit that predicts exactly has no scale for a relative difference
        return (f"{rms}; {relative}mean squared difference {self.mean_held - self.mean_free:.3g} [{self.lo:.3g}, "
                f"{self.hi:.3g}] ({PHYSICS_CI:g} % HAC interval over {self.n} held-out samples)")


def _percent(v: float) -> str:
    """A signed percentage in three figures, whole numbers from 1000 on (never ``+1.39e+04``)."""
    return f"{v:+.3g}" if abs(v) < 1000 else f"{v:+.0f}"


def _held_vs_free(held: np.ndarray, free: np.ndarray) -> _Comparison:
    """Whether the held plant predicts the held-out samples worse than the free one: the Diebold–Mariano comparison of
    two forecasts, ``d_k = Σ_rows e_held² − e_free²`` per held-out sample, its mean with a Newey–West (HAC) interval
    (the one-step errors of a plant are autocorrelated; lags by the Newey–West rule ``⌊4 (T/100)^{2/9}⌋``)."""
    d = (held**2).sum(axis=1) - (free**2).sum(axis=1)
    n = len(d)
    mean_held, mean_free = (float((e**2).sum(axis=1).mean()) if n else float("nan") for e in (held, free))
    if n < 2 or not np.isfinite(d).all():
        return _Comparison(mean_held, mean_free, float("nan"), float("nan"), n)
    if not np.ptp(d) > 0:  # identical forecasts: no difference, no spread to judge one by
        return _Comparison(mean_held, mean_free, float(d[0]), float(d[0]), n)
    import statsmodels.api as sm  # here: identification without a failed check never needs it

    lags = int(np.floor(4.0 * (n / 100.0) ** (2.0 / 9.0)))
    fit = sm.OLS(d, np.ones(n)).fit(cov_type="HAC", cov_kwds={"maxlags": lags})
    lo, hi = (float(v) for v in np.asarray(fit.conf_int(alpha=1.0 - PHYSICS_CI / 100.0))[0])
    return _Comparison(mean_held, mean_free, lo, hi, n)


def _estimate(demos: DemonstrationSet, layout: _Layout, Z: np.ndarray, Xn: np.ndarray, r: ResolvedRoles,
              structure: str, horizon_s: float, translation_invariant: bool,
              group: str | None) -> tuple[np.ndarray, np.ndarray, float, IdentificationReport, np.ndarray]:
    """(A, B) of ``layout`` on the pairs ``Z → Xn``, their residual and report (held out, checks, warnings), and the
    held-out one-step errors (rows: the held-out samples of every fold in turn)."""
    n, m, dt = layout.n, layout.m, layout.dt
    names = tuple(demos.state_names)
    roles = demos.roles
    pairs = layout.pairs
    cols = layout.columns
    AB = _fit(layout, Z, Xn)
    A, B = AB[:, :n], AB[:, n:]
    residual = float(np.sqrt(np.mean((Xn - Z @ AB.T) ** 2)))

    # held out: each segment predicted by the plant fitted on the others
    segs, cut = _segments(demos)
    h = max(1, int(round(horizon_s / dt)))
    P = r.constant_velocity(n, dt)  # a free plant too is compared with constant velocity where roles know it
    zero_B = np.zeros((n, m))
    errs: dict[str, list[np.ndarray]] = {"one": [], "h": [], "one_p": [], "h_p": []}
    n_folds = 0
    for i, (x, u) in enumerate(segs):
        if len(x) < 2:
            continue
        train = [s for j, s in enumerate(segs) if j != i]
        Zt, Xt = _pairs(train)
        if _rank(Zt[:, cols]) < len(cols):
            continue  # this fold's training data alone do not excite every direction
        ABi = _fit(layout, Zt, Xt)
        one, hs = _errors(ABi[:, :n], ABi[:, n:], x, u, h)
        one_p, hs_p = _errors(P, zero_B, x, u, h)
        for key, e in (("one", one), ("h", hs), ("one_p", one_p), ("h_p", hs_p)):
            errs[key].append(e)
        n_folds += 1
    sigma = np.concatenate([d.x for d in demos]).std(axis=0)
    sigma[~(sigma > 0)] = 1.0
    rm = {k: _rms(v, n) for k, v in errs.items()}
    what = "contiguous pieces of the segments" if cut else "segments"
    validation = f"leave-one-out over {len(segs)} {what}, {n_folds} folds fitted"

    n_int = len(tuple(_pairs_of(r)))
    rho = float(np.abs(np.linalg.eigvals(A)).max())
    rho_free = _beyond_integrators(A, n_int)
    cond = _normalized_cond(Z[:, cols])
    checks = group_checks(A, r, roles, names, dt, group)
    responses = stick_responses(A, B, r, roles, names, tuple(demos.input_names), dt, group)
    elsewhere = ", no position elsewhere" if translation_invariant else ""
    fixed = tuple(f"{names[p]}[k+1] = {names[p]}[k] + dt·{names[v]}[k] (no input{elsewhere})" for p, v in pairs)
    positions = list(r.position) if n_int else []
    others = [i for i in range(n) if i not in positions]
    pull = float(np.abs(A[np.ix_(others, positions)]).max()) if positions and others else 0.0

    scores = {k: _score(v, sigma) for k, v in rm.items()}
    warns = []
    if rho_free > 1.0 + UNSTABLE_TOL:
        warns.append(f"unstable beyond its integrators (ρ = {rho_free:.4g})")
    worse = [f"{label} ({scores[a]:.3g} vs {scores[b]:.3g})" for label, a, b in
             (("one step", "one", "one_p"), (f"{h * dt:g} s", "h", "h_p")) if scores[a] > scores[b]]
    if worse:
        warns.append("worse than persistence on held-out segments at " + " and ".join(worse))
    if n_folds == 0:
        warns.append("no held-out check: no fold's training data excite every direction")
    for c in checks:
        if not c.within():
            warns.append(_disagreement(c))
    if cond > ILL_CONDITIONED:
        warns.append(f"ill-conditioned regressor (cond {cond:.3g} > {ILL_CONDITIONED:g})")
    report = IdentificationReport(
        structure=structure, validation=validation, n_segments=len(demos), n_pairs=len(Z), dt=dt, n_steps=h,
        state_names=names, one_step_rmse=rm["one"], one_step_rmse_persistence=rm["one_p"], horizon_rmse=rm["h"],
        horizon_rmse_persistence=rm["h_p"], one_step_score=scores["one"], one_step_score_persistence=scores["one_p"],
        horizon_score=scores["h"], horizon_score_persistence=scores["h_p"], spectral_radius=rho,
        spectral_radius_beyond_integrators=rho_free, n_integrators=n_int, condition_number=cond, fixed=fixed,
        checks=checks, warnings=tuple(warns), position_pull=pull, plant_group=group, responses=responses,
        state_scale=sigma,
    )
    one_step = np.concatenate(errs["one"]) if errs["one"] else np.empty((0, n))
    return A, B, residual, report, one_step
