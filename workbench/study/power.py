"""Power curves of weight ratios: how many demonstrations this operator would need for a ratio to be pinned down.

An interval that spans more than ×10 says the data do not identify a ratio; a user then needs to know whether
more demonstrations would help, and how many. This module answers by simulation from the fitted model: new
demonstrations are flown on the same plant and task by the model itself (``u = K̂(x − target) + w``, ``w`` drawn
from its GMR variability with the AR(1) persistence of its residuals, without the band-calibration factor, which
widens prediction bands for the mean's own error and is no part of the operator), with starts uniform in the box of
the training starts and lengths and targets drawn from the training trials. Each simulated set of ``n`` is
refitted as the data were (instrumental-variable gain, its covariance over resampled trials, the minimum-distance
ratios of :mod:`workbench.method.ratio_profile`), and each ratio's interval span is measured at several ``n``.

The span is measured by the Wald approximation of the profile interval, ``exp(2 t se)`` with ``se`` from the
minimum-distance fit's curvature ``(Gᵀ Σ⁻¹ G)⁻¹``: near the target span of ×2 the profile is close to quadratic, and
a profile walk per simulated set would cost minutes.

The law (:data:`LAW`): between the simulated sizes the median log span is interpolated linearly in ``log n``; beyond
the largest size it shrinks as ``1/√n`` from that size's median (``log span · √n`` constant). The √n law is the
asymptotic one; it is anchored at the largest size because smaller sets are further from it — their critical value
has fewer degrees of freedom and their profile is more curved, so their spans shrink faster than ``1/√n`` and a
constant fitted through all sizes (this module's first law, the median of ``log span · √n`` over every set) over-
predicts the demonstrations needed. ``tests/study/test_power_sim.py`` checks the law against sets simulated at a
larger size than the curve's. A ratio whose simulated estimate stays at a zero or infinite weight at the largest
size needs more than simulated (``inf``).

Enough sets to be monotone, and the law's own uncertainty (issue 40). One set per size gave curves such as "n=24:
×1.96, n=48: ×3.84e+09, n=96: ×1.27": a single set's accident decides the number. Each size now gets at least
:data:`MIN_SETS` sets, and one more set per size is simulated, up to :data:`MAX_SETS`, until the median log spans no
longer grow with n; a curve still not monotone then gives no number ("not monotone"). The number needed carries a
90 % interval from resampling the simulated sets within each size (:data:`NEEDED_RESAMPLES` times), which says how
much the simulation itself leaves open.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from workbench.errors import DataError, ModelError
from workbench.method import ratio_profile

__all__ = ["PowerCurve", "simulate_like", "power_curve", "as_fitted", "regulated_plant", "LAW", "MIN_SETS",
           "MAX_SETS"]

#: Simulated sets per size at least (a median of fewer is one set's accident), and at most while the curve is not yet
#: monotone; resamples of the sets behind the 90 % interval of the number needed.
MIN_SETS, MAX_SETS = 3, 6
NEEDED_RESAMPLES = 200
#: The law behind "demonstrations needed", as the report states it.
LAW = ("the median simulated log span interpolated in log n between the simulated sizes, and shrinking as 1/√n "
       "from the largest simulated size beyond it")


@dataclass(frozen=True, eq=False)
class PowerCurve:
    """Simulated interval spans of every weight ratio against the number of demonstrations.

    Attributes
    ----------
    spans : DataFrame
        ``ratio, n, repeat, span`` (inf where the simulated estimate is at a zero or infinite weight).
    needed : dict of str to float
        Per ratio, the demonstrations for a span below ``target`` (:data:`LAW`; inf: more than simulated; NaN: the
        median spans still grew with n after :data:`MAX_SETS` sets per size, so the law gives no number).
    target : float
    n_trials : int
        The demonstrations the model was fitted on.
    needed_lo, needed_hi : dict of str to float
        Per ratio, the 90 % interval of ``needed`` over resamples of the simulated sets within each size.
    """

    spans: pd.DataFrame
    needed: dict[str, float]
    target: float
    n_trials: int
    needed_lo: dict[str, float] = field(default_factory=dict)
    needed_hi: dict[str, float] = field(default_factory=dict)

    def predicted_log_span(self, ratio: str, n: float) -> float:
        """The law's log span of ``ratio`` at ``n`` demonstrations (inf: unbounded at the largest simulated size;
        nan: not simulated)."""
        med = _medians(self.spans[self.spans["ratio"] == ratio])
        if med is None:
            return float("nan")
        return _law(med, float(n))

    @property
    def law(self) -> str:
        """The law behind :attr:`needed`, in words (:data:`LAW`)."""
        return LAW

    @property
    def largest(self) -> int:
        """The largest simulated number of demonstrations."""
        return int(self.spans["n"].max()) if len(self.spans) else 0

    def describe(self) -> list[str]:
        """One line per ratio: its median simulated span at each size (with the sets behind it) and the
        demonstrations needed with their interval."""
        lines = []
        med = self.spans.groupby(["ratio", "n"], sort=False)["span"].median()
        sets = self.spans.groupby(["ratio", "n"], sort=False)["span"].size()
        for ratio in dict.fromkeys(self.spans["ratio"]):
            pts = ", ".join(f"n={n}: ×{v:.3g}" if np.isfinite(v) else f"n={n}: unbounded"
                            for n, v in med[ratio].items())
            k = sorted(set(sets[ratio].tolist()))
            per = f"{k[0]}" if len(k) == 1 else f"{k[0]}–{k[-1]}"
            need = self.needed.get(ratio, float("inf"))
            lo, hi = self.needed_lo.get(ratio, np.nan), self.needed_hi.get(ratio, np.nan)
            if np.isnan(need):
                tail = (f"no number: the median span still grows with n at some size after {per} sets per size "
                        "(the simulation cannot say)")
            elif not np.isfinite(need):
                tail = f"span < ×{self.target:g} at more than {self.largest} demonstrations"
            else:
                band = (f" [90 % over resampled sets: {_count(lo)}–{_count(hi)}]" if np.isfinite(lo) and
                        np.isfinite(hi) else " [90 % over resampled sets: up to more than simulated]"
                        if np.isfinite(lo) else "")
                tail = f"span < ×{self.target:g} at ~{_count(need)} demonstrations{band}"
            lines.append(f"{ratio}: {pts} (median of {per} simulated sets each); {tail}")
        return lines


def simulate_like(model, demos, n_trials: int, seed: int = 0):
    """``n_trials`` demonstrations flown by a fitted model on its plant and the demonstrations' task.

    Starts are uniform in the box of the demonstrations' starts, lengths and targets drawn from them; the input is
    the model's ``u = K̂(x − target) + w`` with ``w`` its GMR variability, drawn with the AR(1) persistence and scale
    of its training residuals (:func:`workbench.models.prediction.rollout_samples`).
    """
    from workbench.data.demonstrations import Demonstration, DemonstrationSet
    from workbench.models.prediction import rollout_samples

    ds = list(demos)
    if not ds:
        raise DataError("simulate_like: no demonstrations to take the task from")
    if int(n_trials) < 1:
        raise DataError(f"simulate_like: n_trials must be ≥ 1, got {n_trials}")
    rng = np.random.default_rng(seed)
    starts = np.array([d.x[0] for d in ds])
    lo, hi = starts.min(axis=0), starts.max(axis=0)
    A, B = np.asarray(model.plant.A, dtype=float), np.asarray(model.plant.B, dtype=float)
    scale = np.asarray(model.noise_scale_, dtype=float) / float(model.noise_band_factor_)
    m = B.shape[1]
    trials = []
    for _ in range(int(n_trials)):
        like = ds[int(rng.integers(len(ds)))]
        x0 = rng.uniform(lo, hi)
        target = like.target if like.target is not None else model.default_target(x0)
        task = model._task(x0, target)  # noqa: SLF001 - one conditional per trial, not per step
        # the draws rollout_samples makes for this trial (one (1, m) row per step), taken in the same order
        trials.append((like, x0, task, rng.standard_normal((max(len(like) - 1, 1), m))))
    # every trial rolled out at once where the model reads its tasks in one batch; else trial by trial
    runs = _rollouts_together(model, A, B, trials, scale)
    out = []
    for j, (like, x0, task, draws) in enumerate(trials):
        if runs is None:
            # the model's input distribution for this task, as its predictions use it
            policy = model._policy(*task)  # noqa: SLF001
            X, U = rollout_samples(A, B, policy, x0, len(like) - 1, 1, _Replay(draws), model.noise_rho_, None,
                                   scale)
        else:
            X, U = runs[j]
        x, u = X[0, :-1], U[0]
        t = model.plant.dt * np.arange(len(x))
        meta = {"id": f"sim-{j:04d}", "label": like.label, "source": "simulated from the fitted model"}
        if like.target is not None:
            meta["target"] = [float(v) for v in like.target]
        out.append(Demonstration(t, x, u, meta))
    return DemonstrationSet(out, model.plant.state_names, model.plant.input_names, model.plant.dt,
                            roles=model.plant.roles)


class _Replay:
    """Stands in for the generator in :func:`~workbench.models.prediction.rollout_samples`: hands back one trial's
    draws, taken beforehand in the order that function takes them."""

    def __init__(self, draws: np.ndarray) -> None:
        self._draws, self._k = draws, 0

    def standard_normal(self, shape: tuple[int, int]) -> np.ndarray:
        z = self._draws[self._k : self._k + 1].reshape(shape)
        self._k += 1
        return z


def _rollouts_together(model, A: np.ndarray, B: np.ndarray, trials: list, scale: np.ndarray) -> list | None:
    """One sample of every trial of :func:`simulate_like`, all rolled out in one batch, each row as
    :func:`~workbench.models.prediction.rollout_samples` would roll it out alone (its own task's policy, its own
    draws, its own Cholesky factor): per trial ``(X (1, H+1, n), U (1, H, m))``. None where the model cannot read
    its tasks in one batch (``_stacked_policy``) or a task's policy follows a reference."""
    from workbench.models.prediction import psd_sqrt

    stacked = getattr(model, "_stacked_policy", None)
    if stacked is None or len(trials) < 2:
        return None
    steps = np.array([len(like) - 1 for like, *_ in trials])
    if steps.min() < 1:
        return None
    order = np.argsort(-steps, kind="stable")  # longest first: the trials still running are always a prefix
    policies: dict[int, object] = {}
    full = stacked([trials[j][2] for j in order], [1] * len(order))
    if full is None:
        return None
    policies[len(order)] = full
    rho = np.broadcast_to(np.asarray(model.noise_rho_, dtype=float), (B.shape[1],))
    innov = np.sqrt(1.0 - rho**2)
    n, m = B.shape
    T, H = len(order), int(steps.max())
    X = np.empty((T, H + 1, n))
    U = np.empty((T, H, m))
    x = np.array([trials[j][1] for j in order], dtype=float)
    X[:, 0] = x
    draws = [trials[j][3] for j in order]
    z = np.array([d[0] for d in draws])
    AT, BT = A.T, B.T
    for k in range(H):
        live = int((steps[order] > k).sum())
        if live not in policies:
            policies[live] = stacked([trials[j][2] for j in order[:live]], [1] * live)
        policy = policies[live]
        x, z = x[:live], z[:live]
        if k:
            z = rho * z + innov * np.array([d[k] for d in draws[:live]])
        mean, cov = policy(x)
        try:
            root = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:  # row by row, as each trial alone decides (Cholesky or its eigen-fallback)
            root = np.concatenate([psd_sqrt(cov[i : i + 1]) for i in range(live)])
        u = mean + np.einsum("sij,sj->si", root, scale * z)
        U[:live, k] = u
        x = x @ AT + u @ BT
        X[:live, k + 1] = x
    runs: list = [None] * T
    for row, j in enumerate(order):
        runs[j] = (X[row : row + 1, : steps[j] + 1], U[row : row + 1, : steps[j]])
    return runs


