"""The scene: the plane of flight from the data's vehicle roles, seen from the side and fitted to the flown tracks,
with every method's prediction from the focus trial, beside that trial's two position states zoomed to the
prediction window (and the held-out scores above them); a pad only where the data declare a landing target. No
scene for a plant without position roles. The first view's title says when a model does not fit the data or is
shown on its own training trials.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import rerun.blueprint as rrb

from workbench.models.registry import REGISTRY
from workbench.viewer import entities as paths
from workbench.viewer import style
from workbench.viewer.entities import LoggedSession, query
from workbench.viewer.tab import Tab
from workbench.viewer.views import focus_trials, overlay, plot, prediction_paths

__all__ = ["TAB"]


def _scene_name(s: LoggedSession, across: str, up: str) -> str:
    name = f"plane of flight: {s.title(across)} → / {s.title(up)} ↑"
    bad = [m for m, v in s.verdicts.items() if not v.fits]
    if bad:  # a wrong model is seen in the first second: in the first view's title
        name = f"⚠ MODEL {', '.join(bad)} DOES NOT FIT THESE DATA (see objective) — " + name
    inside = [m for m, v in s.verdicts.items() if v.all_in_sample]
    if inside:  # a model shown on its own training trials: nothing here is a held-out number
        name = f"⚠ {', '.join(inside)} SHOWN ON ITS TRAINING TRIALS (in-sample) — " + name
    if s.methods:
        words = {m.name: style.color_name(m.colour) for m in REGISTRY}
        name += " — " + ", ".join(f"{style.method_title(m)} {words[m]}" if m in words else style.method_title(m)
                                  for m in s.methods)
        if s.bands:
            name += ", MC band gray"
    return name


def _scene_tab(s: LoggedSession, plane: Sequence[str] | None, focus: Sequence[str]) -> Any:
    bounds = None
    if s.bounds is not None:
        bounds = rrb.VisualBounds2D(x_range=s.bounds[0], y_range=s.bounds[1])
    across, up = plane if plane is not None else ("", "")
    scene = rrb.Spatial2DView(origin="/scene", name=_scene_name(s, across, up) if plane else "plane of flight",
                              visual_bounds=bounds)
    if plane is None:
        return rrb.Horizontal(scene, name="scene")
    side = []
    for name in plane:
        if focus and focus[0] in s.predictions:
            fid = focus[0]
            key = paths.prediction_plot(fid, name)
            side.append(plot(f"{s.title(name)} · {fid}", prediction_paths(s, fid, name),
                             # no legend: the scene's title names every colour, and a legend covered a third
                             # of a plot this small (seen with rrd-look)
                             legend=rrb.PlotLegend(s.corners.get(key, "RightTop"), visible=False),
                             y_range=s.ranges.get(key),
                             window=s.windows.get(fid)))
        else:
            side.append(overlay(s, s.title(name),
                                 [query(paths.series_path(i, "states", name)) for i in s.demo_ids],
                                 key=paths.overlay_plot("states", name)))
    if paths.SCORES in s.entities:
        # the first question's answer where the eye lands: each method's held-out error beside the tracks
        side.insert(0, rrb.TextDocumentView(origin=paths.origin(paths.SCORES), name="held-out prediction error"))
        # the scores' tables whole (a line is ~26 px of the ~940 px column, measured with rrd-look: a title of two
        # lines, per label its name, a header, a row per method and a gap of two), the plots sharing the rest, tall
        # enough for three ticks
        scored = s.scores if s.scores is not None and len(s.scores) else None
        labels = max(len(set(scored["label"])) if scored is not None else len(s.label_colors), 1)
        rows = len(set(scored["method"])) if scored is not None else len(s.methods)
        doc = 26.0 * (3 + labels * (4 + max(rows, 1)))
        # the two position plots side by side under the scores: each as tall as the space left (one above the
        # other, ~175 px each, the x plot kept a single "0" label; seen with rrd-look), a 3 s window still wide
        # enough for a label per second
        plots = max(940.0 - doc, 300.0)
        return rrb.Horizontal(scene, rrb.Vertical(side[0], rrb.Horizontal(*side[1:]), row_shares=[doc, plots]),
                              column_shares=[3, 2], name="scene")
    return rrb.Horizontal(scene, rrb.Vertical(*side), column_shares=[3, 2], name="scene")


class Scene(Tab):
    """Shows what the session logged: the scene (ground, pad, starts, scale) before the trials, whose tracks and
    vehicles come with each trial, and the predictions."""

    name = "scene"
    order = 10
    description = ("the plane of flight with the tracks and every method's prediction, beside the focus trial's "
                   "positions and the held-out scores")

    def views(self, session: LoggedSession) -> list[Any]:
        if not session.scene:
            return []
        return [_scene_tab(session, session.plane_names, focus_trials(session))]


TAB = Scene()
