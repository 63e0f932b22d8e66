"""The recorded inputs of every trial, and per focus trial ŵ = u − K̂x on its GMR ±1σ / ±3σ bands with the samples
outside 3σ marked; each ŵ title carries the band's coverage and its verdict (the report's words)."""

from __future__ import annotations

from typing import Any

import rerun.blueprint as rrb

from workbench.viewer import entities as paths
from workbench.viewer.entities import LoggedSession, query
from workbench.viewer.tab import Tab
from workbench.viewer.views import focus_trials, key_views, overlays, plot

__all__ = ["TAB"]


class Inputs(Tab):
    name = "inputs & variability"
    order = 30
    description = "the recorded inputs, and per focus trial ŵ = u − K̂x on its GMR ±1σ / ±3σ bands"

    def views(self, session: LoggedSession) -> list[Any]:
        s = session
        input_views: list[Any] = overlays(s, "inputs", s.input_names)
        w_rows: list[Any] = []
        for i in [f for f in focus_trials(s) if f in s.variability]:
            row = []
            for name in s.input_names:
                p = paths.series_path(i, "variability", name)
                fit = s.fit_titles.get(p)
                where = " (in-sample)" if i in s.in_sample else ""
                # the trial first (a long title is cut at its end, and the trial says which row this is), then the
                # input and the band's verdict (the report's words, band_verdict); the key view explains the colors
                # and the nominal shares (no legend)
                row.append(plot(f"{i}{where} · ŵ {name}" + (f" · {fit}" if fit else ""),
                                [query(p, recursive=True)], legend=rrb.PlotLegend(visible=False),
                                y_range=s.ranges.get(p), window=s.trial_windows.get(i)))
            w_rows.append(rrb.Horizontal(*row))
        if not w_rows:
            return [rrb.Grid(*input_views, *key_views(s), name=self.name)]
        # a row per focus trial, its inputs side by side: plots twice as wide as in a grid of four, so a time axis
        # of a few seconds gets more than its "+0s" label (seen with rrd-look)
        # the inputs one above the other, three quarters of the width: side by side beside the key, a flight's
        # 13 minutes got one time label ("+10m", seen with rrd-look)
        key = key_views(s)
        top = rrb.Horizontal(rrb.Vertical(*input_views), *key, column_shares=[3, 1]) if key else \
            rrb.Vertical(*input_views)
        return [rrb.Vertical(top, *w_rows, name=self.name)]


TAB = Inputs()
