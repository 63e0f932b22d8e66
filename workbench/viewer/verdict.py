"""Does a model fit the data it is shown with? The verdict every model view carries in its title.

Three kinds of evidence, all computed from the model and the demonstrations, never from the viewer's drawing:

* **in-sample** — which of the trials shown the model was fitted on (:mod:`workbench.models.training`, from the
  trial ids and digests its file records): a model that fits its own training trials says nothing about a pilot's
  next flight, so such trials are named "in-sample" wherever they are shown;
* **mismatches** — what the model was fitted on differs from these data: state or input names, the vehicle
  roles, the sampling step (the data were resampled to the model's ``dt``), or states far outside the box of the
  training states (``state_envelope_``, :func:`workbench.models.fitting.state_envelope`);
* **calibration** — the share of the recorded inputs inside the model's ±1σ and ±3σ bands, judged by the one
  function every view, table and line uses, :func:`workbench.study.calibration.band_verdict` ("fits", "too
  narrow", "too wide", "does not fit" against the spread sampling allows; inputs at their limits left out).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy.stats import norm

from workbench.models.behavior import BehaviorModel
from workbench.models.training import in_sample, training_known
from workbench.study.calibration import (
    DOES_NOT_FIT,
    FITS,
    band_words,
    calibration_check,
    calibration_counts,
)

__all__ = ["NOMINAL_1SIGMA", "NOMINAL_3SIGMA", "LEVELS", "Verdict", "verdict", "trial_band_titles"]

NOMINAL_1SIGMA = float(norm.cdf(1.0) - norm.cdf(-1.0))
NOMINAL_3SIGMA = float(norm.cdf(3.0) - norm.cdf(-3.0))
#: The band levels a view shows (the report's table adds 2σ; the verdict of a level is the same function's).
LEVELS = (1.0, 3.0)
# States farther than this many training widths outside the training box mean the model meets a state space it
# has never seen (the envelope itself already has a margin, ENVELOPE_MARGIN of the width).
FAR_OUTSIDE = 1.0
FAR_SHARE = 0.2  # …for at least this share of the samples


@dataclass(frozen=True)
class Verdict:
    """What a model meets: the mismatches with its training data (one sentence each), the calibration of its input
    band over the trials shown (:func:`workbench.study.calibration.calibration_check` rows) and which of those
    trials trained it."""

    model: str
    mismatches: tuple[str, ...]
    calibration: pd.DataFrame | None = None
    n_trials: int = 0
    in_sample: tuple[str, ...] = ()
    training_known: bool = True
    notes: tuple[str, ...] = field(default_factory=tuple)
    n_judged: int = 0  # the trials the band is judged on: the held-out ones where any are shown, else all

    @property
    def does_not_fit(self) -> tuple[str, ...]:
        """The inputs whose band "does not fit" at some level."""
        c = self.calibration
        if c is None or not len(c):
            return ()
        return tuple(dict.fromkeys(c.loc[c["verdict"] == DOES_NOT_FIT, "input"]))

    @property
    def fits(self) -> bool:
        return not self.mismatches and not self.does_not_fit

    @property
    def all_in_sample(self) -> bool:
        return self.n_trials > 0 and len(self.in_sample) == self.n_trials

    def miscalibrated(self) -> list[str]:
        """``["u1 too narrow at 3σ", …]``: every reading of the band that is not "fits" (a "does not fit" too)."""
        c = self.calibration
        if c is None or not len(c):
            return []
        bad = c[c["verdict"] != FITS]
        return [f"{r.input} {r.verdict} at {float(r.n_sigma):g}σ" for r in bad.itertuples()]

    def head(self, short: bool = False) -> str:
        """The verdict in words that follow from its own readings: "fits these data" only where no reading says
        otherwise; "DOES NOT FIT these data" for a mismatch or a band that does not fit; else what the band misses
        ("band too narrow: u1 at 3σ, …"). ``short``: a title's few words."""
        if not self.fits:
            return "DOES NOT FIT" if short else "DOES NOT FIT these data"
        bad = self.miscalibrated()
        if not bad:
            return "fits" if short else "fits these data"
        if short:
            return "band miscalibrated"
        return "states fit; its input band is miscalibrated: " + ", ".join(bad)

    def band_text(self) -> str:
        """``"u1: 3σ 98.2 % too narrow, 1σ 74 % too wide; u2: …"`` over the trials shown, or "no band"."""
        c = self.calibration
        if c is None or not len(c):
            return "no band"
        return "; ".join(f"{name}: {band_words(rows)}" for name, rows in c.groupby("input", sort=False))

    def sample_text(self) -> str:
        """Which trials the numbers come from: held-out, in-sample or unknown."""
        if not self.training_known:
            return f"{self.n_trials} trial(s); its training trials are unknown (model file predates their record)"
        n_in = len(self.in_sample)
        if n_in == self.n_trials:
            return f"all {n_in} trial(s) IN-SAMPLE: it was fitted on them, so this says nothing about new data"
        if n_in:
            return (f"the {self.n_trials - n_in} held-out trial(s) ({n_in} in-sample trial(s) shown are not "
                    "counted)")
        return f"{self.n_trials} held-out trial(s)"

    def warning(self) -> str | None:
        """One line for the terminal and the recording, or None when nothing speaks against the model."""
        if self.fits:
            return None
        why = list(self.mismatches)
        if self.does_not_fit:
            why.append(f"its input band does not fit ({self.band_text()})")
        return f"model {self.model} does not fit these data: " + "; ".join(why)


