"""The experimenter's view: the session as it happens, in rerun (``workbench collect --spawn|--serve|--save``).

While a subject flies, the page sends the server its states every few physics steps (``POST /api/live``, only
when this view is on; nothing of it is stored: the trial is written when it ends); they are drawn in the scene
``live/<subject>`` with, where a model of the block's label is known (``--model CS1=cs1.npz``, or the subject's own
from a fit step), that model's mean prediction from the trial's start state beside the live track. Each finished
trial adds its track to ``trials/<subject>/<id>`` in its outcome's colour (one per outcome,
:data:`workbench.palette.OUTCOME_COLORS`, apart for colour-blind readers, with a legend drawn in the scene) and a
line to the ``outcomes`` log; only the newest trial's track is labelled, so labels never pile up. The ``summary``
document holds the whole outcome table (per subject, label and role: every outcome's count), each fit step's model
with its held-out error, the exclusions, and where the session and this recording are written.

Time lines: ``session`` (seconds since the server started) for everything, ``step`` (the trial's physics step) for
the live track.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from workbench.collect.task import OUTCOMES
from workbench.defaults import HORIZON_S
from workbench.palette import METHOD_COLORS, OUTCOME_COLORS, RECORDED_SCREEN

__all__ = ["ExperimenterView", "OUTCOME_COLORS"]

LIVE_COLOR = RECORDED_SCREEN  # the trial in flight: what is recorded
PREDICTION_COLOR = METHOD_COLORS[0]  # a model's prediction: the proposed model's colour


class ExperimenterView:
    """Log a collecting session to the rerun recording ``rec``; ``models`` maps a block label to a fitted model.

    Calls come from the server's worker threads; a lock keeps each update whole. ``out`` is the session folder
    and ``saved`` the recording's file (named in the summary).
    """

    def __init__(self, rec: Any, spec: Mapping[str, Any], models: Mapping[str, Any] | None = None,
                 horizon_s: float = HORIZON_S, out: str | None = None, saved: str | None = None) -> None:
        import rerun as rr

        self.rr = rr
        self.rec = rec
        self.spec = spec
        self.models = dict(models or {})
        self.fitted: dict[tuple[str, str], Any] = {}
        self.fit_lines: dict[tuple[str, str], str] = {}
        self.exclusions: dict[str, str] = {}
        self.out, self.saved = out, saved
        self.n_steps = max(1, int(round(horizon_s / spec["dt"])))
        self.t0 = time.monotonic()
        self.lock = threading.Lock()
        self.counts: dict[tuple[str, str, str], dict[str, int]] = {}
        i = spec["index"]
        self.ix, self.iy = i["x"], i["y"]
        (x_lo, x_hi), y_hi = spec["domain"]["x"], spec["domain"]["y"][1]
        pad = spec["pad"]
        # rerun's 2-D views point y down: heights are negated so that up is drawn up (as the viewer's scenes do)
        ground = [[[x_lo, 0.0], [x_hi, 0.0]], [[pad["x"] - pad["half_width"], 0.0],
                                                [pad["x"] + pad["half_width"], 0.0]]]
        rec.log("scene/ground", rr.LineStrips2D(ground, colors=[(107, 125, 90), (170, 190, 140)],
                                                radii=[0.02, 0.05]), static=True)
        rec.log("scene/pad", rr.Points2D([[pad["x"], 0.25]], radii=[0.0], labels=["pad"], colors=[(60, 60, 60)]),
                static=True)
        rec.log("scene/domain", rr.LineStrips2D([[[x_lo, 0], [x_lo, -y_hi], [x_hi, -y_hi], [x_hi, 0]]],
                                                colors=[(135, 150, 171)], radii=[0.005]), static=True)
        # the legend: one marker per outcome in a row above the domain, each labelled (they never overlap)
        step = (x_hi - x_lo) / len(OUTCOMES)
        rec.log("scene/legend", rr.Points2D([[x_lo + 0.15 + k * step, -y_hi - 0.35] for k in range(len(OUTCOMES))],
                                            colors=[OUTCOME_COLORS[o] for o in OUTCOMES], radii=[0.07] * len(OUTCOMES),
                                            labels=list(OUTCOMES), show_labels=True), static=True)
        rec.log("outcomes", rr.TextLog("session started"))
        self._summary()
        rec.send_blueprint(self.blueprint(), make_active=True, make_default=True)

    def screen(self, xs: np.ndarray) -> np.ndarray:
        """Screen points (N, 2) of states (N, n): across, and height negated (rerun draws y down)."""
        return np.column_stack([xs[:, self.ix], -xs[:, self.iy]])

    def blueprint(self) -> Any:
        """The scene (legend, pad, live tracks, predictions, finished trials) beside the summary (the whole
        outcome table, the fits, where things are written) over the outcomes log."""
        import rerun.blueprint as rrb

        (x_lo, x_hi), y_hi = self.spec["domain"]["x"], self.spec["domain"]["y"][1]
        bounds = rrb.VisualBounds2D(x_range=[x_lo - 0.2, x_hi + 0.2], y_range=[-y_hi - 0.6, 0.45])
        return rrb.Blueprint(rrb.Horizontal(
            rrb.Spatial2DView(name="landings", origin="/", contents=["scene/**", "live/**", "trials/**"],
                              visual_bounds=bounds),
            rrb.Vertical(rrb.TextDocumentView(name="summary", origin="summary"),
                         rrb.TextLogView(name="outcomes", origin="outcomes"), row_shares=[3, 2]),
            column_shares=[3, 2]), collapse_panels=True)

    def _clock(self) -> None:
        self.rr.set_time("session", duration=time.monotonic() - self.t0, recording=self.rec)

    def _model(self, subject: str, label: str | None) -> Any:
        return self.fitted.get((subject, label or "")) or self.models.get(label or "")

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
                model = self._model(subject, label)
                if model is not None:
                    pred = model.predict(xs[0], self.n_steps, self.spec["target"], clip=True)
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
        """A trial was written: its track in its outcome's colour (labelled while it is the newest), its outcome
        with the reason, the summary."""
        rr = self.rr
        xs = np.asarray(payload["x"], dtype=np.float64)
        outcome, subject = str(result["outcome"]), str(result["subject"])
        key = (subject, str(item["label"]), str(item["role"]))
        with self.lock:
            self.rec.reset_time()
            self._clock()
            color = OUTCOME_COLORS.get(outcome, LIVE_COLOR)
            self.rec.log(f"trials/{subject}/{result['id']}", rr.LineStrips2D([self.screen(xs)], colors=[color],
                                                                             radii=[0.01]))
            end = self.screen(xs[-1:])
            self.rec.log("trials/newest", rr.Points2D(end, colors=[color], radii=[0.05],
                                                      labels=[f"{result['id']}: {outcome}"], show_labels=True))
            why = result.get("outcome_reason") or outcome
            self.rec.log("outcomes", rr.TextLog(f"{result['id']}: {why} ({len(xs)} steps)",
                                                level="INFO" if outcome == "landed" else "WARN"))
            count = self.counts.setdefault(key, {o: 0 for o in OUTCOMES})
            count[outcome] = count.get(outcome, 0) + 1
            self._summary()

    def event(self, kind: str, text: str) -> None:
        """A warning (an unknown or repeated subject ID), a declined consent, a fit's result or an exclusion, in the
        log; exclusions also in the summary."""
        with self.lock:
            self._clock()
            self.rec.log("outcomes", self.rr.TextLog(f"{kind}: {text}", level="WARN" if kind == "warning" else "INFO"))
            if kind == "exclusion":
                trial, _, rest = text.partition(" ")
                if rest.startswith("excluded"):
                    self.exclusions[trial] = rest
                else:
                    self.exclusions.pop(trial, None)
                self._summary()

    def fit(self, record: Mapping[str, Any]) -> None:
        """A fit step's result: the model then predicts that subject's label live, and the summary shows it with
        its held-out error (or why it failed)."""
        subject, label = str(record.get("subject")), str(record.get("label"))
        if record.get("state") == "ready" and self.out is not None:
            from workbench.models import load_model

            self.fitted[(subject, label)] = load_model(Path(self.out) / "_collect" / "models" / subject /
                                                       f"{label}.npz")
            err = record.get("held_out_error")
            line = (f"| {subject} | {label} | {record['n_train']} | "
                    + (f"{err:.3g} m over {len(record['held_out'])}" if err is not None else "no held-out trials")
                    + f" | `{str(record['digest'])[:12]}` |")
        else:
            line = f"| {subject} | {label} | — | not fitted: {record.get('reason', '?')} | — |"
        with self.lock:
            self.fit_lines[(subject, label)] = line
            self._summary()

    def _summary(self) -> None:
        head = "| subject | label | role | trials | " + " | ".join(OUTCOMES) + " |"
        rows = [f"| {s} | {lbl} | {role} | {sum(c.values())} | " + " | ".join(str(c.get(o, 0)) for o in OUTCOMES)
                + " |" for (s, lbl, role), c in sorted(self.counts.items())]
        text = ["## Outcomes", "", head, "|" + "---|" * (4 + len(OUTCOMES)), *rows]
        if not rows:
            text.append("| (no trial yet) |" + " |" * (3 + len(OUTCOMES)))
        if self.fit_lines:
            text += ["", "## Fits (each subject's model, from their landed training trials)", "",
                     "| subject | label | trials | held-out position RMSE | model digest |", "|---|---|---|---|---|",
                     *(self.fit_lines[k] for k in sorted(self.fit_lines))]
        if self.exclusions:
            text += ["", "## Excluded from the analysis", "",
                     *(f"- `{trial}` {why}" for trial, why in sorted(self.exclusions.items()))]
        text += ["", "## Where", ""]
        if self.out is not None:
            text.append(f"- trials: `{self.out}` (one line each: `{Path(self.out) / '_collect' / 'trials.csv'}`)")
        text.append(f"- this recording: `{self.saved}` (written when the server stops)" if self.saved
                    else "- this recording: streamed, not saved (use --save FILE.rrd to keep it)")
        self.rec.log("summary", self.rr.TextDocument("\n".join(text), media_type="text/markdown"))
