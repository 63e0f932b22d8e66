"""Weight ratios inside the coupled parts of a plant: what a task objective can say about an operator.

The full inverse-LQR SDP returns the minimum-condition-number cost with the fitted gain, which keeps no ratio
between two operators' weights. With ``S = 0`` and diagonal Q, R a cost is determined up to one scale per
decoupled part of the plant (:func:`workbench.method.structured.decoupled_parts`), so the interpretable quantities are
ratios
inside one part, e.g. ``Q_φφ / R_u1`` of the quadrotor's lateral part. This module estimates them from a gain
and its bootstrap distribution (:func:`workbench.method.resampling.bootstrap_gain`) by minimum distance, with profile
intervals (:mod:`workbench.method.ratio_profile`), and compares two strategies ratio by ratio, saying "not
identifiable from these data" where an interval spans more than a factor of :data:`IDENTIFIABLE_SPAN`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from workbench.errors import DataError, ModelError
from workbench.method import ratio_profile

__all__ = [
    "IDENTIFIABLE_SPAN",
    "RatioInterval",
    "format_interval",
    "WeightRatios",
    "PartFit",
    "ObjectiveIntervals",
    "objective_intervals",
    "ratio_bootstrap",
    "weight_ratios",
    "compare_strategies",
]

IDENTIFIABLE_SPAN = 10.0
# Log ratios are searched down to -ratio_profile.LOG_BOUND (e^-30 ≈ 1e-13): a ratio below this is a weight at the
# bottom of the search, i.e. zero, and an interval reaching it is not a finite ratio.
ZERO_RATIO = 1e-9
NOT_IDENTIFIABLE = "not identifiable from these data"
NOT_EXPLAINED = "no diagonal cost explains this part's gain"


@dataclass(frozen=True)
class RatioInterval:
    """One weight ratio (or a factor between two strategies' ratios) with its interval.

    ``explained`` is False where no diagonal cost explains the gain of the ratio's part
    (:func:`workbench.method.ratio_profile.explains`): the ratio then describes no objective the operator could have
    had.
    """

    name: str
    estimate: float
    lo: float
    hi: float
    ci: float
    explained: bool = True

    @property
    def span(self) -> float:
        """``hi / lo``: how many-fold the interval stretches (``inf`` if it reaches 0 or ∞, i.e. an end of the
        search: ``ZERO_RATIO`` or ``1 / ZERO_RATIO``)."""
        if self.lo <= ZERO_RATIO or self.hi >= 1 / ZERO_RATIO:
            return float("inf")
        return float(self.hi / self.lo)

    @property
    def identifiable(self) -> bool:
        return bool(np.isfinite(self.span) and self.span <= IDENTIFIABLE_SPAN)

    @property
    def note(self) -> str:
        """Why the interval says little: the part's gain is not that of a diagonal cost, or it spans > ×10."""
        if not self.explained:
            return NOT_EXPLAINED
        return "" if self.identifiable else NOT_IDENTIFIABLE

    def describe(self) -> str:
        text = f"{self.name} = {format_interval(self.estimate, self.lo, self.hi)}"
        return f"{text}: {self.note}" if self.note else text


def format_interval(estimate: float, lo: float, hi: float) -> str:
    """``estimate [lo, hi]`` to 3 digits; a bound at the end of the search reads 0 or ∞ (it is not a number the
    data gave, only the edge of the searched range)."""

    def bound(v: float) -> str:
        if v <= ZERO_RATIO:
            return "0"
        return "∞" if v >= 1 / ZERO_RATIO else f"{v:.3g}"

    return f"{bound(estimate)} [{bound(lo)}, {bound(hi)}]"


def _part_ratio_names(states: Sequence[int], inputs: Sequence[int], state_names: Sequence[str],
                      input_names: Sequence[str]) -> list[str]:
    """Names of one part's ratios in the order of :class:`ratio_profile.PartDistance`'s θ: every ``Q_ii / R_kk``,
    then every other input's ``R_jj / R_kk``, ``R_kk`` the part's first input."""
    k = input_names[inputs[0]]
    return ([f"Q_{state_names[i]} / R_{k}" for i in states]
            + [f"R_{input_names[j]} / R_{k}" for j in inputs[1:]])


@dataclass(frozen=True)
class PartFit:
    """The distance test of the diagonal structure on one decoupled part (:func:`ratio_profile.explains`).

    Attributes
    ----------
    states, inputs : tuple of str
    distance : float
        ``D(θ̂)``: the whitened squared distance from the estimated gain to the closest diagonal cost's gain.
    restrictions : int
        Gain entries beyond the part's ratios.
    critical : float
        The test's critical value at the ratios' level.
    explained : bool
        ``distance ≤ critical``.
    """

    states: tuple[str, ...]
    inputs: tuple[str, ...]
    distance: float
    restrictions: int
    critical: float
    explained: bool

    def describe(self) -> str:
        verdict = "explains" if self.explained else "does not explain"
        return (f"part ({', '.join(self.states)}; {', '.join(self.inputs)}): a diagonal cost {verdict} the gain "
                f"(distance {self.distance:.3g}, critical value {self.critical:.3g})")


@dataclass(frozen=True, eq=False)
class WeightRatios:
    """One operator's weight ratios inside the coupled parts of its plant, with profile intervals.

    Attributes
    ----------
    intervals : tuple of RatioInterval
        Every ``Q_ii / R_kk`` (and ``R_jj / R_kk``) inside a part, ``R_kk`` the part's first input.
    Q_diag, R_diag : ndarray
        The minimum-distance diagonal cost, each part scaled so that its largest weight is 1.
    forward_gain_error : float
        ``‖K_LQR(Q, R) − K̂‖_F / ‖K̂‖_F`` of that cost (DARE).
    gains : GainBootstrap
        The gain estimate and its resamples.
    ci : float
    fits : tuple of PartFit
        Per part with an input: whether a diagonal cost explains its gain.
    """

    intervals: tuple[RatioInterval, ...]
    Q_diag: np.ndarray
    R_diag: np.ndarray
    forward_gain_error: float
    gains: object
    ci: float
    fits: tuple[PartFit, ...]
    _parts: tuple  # (PartDistance, θ̂, D(θ̂)) per part with an input
    _index: tuple  # (part, j) per interval

    @property
    def names(self) -> list[str]:
        return [iv.name for iv in self.intervals]


def weight_ratios(gains, system, ci: float = 95.0) -> WeightRatios:
    """Minimum-distance weight ratios and their profile intervals from a gain bootstrap (see
    :mod:`workbench.method.ratio_profile`).

    Parameters
    ----------
    gains : GainBootstrap
        From :func:`workbench.method.resampling.bootstrap_gain` (or anything with ``K``, ``K_samples``, ``n_trials``).
    system : LinearSystem
        The plant, with ``state_names`` and ``input_names``.
    ci : float
        Interval level in percent.
    """
    from workbench.method.objective import forward_gain
    from workbench.method.structured import closest_structured_objective, decoupled_parts

    if not 0 < ci < 100:
        raise DataError(f"ci must be a percentage in (0, 100), got {ci}")
    A, B = np.asarray(system.A, dtype=float), np.asarray(system.B, dtype=float)
    n, m = B.shape
    K, K_s = np.asarray(gains.K, dtype=float), np.asarray(gains.K_samples, dtype=float)
    parts = decoupled_parts(A, B)
    q, r = np.ones(n), np.ones(m)
    fitted, index, intervals, fits = [], [], [], []
    for states, inputs in parts:
        if not inputs:
            continue  # a part no input reaches: its weights do not affect the gain
        s, c = list(states), list(inputs)
        part = ratio_profile.PartDistance.from_samples(
            A[np.ix_(s, s)], B[np.ix_(s, c)], K[np.ix_(c, s)], K_s[:, c][:, :, s], gains.n_trials)
        start = closest_structured_objective(part.A, part.B, K[np.ix_(c, s)], "diagonal")
        w0 = np.r_[np.diag(start.Q), np.diag(start.R)[1:]] / start.R[0, 0]
        theta, d_min = ratio_profile.fit(part, np.log(np.maximum(w0, 1e-300)))
        explained = ratio_profile.explains(part, d_min, ci)
        fits.append(PartFit(tuple(system.state_names[i] for i in s), tuple(system.input_names[k] for k in c),
                            float(d_min), part.restrictions,
                            ratio_profile.critical_value(ci, part.n_trials, part.restrictions), explained))
        Qp, Rp = part.weights(theta)
        scale = max(float(Qp.max()), float(Rp.max()))
        q[s], r[c] = np.diag(Qp) / scale, np.diag(Rp) / scale
        names = _part_ratio_names(s, c, system.state_names, system.input_names)
        for j, name in enumerate(names):
            lo, hi = ratio_profile.interval(part, theta, d_min, j, ci)
            intervals.append(RatioInterval(name, float(np.exp(theta[j])), float(np.exp(lo)), float(np.exp(hi)), ci,
                                           explained))
            index.append((len(fitted), j))
        fitted.append((part, theta, d_min))
    K_fwd, _ = forward_gain(A, B, np.diag(q), np.diag(r))
    err = float(np.linalg.norm(K_fwd - K) / max(float(np.linalg.norm(K)), 1e-300))
    return WeightRatios(intervals=tuple(intervals), Q_diag=q, R_diag=r, forward_gain_error=err, gains=gains,
                        ci=float(ci), fits=tuple(fits), _parts=tuple(fitted), _index=tuple(index))


def compare_strategies(ratios: dict[str, WeightRatios]) -> pd.DataFrame:
    """Weight ratios per strategy and, for two or more, the factor between each strategy's and the first one's.

    A factor's interval is the profile interval of the difference of one log ratio between two strategies
    (:func:`workbench.method.ratio_profile.factor_interval`), each strategy with its own gain and covariance.

    Returns
    -------
    DataFrame
        One row per ratio and strategy: ``ratio``, ``strategy``, ``estimate``, ``lo``, ``hi``, ``identifiable``,
        ``explained``, ``note`` (:attr:`RatioInterval.note`), and for the second strategy on: ``factor`` (its
        ratio over the first's), ``factor_lo``, ``factor_hi``, ``factor_identifiable``, ``factor_note``.

    Raises
    ------
    ModelError
        If two strategies' gains were resampled with the same seed (their resamples would not be independent),
        or their plants have different ratios.
    """
    labels = list(ratios)
    if not labels:
        raise ModelError("compare_strategies: no strategies")
    first = ratios[labels[0]]
    seed0 = getattr(first.gains, "seed", None)
    for lb in labels[1:]:
        if seed0 is not None and getattr(ratios[lb].gains, "seed", None) == seed0:
            # one generator seed draws the same trial positions in resample j of both strategies: their
            # covariances would share the resampling noise
            raise ModelError(
                f"compare_strategies: strategies {labels[0]!r} and {lb!r} were bootstrapped with the same seed "
                f"({seed0}); bootstrap each strategy with its own seed so their resamples are independent"
            )
        if ratios[lb].names != first.names:
            raise ModelError(f"compare_strategies: {labels[0]!r} and {lb!r} have different weight ratios "
                             f"({first.names} against {ratios[lb].names}): not the same plant")
    rows = []
    for lb in labels:
        wr = ratios[lb]
        for k, iv in enumerate(wr.intervals):
            row = {"ratio": iv.name, "strategy": lb, "estimate": iv.estimate, "lo": iv.lo, "hi": iv.hi,
                   "identifiable": iv.identifiable, "explained": iv.explained, "note": iv.note}
            if lb != labels[0]:
                p, j = wr._index[k]
                part_a, theta_a, d_a = first._parts[p]
                part_b, theta_b, d_b = wr._parts[p]
                lo, hi = ratio_profile.factor_interval(part_a, theta_a, d_a, part_b, theta_b, d_b, j, wr.ci)
                f = RatioInterval(iv.name, float(np.exp(theta_b[j] - theta_a[j])), float(np.exp(lo)),
                                  float(np.exp(hi)), wr.ci, iv.explained and first.intervals[k].explained)
                row.update(factor=f.estimate, factor_lo=f.lo, factor_hi=f.hi, factor_identifiable=f.identifiable,
                           factor_note=f.note)
            rows.append(row)
    return pd.DataFrame(rows)


@dataclass(frozen=True, eq=False)
class ObjectiveIntervals:
    """Bootstrap intervals of a fitted model's task objective, and its weight ratios.

    Attributes
    ----------
    boot : BootstrapResult
        Resamples of the model's own objective (its gain method and cost structure).
    ratios : WeightRatios or None
        Weight ratios from the ``ratio_gain`` estimate; None where they could not be estimated (``note`` says
        why).
    ratio_gain : str
        Gain method of ``ratios``: ``"iv"`` where the demonstrations' starts excite every state (least squares is
        biased in closed loop), else the model's.
    note : str
    """

    boot: object
    ratios: WeightRatios | None
    ratio_gain: str
    note: str = ""


def _as_fitted(model, demos) -> list:
    """The demonstrations as the model saw them: states relative to their targets when it is goal-relative."""
    from types import SimpleNamespace

    from workbench.models.behavior import references

    ds = list(demos)
    refs, _ = references(ds, model.system.n)
    return [SimpleNamespace(x=d.x - r, u=d.u, id=d.id) for d, r in zip(ds, refs, strict=True)]


def _used_gain(model) -> str:
    """The estimator that made the model's K̂ (its ``gain_method`` may be the rule "iv-or-direct")."""
    return getattr(model, "gain_method_", None) or getattr(model, "gain_method", "direct")


def ratio_bootstrap(model, demos, n_boot: int = 100, seed: int = 0, ratio_gain: str = "iv", ci: float = 95.0,
                    progress: Callable[[int, int], None] | None = None) -> tuple[WeightRatios | None, str, str]:
    """Weight ratios of a fitted model's demonstrations: ``(ratios or None, gain method, note)``.

    The gain is estimated by ``ratio_gain`` (default instrumental variables: least squares is biased in closed
    loop), falling back to the model's own method where that fails (e.g. all trials start alike); its
    covariance comes from ``n_boot`` resamples of whole trials.
    """
    from workbench.method.resampling import bootstrap_gain

    shifted = _as_fitted(model, demos)
    note = ""
    for gain in dict.fromkeys((ratio_gain, _used_gain(model))):
        try:
            gains = bootstrap_gain(shifted, model.system, n_boot=n_boot, method=gain, seed=seed, progress=progress)
            return weight_ratios(gains, model.system, ci), gain, note.strip()
        except ModelError as exc:
            note += f"weight ratios with gain {gain!r} failed: {exc}. "
    return None, ratio_gain, note.strip()


def objective_intervals(model, demos, n_boot: int = 100, seed: int = 0, ratio_gain: str = "iv") -> ObjectiveIntervals:
    """Bootstrap a fitted model's objective over its training demonstrations (whole trials resampled).

    The demonstrations are seen as the model saw them (states relative to their targets when the model is
    goal-relative), so the point estimate of ``boot`` is the model's own ``objective_``; the weight ratios come
    from :func:`ratio_bootstrap`.
    """
    from workbench.method.resampling import bootstrap

    method = _used_gain(model)
    structure = getattr(model, "structure", "full")
    boot = bootstrap(_as_fitted(model, demos), model.system, n_boot=n_boot, method=method, structure=structure,
                     seed=seed)
    ratios, gain, note = ratio_bootstrap(model, demos, n_boot, seed, ratio_gain, boot.ci)
    return ObjectiveIntervals(boot=boot, ratios=ratios, ratio_gain=gain, note=note)
