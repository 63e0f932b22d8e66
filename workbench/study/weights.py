"""Weight ratios inside the coupled parts of a plant: what a task objective can say about an operator.

The full inverse-LQR SDP returns the minimum-condition-number cost with the fitted gain, which keeps no ratio
between two operators' weights. With ``S = 0`` and diagonal Q, R a cost is determined up to one scale per
decoupled part of the plant (:func:`workbench.method.structured.decoupled_parts`), so the interpretable quantities are
ratios
inside one part, e.g. ``Q_φφ / R_u1`` of the quadrotor's lateral part. This module estimates them from a gain
and its bootstrap distribution (:func:`workbench.method.resampling.bootstrap_gain`) by minimum distance, with profile
intervals (:mod:`workbench.method.ratio_profile`), and compares two strategies ratio by ratio. Every ratio ends in one
of three readings: a finite estimate with its interval; "not identifiable" where the interval spans more than
×:data:`IDENTIFIABLE_SPAN`, with the demonstrations a power curve says it would need (:mod:`workbench.study.power`);
or "not of this form" where the part's gain is no diagonal cost's, with the closest one and the mismatch per gain
entry (:mod:`workbench.method.pseudo_true`).

Beside each factor of ``Q_s / R_u`` between strategies stands the factor of the gain entry ``K̂[u, s]`` itself
(:func:`gain_factor`, Fieller's interval). A weight that barely moves the gain leaves its ratio's factor without
an upper end (the instructed CS1's attitude weight, 1/30 of CS2's, moves its attitude gain 3 %), while the gain
entries, which the fit estimates directly, still compare between the strategies.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from workbench.defaults import OBJECTIVE_RESAMPLES
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
    "identified_first",
    "with_power",
    "needed_words",
    "TARGET_SPAN",
    "GainFactor",
    "gain_factor",
    "format_gain_factor",
    "gain_contrasts",
    "entry_error",
]

IDENTIFIABLE_SPAN = 10.0
#: The span a power curve aims at: an interval narrower than ×2 pins a ratio down to within a factor √2.
TARGET_SPAN = 2.0
# Log ratios are searched down to -ratio_profile.LOG_BOUND (e^-30 ≈ 1e-13): a ratio below this is a weight at the
# bottom of the search, i.e. zero, and an interval reaching it is not a finite ratio.
ZERO_RATIO = 1e-9
NOT_IDENTIFIABLE = "not identifiable"
NOT_EXPLAINED = "not of this form"
# A whitened squared distance below this is an exact fit: the estimated gain is a diagonal cost's gain.
EXACT_DISTANCE = 1e-6


@dataclass(frozen=True)
class RatioInterval:
    """One weight ratio (or a factor between two strategies' ratios) with its interval.

    ``explained`` is False where the ratio's part is not of the diagonal form (the structure test rejects it, or,
    without restrictions to test, the estimated gain departs from the closest diagonal cost's by more than its
    spread): the estimate and interval are then those of the closest diagonal cost (the pseudo-true value,
    :mod:`workbench.method.pseudo_true`) and ``mismatch`` says in words how the gain departs from it.
    ``needed`` is the number of demonstrations a power curve (:mod:`workbench.study.power`) says would make
    the interval narrower than ×:data:`TARGET_SPAN` (inf: more than the ``simulated`` largest size; None: not
    computed).
    """

    name: str
    estimate: float
    lo: float
    hi: float
    ci: float
    explained: bool = True
    mismatch: str = ""
    needed: float | None = None
    simulated: int | None = None

    @property
    def span(self) -> float:
        """``hi / lo``: how many-fold the interval stretches (``inf`` if it reaches 0 or ∞, i.e. an end of the
        search: ``ZERO_RATIO`` or ``1 / ZERO_RATIO``)."""
        if self.lo <= ZERO_RATIO or self.hi >= 1 / ZERO_RATIO:
            return float("inf")
        return float(self.hi / self.lo)

    @property
    def identifiable(self) -> bool:
        return bool(self.explained and np.isfinite(self.span) and self.span <= IDENTIFIABLE_SPAN)

    @property
    def note(self) -> str:
        """Why the interval says little: the part is not of the diagonal form (with its mismatch), or it spans
        more than ×10 (with the demonstrations a power curve says would be needed)."""
        if not self.explained:
            return f"{NOT_EXPLAINED}: mismatch {self.mismatch}" if self.mismatch else NOT_EXPLAINED
        if self.identifiable:
            return ""
        return f"{NOT_IDENTIFIABLE}: {needed_words(self.needed, self.simulated)}"

    def describe(self) -> str:
        """One line; a part's mismatch is its part's to say (:meth:`PartFit.describe`), once, not on every ratio."""
        shown = format_interval(self.estimate, self.lo, self.hi)
        note = f"{NOT_EXPLAINED} (its part's mismatch below)" if not self.explained else self.note
        if shown.startswith(NOT_IDENTIFIABLE):  # words, no estimate: the note adds only what would help
            note = note.removeprefix(f"{NOT_IDENTIFIABLE}: ")
            return f"{self.name} {shown}" + (f"; {note}" if note else "")
        text = f"{self.name} = {shown}"
        return f"{text}: {note}" if note else text


def needed_words(needed: float | None, simulated: int | None = None) -> str:
    """``~N demonstrations needed`` from a power curve; what is known where none was computed."""
    if needed is None:
        return "demonstrations needed not computed (`workbench report` or `fit --power`)"
    if not np.isfinite(needed):
        most = f" than {simulated}" if simulated else " than simulated"
        return f"more demonstrations needed{most} (a zero or infinite weight fits at every simulated size)"
    return f"~{_round_up(needed)} demonstrations needed"


def _round_up(n: float) -> int:
    """``n`` rounded up to two significant figures: a simulated estimate claims no more."""
    n = max(1, int(np.ceil(n)))
    step = 10 ** max(0, len(str(n)) - 2)
    return int(np.ceil(n / step) * step)


def format_interval(estimate: float, lo: float, hi: float) -> str:
    """``estimate [lo, hi]`` to 3 digits where the interval identifies the ratio (finite, within
    ×:data:`IDENTIFIABLE_SPAN`); otherwise words without an estimate: a bound at an end of the searched range is no
    number the data gave (never "0 [0, 0]", "[0, ∞]" or "∞"), and a finite interval wider than ×10 gives its ends
    but no estimate."""
    zero_lo, inf_hi = lo <= ZERO_RATIO, hi >= 1 / ZERO_RATIO
    if not (np.isfinite(lo) and np.isfinite(hi)) and not (zero_lo or inf_hi):
        return "no interval"
    if zero_lo and inf_hi:
        return f"{NOT_IDENTIFIABLE}: the data allow any value"
    if zero_lo:
        return (f"{NOT_IDENTIFIABLE}: a zero weight fits (the end of the search)" if hi <= ZERO_RATIO else
                f"{NOT_IDENTIFIABLE}: at most {hi:.3g}, no lower bound")
    if inf_hi:
        return (f"{NOT_IDENTIFIABLE}: an infinite weight fits (the end of the search)" if lo >= 1 / ZERO_RATIO else
                f"{NOT_IDENTIFIABLE}: at least {lo:.3g}, no upper bound")
    if hi / lo > IDENTIFIABLE_SPAN:
        return f"{NOT_IDENTIFIABLE}: between {lo:.3g} and {hi:.3g} (×{hi / lo:.3g})"
    return f"{estimate:.3g} [{lo:.3g}, {hi:.3g}]"


def _pct(v: float) -> str:
    """A fraction as a percentage: two significant figures below 10 %, whole percent above."""
    v = 100.0 * abs(float(v))
    return f"{v:.0f} %" if v >= 10 else f"{v:.2g} %"


@dataclass(frozen=True)
class PartFit:
    """Whether a diagonal cost explains one decoupled part's gain, and how far the closest one is where not.

    Attributes
    ----------
    states, inputs : tuple of str
    distance : float
        ``D(θ̂)``: the whitened squared distance from the estimated gain to the closest diagonal cost's gain.
    restrictions : int
        Gain entries minus free log ratios: the overidentifying restrictions of the structure test.
    critical : float
        The test's critical value at the ratios' level, for its restrictions plus ``edges`` (nan where there is
        nothing to test).
    explained : bool or None
        The structure test (:func:`ratio_profile.explains`); None where the part has no restrictions.
    closest : PseudoTrue or None
        The closest diagonal cost and its mismatch (:func:`workbench.method.pseudo_true.pseudo_true`), where the
        test rejects or, untested, the estimate is no diagonal cost's gain.
    dof : float
        Degrees of freedom of the gain's covariance behind the test and the intervals
        (:func:`workbench.method.ratio_profile.effective_dof`).
    edges : int
        Ratios of the closest diagonal cost at a zero or infinite weight (:func:`ratio_profile.at_edge`): no free
        parameters there, so each is one more restriction of the test.
    bias_corrected : bool
        Whether the part's gain entries are the jackknife's bias-corrected estimate
        (:meth:`ratio_profile.PartDistance.from_samples`), which differs from the K̂ ``fit`` prints first.
    """

    states: tuple[str, ...]
    inputs: tuple[str, ...]
    distance: float
    restrictions: int
    critical: float
    explained: bool | None
    closest: object = None
    dof: float = float("nan")
    edges: int = 0
    bias_corrected: bool = False

    @property
    def tested(self) -> bool:
        return self.restrictions > 0

    @property
    def of_form(self) -> bool:
        """False where the test rejects the diagonal form, or, untested, the gain departs from the closest
        diagonal cost's by more than its spread in some entry."""
        if self.explained is not None:
            return self.explained
        return self.closest is None or not bool(np.any(self.closest.shown))

    def mismatch_words(self) -> str:
        """How the gain departs from the closest diagonal cost's, per entry the data show, on the entry's own scale:
        the estimated gain entry with its interval against the closest diagonal cost's, e.g. ``u1 on phi −0.206
        [−0.25, −0.16], stiffer than its −0.095`` (stiffer: a larger magnitude; "opposite sign" where the signs
        differ). No percentage: relative to an entry near zero it would be a meaningless number. Where the entries
        are bias-corrected (:attr:`bias_corrected`), the words say so: the K̂ printed first is the uncorrected
        estimate, and two values each called "the estimated gain entry" read as a contradiction."""
        c = self.closest
        if c is None:
            return ""
        words = []
        for e in np.flatnonzero(c.shown):
            where = f"{self.inputs[e // len(self.states)]} on {self.states[e % len(self.states)]}"
            k, k0 = float(c.k_hat[e]), float(c.k_closest[e])
            a, b = k0 + float(c.mismatch_lo[e]), k0 + float(c.mismatch_hi[e])  # k̂ = k* + δ
            if np.sign(k) != np.sign(k0) and abs(k0) > 0:
                way = "opposite in sign to"
            else:
                way = "stiffer than" if abs(k) > abs(k0) else "softer than"
            d = _distinct_digits((k, k0), (a, b))
            words.append(f"{where} {k:.{d}g} [{a:.{d}g}, {b:.{d}g}], {way} its {k0:.{d}g}")
        if not words:
            return ""
        if self.bias_corrected:
            return ("; ".join(words) + " (each the gain entry after the jackknife's bias correction over trials, "
                    "against the closest diagonal LQR gain's; K̂ as printed above is uncorrected)")
        return "; ".join(words) + " (the estimated gain entry against the closest diagonal LQR gain's)"

    def describe(self) -> str:
        where = f"part ({', '.join(self.states)}; {', '.join(self.inputs)})"
        if not self.tested:
            entries = self.restrictions + len(self.states) + len(self.inputs) - 1
            text = f"{where}: no restriction to test a diagonal cost ({entries} gain entries, as many free ratios)"
            if not self.of_form:
                text += f"; the estimated gain lies outside every diagonal cost's: {self.mismatch_words()}"
            return text
        if not np.isfinite(self.critical):  # no verdict from a test that cannot reject
            return (f"{where}: no verdict on a diagonal cost: the test's critical value is not finite (distance "
                    f"{self.distance:.3g}, {self.restrictions} restriction(s), {self.dof:.3g} degrees of freedom of "
                    "the gain's covariance: too few resamples fitted for the test)")
        verdict = "explains" if self.explained else "does not explain"
        edges = f", one more per weight ratio at 0 or ∞: {self.edges}" if self.edges else ""
        text = (f"{where}: a diagonal cost {verdict} the gain (distance {self.distance:.3g}, critical value "
                f"{self.critical:.3g}, {self.restrictions} restriction(s){edges})")
        return text + (f"; {self.mismatch_words()}" if not self.explained and self.closest is not None else "")


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
        Per part with an input: whether a diagonal cost explains its gain, and the closest one where not.
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
    #: per interval, the gain entry ``(input, state, "K[u1, phi]")`` of its ``Q_s / R_u`` (None for ``R_j / R_k``)
    _entries: tuple = ()

    @property
    def names(self) -> list[str]:
        return [iv.name for iv in self.intervals]

    def with_needed(self, needed: dict[str, float], simulated: int | None = None) -> WeightRatios:
        """A copy whose intervals carry the demonstrations a power curve (up to ``simulated``) says each needs."""
        from dataclasses import replace

        return replace(self, intervals=tuple(replace(iv, needed=needed.get(iv.name, iv.needed), simulated=simulated)
                                             for iv in self.intervals))