def as_fitted(model, demos) -> list:
    """The demonstrations as the model saw them: its pilot's view (:meth:`~workbench.models.behavior.BehaviorModel.
    pilot_view`: the regulated states relative to the goal or the reference, the input net of its feedforward), on
    the plant of those states (:func:`regulated_plant`)."""
    return model.pilot_view(list(demos))


def regulated_plant(model):
    """The plant the model's gain acts on: the regulated states' (the whole plant where it regulates them all)."""
    return model.plant_regulated


def _log_spans(gains, plant, ci: float, ratios: Sequence[str] | None = None) -> dict[str, float]:
    """Per ratio, ``2 t se`` of its minimum-distance log estimate (inf at a zero or infinite weight); only the
    parts holding one of ``ratios`` (default all)."""
    from workbench.method.structured import closest_structured_objective, decoupled_parts

    A, B = np.asarray(plant.A, dtype=float), np.asarray(plant.B, dtype=float)
    K, K_s = np.asarray(gains.K, dtype=float), np.asarray(gains.K_samples, dtype=float)
    out = {}
    for states, inputs in decoupled_parts(A, B):
        if not inputs:
            continue
        s, c = list(states), list(inputs)
        names = ratio_profile.ratio_names(s, c, plant.state_names, plant.input_names)
        if ratios is not None and not set(names) & set(ratios):
            continue
        try:
            part = ratio_profile.PartDistance.from_samples(A[np.ix_(s, s)], B[np.ix_(s, c)], K[np.ix_(c, s)],
                                                           K_s[:, c][:, :, s], gains.n_trials)
            start = closest_structured_objective(part.A, part.B, K[np.ix_(c, s)], "diagonal")
        except ModelError:
            out.update(dict.fromkeys(names, float("inf")))
            continue
        w0 = np.r_[np.diag(start.Q), np.diag(start.R)[1:]] / start.R[0, 0]
        theta, _ = ratio_profile.fit(part, np.log(np.maximum(w0, 1e-300)))
        # the half-width of the part's simultaneous intervals (ratio_profile.interval), linearized
        t = float(np.sqrt(ratio_profile.critical_value(ci, gains.n_trials, part.d, part.nu)))
        _, jac = part.problem()
        G = jac(theta)
        at_bound = np.abs(theta) >= ratio_profile.LOG_BOUND - 1e-3
        lam, V = np.linalg.eigh(G.T @ G)
        flat = lam <= 1e-10 * max(float(lam.max(initial=0.0)), 1e-300)
        cov = (V[:, ~flat] / lam[~flat]) @ V[:, ~flat].T
        unbounded = at_bound | (np.abs(V[:, flat]).max(axis=1, initial=0.0) > 1e-6)
        for j, name in enumerate(names):
            out[name] = float("inf") if unbounded[j] else 2.0 * t * float(np.sqrt(max(cov[j, j], 0.0)))
    return out


