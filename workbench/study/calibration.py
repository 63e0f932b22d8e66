"""Is the one-step band calibrated? Coverage without saturated inputs, against the spread sampling allows.

The one-step coverage (:func:`workbench.study.evaluate.one_step_coverage`) counts the recorded inputs inside
the model's band ``m(x_k) ± c σ(x_k)``. Two things hide or fake a miscalibration there:

* **Saturation.** An input held at its limit — the plant's ``u_min`` / ``u_max``, or a stick pinned at the
  extreme of its travel in the data — is censored: the operator wanted at least that much, the Gaussian band
  does not model it. :func:`saturated` flags those samples; coverage is scored with and without them.
* **Sampling spread.** Samples within a trial are correlated, so the count inside the band varies more than a
  binomial of N samples. The effective count ``N_eff = N (1 − ρ) / (1 + ρ)`` uses the lag-1 autocorrelation ρ
  of the inside/outside indicator within trials (an AR(1) approximation); a band is called off only where the
  observed share lies outside the binomial 95 % interval of the nominal share over ``N_eff`` samples
  (``scipy.stats.binom.interval``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import pandas as pd
import scipy.stats

from workbench.data.demonstrations import Demonstration
from workbench.study.evaluate import nominal_coverage

__all__ = ["saturated", "calibration_counts", "calibration_check", "band_verdict", "band_words", "check_table",
           "PINNED_SHARE", "FITS", "TOO_NARROW", "TOO_WIDE", "DOES_NOT_FIT"]

#: A value at the data's extreme counts as a pinned stick when at least this share of the samples sit on it.
PINNED_SHARE = 0.01


def saturated(demos: Sequence[Demonstration], plant: Any, pinned_share: float = PINNED_SHARE) -> list[np.ndarray]:
    """Per demonstration, a (N, m) mask of the inputs at their limits.

    An input is at its limit where it equals the plant's ``u_min`` / ``u_max`` (within 1e-9 of its range), or —
    with or without declared limits — where it equals the smallest or largest value it takes over ``demos`` and
    at least ``pinned_share`` of the samples (and 3) sit exactly there: a stick held against its stop.
    """
    U = np.concatenate([d.u for d in demos]) if demos else np.zeros((0, plant.m))
    lo_d, hi_d = (U.min(axis=0), U.max(axis=0)) if len(U) else (np.zeros(plant.m), np.zeros(plant.m))
    pinned_lo = ((U == lo_d).sum(axis=0) >= max(3, pinned_share * len(U))) & (hi_d > lo_d)
    pinned_hi = ((U == hi_d).sum(axis=0) >= max(3, pinned_share * len(U))) & (hi_d > lo_d)
    u_min = None if plant.u_min is None else np.asarray(plant.u_min, dtype=float)
    u_max = None if plant.u_max is None else np.asarray(plant.u_max, dtype=float)
    tol = 1e-9 * np.maximum(1.0, np.abs(hi_d - lo_d))
    out = []
    for d in demos:
        mask = (pinned_lo & (d.u == lo_d)) | (pinned_hi & (d.u == hi_d))
        if u_min is not None:
            mask |= d.u <= u_min + tol
        if u_max is not None:
            mask |= d.u >= u_max - tol
        out.append(mask)
    return out


def _lag1(indicators: Iterable[np.ndarray]) -> float:
    """Pooled lag-1 autocorrelation of 0/1 series (one per trial), clipped to [0, 0.99]."""
    num = den = 0.0
    for z in indicators:
        if len(z) < 3:
            continue
        c = z - z.mean()
        num += float(np.sum(c[1:] * c[:-1]))
        den += float(np.sum(c * c))
    return float(np.clip(num / den, 0.0, 0.99)) if den > 0 else 0.0


def calibration_counts(
    model: Any, test: Sequence[Demonstration], n_sigmas: Sequence[float] = (1, 2, 3), *, by_trial: bool = False
) -> pd.DataFrame:
    """Counts behind the calibration check, per input and level: ``input, n_sigma, n, n_saturated, hits,
    n_free, hits_free, n_eff`` (``free``: samples not at a limit; ``n_eff`` of the free samples). Counts of
    several test sets (folds) add up.

    ``by_trial``: one row per trial, input and level (a ``trial`` column), the limits found over all of ``test``
    as for the pooled rows, so a view's per-trial verdicts and its model's pooled one come from the same masks.
    """
    demos = list(test)
    masks = saturated(demos, model.plant)
    rows = []
    dev, sig = [], []
    for d in demos:
        mean, Sigma = model.input_distribution_along(d)  # with the pilot's timing: given the trial before each
        dev.append(np.abs(d.u - mean))
        sig.append(np.sqrt(np.clip(np.diagonal(Sigma, axis1=1, axis2=2), 0.0, None)))
    groups = [(d.id, [i]) for i, d in enumerate(demos)] if by_trial else [(None, list(range(len(demos))))]
    for trial, members in groups:
        for j, name in enumerate(model.plant.input_names):
            for c in n_sigmas:
                inside = [(dev[i][:, j] <= float(c) * sig[i][:, j]).astype(float) for i in members]
                free = [z[~masks[i][:, j]] for z, i in zip(inside, members, strict=True)]
                n_free = int(sum(len(z) for z in free))
                rho = _lag1(free)
                rows.append(((trial,) if by_trial else ()) + (
                    name, float(c), int(sum(len(z) for z in inside)),
                    int(sum(int(masks[i][:, j].sum()) for i in members)), float(sum(z.sum() for z in inside)),
                    n_free, float(sum(z.sum() for z in free)), n_free * (1.0 - rho) / (1.0 + rho)))
    columns = ["input", "n_sigma", "n", "n_saturated", "hits", "n_free", "hits_free", "n_eff"]
    return pd.DataFrame(rows, columns=(["trial"] if by_trial else []) + columns)


#: The four answers of :func:`band_verdict`, the only words any view, table or line uses for a band's calibration.
FITS, TOO_NARROW, TOO_WIDE, DOES_NOT_FIT = "fits", "too narrow", "too wide", "does not fit"
#: A band "does not fit" (rather than being "too narrow") where it misses this many times more samples than the
#: upper end of the sampling range of a calibrated band's misses: a band of other data, not a slightly narrow one
#: (at 3σ and a few hundred effective samples: below ~93 % inside, where a narrow band of the right data sits at
#: 97–99 %).
MISS_FACTOR = 10.0


def band_verdict(coverage: Any, nominal: Any, n_eff: Any, ci: float = 95.0) -> np.ndarray:
    """The one verdict on a band's coverage: "fits", "too narrow", "too wide" or "does not fit".

    The observed share inside the band is judged against the binomial ``ci`` % interval of the nominal share over
    ``n_eff`` effective samples (:func:`calibration_counts`): inside it the band fits; below it the band is too
    narrow, and it does not fit at all where it misses more than :data:`MISS_FACTOR` times the interval's largest
    share of misses; above it the band is too wide. A share without samples (NaN) gets "".

    Parameters
    ----------
    coverage, nominal, n_eff : float or array_like (broadcast together)

    Returns
    -------
    ndarray of str, the shape of the broadcast inputs (a 0-d array for scalars; ``str(...)`` reads it).
    """
    cov, nom, n = np.broadcast_arrays(np.asarray(coverage, dtype=float), np.asarray(nominal, dtype=float),
                                      np.asarray(n_eff, dtype=float))
    k = np.maximum(1, np.round(np.nan_to_num(n, nan=1.0))).astype(int)
    lo, hi = scipy.stats.binom.interval(ci / 100.0, k, nom)
    lo, hi = lo / k, hi / k
    out = np.where(cov < lo, TOO_NARROW, np.where(cov > hi, TOO_WIDE, FITS)).astype(object)
    out = np.where((cov < lo) & (1.0 - cov > MISS_FACTOR * (1.0 - lo)), DOES_NOT_FIT, out)
    return np.where(np.isfinite(cov), out, "").astype(object)


def band_words(check: pd.DataFrame, levels: Sequence[float] = (3.0, 1.0)) -> str:
    """``"3σ 98.2 % too narrow, 1σ 74 % too wide"``: the check's rows of one input at ``levels`` (outer first,
    the one a title must not lose), each with its share and :func:`band_verdict`'s word — the text the viewer's
    titles, the terminal and the report print for a band."""
    by = check.set_index("n_sigma")
    parts = []
    for c in levels:
        if c in by.index:
            r = by.loc[c]
            parts.append(f"{c:g}σ {100 * float(r['coverage_free']):.{1 if c >= 3 else 0}f} % {r['verdict']}")
    return ", ".join(parts)


def calibration_check(counts: pd.DataFrame, ci: float = 95.0) -> pd.DataFrame:
    """Coverage with and without saturated inputs, and whether it is off by more than sampling allows.

    Parameters
    ----------
    counts : DataFrame
        :func:`calibration_counts` rows, possibly of several test sets (summed per ``label`` where present,
        input and level).

    Returns
    -------
    DataFrame with ``[label,] input, n_sigma, nominal, coverage, coverage_free, saturated, n_eff, lo, hi,
    verdict``: ``lo``–``hi`` is the binomial interval of the nominal share over ``n_eff`` samples; the verdict is
    :func:`band_verdict`'s ("fits", "too narrow", "too wide", "does not fit").
    """
    keys = [k for k in ("label", "input", "n_sigma") if k in counts.columns]
    g = counts.groupby(keys, sort=False)[["n", "n_saturated", "hits", "n_free", "hits_free", "n_eff"]].sum()
    g = g.reset_index()
    nominal = np.asarray(nominal_coverage(g["n_sigma"].to_numpy(float)), dtype=float)
    n_eff = np.maximum(1, np.round(g["n_eff"].to_numpy(float))).astype(int)
    lo, hi = scipy.stats.binom.interval(ci / 100.0, n_eff, nominal)
    with np.errstate(invalid="ignore", divide="ignore"):
        cov_free = g["hits_free"] / g["n_free"]
        out = g[keys].assign(
            nominal=nominal, coverage=g["hits"] / g["n"], coverage_free=cov_free,
            saturated=g["n_saturated"] / g["n"], n_eff=g["n_eff"], lo=lo / n_eff, hi=hi / n_eff)
    out["verdict"] = band_verdict(out["coverage_free"].to_numpy(float), nominal, g["n_eff"].to_numpy(float), ci)
    return out


def check_table(check: pd.DataFrame) -> pd.DataFrame:
    """:func:`calibration_check` for reading: percentages, the sampling range, the verdict per row."""
    rows = []
    for r in check.itertuples(index=False):
        rows.append({
            **({"label": r.label} if "label" in check.columns else {}),
            "input": r.input, "band": f"{r.n_sigma:g}σ", "nominal [%]": f"{100 * r.nominal:.1f}",
            "inside [%]": f"{100 * r.coverage:.1f}", "at a limit [%]": f"{100 * r.saturated:.1f}",
            "inside, limits excluded [%]": f"{100 * r.coverage_free:.1f}",
            "sampling 95 % range [%] (N_eff)": f"{100 * r.lo:.1f}–{100 * r.hi:.1f} ({r.n_eff:.0f})",
            "calibration": r.verdict,
        })
    return pd.DataFrame(rows)
