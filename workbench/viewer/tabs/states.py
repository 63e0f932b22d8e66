"""Every state of every trial overlaid (time since each trial's start, or since the log's start for the segments of a
flight), with the flight-mode lanes, one colour per mode, and the key of the trials' colours."""

from __future__ import annotations

from typing import Any

import rerun.blueprint as rrb

from workbench.viewer import entities as paths
from workbench.viewer.entities import LoggedSession, query
from workbench.viewer.tab import Tab
from workbench.viewer.views import key_views, overlays, time_axis

__all__ = ["TAB"]


class States(Tab):
    name = "states"
    order = 20
    description = "every state of every trial overlaid, and the flight-mode lanes"

    def views(self, session: LoggedSession) -> list[Any]:
        s = session
        views: list[Any] = overlays(s, "states", s.state_names)
        if s.modes:
            lanes = [query(paths.FLIGHT_MODE)] if s.clock == "log" else [query(paths.mode_path(i)) for i in s.modes]
            views.append(rrb.StateTimelineView(origin="/", contents=lanes, name="flight mode",
                                               time_view=time_axis(s.span) if s.clock == "log" else None))
        # three columns: a plot of a 12 s trial four to a row was too narrow for more than two time labels
        # (two on a flight's clock: minutes of flight need the width for a time label per minute)
        return [rrb.Grid(*views, *key_views(s), grid_columns=2 if s.clock == "log" else 3, name=self.name)]


TAB = States()