def weight_ratios(gains, plant, ci: float = 95.0) -> WeightRatios:
    """Minimum-distance weight ratios and their profile intervals from a gain bootstrap (see
    :mod:`workbench.method.ratio_profile`); where a part is not of the diagonal form, the closest diagonal cost
    with sandwich intervals and its mismatch (:mod:`workbench.method.pseudo_true`).

    Where ``gains`` carries leave-one-trial-out gains (``K_loo``, the default of ``bootstrap_gain``), the part's
    gain is the jackknife bias-corrected one (not where the gain has the pilot's timing, ``gains.timing``: LIML, see
    :mod:`workbench.method.ratio_profile`), its covariance the jackknife's and the critical values use that
    covariance's effective degrees of freedom; the intervals hold simultaneously for a part's ratios
    (:mod:`workbench.method.ratio_profile`).

    Per part: with restrictions (gain entries beyond its free ratios) the structure test decides, a ratio fitted at
    a zero or infinite weight counting as one restriction more; without, nothing is tested, and the part counts as
    not of the form only where the estimated gain is no diagonal cost's gain and departs from the closest one's by
    more than its spread in some entry.

    Parameters
    ----------
    gains : GainBootstrap
        From :func:`workbench.method.resampling.bootstrap_gain` (or anything with ``K``, ``K_samples``, ``n_trials``).
    plant : LinearSystem
        The plant, with ``state_names`` and ``input_names``.
    ci : float
        Interval level in percent.
    """
    from workbench.method.objective import forward_gain
    from workbench.method.pseudo_true import pseudo_true
    from workbench.method.structured import closest_structured_objective, decoupled_parts

    if not 0 < ci < 100:
        raise DataError(f"ci must be a percentage in (0, 100), got {ci}")
    A, B = np.asarray(plant.A, dtype=float), np.asarray(plant.B, dtype=float)
    n, m = B.shape
    K, K_s = np.asarray(gains.K, dtype=float), np.asarray(gains.K_samples, dtype=float)
    parts = decoupled_parts(A, B)
    q, r = np.ones(n), np.ones(m)
    fitted, index, intervals, fits, entries = [], [], [], [], []
    for states, inputs in parts:
        if not inputs:
            continue  # a part no input reaches: its weights do not affect the gain
        s, c = list(states), list(inputs)
        samples = K_s[:, c][:, :, s]
        loo = getattr(gains, "K_loo", None)
        correct = getattr(gains, "timing", None) is None  # not the timed LIML gain (ratio_profile)
        part = ratio_profile.PartDistance.from_samples(
            A[np.ix_(s, s)], B[np.ix_(s, c)], K[np.ix_(c, s)], samples, gains.n_trials,
            None if loo is None else np.asarray(loo, dtype=float)[:, c][:, :, s], bias_correct=correct)
        start = closest_structured_objective(part.A, part.B, _stabilizing(part, K[np.ix_(c, s)]), "diagonal")
        w0 = np.r_[np.diag(start.Q), np.diag(start.R)[1:]] / start.R[0, 0]
        theta0 = np.log(np.maximum(w0, 1e-300))
        theta, d_min = ratio_profile.fit(part, theta0)
        test = ratio_profile.structure_test(part, theta, d_min, ci)
        closest = None
        if test.explained is False or (test.explained is None and d_min > EXACT_DISTANCE):
            closest = pseudo_true(part, samples, theta0, ci)
        fit = PartFit(tuple(plant.state_names[i] for i in s), tuple(plant.input_names[k] for k in c),
                      float(d_min), part.restrictions, test.critical, test.explained, closest, part.nu, test.edges,
                      bias_corrected=correct and part.dof is not None)
        fits.append(fit)
        shown = theta if fit.of_form else closest.theta
        Qp, Rp = part.weights(shown)
        scale = max(float(Qp.max()), float(Rp.max()))
        q[s], r[c] = np.diag(Qp) / scale, np.diag(Rp) / scale
        names = ratio_profile.ratio_names(s, c, plant.state_names, plant.input_names)
        words = "" if fit.of_form else fit.mismatch_words()
        for j, name in enumerate(names):
            if fit.of_form:
                lo, hi = ratio_profile.interval(part, theta, d_min, j, ci)
                est = theta[j]
            else:  # the pseudo-true value: profiling a distance no diagonal cost comes near only walks to the bounds
                est, lo, hi = closest.theta[j], closest.theta_lo[j], closest.theta_hi[j]
            intervals.append(RatioInterval(name, float(np.exp(est)), float(np.exp(lo)), float(np.exp(hi)), ci,
                                           fit.of_form, words))
            index.append((len(fitted), j))
            entries.append(None if j >= len(s) else
                           (c[0], s[j], f"K[{plant.input_names[c[0]]}, {plant.state_names[s[j]]}]"))
        fitted.append((part, shown, d_min))
    K_fwd, _ = forward_gain(A, B, np.diag(q), np.diag(r))
    err = float(np.linalg.norm(K_fwd - K) / max(float(np.linalg.norm(K)), 1e-300))
    return WeightRatios(intervals=tuple(intervals), Q_diag=q, R_diag=r, forward_gain_error=err, gains=gains,
                        ci=float(ci), fits=tuple(fits), _parts=tuple(fitted), _index=tuple(index),
                        _entries=tuple(entries))


