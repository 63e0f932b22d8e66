"""The experimenter's view: the session as it happens, in rerun (``workbench collect --spawn|--serve|--save``).

While a subject flies, the page sends the server its states every few physics steps (``POST /api/live``, only
when this view is on; nothing of it is stored: the trial is written when it ends); they are drawn in the scene
``live/<subject>`` with, where a model of the block's label was given (``--model CS1=cs1.npz``), that model's mean
prediction from the trial's start state beside the live track. Each finished trial adds its track to
``trials/<subject>/<id>`` (green landed, red crashed, grey otherwise), a line to the ``outcomes`` log, and the
``summary`` document (trials and landings per subject, label and role) is rewritten.

Time lines: ``session`` (seconds since the server started) for everything, ``step`` (the trial's physics step) for
the live track.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from workbench.defaults import HORIZON_S

__all__ = ["ExperimenterView", "OUTCOME_COLORS"]

OUTCOME_COLORS = {"landed": (46, 158, 87), "crashed": (192, 57, 43)}
OTHER_COLOR = (140, 150, 165)
LIVE_COLOR = (31, 45, 74)
PREDICTION_COLOR = (59, 111, 216)


class ExperimenterView:
    """Log a collecting session to the rerun recording ``rec``; ``models`` maps a block label to a fitted model.

    Calls come from the server's worker threads; a lock keeps each update whole.
    """

    def __init__(self, rec: Any, spec: Mapping[str, Any], models: Mapping[str, Any] | None = None,
                 horizon_s: float = HORIZON_S) -> None:
        import rerun as rr

        self.rr = rr
        self.rec = rec
        self.spec = spec
        self.models = dict(models or {})
        self.n_steps = max(1, int(round(horizon_s / spec["dt"])))
        self.t0 = time.monotonic()
        self.lock = threading.Lock()
        self.counts: dict[tuple[str, str, str], list[int]] = {}
        i = spec["index"]
        self.ix, self.iy = i["x"], i["y"]
        (x_lo, x_hi), y_hi = spec["domain"]["x"], spec["domain"]["y"][1]
        pad = spec["pad"]
        # rerun's 2-D views point y down: heights are negated so that up is drawn up (as the viewer's scenes do)
        ground = [[[x_lo, 0.0], [x_hi, 0.0]], [[pad["x"] - pad["half_width"], 0.0],
                                                [pad["x"] + pad["half_width"], 0.0]]]
        rec.log("scene/ground", rr.LineStrips2D(ground, colors=[(107, 125, 90), (46, 158, 87)], radii=[0.02, 0.05],
                                                labels=["", "pad"]), static=True)
        rec.log("scene/domain", rr.LineStrips2D([[[x_lo, 0], [x_lo, -y_hi], [x_hi, -y_hi], [x_hi, 0]]],
                                                colors=[(135, 150, 171)], radii=[0.005]), static=True)
        rec.log("outcomes", rr.TextLog("session started"))
        rec.send_blueprint(self.blueprint(), make_active=True, make_default=True)

    def screen(self, xs: np.ndarray) -> np.ndarray:
        """Screen points (N, 2) of states (N, n): across, and height negated (rerun draws y down)."""
        return np.column_stack([xs[:, self.ix], -xs[:, self.iy]])

    def blueprint(self) -> Any:
        """The scene (pad, live tracks, predictions, finished trials) beside the outcomes log and the summary."""
        import rerun.blueprint as rrb

        (x_lo, x_hi), y_hi = self.spec["domain"]["x"], self.spec["domain"]["y"][1]
        bounds = rrb.VisualBounds2D(x_range=[x_lo - 0.2, x_hi + 0.2], y_range=[-y_hi - 0.2, 0.4])
        return rrb.Blueprint(rrb.Horizontal(
            rrb.Spatial2DView(name="landings", origin="/", contents=["scene/**", "live/**", "trials/**"],
                              visual_bounds=bounds),
            rrb.Vertical(rrb.TextLogView(name="outcomes", origin="outcomes"),
                         rrb.TextDocumentView(name="summary", origin="summary"), row_shares=[2, 1]),
            column_shares=[3, 1]), collapse_panels=True)

    def _clock(self) -> None:
        self.rr.set_time("session", duration=time.monotonic() - self.t0, recording=self.rec)

    def live(self, payload: Mapping[str, Any], item: Mapping[str, Any] | None) -> None:
        """A piece of a trial in flight: ``{subject, slot, k0, x}`` (states from step ``k0`` on)."""
        rr = self.rr
        subject, k0, xs = str(payload["subject"]), int(payload["k0"]), np.asarray(payload["x"], dtype=np.float64)
        base = f"live/{subject}"
        with self.lock:
            self._clock()
            if k0 == 0 and len(xs):
                self.rec.log(f"{base}/track", rr.Clear(recursive=False))
                self.rec.log(f"{base}/prediction", rr.Clear(recursive=False))
                label = (item or {}).get("label")
                if label in self.models:
                    pred = self.models[label].predict(xs[0], self.n_steps, self.spec["target"], clip=True)
                    self.rec.log(f"{base}/prediction", rr.LineStrips2D(
                        [self.screen(pred.x)], colors=[PREDICTION_COLOR], radii=[0.015],
                        labels=[f"{label} model, {self.n_steps * self.spec['dt']:g} s"]))
                self.rec.log(f"{base}/label", rr.TextDocument(
                    f"{subject}: {label or 'practice'} trial {(item or {}).get('trial', '')}"))
            for j, x in enumerate(xs):
                rr.set_time("step", sequence=k0 + j, recording=self.rec)
                self.rec.log(f"{base}/vehicle", rr.Points2D(self.screen(x[None, :]), colors=[LIVE_COLOR],
                                                             radii=[0.06]))

    def trial(self, result: Mapping[str, Any], payload: Mapping[str, Any], item: Mapping[str, Any]) -> None:
        """A trial was written: its track, its outcome, the summary."""
        rr = self.rr
        xs = np.asarray(payload["x"], dtype=np.float64)
        outcome, subject = str(result["outcome"]), str(result["subject"])
        key = (subject, str(item["label"]), str(item["role"]))
        with self.lock:
            self._clock()
            self.rec.reset_time()
            self._clock()
            color = OUTCOME_COLORS.get(outcome, OTHER_COLOR)
            self.rec.log(f"trials/{subject}/{result['id']}", rr.LineStrips2D(
                [self.screen(xs)], colors=[color], radii=[0.01], labels=[f"{result['id']}: {outcome}"]))
            self.rec.log("outcomes", rr.TextLog(f"{result['id']}: {outcome} ({len(xs)} steps)",
                                                level="INFO" if outcome == "landed" else "WARN"))
            count = self.counts.setdefault(key, [0, 0])
            count[0] += 1
            count[1] += outcome == "landed"
            rows = "\n".join(f"| {s} | {lbl} | {role} | {n} | {ok} |" for (s, lbl, role), (n, ok) in
                             sorted(self.counts.items()))
            self.rec.log("summary", rr.TextDocument(
                "| subject | label | role | trials | landed |\n|---|---|---|---|---|\n" + rows,
                media_type="text/markdown"))
