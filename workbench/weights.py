"""Weight ratios inside the coupled parts of a plant: what a task objective can say about an operator.

The full inverse-LQR SDP returns the minimum-condition-number cost with the fitted gain, which keeps no ratio
between two operators' weights. With ``S = 0`` and diagonal Q, R (:func:`workbench.ioc.closest_structured_objective`)
a cost is determined up to one scale per decoupled part of the plant (:func:`workbench.ioc.decoupled_parts`), so
the interpretable quantities are ratios inside one part, e.g. ``Q_φφ / R_u1`` of the quadrotor's lateral part. This
module turns bootstrap samples (:func:`workbench.ioc.bootstrap` with ``structure="diagonal"``) into those ratios
with percentile intervals, and compares two strategies ratio by ratio, saying "not identifiable from these data"
where an interval spans more than a factor of :data:`IDENTIFIABLE_SPAN`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from workbench.errors import ModelError

__all__ = [
    "IDENTIFIABLE_SPAN",
    "RatioInterval",
    "ObjectiveIntervals",
    "objective_intervals",
    "ratio_bootstrap",
    "weight_ratios",
    "ratio_samples",
    "compare_strategies",
]

IDENTIFIABLE_SPAN = 10.0
# Weights are scaled to a largest weight of 1 per part and searched down to e^-30 ≈ 1e-13: a ratio below this is a
# weight at the bottom of the search, i.e. zero, and an interval reaching it is not a finite ratio.
ZERO_RATIO = 1e-9
NOT_IDENTIFIABLE = "not identifiable from these data"


@dataclass(frozen=True)
class RatioInterval:
    """One weight ratio (or a factor between two strategies' ratios) with its percentile interval."""

    name: str
    estimate: float
    lo: float
    hi: float
    ci: float

    @property
    def span(self) -> float:
        """``hi / lo``: how many-fold the interval stretches (``inf`` if it reaches 0, i.e. ``ZERO_RATIO``)."""
        return float(self.hi / self.lo) if self.lo > ZERO_RATIO else float("inf")

    @property
    def identifiable(self) -> bool:
        return bool(np.isfinite(self.span) and self.span <= IDENTIFIABLE_SPAN)

    def describe(self) -> str:
        text = f"{self.name} = {self.estimate:.3g} [{self.lo:.3g}, {self.hi:.3g}]"
        return text if self.identifiable else f"{text}: {NOT_IDENTIFIABLE}"


def _ratio_names(
    parts: Sequence[tuple[tuple[int, ...], tuple[int, ...]]], state_names: Sequence[str], input_names: Sequence[str]
) -> list[tuple[str, int, int]]:
    """``(name, state, input)`` of every ``Q_ii / R_kk`` with state and input in one part; ``R_kk`` is the part's
    first input (any other input of the part is a ratio of these)."""
    out = []
    for states, inputs in parts:
        if not inputs:
            continue
        k = inputs[0]
        out += [(f"Q_{state_names[i]} / R_{input_names[k]}", i, k) for i in states]
        out += [(f"R_{input_names[j]} / R_{input_names[k]}", -1 - j, k) for j in inputs[1:]]
    return out


def _ratios(q: np.ndarray, r: np.ndarray, spec: list[tuple[str, int, int]]) -> np.ndarray:
    """Ratios of weight samples ``q`` (S, n), ``r`` (S, m) per ``spec``, shape (S, len(spec))."""
    num = np.stack([q[:, i] if i >= 0 else r[:, -1 - i] for _, i, _ in spec], axis=1)
    den = np.stack([r[:, k] for _, _, k in spec], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return num / den


def ratio_samples(boot, state_names: Sequence[str], input_names: Sequence[str]) -> tuple[list[str], np.ndarray,
                                                                                          np.ndarray]:
    """Weight ratios of a diagonal-structure bootstrap: names, point estimates (K,), samples (n_ok, K)."""
    obj = boot.objective
    if boot.structure != "diagonal" or not obj.parts:
        raise ModelError(
            f"weight ratios need a bootstrap with structure='diagonal' (S = 0, diagonal Q and R), got "
            f"{boot.structure!r}: the full SDP's cost keeps no ratio between operators"
        )
    spec = _ratio_names(obj.parts, state_names, input_names)
    point = _ratios(np.diag(obj.Q)[None], np.diag(obj.R)[None], spec)[0]
    return [s[0] for s in spec], point, _ratios(np.asarray(boot.Q_diag_samples), np.asarray(boot.R_diag_samples), spec)


def _interval(name: str, estimate: float, samples: np.ndarray, ci: float) -> RatioInterval:
    finite = samples[np.isfinite(samples)]
    if finite.size == 0:
        return RatioInterval(name, float(estimate), 0.0, float("inf"), ci)
    lo, hi = np.percentile(finite, [(100 - ci) / 2, 100 - (100 - ci) / 2])
    return RatioInterval(name, float(estimate), float(lo), float(hi), ci)


def weight_ratios(boot, state_names: Sequence[str], input_names: Sequence[str]) -> list[RatioInterval]:
    """Every weight ratio inside a coupled part, with the bootstrap's percentile interval."""
    names, point, samples = ratio_samples(boot, state_names, input_names)
    return [_interval(nm, point[j], samples[:, j], boot.ci) for j, nm in enumerate(names)]


def compare_strategies(
    boots: dict[str, object], state_names: Sequence[str], input_names: Sequence[str]
) -> pd.DataFrame:
    """Weight ratios per strategy and, for two or more, the factor between each strategy's and the first one's.

    The bootstraps resample each strategy's demonstrations independently (each with its own seed), so resample
    ``j`` of one strategy paired with resample ``j`` of another is a draw of the factor; its percentiles are the
    interval.

    Returns
    -------
    DataFrame
        One row per ratio and strategy: ``ratio``, ``strategy``, ``estimate``, ``lo``, ``hi``, ``identifiable``,
        ``note``, and for the second strategy on: ``factor`` (its ratio over the first's), ``factor_lo``,
        ``factor_hi``, ``factor_identifiable``, ``factor_note``.

    Raises
    ------
    ModelError
        If two strategies were bootstrapped with the same seed (their resamples would not be independent).
    """
    labels = list(boots)
    if not labels:
        raise ModelError("compare_strategies: no strategies")
    seeds = {lb: getattr(boots[lb], "seed", None) for lb in labels}
    shared = [lb for lb in labels[1:] if seeds[lb] is not None and seeds[lb] == seeds[labels[0]]]
    if shared:
        # one generator seed draws the same trial positions in resample j of both, so the paired factor is not a
        # draw from independent resamples of the two strategies (measured: it can narrow or widen the interval)
        raise ModelError(
            f"compare_strategies: strategies {labels[0]!r} and {shared[0]!r} were bootstrapped with the same seed "
            f"({seeds[labels[0]]}); bootstrap each strategy with its own seed so their resamples are independent"
        )
    per = {lb: ratio_samples(boots[lb], state_names, input_names) for lb in labels}
    names = per[labels[0]][0]
    rows = []
    base_point, base_samples = per[labels[0]][1], per[labels[0]][2]
    for lb in labels:
        _, point, samples = per[lb]
        ci = float(boots[lb].ci)
        for j, nm in enumerate(names):
            iv = _interval(nm, point[j], samples[:, j], ci)
            row = {"ratio": nm, "strategy": lb, "estimate": iv.estimate, "lo": iv.lo, "hi": iv.hi,
                   "identifiable": iv.identifiable, "note": "" if iv.identifiable else NOT_IDENTIFIABLE}
            if lb != labels[0]:
                k = min(len(samples), len(base_samples))
                with np.errstate(divide="ignore", invalid="ignore"):
                    f = _interval(nm, point[j] / base_point[j], samples[:k, j] / base_samples[:k, j], ci)
                row.update(factor=f.estimate, factor_lo=f.lo, factor_hi=f.hi, factor_identifiable=f.identifiable,
                           factor_note="" if f.identifiable else NOT_IDENTIFIABLE)
            rows.append(row)
    return pd.DataFrame(rows)


@dataclass(frozen=True, eq=False)
class ObjectiveIntervals:
    """Bootstrap intervals of a fitted model's task objective, and of its weight ratios.

    Attributes
    ----------
    boot : BootstrapResult
        Resamples of the model's own objective (its gain method and cost structure).
    ratio_boot : BootstrapResult or None
        Resamples of the closest diagonal cost (``structure="diagonal"``) from the ``ratio_gain`` estimate, the
        source of the weight ratios; None where it could not be fitted (``note`` says why).
    ratio_gain : str
        Gain method of ``ratio_boot``: ``"iv"`` where the demonstrations' starts excite every state (least
        squares is biased in closed loop), else the model's.
    note : str
    """

    boot: object
    ratio_boot: object | None
    ratio_gain: str
    note: str = ""


def _as_fitted(model, demos) -> list:
    """The demonstrations as the model saw them: states relative to their targets when it is goal-relative."""
    from types import SimpleNamespace

    from workbench.behavior import references

    ds = list(demos)
    refs, _ = references(ds, model.system.n)
    return [SimpleNamespace(x=d.x - r, u=d.u, id=d.id) for d, r in zip(ds, refs, strict=True)]


def ratio_bootstrap(model, demos, n_boot: int = 100, seed: int = 0, ratio_gain: str = "iv"):
    """Bootstrap of the closest diagonal cost, the source of weight ratios: ``(boot or None, gain, note)``.

    The gain is estimated by ``ratio_gain`` (default instrumental variables: least squares is biased in closed
    loop), falling back to the model's own method where that fails (e.g. all trials start alike).
    """
    from workbench.ioc import bootstrap

    shifted = _as_fitted(model, demos)
    note = ""
    for gain in dict.fromkeys((ratio_gain, getattr(model, "gain_method", "direct"))):
        try:
            boot = bootstrap(shifted, model.system, n_boot=n_boot, method=gain, structure="diagonal", seed=seed)
        except ModelError as exc:
            note += f"weight ratios with gain {gain!r} failed: {exc}. "
            continue
        return boot, gain, note.strip()
    return None, ratio_gain, note.strip()


def objective_intervals(model, demos, n_boot: int = 100, seed: int = 0, ratio_gain: str = "iv") -> ObjectiveIntervals:
    """Bootstrap a fitted model's objective over its training demonstrations (whole trials resampled).

    The demonstrations are seen as the model saw them (states relative to their targets when the model is
    goal-relative), so the point estimate of ``boot`` is the model's own ``objective_``; the weight ratios come
    from :func:`ratio_bootstrap`.
    """
    from workbench.ioc import bootstrap

    method = getattr(model, "gain_method", "direct")
    structure = getattr(model, "structure", "full")
    boot = bootstrap(_as_fitted(model, demos), model.system, n_boot=n_boot, method=method, structure=structure,
                     seed=seed)
    if structure == "diagonal" and method == ratio_gain:
        return ObjectiveIntervals(boot=boot, ratio_boot=boot, ratio_gain=method)
    ratio_boot, gain, note = ratio_bootstrap(model, demos, n_boot, seed, ratio_gain)
    return ObjectiveIntervals(boot=boot, ratio_boot=ratio_boot, ratio_gain=gain, note=note)