def _distinct_digits(*pairs: tuple[float, float], least: int = 3, most: int = 8) -> int:
    """The fewest significant digits (at least ``least``) at which each pair prints as two different numbers: a
    mismatch shown at 3 digits as "−0.0947 [−0.0947, −0.0947], softer than its −0.0947" reads as a contradiction,
    where the entry differs from the closest cost's in its fourth digit."""
    for d in range(least, most + 1):
        if all(f"{x:.{d}g}" != f"{y:.{d}g}" for x, y in pairs if x != y):
            return d
    return most


def _stabilizing(part, K_part: np.ndarray) -> np.ndarray:
    """The part's (bias-corrected) gain where it stabilizes the part, else the uncorrected one: only the start of
    the fit, which needs a stabilizing gain."""
    K_bc = part.k_hat.reshape(K_part.shape)
    rho = float(np.max(np.abs(np.linalg.eigvals(part.A + part.B @ K_bc))))
    return K_bc if rho < 1.0 else K_part


def compare_strategies(ratios: dict[str, WeightRatios]) -> pd.DataFrame:
    """Weight ratios per strategy and, for two or more, the factor between each strategy's and the first one's.

    A factor's interval is the profile interval of the difference of one log ratio between two strategies
    (:func:`workbench.method.ratio_profile.factor_interval`), each strategy with its own gain and covariance; where
    either strategy's part is not of the diagonal form there is no factor (NaN) and its note says why. Beside each
    ``Q_s / R_u``, the factor of the gain entry ``K̂[u, s]`` itself (:func:`gain_factor`): the gains are identified
    where a weight that barely moves them is not.

    Returns
    -------
    DataFrame
        One row per ratio and strategy: ``ratio``, ``strategy``, ``estimate``, ``lo``, ``hi``, ``identifiable``,
        ``explained``, ``note`` (:attr:`RatioInterval.note`), ``gain`` (the entry ``K[u, s]`` of ``Q_s / R_u``, ""
        for ``R_j / R_k``), and for the second strategy on: ``factor`` (its ratio over the first's), ``factor_lo``,
        ``factor_hi``, ``factor_identifiable``, ``factor_note``, and the factor of the gain entry with its interval
        (:func:`gain_factor`): ``gain_factor``, ``gain_factor_lo``, ``gain_factor_hi``,
        ``gain_factor_identifiable``.

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
            entry = wr._entries[k] if k < len(wr._entries) else None
            row = {"ratio": iv.name, "strategy": lb, "estimate": iv.estimate, "lo": iv.lo, "hi": iv.hi,
                   "identifiable": iv.identifiable, "explained": iv.explained, "note": iv.note,
                   "gain": "" if entry is None else entry[2]}
            if lb != labels[0]:
                row.update(_factor(first, wr, k))
                row.update(_gain_factor(first, wr, k))
            rows.append(row)
    return pd.DataFrame(rows)


def _factor(first: WeightRatios, other: WeightRatios, k: int) -> dict:
    """The factor of interval ``k`` between two strategies: its profile interval where both parts are of the
    diagonal form; else no factor (the closest costs of a misspecified part estimate no operator's ratio) and the
    mismatch as its note. The demonstrations a factor needs, each strategy's needs added (the √n law: squared
    log spans add)."""
    a, b = first.intervals[k], other.intervals[k]
    if not (a.explained and b.explained):
        bad = b if not b.explained else a
        return {"factor": float("nan"), "factor_lo": float("nan"), "factor_hi": float("nan"),
                "factor_identifiable": False, "factor_note": bad.note}
    p, j = other._index[k]
    part_a, theta_a, d_a = first._parts[p]
    part_b, theta_b, d_b = other._parts[p]
    lo, hi = ratio_profile.factor_interval(part_a, theta_a, d_a, part_b, theta_b, d_b, j, other.ci)
    needed = None if a.needed is None or b.needed is None else a.needed + b.needed
    f = RatioInterval(b.name, float(np.exp(theta_b[j] - theta_a[j])), float(np.exp(lo)), float(np.exp(hi)), other.ci,
                      needed=needed, simulated=max(a.simulated or 0, b.simulated or 0) or None)
    return {"factor": f.estimate, "factor_lo": f.lo, "factor_hi": f.hi, "factor_identifiable": f.identifiable,
            "factor_note": f.note}


@dataclass(frozen=True)
class GainFactor:
    """The factor between two strategies' gain entry ``K̂[u, s]`` (second over first), with its interval.

    It stands beside the weight ratio ``Q_s / R_u``: the ratio says how the cost weights the state, the entry how
    hard the pilot pushes on it. Where a weight barely moves the gain (CS1's attitude weight, 1/30 of CS2's, moves
    its attitude gain 3 %), the ratio's interval has no upper end while the gain entries, which a fit estimates
    directly, still compare (:func:`gain_factor`).
    """

    entry: str
    ratio: str
    estimate: float
    lo: float
    hi: float
    ci: float

    @property
    def identifiable(self) -> bool:
        """Bounded, of one sign, and within ×:data:`IDENTIFIABLE_SPAN` (as a weight ratio's)."""
        lo, hi = abs(self.lo), abs(self.hi)
        return bool(np.isfinite(lo) and np.isfinite(hi) and np.sign(self.lo) == np.sign(self.hi) != 0
                    and max(lo, hi) / min(lo, hi) <= IDENTIFIABLE_SPAN)

    def shown(self) -> str:
        return format_gain_factor(self.estimate, self.lo, self.hi)


def gain_factor(k_a: float, s_a: float, nu_a: float, k_b: float, s_b: float, nu_b: float, ci: float = 95.0
                ) -> tuple[float, float]:
    """Fieller's ``ci`` % interval of ``k_b / k_a`` for two independent gain estimates with standard errors ``s_a``,
    ``s_b`` of ``nu_a``, ``nu_b`` degrees of freedom: every θ with ``(k̂_b − θ k̂_a)² ≤ t² (s_b² + θ² s_a²)``, ``t``
    the ``t_ν`` quantile, ``ν`` the Welch–Satterthwaite degrees of freedom of ``s_b² + θ̂² s_a²`` at
    ``θ̂ = k̂_b / k̂_a``.

    The ratio is not linearized: where ``k̂_a`` is within ``t s_a`` of zero the set is unbounded (``(-inf, inf)``:
    no factor is excluded in size), otherwise a bounded interval that may include 0 or negative values (the entries'
    signs may differ).

    Returns
    -------
    (lo, hi) : tuple of float
        ``(-inf, inf)`` where unbounded, ``(nan, nan)`` where an estimate or a standard error is not finite.
    """
    import scipy.stats

    if not np.all(np.isfinite([k_a, s_a, nu_a, k_b, s_b, nu_b])) or k_a == 0:
        return float("nan"), float("nan")
    theta = k_b / k_a
    var = s_b**2 + theta**2 * s_a**2
    nu = var**2 / (s_b**4 / nu_b + theta**4 * s_a**4 / nu_a) if var > 0 else min(nu_a, nu_b)
    t = float(scipy.stats.t.ppf(0.5 + ci / 200.0, max(float(nu), 1.0)))
    a = k_a * k_a - t * t * s_a * s_a  # the quadratic a θ² − 2 k_a k_b θ + c ≤ 0
    c = k_b * k_b - t * t * s_b * s_b
    if a <= 0:
        return float("-inf"), float("inf")
    root = float(np.sqrt(max(k_a * k_a * k_b * k_b - a * c, 0.0)))
    return float((k_a * k_b - root) / a), float((k_a * k_b + root) / a)


def entry_error(gains, u: int, x: int) -> tuple[float, float]:
    """The standard error of the gain entry ``K̂[u, x]`` and its degrees of freedom, as the weight ratios beside it
    take the gain's covariance (:meth:`workbench.method.ratio_profile.PartDistance.from_samples`): the
    delete-one-trial jackknife's (CV3) with its effective degrees of freedom
    (:func:`~workbench.method.ratio_profile.effective_dof`) where ``gains`` has every leave-one-out gain, else the
    resampled gains' standard deviation times ``√(n / (n − 1))`` with ``n − 1``.

    The jackknife's was chosen on 13 virtual subjects' seeds (:mod:`workbench.collect.virtual`, choosing seeds
    600-625), where the resampled gains' spread looked too small for the pure-LQR CS2 subject's attitude gain. On
    100 more choosing seeds (640-739) both match the spread of K̂ over independent seeds (standard error / spread
    1.00 and 0.96), and the factor's interval covers on 98 of 100; the 13 seeds' shortfall was one rare draw, seed
    621 (``bench/results.md``, "gain entries" and its round 9).
    """
    n = int(gains.n_trials)
    loo = getattr(gains, "K_loo", None)
    if loo is not None and len(loo) == n and np.isfinite(np.asarray(loo, dtype=float)).all():
        dev = np.asarray(loo, dtype=float)[:, u, x]
        dev = dev - dev.mean()
        if float(dev @ dev) > 0:
            return float(np.sqrt((n - 1) / n * float(dev @ dev))), ratio_profile.effective_dof(dev[:, None])
    S = np.asarray(gains.K_samples, dtype=float)
    if len(S) < 2 or n < 2:
        return float("nan"), float("nan")
    return float(S[:, u, x].std(ddof=1) * np.sqrt(n / (n - 1))), float(n - 1)


def format_gain_factor(estimate: float, lo: float, hi: float) -> str:
    """``estimate [lo, hi]`` where the interval bounds the factor to one sign and within ×:data:`IDENTIFIABLE_SPAN`
    (as :func:`format_interval`), else words without an estimate."""
    if np.isnan(lo) or np.isnan(hi):
        return "no interval"
    if not (np.isfinite(lo) and np.isfinite(hi)):
        return f"{NOT_IDENTIFIABLE}: the first strategy's entry is not distinguishable from 0"
    if lo <= 0 <= hi:
        return f"{NOT_IDENTIFIABLE}: between {lo:.3g} and {hi:.3g} (the entries' signs may differ)"
    if hi < 0:
        if lo / hi > IDENTIFIABLE_SPAN:
            return f"{NOT_IDENTIFIABLE}: between {lo:.3g} and {hi:.3g}, opposite signs"
        return f"{estimate:.3g} [{lo:.3g}, {hi:.3g}] (opposite signs)"
    return format_interval(estimate, lo, hi)


def _gain_factor(first: WeightRatios, other: WeightRatios, k: int) -> dict:
    """The factor of interval ``k``'s gain entry between two strategies (:func:`gain_factor`): ``K̂`` as fitted (the
    K̂ ``fit`` prints), its standard error over whole trials (:func:`entry_error`)."""
    entry = other._entries[k] if k < len(other._entries) else None
    none = {"gain_factor": float("nan"), "gain_factor_lo": float("nan"), "gain_factor_hi": float("nan"),
            "gain_factor_identifiable": False}
    if entry is None:
        return none
    u, x, _ = entry
    ga, gb = first.gains, other.gains
    ka, kb = float(np.asarray(ga.K)[u, x]), float(np.asarray(gb.K)[u, x])
    lo, hi = gain_factor(ka, *entry_error(ga, u, x), kb, *entry_error(gb, u, x), other.ci)
    f = GainFactor(entry[2], other.intervals[k].name, kb / ka if ka else float("nan"), lo, hi, other.ci)
    return {"gain_factor": f.estimate, "gain_factor_lo": f.lo, "gain_factor_hi": f.hi,
            "gain_factor_identifiable": f.identifiable}


def _no_factor(note: str) -> str:
    """The verdict of a weight ratio's missing factor (``"not of this form"``), its reason (the part's mismatch)
    printed once with the part."""
    return str(note or "").split(":")[0].strip() or "no factor"


def gain_contrasts(table: pd.DataFrame) -> list[dict[str, str]]:
    """The rows the report and the terminal print for the gain entries compared between strategies: per strategy
    after the first and per weight ratio with a gain entry, the entry, the strategies, the gain factor with its
    interval (:func:`format_gain_factor`) and, beside it, the weight ratio and its factor (:func:`format_interval`).
    """
    if "gain_factor_lo" not in table or not len(table):
        return []
    first = str(table["strategy"].iloc[0])
    rows = []
    for r in table[(table["strategy"] != first) & (table["gain"] != "")].itertuples():
        ratio = "" if r.factor != r.factor else format_interval(r.factor, r.factor_lo, r.factor_hi)
        rows.append({"gain entry": r.gain, "strategies": f"{r.strategy} / {first}",
                     "gain factor [interval]": format_gain_factor(r.gain_factor, r.gain_factor_lo, r.gain_factor_hi),
                     "weight ratio": r.ratio, "its factor": ratio or _no_factor(r.factor_note)})
    return rows


def identified_first(table: pd.DataFrame) -> list[str]:
    """Sentences for what the data identify, contrasts first: each factor of a gain entry between strategies whose
    interval is finite, of one sign and within ×10, each such factor of a weight ratio, then each ratio that is."""
    out = []
    if "gain_factor_identifiable" in table:
        for r in table[table["gain_factor_identifiable"] == True].itertuples():  # noqa: E712 - NaN in the first's
            out.append(f"{r.gain} (beside {r.ratio}): {r.strategy} / {table['strategy'].iloc[0]} = "
                       f"{format_gain_factor(r.gain_factor, r.gain_factor_lo, r.gain_factor_hi)}")
    if "factor" in table:
        for r in table[table["factor_identifiable"] == True].itertuples():  # noqa: E712 - NaN in the first's rows
            out.append(f"{r.ratio}: {r.strategy} / {table['strategy'].iloc[0]} = "
                       f"{format_interval(r.factor, r.factor_lo, r.factor_hi)}")
    for r in table[table["identifiable"]].itertuples():
        out.append(f"{r.ratio} of {r.strategy} = {format_interval(r.estimate, r.lo, r.hi)}")
    return out


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
    power : PowerCurve or None
        The simulated power curve behind the ratios' ``needed`` (None where not computed).
    """

    boot: object
    ratios: WeightRatios | None
    ratio_gain: str
    note: str = ""
    power: object = None


def _used_gain(model) -> str:
    """The estimator that made the model's K̂ (its ``gain_method`` may be the rule "iv-or-direct"); with the pilot's
    timing LIML, which the resampling calls by the instruments' name, "iv"."""
    return "iv" if model.gain_method_ == "liml" else model.gain_method_


def ratio_bootstrap(model, demos, n_boot: int = OBJECTIVE_RESAMPLES, seed: int = 0, ratio_gain: str = "iv",
                    ci: float = 95.0, progress: Callable[[int, int], None] | None = None
                    ) -> tuple[WeightRatios | None, str, str]:
    """Weight ratios of a fitted model's demonstrations: ``(ratios or None, gain method, note)``.

    The gain is estimated by ``ratio_gain`` (default instrumental variables: least squares is biased in closed
    loop), falling back to the model's own method where that fails (e.g. all trials start alike); its
    covariance comes from ``n_boot`` resamples of whole trials.
    """
    from workbench.method.resampling import bootstrap_gain
    from workbench.models.fitting import timing_setting
    from workbench.study.power import as_fitted, regulated_plant

    shifted = as_fitted(model, demos)
    plant = regulated_plant(model)
    failed: dict[str, list[str]] = {}  # cause → the gains it stopped, each cause said once
    timing = timing_setting(model)  # the gain the model has: on the seen state where it has the pilot's timing
    for gain in dict.fromkeys((ratio_gain, _used_gain(model))):
        try:
            gains = bootstrap_gain(shifted, plant, n_boot=n_boot, method=gain, seed=seed, progress=progress,
                                   timing=timing)
            return weight_ratios(gains, plant, ci), gain, _failures(failed)
        except ModelError as exc:
            failed.setdefault(str(exc).rstrip(". "), []).append(gain)
    return None, ratio_gain, _failures(failed)


def _failures(failed: dict[str, list[str]]) -> str:
    """``"weight ratios with gain 'iv' and 'direct' failed: <cause>."``: one sentence per cause (the fit of a single
    demonstration printed the same long cause twice, once per gain)."""
    return " ".join(f"weight ratios with gain {' and '.join(repr(g) for g in gains)} failed: {cause}."
                    for cause, gains in failed.items())


def objective_intervals(model, demos, n_boot: int = OBJECTIVE_RESAMPLES, seed: int = 0, ratio_gain: str = "iv",
                        power: int = 0) -> ObjectiveIntervals:
    """Bootstrap a fitted model's objective over its training demonstrations (whole trials resampled).

    The demonstrations are seen as the model saw them (states relative to their targets when the model is
    goal-relative), so the point estimate of ``boot`` is the model's own ``objective_``; the weight ratios come
    from :func:`ratio_bootstrap`. ``power`` > 0: simulated sets per size of a power curve
    (:func:`workbench.study.power.power_curve`) for the ratios of the diagonal form whose interval spans more
    than ×:data:`TARGET_SPAN`, so that a ratio the data do not identify says how many demonstrations would.
    """
    from workbench.method.resampling import bootstrap
    from workbench.models.fitting import timing_setting
    from workbench.study.power import as_fitted, regulated_plant

    method = _used_gain(model)
    structure = model.structure
    boot = bootstrap(as_fitted(model, demos), regulated_plant(model), n_boot=n_boot, method=method, structure=structure,
                     seed=seed, timing=timing_setting(model))
    ratios, gain, note = ratio_bootstrap(model, demos, n_boot, seed, ratio_gain, boot.ci)
    curve = None
    if ratios is not None and power > 0:
        ratios, curve = with_power(model, demos, ratios, power, seed, ratio_gain)
    return ObjectiveIntervals(boot=boot, ratios=ratios, ratio_gain=gain, note=note, power=curve)


def with_power(model, demos, ratios: WeightRatios, repeats: int = 1, seed: int = 0, gain: str = "iv",
               sizes=None) -> tuple[WeightRatios, object]:
    """``ratios`` with the demonstrations each would need for a span below ×:data:`TARGET_SPAN`, and the power
    curve: simulated for the ratios of the diagonal form wider than that; a ratio already narrower needs
    ``n (log span / log 2)²`` by the √n law from its own interval."""
    from workbench.study.power import power_curve

    n0 = ratios.gains.n_trials
    needed = {iv.name: n0 * (np.log(iv.span) / np.log(TARGET_SPAN)) ** 2
              for iv in ratios.intervals if iv.explained and iv.span <= TARGET_SPAN}
    wide = [iv.name for iv in ratios.intervals if iv.explained and iv.span > TARGET_SPAN]
    curve = None
    if wide:
        curve = power_curve(model, demos, sizes=sizes, repeats=repeats, seed=seed, gain=gain, ratios=wide)
        needed.update({k: v for k, v in curve.needed.items() if k in wide})
    return ratios.with_needed(needed, None if curve is None else curve.largest), curve
