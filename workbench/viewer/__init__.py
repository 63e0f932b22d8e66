"""Rerun recordings of demonstrations, fitted models and their predictions.

What the user sees first. A session is logged into a rerun recording as:

* ``demos/<id>/states/<state>`` and ``demos/<id>/inputs/<input>`` — the recorded trial (inputs drawn step-after,
  i.e. zero-order hold, because a stick command stays in force until the next sample);
* ``demos/<id>/variability/<input>/{w,gmr,gmr_3sigma,outside_3sigma}`` — the residual variability
  ``ŵ = u − K̂ x`` (eq. (20) of the method paper), the GMR mean of ``w`` given ``x`` (eqs. (24)–(27)) drawn with a
  ±1σ band (``gmr``) and a ±3σ band (``gmr_3sigma``), and the samples where ``ŵ`` leaves the 3σ band;
* ``demos/<id>/predictions/from_<k>/<method>/<state>`` — predictions (``û = K̂ x̂ + μ̂(x̂)``, the paper's section
  "Trajectory Prediction"; the IOC-only and GMR-only baselines) from state ``k`` of the trial, and
  ``…/band/<state>`` the Monte Carlo percentile band;
* ``demos/<id>/mode`` — flight-mode / manual-engaged lanes where the log has them;
* ``scene/…`` — a spatial view of the landing: domain box, pad, start points, flown paths, the vehicle's pose
  over time and the predicted paths as line strips (x right, altitude up, in the plane ``y = 0`` of a 3-D view,
  because rerun's 2-D views point their y axis down);
* ``models/<name>/{K,Q,R,S,summary}`` — the gain, the normalized cost blocks as tensors (heatmaps) and α with the
  fit diagnostics as text.

Bulk data go through ``send_columns`` only (timeline ``time`` in seconds since the trial's start and sequence
``step``); styling is logged once, static. :func:`default_blueprint` arranges the views in tabs (scene, states,
inputs & variability, predictions, objective) so the first view is already the useful one.
"""

from workbench.viewer.replay import ReplayStats, replay, replay_blueprint
from workbench.viewer.session import (
    APPLICATION_ID,
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
