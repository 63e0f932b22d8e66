"""Rerun recordings of demonstrations, fitted models and their predictions.

What the user sees first. A session is logged into a rerun recording as:

* ``demos/<id>/states/<state>`` and ``demos/<id>/inputs/<input>`` — the recorded trial (inputs drawn step-after,
  i.e. zero-order hold, because a stick command stays in force until the next sample);
* ``demos/<id>/variability/<input>/{w,gmr,gmr_3sigma,outside_3sigma}`` — the residual variability
  ``ŵ = u − K̂ x`` (eq. (20) of the method paper), the GMR mean of ``w`` given ``x`` (eqs. (24)–(27)) drawn with a
  ±1σ band (``gmr``) and a ±3σ band (``gmr_3sigma``), and the samples where ``ŵ`` leaves the 3σ band;
* ``demos/<id>/predictions/from_<k>/<method>/<state>`` — predictions (``û = K̂ x̂ + μ̂(x̂)``, the paper's section
  "Trajectory Prediction"; the IOC-only and GMR-only baselines) from state ``k`` of the trial, and
  ``…/<method>_band/<state>`` its Monte Carlo percentile band;
* ``demos/<id>/mode`` — flight-mode / manual-engaged lanes where the log has them;
* ``scene/…`` — the plane of flight from the vehicle roles (:mod:`workbench.viewer.scene`), in a 2-D view:
  the flown tracks (one color per strategy label, or per segment of a flight), the vehicle's pose over time, the
  predicted paths (one color per method) with the Monte Carlo band as a light tube of percentile boxes, and a pad
  with start points only where the data declare a landing target; no scene for a plant without roles;
* ``models/<name>/{K,Q,R,S,summary}`` — the gain and the normalized cost blocks as tensors, the same as labelled
  heatmaps on one color scale per block (``models/<name>/heatmap/<block>``), and α with the fit diagnostics.

Bulk data go through one guarded ``send_columns`` (:mod:`workbench.viewer.columns`: never a chunk without rows,
which crashes the viewer) on timeline ``time`` — seconds since the trial's start, or since the log's start for the
segments of a flight — and sequence ``step``; styling is logged once, static. :func:`default_blueprint`
(:mod:`workbench.viewer.blueprint`) arranges the views in tabs so the first view is already the useful one.
Each kind of recording has its own application id (:data:`APPLICATION_IDS`), so each keeps its own layout.
"""

from workbench.viewer.replaying import ReplayStats, replay, replay_blueprint
from workbench.viewer.session import (
    APPLICATION_ID,
    APPLICATION_IDS,
    HAS_MEASUREMENTS,
    METHOD_COLORS,
    LoggedSession,
    SessionLogger,
    default_blueprint,
    has_display,
    label_color,
    log_session,
    new_recording,
    open_output,
    record_session,
    record_study,
)

__all__ = [
    "APPLICATION_ID",
    "APPLICATION_IDS",
    "HAS_MEASUREMENTS",
    "LoggedSession",
    "METHOD_COLORS",
    "ReplayStats",
    "SessionLogger",
    "default_blueprint",
    "has_display",
    "label_color",
    "log_session",
    "new_recording",
    "open_output",
    "record_session",
    "record_study",
    "replay",
    "replay_blueprint",
]
