"""Does a model fit the data it is shown with? The verdict every model view carries in its title.

Two kinds of evidence, both computed from the model and the demonstrations, never from the viewer's drawing:

* **mismatches** — what the model was fitted on differs from these data: state or input names, the vehicle
  roles, the sampling step (the data were resampled to the model's ``dt``), or states far outside the box of the
  training states (``state_envelope_``, :func:`workbench.models.behavior.state_envelope`);
* **calibration** — the share of ``ŵ = u − K̂x`` inside the GMR's ±1σ and ±3σ bands (eqs. (24)–(27) of the
  method paper) against the nominal 68.3 % and 99.7 % of a Gaussian. A model of these data lands near nominal; a
  model of other data leaves most samples outside 3σ.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import norm

__all__ = ["NOMINAL_1SIGMA", "NOMINAL_3SIGMA", "Coverage", "Verdict", "coverage", "verdict"]

NOMINAL_1SIGMA = float(norm.cdf(1.0) - norm.cdf(-1.0))
NOMINAL_3SIGMA = float(norm.cdf(3.0) - norm.cdf(-3.0))
# A band is "poor" when its share inside 3σ falls this far below nominal: with a few hundred samples the
# binomial spread of a calibrated band is ~1 point, the demo's models land within 1.5 points of 99.7 %.
POOR_3SIGMA = 0.90
# States farther than this many training widths outside the training box mean the model meets a state space it
# has never seen (the envelope itself already has a margin, ENVELOPE_MARGIN of the width).
FAR_OUTSIDE = 1.0
FAR_SHARE = 0.2  # …for at least this share of the samples


@dataclass(frozen=True)
class Coverage:
    """Shares of ŵ samples inside the GMR's ±1σ and ±3σ bands, over ``n`` samples (all inputs pooled)."""

    inside_1sigma: float
    inside_3sigma: float
    n: int

    @property
    def poor(self) -> bool:
        """Whether the 3σ band misses far more samples than a calibrated band would."""
        return self.n > 0 and self.inside_3sigma < POOR_3SIGMA

    def short(self) -> str:
        """``"✓ 3σ 98.2 %, 1σ 74 %"``: a plot title's verdict (the nominal 99.7 % and 68 % are in the tab's key).

        A plot title is cut at the width of its view (about 40 characters in a grid of four): the mark and the
        3σ share come first, and a poor band says so in words.
        """
        if not self.n:
            return "no samples"
        head = "✗ DOES NOT FIT: " if self.poor else "✓ "
        return f"{head}3σ {100 * self.inside_3sigma:.1f} %, 1σ {100 * self.inside_1sigma:.0f} %"

    def text(self) -> str:
        """``"✓ 3σ 99.1 % (nominal 99.7), 1σ 70 % (68)"``: the 3σ share first (titles are cut at their end), and
        words a reader sees at once when the band is poor."""
        if not self.n:
            return "no samples"
        head = "✗ DOES NOT FIT " if self.poor else "✓ "
        return (f"{head}3σ {100 * self.inside_3sigma:.1f} % (nominal {100 * NOMINAL_3SIGMA:.1f}), "
                f"1σ {100 * self.inside_1sigma:.0f} % ({100 * NOMINAL_1SIGMA:.0f})")


def coverage(w: np.ndarray, mu: np.ndarray, sigma: np.ndarray) -> Coverage:
    """The share of ``w`` within ``mu ± σ`` and ``mu ± 3σ`` (arrays of one shape; non-finite rows ignored)."""
    w, mu, sigma = (np.asarray(a, dtype=float) for a in (w, mu, sigma))
    ok = np.isfinite(w) & np.isfinite(mu) & np.isfinite(sigma)
    dev = np.abs(w - mu)[ok]
    s = sigma[ok]
    if not dev.size:
        return Coverage(float("nan"), float("nan"), 0)
    return Coverage(float(np.mean(dev <= s)), float(np.mean(dev <= 3.0 * s)), int(dev.size))


@dataclass(frozen=True)
class Verdict:
    """What a model meets: the mismatches with its training data (one sentence each) and ŵ's band coverage."""

    model: str
    mismatches: tuple[str, ...]
    coverage: Coverage | None

    @property
    def fits(self) -> bool:
        return not self.mismatches and not (self.coverage is not None and self.coverage.poor)

    def warning(self) -> str | None:
        """One line for the terminal and the recording, or None when nothing speaks against the model."""
        if self.fits:
            return None
        why = list(self.mismatches)
        if self.coverage is not None and self.coverage.poor:
            why.append(f"only {100 * self.coverage.inside_3sigma:.1f} % of ŵ inside the GMR 3σ band "
                       f"(nominal {100 * NOMINAL_3SIGMA:.1f} %)")
        return f"model {self.model} does not fit these data: " + "; ".join(why)


def _roles_json(roles: Any) -> Any:
    return roles.to_json() if roles else None


def mismatches(model: Any, state_names: Sequence[str], input_names: Sequence[str], roles: Any,
               X: np.ndarray | None, *, source_dt: float | None = None) -> list[str]:
    """Sentences naming what differs between the model's training data and these (see the module docstring).

    ``X`` (N, n) are the states shown; ``source_dt`` the data's step before any resampling to the model's.
    """
    system = getattr(model, "system", None)
    if system is None:
        return []
    out = []
    names = tuple(getattr(system, "state_names", ()) or ())
    if names and tuple(state_names) != names:
        out.append(f"its states are {list(names)}, these data's {list(state_names)}")
    inputs = tuple(getattr(system, "input_names", ()) or ())
    if inputs and tuple(input_names) != inputs:
        out.append(f"its inputs are {list(inputs)}, these data's {list(input_names)}")
    mine = _roles_json(getattr(system, "roles", None))
    if mine is not None and roles is not None and mine != _roles_json(roles):
        out.append("its vehicle roles differ from these data's (another mapping or vehicle)")
    dt = float(getattr(system, "dt", np.nan))
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


def verdict(name: str, model: Any, demos: Any, *, source_dt: float | None = None,
            w_parts: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]] = ()) -> Verdict:
    """The verdict on ``model`` shown with ``demos`` (a DemonstrationSet): mismatches and pooled ŵ coverage.

    ``w_parts`` are (ŵ, μ, σ) arrays of the trials the model explains, as the viewer logged them.
    """
    X = np.concatenate([d.x for d in demos]) if len(demos) else None
    found = mismatches(model, demos.state_names, demos.input_names, getattr(demos, "roles", None), X,
                       source_dt=source_dt)
    cov = None
    if w_parts:
        cov = coverage(*(np.concatenate([np.ravel(p[k]) for p in w_parts]) for k in range(3)))
    return Verdict(name, tuple(found), cov)