def power_curve(model, demos, sizes: Sequence[int] | None = None, repeats: int = MIN_SETS, n_boot: int = 40,
                seed: int = 0, ci: float = 95.0, target: float = 2.0, gain: str = "iv",
                ratios: Sequence[str] | None = None) -> PowerCurve:
    """Simulated interval spans of the weight ratios of a fitted model at several numbers of demonstrations.

    Parameters
    ----------
    model : HumanBehaviorModel
        Fitted; the simulated operator.
    demos : DemonstrationSet
        Its training demonstrations (the task: starts, lengths, targets).
    sizes : sequence of int, optional
        Numbers of demonstrations to simulate; default ``n/2``, ``n`` and ``2n`` for ``n`` training trials.
    n_boot : int
        Resampled gains per simulated set for the gain's covariance.
    ratios : sequence of str, optional
        Only the parts holding these ratios are refitted (default all): the others cost time and say nothing new.
    repeats : int
        Simulated sets per size to start with (at least :data:`MIN_SETS`); one more per size is simulated, up to
        :data:`MAX_SETS`, while some ratio's median span still grows with n.
    """
    from workbench.method.resampling import bootstrap_gain

    n0 = len(demos)
    # half, once and twice the trials at hand: the sizes tests/study/test_power_sim.py checks the law's
    # extrapolation from (to 4n)
    sizes = sorted({int(v) for v in (sizes if sizes is not None else (max(2, n0 // 2), n0, 2 * n0))})
    if not sizes or sizes[0] < 2:
        raise DataError(f"power_curve: sizes must be numbers of demonstrations ≥ 2, got {sizes}")
    if int(repeats) < 1:
        raise DataError(f"power_curve: repeats must be ≥ 1, got {repeats}")
    rng = np.random.default_rng(seed)
    rows: list[dict] = []

    def one_set(n: int, rep: int) -> None:
        sim = simulate_like(model, demos, n, seed=int(rng.integers(2**31)))
        try:
            # no jackknife: n refits per simulated set (up to 2n trials) for a span the law extrapolates
            plant = regulated_plant(model)
            gains = bootstrap_gain(as_fitted(model, sim), plant, n_boot=n_boot, method=gain,
                                   seed=int(rng.integers(2**31)), jackknife=False)
            spans = _log_spans(gains, plant, ci, ratios)
        except ModelError:
            return
        rows.extend({"ratio": r, "n": n, "repeat": rep, "span": float(np.exp(v)) if np.isfinite(v) else np.inf}
                    for r, v in spans.items())

    reps = max(int(repeats), MIN_SETS)
    for rep in range(reps):
        for n in sizes:
            one_set(n, rep)
    while reps < MAX_SETS and not _all_monotone(pd.DataFrame(rows, columns=["ratio", "n", "repeat", "span"])):
        for n in sizes:
            one_set(n, reps)
        reps += 1
    table = pd.DataFrame(rows, columns=["ratio", "n", "repeat", "span"])
    log_target = float(np.log(target))
    needed, lo, hi = {}, {}, {}
    boot = np.random.default_rng([seed, 40])
    for ratio, g in table.groupby("ratio", sort=False):
        med = _medians(g)
        if med is not None and np.isfinite(med.iloc[-1]) and not _monotone(med):
            needed[ratio] = float("nan")  # the simulation cannot say: no number
            continue
        needed[ratio] = _needed(med, log_target)
        if np.isfinite(needed[ratio]):
            draws = [_needed(_medians(_resample(g, boot)), log_target) for _ in range(NEEDED_RESAMPLES)]
            draws = np.array([d for d in draws if not np.isnan(d)])
            if draws.size:
                lo[ratio], hi[ratio] = (float(v) for v in np.quantile(draws, [0.05, 0.95]))
    return PowerCurve(spans=table, needed=needed, target=float(target), n_trials=n0, needed_lo=lo, needed_hi=hi)


def _resample(g: pd.DataFrame, rng: np.random.Generator) -> pd.DataFrame:
    """The simulated sets of one ratio resampled with replacement within each size."""
    parts = [part.iloc[rng.integers(len(part), size=len(part))] for _, part in g.groupby("n", sort=True)]
    return pd.concat(parts, ignore_index=True)


def _monotone(med: pd.Series) -> bool:
    """Whether the median log spans do not grow with n (an unbounded size counts as larger than any)."""
    v = med.to_numpy(dtype=float)
    return bool(np.all(np.diff(np.where(np.isfinite(v), v, np.inf)) <= 1e-12) or len(v) < 2)


def _all_monotone(table: pd.DataFrame) -> bool:
    """Whether every ratio's median curve is monotone (a curve unbounded at its largest size needs no more sets)."""
    for _, g in table.groupby("ratio", sort=False):
        med = _medians(g)
        if med is not None and np.isfinite(med.iloc[-1]) and not _monotone(med):
            return False
    return True


def _count(n: float) -> str:
    """A number of demonstrations, rounded up to two significant figures (a simulated estimate claims no more)."""
    n = max(1, int(np.ceil(n)))
    step = 10 ** max(0, len(str(n)) - 2)
    return str(int(np.ceil(n / step) * step))


def _medians(g: pd.DataFrame) -> pd.Series | None:
    """Median log span per simulated size from the smallest size on which every larger one bounded every set
    (inf at the largest size where some set there was unbounded); None where nothing was simulated."""
    if g.empty:
        return None
    logs = np.log(g["span"].astype(float))
    by = logs.groupby(g["n"]).agg(lambda v: float(np.median(v)) if np.isfinite(v).all() else float("inf"))
    by = by.sort_index()
    if not np.isfinite(by.iloc[-1]):
        return by.iloc[-1:]
    unbounded = by.index[~np.isfinite(by.to_numpy())]
    # not believed below the smallest size from which every simulated interval was bounded
    kept = by[by.index > unbounded.max()] if len(unbounded) else by
    kept.attrs["floor"] = float(kept.index[0]) if len(unbounded) else 0.0
    return kept


def _law(med: pd.Series, n: float) -> float:
    """:data:`LAW` at ``n`` from the median log spans ``med`` by size (sorted, finite but maybe the last)."""
    sizes, logs = med.index.to_numpy(dtype=float), med.to_numpy(dtype=float)
    if not np.isfinite(logs[-1]):
        return float("inf")
    if n >= sizes[-1] or len(sizes) == 1:
        return float(logs[-1] * np.sqrt(sizes[-1] / n))
    if n <= sizes[0]:  # below the simulated sizes: the same √n law from the smallest
        return float(logs[0] * np.sqrt(sizes[0] / n))
    return float(np.interp(np.log(n), np.log(sizes), logs))


def _needed(med: pd.Series | None, log_target: float) -> float:
    """The demonstrations for a log span below ``log_target`` by :data:`LAW` (inf: unbounded at the largest size),
    never below the smallest size from which every simulated set was bounded."""
    if med is None or not np.isfinite(med.iloc[-1]):
        return float("inf")
    sizes, logs = med.index.to_numpy(dtype=float), med.to_numpy(dtype=float)
    if logs[-1] > log_target:
        return float(sizes[-1] * (logs[-1] / log_target) ** 2)
    # the first simulated size at or below the target (every larger one is too: the medians may wobble)
    k = next(i for i in range(len(sizes)) if (logs[i:] <= log_target).all())
    if k == 0:  # below the smallest size: the √n law from it
        return max(float(sizes[0] * (logs[0] / log_target) ** 2), float(med.attrs.get("floor", 0.0)))
    # between sizes k-1 and k, linear in log n
    t = (logs[k - 1] - log_target) / (logs[k - 1] - logs[k])
    return float(np.exp(np.log(sizes[k - 1]) + t * (np.log(sizes[k]) - np.log(sizes[k - 1]))))
