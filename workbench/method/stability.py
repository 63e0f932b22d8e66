"""Assumption 3 judged with its uncertainty: is the closed loop ``A + B K̂`` on the regulated states stable?

The paper refuses a gain whose spectral radius ``ρ(A + B K̂)`` is ≥ 1 (Assumption 3). But ``K̂`` is estimated, so
``ρ`` is too: a loop that keeps an integrator (a free flight's absolute position, which nobody steers back) sits at
``|λ| ≈ 1``, and least squares puts it at ``1 ± 0.01``. A refusal decided in the fourth decimal is a coin toss. So
``ρ`` is judged with its interval, from resampling the demonstrations the gain was fitted on:

- the interval lies inside the unit circle: **stable**, and the margin ``1 − ρ̂`` is stated;
- the interval holds 1: **not distinguishable** from the unit circle — still a model (its predictions are fine over
  seconds); where ``ρ̂ ≥ 1`` no quadratic cost has the gain, so the task objective is not found, and said so;
- the interval lies outside: **unstable**, a refusal that names the states the slow mode lies on and, where the
  trials were flown in an assisted mode whose autopilot holds exactly those states, that mode as the likely cause;
- no interval (fewer than two units to resample): ρ̂ < 1 is stable, as the paper's Assumption 3 has it, and ρ̂ ≥ 1 is
  not distinguishable — no refusal rests on a point estimate whose uncertainty is unknown (a rollout that then
  diverges is said so by :mod:`workbench.study.divergence`).

Resampling units are whole demonstrations when there are at least :data:`MIN_DEMOS` of them, else blocks of
:data:`BLOCK_S` seconds inside them (a free flight is often one or two long segments). Each resample refits the
gain with the estimator the fit used (both stages of the ``iv`` gain), from per-unit Gram matrices (eq. (13)'s data
matrices and the instruments' summed per unit), so a few hundred resamples cost a few tens of milliseconds. The
interval is the union of the percentile and the basic bootstrap intervals: near an integrator (``|λ| = 1``) the
estimate is biased and ``|λ|`` is not symmetric around it, and the union widens where the resamples show it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from workbench.errors import ModelError
from workbench.method.closed_loop import single_threaded_blas
from workbench.method.slow_mode import held_states, likely_cause, slow_mode

__all__ = ["Stability", "judge_stability", "with_timing_resamples", "refusal", "slow_mode", "held_states",
           "likely_cause", "MIN_DEMOS", "BLOCK_S", "RESAMPLES", "LEVEL"]

#: Whole demonstrations are resampled when there are at least this many; fewer are cut into blocks.
MIN_DEMOS = 10
#: Seconds per resampled block inside a demonstration: a few times the hand's drift time (an AR(1) of 0.9 per
#: 0.05 s step forgets in ~0.5 s), so that blocks are nearly independent.
BLOCK_S = 2.0
#: Resamples of the gain behind the interval.
RESAMPLES = 200
#: Level of the interval, percent.
LEVEL = 95.0

Verdict = Literal["stable", "not distinguishable", "unstable"]


@dataclass(frozen=True)
class Stability:
    """``ρ(A + B K̂)`` on the regulated states with its interval, and the verdict.

    Attributes
    ----------
    rho : float
        The estimate's spectral radius.
    lo, hi : float
        Its ``level`` % percentile interval over ``n_resamples`` resampled gains (NaN where none could be drawn).
    verdict : {"stable", "not distinguishable", "unstable"}
    slow_states : tuple of str
        The states the slowest mode lies on.
    states : tuple of str
        The regulated states the loop was judged on.
    unit : str
        What was resampled ("demonstrations" or "blocks of 2 s").
    n_units, n_resamples : int
    level : float
    """

    rho: float
    lo: float
    hi: float
    verdict: Verdict
    slow_states: tuple[str, ...] = ()
    states: tuple[str, ...] = ()
    unit: str = "demonstrations"
    n_units: int = 0
    n_resamples: int = 0
    level: float = LEVEL
    #: the loop judged: the regulator's ``A + BK̂``, or the pilot's loop with its delay and lag
    #: (:func:`workbench.method.timing.timed_spectral_radius`) for a gain on the state the pilot saw
    loop: str = "A + BK̂"
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def margin(self) -> float:
        """``1 − ρ̂``: how far inside the unit circle (negative: outside)."""
        return 1.0 - self.rho

    @property
    def has_interval(self) -> bool:
        return bool(np.isfinite(self.lo) and np.isfinite(self.hi))

    @property
    def refused(self) -> bool:
        return self.verdict == "unstable"

    def interval_words(self) -> str:
        if not self.has_interval:
            if self.loop != "A + BK̂":  # the pilot's loop with its timing: its uncertainty is the timing bootstrap's
                return "no interval here (the pilot's timing and gain are resampled by fit's bootstrap)"
            return "no interval (too few units to resample)"
        return (f"{self.level:g} % interval [{self.lo:.5g}, {self.hi:.5g}] over {self.n_resamples} resamples of "
                f"{self.n_units} {self.unit}")

    def describe(self) -> str:
        """One line: ρ with its interval, the verdict and the margin."""
        on = f" on {', '.join(self.states)}" if self.states else ""
        head = f"closed loop{on}: ρ({self.loop}) = {self.rho:.5g}, {self.interval_words()}"
        if self.verdict == "stable":
            return f"{head}: stable, margin {self.margin:.3g}"
        if self.verdict == "not distinguishable":
            return (f"{head}: not distinguishable from the unit circle (margin {self.margin:.2g}); the slow mode lies "
                    f"on {', '.join(self.slow_states)}")
        return f"{head}: unstable; the slow mode lies on {', '.join(self.slow_states)}"

    def to_dict(self) -> dict[str, Any]:
        return {"rho": self.rho, "lo": _json_float(self.lo), "hi": _json_float(self.hi), "verdict": self.verdict,
                "slow_states": list(self.slow_states), "states": list(self.states), "unit": self.unit,
                "n_units": self.n_units, "n_resamples": self.n_resamples, "level": self.level, "loop": self.loop}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Stability:
        nan = float("nan")
        return cls(rho=float(d["rho"]), lo=nan if d.get("lo") is None else float(d["lo"]),
                   hi=nan if d.get("hi") is None else float(d["hi"]), verdict=d["verdict"],
                   slow_states=tuple(d.get("slow_states", ())), states=tuple(d.get("states", ())),
                   unit=str(d.get("unit", "demonstrations")), n_units=int(d.get("n_units", 0)),
                   n_resamples=int(d.get("n_resamples", 0)), level=float(d.get("level", LEVEL)),
                   loop=str(d.get("loop", "A + BK̂")))


def _json_float(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


# -- the per-unit Gram matrices and the resampled gains --------------------------------------------------------


def _units(views: Sequence[Any], dt: float) -> tuple[list[tuple[int, slice]], str]:
    """Resampling units: (demonstration, rows) pairs; whole demonstrations, or blocks of ``BLOCK_S``."""
    if len(views) >= MIN_DEMOS:
        return [(j, slice(None)) for j in range(len(views))], "demonstrations"
    block = max(2, int(round(BLOCK_S / dt)))
    units = []
    for j, v in enumerate(views):
        T = len(v.x) - 1  # transitions
        for a in range(0, T, block):
            units.append((j, slice(a, min(T, a + block))))
    return units, f"blocks of {BLOCK_S:g} s"


def _grams(views: Sequence[Any], units: list[tuple[int, slice]], method: str, A: np.ndarray,
           B: np.ndarray) -> dict[str, np.ndarray]:
    """Per unit, the sums of outer products the estimator ``method`` needs (shape (J, ·, ·) each)."""
    from workbench.method.gain import iv_instruments

    rows = {}
    for j, v in enumerate(views):
        X, U = np.asarray(v.x, dtype=float)[:-1].T, np.asarray(v.u, dtype=float)[:-1].T
        R = {"X": X, "U": U}
        if method == "dmd":
            R["Xn"] = np.asarray(v.x, dtype=float)[1:].T
        if method == "iv":
            R["Z"] = iv_instruments(X, [X.shape[1]])
        rows[j] = R
    out: dict[str, list[np.ndarray]] = {}

    def add(key: str, a: np.ndarray, b: np.ndarray) -> None:
        out.setdefault(key, []).append(a @ b.T)

    for j, sl in units:
        R = {k: a[:, sl] for k, a in rows[j].items()}
        if method == "iv":
            add("ZZ", R["Z"], R["Z"])
            add("XZ", R["X"], R["Z"])
            add("UZ", R["U"], R["Z"])
        else:
            add("XX", R["X"], R["X"])
            add("UX" if method == "direct" else "NX", R["U"] if method == "direct" else R["Xn"], R["X"])
    return {k: np.stack(v) for k, v in out.items()}


def _resampled_gains(grams: dict[str, np.ndarray], counts: np.ndarray, method: str, A: np.ndarray,
                     B: np.ndarray) -> np.ndarray:
    """Gains of every resample (``counts`` (R, J): how often each unit is drawn), shape (R, m, n)."""

    def total(key: str) -> np.ndarray:
        g = grams[key]
        return (counts @ g.reshape(g.shape[0], -1)).reshape(counts.shape[0], *g.shape[1:])

    if method == "iv":  # both stages refitted (the first stage's own spread is a third of the gain's, measured)
        ZZ, XZ, UZ = total("ZZ"), total("XZ"), total("UZ")
        # first stage X̂ = P Z, P = XZᵀ (ZZᵀ)⁻¹; a ridge at rounding level keeps collinear time constants solvable
        ridge = 1e-10 * np.trace(ZZ, axis1=1, axis2=2)[:, None, None] * np.eye(ZZ.shape[1])
        P = np.swapaxes(np.linalg.solve(ZZ + ridge, np.swapaxes(XZ, 1, 2)), 1, 2)
        XhXh = P @ np.swapaxes(XZ, 1, 2)  # X̂ X̂ᵀ = P ZZ Pᵀ = P ZXᵀ
        UXh = UZ @ np.swapaxes(P, 1, 2)
        return np.swapaxes(np.linalg.solve(XhXh, np.swapaxes(UXh, 1, 2)), 1, 2)
    XX = total("XX")
    if method == "direct":
        UX = total("UX")
        return np.swapaxes(np.linalg.solve(XX, np.swapaxes(UX, 1, 2)), 1, 2)
    NX = total("NX")  # dmd: Ã = X' Xᵀ (X Xᵀ)⁻¹, K̂ = B⁺ (Ã − A)
    At = np.swapaxes(np.linalg.solve(XX, np.swapaxes(NX, 1, 2)), 1, 2)
    return np.linalg.pinv(B) @ (At - A)


def judge_stability(A: np.ndarray, B: np.ndarray, K: np.ndarray, views: Sequence[Any], method: str, dt: float,
                    state_names: Sequence[str], *, n_resamples: int = RESAMPLES, level: float = LEVEL,
                    seed: int = 0) -> Stability:
    """``ρ(A + B K)`` with its interval over resampled gains, and the verdict (see the module docstring).

    Parameters
    ----------
    A, B : ndarray
        The plant of the regulated states.
    K : ndarray, shape (m, n)
        The fitted gain on those states.
    views : sequence
        The demonstrations as the gain was fitted on them (``.x`` (N, n), ``.u`` (N, m)).
    method : {"direct", "iv", "dmd"}
        The estimator that made ``K`` (each resample refits with it).
    dt : float
        The sampling step (for the blocks' length).
    state_names : sequence of str
        Names of the regulated states.
    """
    A, B, K = (np.asarray(a, dtype=float) for a in (A, B, K))
    A_cl = A + B @ K
    rho, slow = slow_mode(A_cl, list(state_names))
    nan = float("nan")
    units, unit = _units(views, dt)
    lo = hi = nan
    n_ok = 0
    if len(units) >= 2 and n_resamples > 0:
        try:
            with single_threaded_blas():  # small batched algebra: threads only spin on a shared machine
                grams = _grams(views, units, method, A, B)
            rng = np.random.default_rng(seed)
            counts = rng.multinomial(len(units), np.full(len(units), 1.0 / len(units)), size=n_resamples)
            with np.errstate(all="ignore"), single_threaded_blas():
                Ks = _resampled_gains(grams, counts.astype(float), method, A, B)
                rhos = np.abs(np.linalg.eigvals(A[None] + B[None] @ Ks)).max(axis=1)
            n_ok = int(np.isfinite(rhos).sum())
            lo, hi = _rho_interval(rho, rhos, level)
        except (np.linalg.LinAlgError, ValueError):
            lo = hi = nan
    verdict = _verdict(rho, lo, hi)
    return Stability(rho=rho, lo=lo, hi=hi, verdict=verdict, slow_states=slow, states=tuple(state_names),
                     unit=unit, n_units=len(units), n_resamples=n_ok, level=float(level))


def _rho_interval(rho: float, rhos: np.ndarray, level: float) -> tuple[float, float]:
    """ρ's ``level`` % interval from resampled ρ's (NaN, NaN with fewer than two finite ones): the union of the
    percentile and the basic interval — a bias the resamples show (a root at 1, an integrator, is estimated with
    one, and |λ| is not symmetric around it) widens the interval instead of moving it past the truth — and the
    point estimate kept inside it (a percentile interval may miss it by a hair)."""
    rhos = np.asarray(rhos, dtype=float)
    rhos = rhos[np.isfinite(rhos)]
    if rhos.size < 2:
        return float("nan"), float("nan")
    tail = (100.0 - level) / 2.0
    q_lo, q_hi = (float(v) for v in np.percentile(rhos, [tail, 100.0 - tail]))
    return min(q_lo, 2.0 * rho - q_hi, rho), max(q_hi, 2.0 * rho - q_lo, rho)


def _verdict(rho: float, lo: float, hi: float) -> Verdict:
    """The interval judges. Without one the point estimate is accepted as the paper's Assumption 3 accepts it, but
    a refusal needs its interval outside the unit circle, and there is none: ρ̂ ≥ 1 is not distinguishable."""
    if np.isfinite(lo) and np.isfinite(hi):
        return "stable" if hi < 1.0 else "unstable" if lo > 1.0 else "not distinguishable"
    return "stable" if rho < 1.0 else "not distinguishable"


def with_timing_resamples(stability: Stability, A: np.ndarray, B: np.ndarray, dt: float, timing: Any,
                          level: float = LEVEL) -> Stability:
    """The stability of a gain on the state the pilot saw, with ρ's interval from the timing bootstrap's resamples.

    ``stability`` judged the pilot's loop with its delay and lag at the point estimate alone (the fit does not
    resample the timing). ``timing`` is the :class:`~workbench.method.timing.PilotTiming` of a bootstrap over
    whole trials: every resample's ``(K̂_b, d̂_b, τ̂_b)`` gives ``ρ_b`` of the loop it implies
    (:func:`workbench.method.timing.timed_spectral_radius`, eq. (T1) closed around the plant), and ρ's interval
    is made from them as :func:`judge_stability` makes it from resampled gains (:func:`_rho_interval`), so both
    loops are judged by one rule; the slow mode and the states stay the point's. Returned unchanged where the
    timing has no timed resamples (a refused timing, given values, no resamples)."""
    from workbench.method.pilot_loop import timed_spectral_radius

    Ks, ds, ts = (np.asarray(getattr(timing, k, ()), dtype=float) for k in ("K_samples", "delay_samples",
                                                                         "lag_samples"))
    if getattr(timing, "method", "none") == "none" or len(Ks) != len(ds) or len(ds) != len(ts) or len(ds) < 2:
        return stability
    rhos = np.array([timed_spectral_radius(A, B, K, d, t, dt) for K, d, t in zip(Ks, ds, ts, strict=True)])
    lo, hi = _rho_interval(stability.rho, rhos, level)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return stability
    return replace(stability, lo=lo, hi=hi, verdict=_verdict(stability.rho, lo, hi), unit="trials",
                   n_units=int(timing.n_trials), n_resamples=int(np.isfinite(rhos).sum()), level=float(level))


def refusal(stability: Stability, demos: Sequence[Any], roles: Any, method: str) -> ModelError:
    """The error of a loop judged unstable: ρ with its interval, the slow mode's states, the likely cause."""
    cause = likely_cause(demos, stability.slow_states, roles, stability.states)
    return ModelError(
        f"the gain ({method}) is not stabilizing: {stability.describe()}. In these demonstrations the pilot does not "
        f"bring {' and '.join(stability.slow_states)} back (no quadratic cost has this gain, Assumption 3 of the "
        f"method paper); fit only the states the pilot holds (--task …@states){cause}")