def _roles_json(roles: Any) -> Any:
    return roles.to_json() if roles else None


def mismatches(model: Any, state_names: Sequence[str], input_names: Sequence[str], roles: Any,
               X: np.ndarray | None, *, source_dt: float | None = None) -> list[str]:
    """Sentences naming what differs between the model's training data and these (see the module docstring).

    ``X`` (N, n) are the states shown; ``source_dt`` the data's step before any resampling to the model's.
    """
    plant = getattr(model, "plant", None)
    if plant is None:
        return []
    out = []
    names = tuple(getattr(plant, "state_names", ()) or ())
    if names and tuple(state_names) != names:
        out.append(f"its states are {', '.join(names)}, these data's {', '.join(state_names)}")
    inputs = tuple(getattr(plant, "input_names", ()) or ())
    if inputs and tuple(input_names) != inputs:
        out.append(f"its inputs are {', '.join(inputs)}, these data's {', '.join(input_names)}")
    mine = _roles_json(getattr(plant, "roles", None))
    if mine is not None and roles is not None and mine != _roles_json(roles):
        out.append("its vehicle roles differ from these data's (another mapping or vehicle)")
    dt = float(getattr(plant, "dt", np.nan))
    if source_dt is not None and np.isfinite(dt) and not np.isclose(source_dt, dt, rtol=1e-6):
        out.append(f"it was fitted at dt = {dt:g} s, these data are sampled at {source_dt:g} s (resampled)")
    box = getattr(model, "state_envelope_", None)
    if box is not None and X is not None and len(X) and np.shape(box) == (2, np.shape(X)[1]):
        lo, hi = np.asarray(box, dtype=float)
        width = np.maximum(hi - lo, 1e-9)
        beyond = np.maximum(lo - X, X - hi) / width  # in training widths; negative inside
        far = beyond > FAR_OUTSIDE
        share = float(far.any(axis=1).mean())
        if share >= FAR_SHARE:
            worst = int(np.argmax(np.nanmax(beyond, axis=0)))
            label = list(state_names)[worst] if len(state_names) > worst else str(worst)
            out.append(f"{100 * share:.0f} % of the states lie more than {FAR_OUTSIDE:g} training range outside "
                       f"its training states (worst: {label}, {np.nanmax(beyond[:, worst]):.1f} ranges out)")
    return out


def _calibrated(model: Any) -> bool:
    return isinstance(model, BehaviorModel)


def verdict(name: str, model: Any, demos: Any, *, source_dt: float | None = None) -> Verdict:
    """The verdict on ``model`` shown with ``demos`` (a DemonstrationSet): mismatches, the calibration of its input
    band pooled over the trials (the report's computation, :func:`workbench.study.calibration.calibration_check`)
    and which trials are in-sample."""
    demos = list(demos) if not hasattr(demos, "state_names") else demos
    X = np.concatenate([d.x for d in demos]) if len(demos) else None
    found = mismatches(model, demos.state_names, demos.input_names, getattr(demos, "roles", None), X,
                       source_dt=source_dt)
    check = None
    inside = tuple(in_sample(model, demos))
    # the band is judged on the trials the model has not seen where there are any: the study's test trials, the
    # report's coverage; in-sample trials say how well it fits what it learned, not how well it predicts
    judged = [d for d in demos if d.id not in set(inside)] or list(demos)
    if _calibrated(model) and len(demos) and not any("states are" in m or "inputs are" in m for m in found):
        check = calibration_check(calibration_counts(model, judged, LEVELS))
    return Verdict(name, tuple(found), check, len(demos), inside, training_known(model), n_judged=len(judged))


def trial_band_titles(model: Any, demos: Sequence[Any]) -> dict[tuple[str, str], str]:
    """Per (trial id, input): ``"3σ 98.2 % too narrow, 1σ 74 % fits"`` — each trial's band verdict by the same
    function as the pooled one, the limits found over all of ``demos``."""
    if not _calibrated(model) or not demos:
        return {}
    counts = calibration_counts(model, list(demos), LEVELS, by_trial=True)
    out = {}
    for (trial, name), rows in counts.groupby(["trial", "input"], sort=False):
        check = calibration_check(rows.drop(columns="trial"))
        out[(str(trial), str(name))] = band_words(check)
    return out


__all__ += ["FITS", "DOES_NOT_FIT"]
