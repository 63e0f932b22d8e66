"""Resampling whole demonstrations: intervals of ``K̂`` and of the task objective (the bootstrap over trials).

K̂'s intervals are ``K̂ ± t_{J−1} · s`` with ``s`` each entry's standard deviation over resamples of the ``J``
trials (:func:`gain_interval`), not the resamples' percentiles: on simulated pilots whose gain is known the
percentile interval held the truth on 79-82 % of the entries of the LQR and near-LQR operators, the ``t`` interval
on 93-94 %, and on ≥ 93 % of every other operator's (the coverage study ``bench/gain_coverage.py``, its numbers in
``bench/gain_coverage.md``). With the pilot's timing (:mod:`workbench.method.timing`) every resample re-identifies
the delay and the lag, so the gain's interval carries the timing's uncertainty too. The default rule (the timing
where the timing model fits, the paper's gain where it does not: :data:`IDENTIFY_OR_NONE`) is decided once, on all
trials, and every resample follows it: the interval is the printed estimator's, not a mixture of it and the other
one (why: :func:`workbench.method.timing.identify_timing`'s ``fallback``).

What the interval is an interval of: the printed estimator's own target, conditional on the rule's decision — on an
operator whose variability has a state-dependent mean, its dominant behaviour (METHOD.md, Remark 1: the gain plus
the estimator's linear projection of the mean, :func:`workbench.sim.operators.dominant_gain`), not the gain of the
cost it optimizes; on a pilot with no gain of its own, that estimator's value on many trials. Judged so, on seeds
that chose nothing, it held 92-100 % of the entries of each of five simulated operators (``bench/gain_coverage.md``,
round 7; the dead-zone pilot 80 % on the choosing seeds, where least squares stood in for the timing); where the
instruments barely move a state (the erratic pilot's thrust row under the timed LIML) the many-trial value itself
is not reproducible, and the interval is wide rather than unbounded.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.defaults import GAIN_RESAMPLES
from workbench.errors import DataError, ModelError
from workbench.frozen import readonly
from workbench.method.closed_loop import plant_matrices, single_threaded_blas
from workbench.method.gain import GainMethod, _first_stage, demo_blocks, gain_from_arrays
from workbench.method.inverse_lqr_sdp import _SOLVER_CHAIN, InverseLQR, cached_problem
from workbench.method.objective import _STRUCTURES, Structure, TaskObjective

__all__ = ['BootstrapResult', 'GainBootstrap', 'bootstrap_gain', 'bootstrap', 'gain_interval', 'GAIN_INTERVAL',
           'IDENTIFY_OR_NONE']

#: The default models' timing rule as a resampling's ``timing``: the pilot's timing where the timing model fits all
#: trials, the paper's instantaneous gain (instruments, else least squares) where it does not; decided on all trials,
#: and every resample (and every leave-one-out set) fits the gain so decided, so K̂'s interval is the interval of the
#: gain printed (the resamples that would have decided otherwise are counted: ``PilotTiming.n_otherwise``).
IDENTIFY_OR_NONE = "identify-or-none"

#: How K̂'s intervals are made from its resamples (see the module docstring and :func:`gain_interval`).
GAIN_INTERVAL = "t over trials"


def gain_interval(K: np.ndarray, K_samples: np.ndarray, n_trials: int, ci: float = 95.0
                  ) -> tuple[np.ndarray, np.ndarray]:
    """K̂'s ``ci`` % interval per entry: ``K̂ ± t_{J−1, (1+ci)/2} · s``, ``s`` the entry's standard deviation over the
    resampled gains (divisor ``n − 1``) and ``J`` the trials resampled (the bootstrap's unit; the resamples' spread
    estimates the estimator's, the ``t`` quantile its uncertainty with few trials). Chosen by coverage (module
    docstring); an entry that never varies gets a zero-width interval only if every resample agrees exactly."""
    import scipy.stats

    S = np.asarray(K_samples, dtype=float)
    if len(S) < 2:
        raise ModelError(f"{len(S)} resampled gain(s): an interval needs two or more")
    sd = S.std(axis=0, ddof=1)
    t = float(scipy.stats.t.ppf(0.5 + ci / 200.0, max(int(n_trials) - 1, 1)))
    K = np.asarray(K, dtype=float)
    return K - t * sd, K + t * sd

@dataclass(frozen=True, eq=False)
class BootstrapResult:
    """Percentile intervals of K̂ and of the normalized objective over demonstration resamples.

    Attributes
    ----------
    K : ndarray, shape (m, n)
        Point estimate from all demonstrations.
    objective : TaskObjective
        Point estimate of the task objective.
    timing : PilotTiming or None
        With the pilot's timing: the delay and the lag with their intervals (every resample re-identified them).
    K_samples : ndarray, shape (n_ok, m, n)
    Q_diag_samples, R_diag_samples : ndarray, shapes (n_ok, n) and (n_ok, m)
        Diagonals of ``Q_normalized`` and ``R_normalized`` per successful resample.
    K_lo, K_hi : ndarray, shape (m, n)
        K̂'s ``ci`` % interval (:func:`gain_interval`).
    Q_diag_lo, Q_diag_hi : ndarray, shape (n,)
    R_diag_lo, R_diag_hi : ndarray, shape (m,)
        Lower and upper percentile bounds of the ``ci`` % interval.
    n_boot, n_failed : int
        Resamples drawn, and resamples whose gain or objective could not be fitted.
    failures : tuple of str
        One message per failed resample (index: reason).
    ci : float
    method, structure : str
    seed : int
    """

    K: np.ndarray
    objective: TaskObjective
    K_samples: np.ndarray
    Q_diag_samples: np.ndarray
    R_diag_samples: np.ndarray
    K_lo: np.ndarray
    K_hi: np.ndarray
    Q_diag_lo: np.ndarray
    Q_diag_hi: np.ndarray
    R_diag_lo: np.ndarray
    R_diag_hi: np.ndarray
    n_boot: int
    n_failed: int
    failures: tuple[str, ...]
    ci: float
    method: str
    structure: str
    seed: int
    stopped: str = ""  # why the resampling stopped short of the resamples asked for (stop_note)
    timing: Any = None

    @property
    def n_ok(self) -> int:
        return self.n_boot - self.n_failed


#: Resamples fitted before deciding whether the rest are worth fitting, and the share of them that may fail.
EARLY_LOOK = 20
EARLY_STOP_FAILED = 0.5


def stop_note(n_boot: int, done: int, failures: Sequence[str]) -> str:
    """Why a bootstrap stopped short of ``n_boot`` (``""`` when it did not): how many failed and the commonest
    cause, for the terminal."""
    if done >= n_boot:
        return ""
    # grouped by the cause's first 160 characters, shown whole (a cut cause read "…do not mov" in the terminal)
    whole = {f.split(": ", 1)[-1].split(";")[0][:160]: f.split(": ", 1)[-1].split(";")[0] for f in failures}
    causes = Counter(f.split(": ", 1)[-1].split(";")[0][:160] for f in failures)
    key, count = causes.most_common(1)[0] if causes else ("", 0)
    cause = whole.get(key, key)
    return (f"stopped after {done} of {n_boot} resamples: {len(failures)} of them failed (more than "
            f"{EARLY_STOP_FAILED:.0%}), so the rest would not bound the intervals; commonest cause ({count}): {cause}")


def failure_note(failures: Sequence[str]) -> str:
    """How many resamples failed and the commonest cause (``""`` when none did), for the terminal."""
    if not failures:
        return ""
    reasons = [f.split(": ", 1)[-1] for f in failures]  # "resample 7: <reason>"
    # grouped by the reason's first clause: the numbers after it (ρ, λmin) differ from resample to resample
    causes = Counter(r.split(": ")[0].split(";")[0][:120] for r in reasons)
    cause, count = causes.most_common(1)[0]
    example = next(r for r in reasons if r.startswith(cause)).split(";")[0]  # whole: the terminal wraps it
    return f"{len(failures)} resample(s) failed; commonest cause ({count}): {example}"


def _resample_fit(
    blocks: list, idx: np.ndarray, A: np.ndarray, B: np.ndarray, method: GainMethod, solver: InverseLQR | None
) -> tuple[np.ndarray, TaskObjective | None]:
    """Gain and (with a solver) task objective of the demonstrations ``idx`` (with repeats) of ``blocks``."""
    X, U, X_next = (np.concatenate([blocks[i][k] for i in idx], axis=1) for k in range(3))
    K = gain_from_arrays(X, U, X_next, A, B, method, lengths=[blocks[i][0].shape[1] for i in idx])
    return K, (None if solver is None else solver.solve(K))


def _resamples(blocks: list, draws: list, A: np.ndarray, B: np.ndarray, method: GainMethod,
               solver: InverseLQR | None) -> list[tuple]:
    """Per resample ``(b, idx)``: ``(b, K, diag Q, diag R, None)`` (Q, R None without a solver), or
    ``(b, None, None, None, reason)``."""
    out = []
    for b, idx in draws:
        try:
            K, obj = _resample_fit(blocks, idx, A, B, method, solver)
        except ModelError as exc:
            out.append((b, None, None, None, str(exc)))
        else:
            q, r = (None, None) if obj is None else (np.diag(obj.Q_normalized), np.diag(obj.R_normalized))
            out.append((b, K, q, r, None))
    return out


def _bootstrap_block(task: tuple) -> list[tuple]:
    """A block of bootstrap resamples, run by a worker: it reads the demonstrations from their file."""
    ref, A, B, method, structure, solvers, draws = task
    blocks = demo_blocks(list(ref.load()), *B.shape)
    return _resamples(blocks, draws, A, B, method, _solver(A, B, structure, solvers))


def _solver(A: np.ndarray, B: np.ndarray, structure: Structure | None,
            solvers: tuple[str, ...] | None = None) -> InverseLQR | None:
    """The cached inverse-LQR problem of ``structure`` (None for gains only); with ``solvers``, a problem that
    tries only those (compiled once per process and solver chain: a bootstrap's blocks share it)."""
    if structure is None:
        return None
    return cached_problem(A, B, structure, True, solvers)


def resample_solvers(point: TaskObjective | None) -> tuple[str, ...] | None:
    """The solver chain of a bootstrap's resamples: the solver that solved the point estimate, alone.

    The point estimate tries every solver in turn; a resample does not. A resample the point's solver cannot
    solve would go on to SCS, which iterates to its limit (its budget in :mod:`~workbench.method.inverse_lqr_sdp`;
    once 200,000 iterations, about 20 s a solve on a real flight's gain, 90 % of a default ``fit``) to return, as a
    rule, nothing the checks accept: such a resample
    is counted as failed, with its reason, instead. ``None`` (every solver) where there is no point objective.
    """
    name = str(getattr(point, "solver", "") or "").upper()
    # a structured cost found by its closest gain ("closest-gain") has no SDP solver: every resample does the same
    return (name,) if name in _SOLVER_CHAIN else None


def _run_resamples(
    demos: Any, blocks: list, A: np.ndarray, B: np.ndarray, method: GainMethod, structure: Structure | None,
    n_boot: int, seed: int, progress: Callable[[int, int], None] | None, executor: Any,
    solvers: tuple[str, ...] | None = None,
) -> list[tuple]:
    """Draw ``n_boot`` resamples of whole trials from one generator and fit each (see :func:`bootstrap`)."""
    solver = _solver(A, B, structure, solvers)
    rng = np.random.default_rng(seed)
    draws = [(b, rng.integers(0, len(blocks), size=len(blocks))) for b in range(n_boot)]
    # Resamples that draw the same trials (in any order) give the same fit: each distinct one is fitted once and
    # counted as often as it was drawn (with few trials most draws repeat: 4 trials have 35 distinct resamples).
    keys = [tuple(np.sort(idx).tolist()) for _, idx in draws]
    unique: dict[tuple, tuple] = {}
    for draw, key in zip(draws, keys, strict=True):
        unique.setdefault(key, draw)
    distinct = list(unique.values())
    n = len(distinct)
    # a first look, then the rest only where it is worth it: when most resamples of the first look fail, the
    # remaining ones would cost minutes to deliver intervals of a few survivors (unbounded ones, often)
    fitted = _run_draws(demos, blocks, A, B, method, structure, solver, distinct[:EARLY_LOOK], 0, n, progress,
                        executor, solvers)
    if n > EARLY_LOOK and sum(r[4] is None for r in fitted) >= (1 - EARLY_STOP_FAILED) * len(fitted):
        fitted += _run_draws(demos, blocks, A, B, method, structure, solver, distinct[EARLY_LOOK:], len(fitted), n,
                             progress, executor, solvers)
    if len(fitted) < n:  # stopped early: the distinct resamples fitted
        return fitted
    by_key = dict(zip(unique, fitted, strict=True))
    return [(b, *by_key[k][1:]) for (b, _), k in zip(draws, keys, strict=True)]


def _run_draws(
    demos: Any, blocks: list, A: np.ndarray, B: np.ndarray, method: GainMethod, structure: Structure | None,
    solver: InverseLQR | None, draws: list, offset: int, n_boot: int, progress: Callable[[int, int], None] | None,
    executor: Any, solvers: tuple[str, ...] | None = None,
) -> list[tuple]:
    """Fit the resamples ``draws`` here or on the executor's workers (progress: ``offset`` done before, of
    ``n_boot``)."""
    if not draws:
        return []
    if executor is None:
        results = []
        with single_threaded_blas():  # as on a worker: the same reductions, so the same intervals
            for i, (b, idx) in enumerate(draws):
                results.extend(_resamples(blocks, [(b, idx)], A, B, method, solver))
                if progress is not None:
                    progress(offset + i + 1, n_boot)
        return results
    # one resample per task in process (progress per resample); on workers ~4 blocks each amortize the setup
    size = max(1, math.ceil(len(draws) / (4 * executor.workers))) if executor.parallel else 1
    ref = executor.share(demos)
    tasks = [(ref, A, B, method, structure, solvers, draws[i : i + size]) for i in range(0, len(draws), size)]
    report = None if progress is None else lambda done, total: progress(min(n_boot, offset + done * size), n_boot)
    return [r for block in executor.map(_bootstrap_block, tasks, progress=report) for r in block]


#: The pilot's timings of resamplings already done in this process, by what decides them (:func:`_timing_key`):
#: ``bootstrap`` and ``bootstrap_gain`` of the same trials, seed and resamples (a study's objective intervals and
#: its weight ratios) re-identify the same delays and lags in the same draws; the second takes the first's.
_TIMINGS: dict[bytes, Any] = {}
_TIMINGS_KEPT = 8


def _timing_key(demos: list, A: np.ndarray, B: np.ndarray, plant: Any, how: str, given: dict, timing: Any,
                n_boot: int, seed: int) -> bytes:
    """A digest of everything :func:`_timed_resampled`'s :class:`PilotTiming` depends on: the trials' states,
    inputs and recorded dead zones, the plant, the estimator, the given timing, the rule, the resamples and the
    seed."""
    import hashlib

    from workbench.method.pilot_loop import recorded_dead_zone

    h = hashlib.blake2b(digest_size=32)
    h.update(repr((how, sorted(given.items()), str(timing), int(n_boot), int(seed), float(plant.dt),
                   int(plant.n), int(plant.m), len(demos))).encode())
    for M in (A, B):
        h.update(np.ascontiguousarray(M, dtype=float).tobytes())
    for d in demos:
        x, u = (np.ascontiguousarray(np.asarray(v, dtype=float)) for v in (d.x, d.u))
        h.update(repr((x.shape, u.shape, recorded_dead_zone(d))).encode())
        h.update(x.tobytes())
        h.update(u.tobytes())
    return h.digest()


def _timed_resampled(
    demos: Any, plant: Any, n_boot: int, method: GainMethod, structure: Structure | None, seed: int,
    progress: Callable[[int, int], None] | None, timing: Any,
) -> tuple[int, np.ndarray, TaskObjective | None, list[tuple], list[str], Any]:
    """:func:`_resampled` with the pilot's timing: every resample re-identifies the delay and the lag and fits the
    gain on the seen state (:func:`workbench.method.timing.identify_timing`, the same draws of trials for a seed),
    then the objective of each resampled gain. The last element is the :class:`PilotTiming`."""
    from workbench.method.timing import identify_timing

    A, B = plant_matrices(plant.A, plant.B)
    given = {} if isinstance(timing, str) else {"delay_s": float(timing[0]), "lag_s": float(timing[1])}
    how = "direct" if method == "direct" and timing != IDENTIFY_OR_NONE else "liml"
    fallback = None
    if timing == IDENTIFY_OR_NONE:  # the model's rule, decided on all trials; every resample follows
        blocks = demo_blocks(list(demos), *B.shape)
        rule: dict[str, str] = {}

        def fallback(counts: np.ndarray) -> np.ndarray:
            if not rule:
                rule["method"] = rule_gain_method(blocks, A, B)
            return _rule_fit(blocks, np.repeat(np.arange(len(blocks)), counts), A, B, rule["method"])

    demos = list(demos)
    key = _timing_key(demos, A, B, plant, how, given, timing, n_boot, seed)
    pt = _TIMINGS.get(key)
    if pt is None:
        pt = identify_timing(demos, plant, method=how, n_boot=n_boot, seed=seed, progress=progress,
                             fallback=fallback, **given)
        _TIMINGS[key] = pt
        while len(_TIMINGS) > _TIMINGS_KEPT:
            _TIMINGS.pop(next(iter(_TIMINGS)))
    elif progress is not None:
        progress(n_boot, n_boot)
    solver = _solver(A, B, structure)
    obj0 = None if solver is None else solver.solve(np.asarray(pt.K))
    # the resamples try the point's solver alone, as without the timing (resample_solvers)
    solver = _solver(A, B, structure, resample_solvers(obj0))
    fits, failures = [], [f"resample: the timing fit failed ({pt.n_failed})"] * pt.n_failed
    with single_threaded_blas():
        for b, K in enumerate(pt.K_samples):
            try:
                obj = None if solver is None else solver.solve(np.asarray(K))
            except ModelError as exc:
                failures.append(f"resample {b}: {exc}")
                continue
            q, r = (None, None) if obj is None else (np.diag(obj.Q_normalized), np.diag(obj.R_normalized))
            fits.append((np.asarray(K), q, r))
    if not fits:
        raise ModelError(f"all {n_boot} bootstrap resamples failed; first failure: {failures[0]}")
    return pt.n_trials, np.asarray(pt.K), obj0, fits, failures, pt


def rule_gain_method(blocks: list, A: np.ndarray, B: np.ndarray) -> str:
    """The paper's gain that the default rule takes where the timing is refused, decided on all trials as
    :func:`workbench.method.gain.choose_gain` decides it: ``"iv"`` where the instruments are relevant and their
    gain stabilizing, else ``"direct"``. Every resample then fits that one (:func:`_rule_fit`), rather than
    choosing again."""
    try:
        _resample_fit(blocks, np.arange(len(blocks)), A, B, "iv", None)
    except ModelError:
        return "direct"
    return "iv"


def _rule_fit(blocks: list, idx: np.ndarray, A: np.ndarray, B: np.ndarray, method: str) -> np.ndarray:
    """The gain ``method`` (decided on all trials by :func:`rule_gain_method`) of the trials ``idx``, as the model
    fits it (:func:`~workbench.method.gain.choose_gain` with ``check=False``: its stability is judged with its
    interval) and without the relevance pretest that decided it: the same estimator in every resample. Two-stage
    least squares with these many instruments keeps its moments where the instruments are weak (it leans toward
    least squares, Bound, Jaeger & Baker 1995, JASA 90), so a resample with weak ones widens the interval rather
    than failing out of it."""
    X, U, X_next = (np.concatenate([blocks[i][k] for i in idx], axis=1) for k in range(3))
    if method == "iv":
        X_hat, _ = _first_stage(X, [blocks[i][0].shape[1] for i in idx])
        return np.linalg.lstsq(X_hat.T, U.T, rcond=None)[0].T
    return gain_from_arrays(X, U, X_next, A, B, method, check=False)


def _resampled(
    demos: Any, plant: Any, n_boot: int, method: GainMethod, structure: Structure | None, seed: int,
    progress: Callable[[int, int], None] | None, executor: Any, timing: Any = "none",
) -> tuple[int, np.ndarray, TaskObjective | None, list[tuple], list[str]] | tuple:
    """The point fit on all trials and ``n_boot`` resampled fits: ``(n_trials, K, objective, fits, failures)``,
    ``fits`` the ``(K, diag Q, diag R)`` of each resample that succeeded (Q, R None for gains only); with a
    ``timing`` other than ``"none"`` also the :class:`PilotTiming` (:func:`_timed_resampled`)."""
    if int(n_boot) < 1:
        raise DataError(f"n_boot must be ≥ 1, got {n_boot}")
    n_boot = int(n_boot)
    if len(demos) < 2:  # every resample of one trial is that trial: zero-width intervals that bound nothing
        raise ModelError(f"{len(demos)} demonstration(s): resampling needs two or more to estimate how the gain "
                         "and the objective vary, so no interval can be given")
    if not (isinstance(timing, str) and timing == "none"):
        return _timed_resampled(demos, plant, n_boot, method, structure, seed, progress, timing)
    A, B = plant_matrices(plant.A, plant.B)
    blocks = demo_blocks(list(demos), *B.shape)
    if not blocks:
        raise DataError("no demonstration has two or more samples: there is no transition to fit a gain to")
    K0, obj0 = _resample_fit(blocks, np.arange(len(blocks)), A, B, method, _solver(A, B, structure))
    fits, failures = [], []
    for b, K, q_diag, r_diag, error in _run_resamples(demos, blocks, A, B, method, structure, n_boot, seed,
                                                      progress, executor, resample_solvers(obj0)):
        if error is None:
            fits.append((K, q_diag, r_diag))
        else:
            failures.append(f"resample {b}: {error}")
    if not fits:
        raise ModelError(f"all {n_boot} bootstrap resamples failed; first failure: {failures[0]}")
    return len(blocks), K0, obj0, fits, failures


@dataclass(frozen=True, eq=False)
class GainBootstrap:
    """Gains ``K̂`` of demonstration resamples, without a task objective per resample.

    Attributes
    ----------
    K : ndarray, shape (m, n)
        Point estimate from all demonstrations.
    K_samples : ndarray, shape (n_ok, m, n)
    n_trials : int
        Demonstrations resampled (each resample draws this many, with repeats).
    n_boot, n_failed : int
    failures : tuple of str
    method : str
    seed : int
    K_loo : ndarray, shape (n_trials, m, n), or None
        The gain of every leave-one-demonstration-out set (the delete-one jackknife over trials), from which
        :mod:`workbench.method.ratio_profile` takes the bias correction, covariance and degrees of freedom of
        ``K̂``; None where not computed or where a leave-one-out fit failed.
    """

    K: np.ndarray
    K_samples: np.ndarray
    n_trials: int
    n_boot: int
    n_failed: int
    failures: tuple[str, ...]
    method: str
    seed: int
    stopped: str = ""  # why the resampling stopped short of the resamples asked for (stop_note)
    K_loo: np.ndarray | None = None
    timing: Any = None  # the PilotTiming, with the pilot's timing

    @property
    def n_ok(self) -> int:
        return self.n_boot - self.n_failed

    def interval(self, ci: float = 95.0) -> tuple[np.ndarray, np.ndarray]:
        """K̂'s ``ci`` % interval per entry (:func:`gain_interval`)."""
        return gain_interval(self.K, self.K_samples, self.n_trials, ci)


def bootstrap_gain(
    demos: Any,
    plant: Any,
    n_boot: int = GAIN_RESAMPLES,
    method: GainMethod = "direct",
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    *,
    executor: Any = None,
    jackknife: bool = True,
    timing: Any = "none",
) -> GainBootstrap:
    """The sampling distribution of ``K̂`` (eqs. (12)-(14)) over resamples of whole demonstrations.

    What :func:`bootstrap` draws, without solving an inverse LQR per resample: the source of the gain's
    covariance for :mod:`workbench.method.ratio_profile`. Same draws as :func:`bootstrap` for the same ``seed``.
    With ``jackknife`` (default) also the ``n`` leave-one-demonstration-out gains (``K_loo``, Quenouille-Tukey
    jackknife over trials): what the ratio intervals take their bias correction and degrees of freedom from.
    ``timing`` (``"identify"`` or a given ``(delay_s, lag_s)``, as a model's): the gain on the seen state, every
    resample re-identifying the timing (:mod:`workbench.method.timing`); :data:`IDENTIFY_OR_NONE`: the default
    model's rule, decided on all trials, every resample following it (``method`` is then the rule's: LIML, else
    "iv" or "direct" as on all trials); ``"none"``: the instantaneous gain.

    Raises
    ------
    ModelError
        If the point estimate on all demonstrations fails, or every resample fails.
    """
    out = _resampled(demos, plant, n_boot, method, None, seed, progress, executor, timing)
    n_trials, K0, _, fits, failures = out[:5]
    timed = len(out) > 5
    loo = None
    if jackknife and n_trials >= 3:
        if timed and getattr(out[5], "method", "") == "none":  # the rule decided no timing: the paper's gain
            A, B = plant_matrices(plant.A, plant.B)
            loo = _leave_one_out(demos, plant, rule_gain_method(demo_blocks(list(demos), *B.shape), A, B))
        elif timed:  # the timing's estimator as decided on all trials (LIML, or least squares where asked for)
            loo = _timed_leave_one_out(demos, plant, "direct" if out[5].method == "direct" else "iv", timing)
        else:
            loo = _leave_one_out(demos, plant, method)
    return GainBootstrap(K=readonly(K0), K_samples=readonly(np.array([f[0] for f in fits])), n_trials=n_trials,
                         n_boot=len(fits) + len(failures), n_failed=len(failures), failures=tuple(failures),
                         method=method, seed=int(seed), K_loo=None if loo is None else readonly(loo),
                         stopped=stop_note(int(n_boot), len(fits) + len(failures), failures),
                         timing=out[5] if timed else None)


def _timed_leave_one_out(demos: Any, plant: Any, method: GainMethod, timing: Any) -> np.ndarray | None:
    """:func:`_leave_one_out` of the gain with the pilot's timing (re-identified without each trial; with
    :data:`IDENTIFY_OR_NONE` the caller has decided on all trials that there is a timing, and by which estimator
    (``method`` "direct": least squares, else LIML), and every set follows)."""
    from workbench.method.timing import TimingData, fit_timing

    given = {} if isinstance(timing, str) else {"delay_s": float(timing[0]), "lag_s": float(timing[1])}
    data = TimingData(list(demos), plant.n, plant.m, plant.dt)
    how = "direct" if method == "direct" else "liml"
    try:
        return np.array([fit_timing(data, how, counts=np.arange(data.n_trials) != j, **given).K
                         for j in range(data.n_trials)])
    except (ModelError, np.linalg.LinAlgError):
        return None


def _leave_one_out(demos: Any, plant: Any, method: GainMethod) -> np.ndarray | None:
    """The gain of every set with one demonstration left out, shape (n, m, n_x); None if one fit fails (e.g. a
    non-stabilizing estimate): a jackknife with a hole in it estimates nothing."""
    A, B = plant_matrices(plant.A, plant.B)
    blocks = demo_blocks(list(demos), *B.shape)
    every = np.arange(len(blocks))
    try:
        with single_threaded_blas():  # as the resamples: the same reductions wherever it runs
            return np.array([_resample_fit(blocks, np.delete(every, j), A, B, method, None)[0] for j in every])
    except ModelError:
        return None


def bootstrap(
    demos: Any,
    plant: Any,
    n_boot: int = GAIN_RESAMPLES,
    method: GainMethod = "direct",
    structure: Structure = "full",
    seed: int = 0,
    ci: float = 95,
    progress: Callable[[int, int], None] | None = None,
    *,
    executor: Any = None,
    timing: Any = "none",
) -> BootstrapResult:
    """Bootstrap intervals of the gain (eqs. (12)-(14)) and the task objective (eqs. (15)-(19)).

    Demonstrations (whole trials, not samples: samples within a trial are correlated) are drawn with
    replacement; each resample is refitted with :func:`gain_from_arrays` and the cached :class:`InverseLQR`
    problem. Resamples that fail (rank-deficient, non-stabilizing, solver failure, infeasible structure)
    are counted and reported, not raised.

    Parameters
    ----------
    demos : DemonstrationSet or sequence of Demonstration
    plant : LinearSystem (anything with ``.A`` and ``.B``)
    n_boot : int
        Number of resamples.
    method, structure
        As in :func:`estimate_gain` and :func:`inverse_lqr`.
    seed : int
        Seed of the resampling generator.
    ci : float
        Interval coverage in percent (K̂: :func:`gain_interval`; the objective: percentiles).
    progress : callable(i, n), optional
        Called after each resample with the count done and ``n_boot`` (after each block with workers).
    timing : "none", "identify", "identify-or-none" or (delay_s, lag_s)
        As a model's (:mod:`workbench.method.timing`; :data:`IDENTIFY_OR_NONE`, as in :func:`bootstrap_gain`):
        with the pilot's timing every resample re-identifies it and
        fits the gain on the seen state (serially: ``executor`` is not used), and ``timing`` of the result holds
        the delay and the lag with their intervals.
    executor : Executor, optional
        Where blocks of resamples run (``workbench.study.executor``; default here, in order); with workers, ``demos``
        must be a DemonstrationSet (they read it from a shared Parquet file). Every resample's trials are drawn
        here from one generator, so the intervals are the same whatever runs them.

    Raises
    ------
    ModelError
        If the point estimate on all demonstrations fails, or every resample fails.
    """
    if not 0 < ci < 100:
        raise DataError(f"ci must be a percentage in (0, 100), got {ci}")
    if structure not in _STRUCTURES:
        raise DataError(f"structure must be one of {_STRUCTURES}, got {structure!r}")
    out = _resampled(demos, plant, n_boot, method, structure, seed, progress, executor, timing)
    n_trials, K0, obj0, fits, failures = out[:5]
    K_s, Q_s, R_s = (np.array([f[i] for f in fits]) for i in range(3))
    q = [(100 - ci) / 2, 100 - (100 - ci) / 2]
    if len(K_s) >= 2:
        K_lo, K_hi = gain_interval(K0, K_s, n_trials, ci)
    else:  # one resample bounds nothing: no interval rather than a zero-width one
        K_lo = K_hi = np.full_like(np.asarray(K0, dtype=float), np.nan)
    Q_lo, Q_hi = np.percentile(Q_s, q, axis=0)
    R_lo, R_hi = np.percentile(R_s, q, axis=0)
    return BootstrapResult(
        K=readonly(K0),
        objective=obj0,
        K_samples=readonly(K_s),
        Q_diag_samples=readonly(Q_s),
        R_diag_samples=readonly(R_s),
        K_lo=readonly(K_lo),
        K_hi=readonly(K_hi),
        Q_diag_lo=readonly(Q_lo),
        Q_diag_hi=readonly(Q_hi),
        R_diag_lo=readonly(R_lo),
        R_diag_hi=readonly(R_hi),
        n_boot=len(fits) + len(failures),
        n_failed=len(failures),
        stopped=stop_note(int(n_boot), len(fits) + len(failures), failures),
        failures=tuple(failures),
        ci=float(ci),
        method=method,
        structure=structure,
        seed=int(seed),
        timing=out[5] if len(out) > 5 else None,
    )
