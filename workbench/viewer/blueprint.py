"""The first view of a session recording, in the spirit of rerun's example blueprints: the tabs of
:data:`workbench.viewer.tabs.TABS` in their order, each only when it has something to show (each tab's module says
what it shows; ``python -c "import workbench.viewer.tabs as t; print(t.describe())"`` lists them), then any extra
tabs (a mapped flight's raw-log tabs).

How it reads: the key of a tab's colors is in its view titles or a small "key" text view, a legend only in the
quiet corner of one plot; the plots of a tab share one time axis (``LinkAxis.LinkToGlobal``); a plot's y-range
is the data's but never narrower than its unit's minimum span (:data:`workbench.viewer.style.MIN_SPAN`); ŵ titles
carry the band's coverage and the one verdict of :func:`workbench.study.calibration.band_verdict`, the first view
and every prediction tab each method's held-out RMSE (:mod:`workbench.study.scores`), trials a model was fitted on
are marked "in-sample", and a model that does not fit the data says so in the first view's title. Side panels
start collapsed and the time cursor at the start (the time panel is paused).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import rerun.blueprint as rrb

from workbench.viewer.entities import LoggedSession
from workbench.viewer.tabs import TABS
from workbench.viewer.views import time_panel

__all__ = ["session_blueprint"]


def session_blueprint(session: LoggedSession, *, extra_tabs: Sequence[Any] = ()) -> rrb.Blueprint:
    """Every tab's views (:data:`~workbench.viewer.tabs.TABS`, in order), then ``extra_tabs``; the first is open."""
    tabs = [view for tab in TABS for view in tab.views(session)]
    tabs += list(extra_tabs)  # e.g. the raw log's tabs (workbench.viewer.rawlog) behind a mapped flight
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), time_panel(), collapse_panels=True)
