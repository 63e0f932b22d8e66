"""Logging a session (demonstrations, fitted models, predictions) into a rerun recording; the entity layout and
the blueprint are described in :mod:`workbench.viewer`."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from workbench.atomic import atomic_path
from workbench.demos import Demonstration, DemonstrationSet
from workbench.errors import DataError, WorkbenchError
from workbench.study import StudyResult
from workbench.viewer.columns import send_columns

__all__ = [
    "APPLICATION_ID",
    "LoggedSession",
    "METHOD_COLORS",
    "SessionLogger",
    "default_blueprint",
    "label_color",
    "log_session",
    "new_recording",
    "open_output",
    "record_session",
]

APPLICATION_ID = "workbench"
HAS_MEASUREMENTS = hasattr(rr, "Measurements")

# tab10, so the report's matplotlib figures and the viewer agree on colors
_PALETTE = np.array(
    [
        [31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
        [140, 86, 75], [227, 119, 194], [127, 127, 127], [188, 189, 34], [23, 190, 207],
    ],
    dtype=np.uint8,
)
METHOD_COLORS = {
    "recorded": (40, 40, 40),
    "proposed": (44, 160, 44),
    "ioc_only": (214, 39, 40),
    "gmr_only": (148, 103, 189),
    "band": (44, 160, 44),
}
METHOD_TITLES = {"proposed": "proposed (K̂x + GMR)", "ioc_only": "IOC-only (K̂x)", "gmr_only": "GMR-only"}
_W_COLOR = (31, 119, 180)
_BAND1_COLOR = (255, 127, 14)
_BAND3_COLOR = (255, 187, 120)
_OUTLIER_COLOR = (214, 39, 40)


def _packed(*colors: Sequence[int]) -> np.ndarray:
    """Colors as packed 0xRRGGBBAA — rerun's fast path; tuples go through a slow per-call conversion."""
    c = np.asarray(colors, dtype=np.uint32).reshape(-1, 3)
    return (c[:, 0] << 24) | (c[:, 1] << 16) | (c[:, 2] << 8) | np.uint32(255)


def label_color(label: str | None, labels: Sequence[str]) -> tuple[int, int, int]:
    """A stable color per strategy label (the order of ``labels``), gray for an unlabeled trial."""
    if label is None or label not in labels:
        return (127, 127, 127)
    return tuple(int(c) for c in _PALETTE[list(labels).index(label) % len(_PALETTE)])


def _safe(name: str) -> str:
    """An entity-path part: rerun splits on '/', and spaces or odd characters make paths hard to type."""
    out = "".join(c if c.isalnum() or c in "-_." else "_" for c in str(name))
    return out or "_"


def new_recording(application_id: str = APPLICATION_ID, *, recording_id: str | None = None) -> rr.RecordingStream:
    """A fresh recording stream (not the global one), so several recordings can live in one process."""
    return rr.RecordingStream(application_id, recording_id=recording_id)


def _time_index(t: np.ndarray, step: np.ndarray | None = None) -> list[rr.TimeColumn]:
    step = np.arange(len(t)) if step is None else step
    return [rr.TimeColumn("time", duration=np.asarray(t, dtype=np.float64)), rr.TimeColumn("step", sequence=step)]


@dataclass
class LoggedSession:
    """What was logged, so a blueprint (and a user) can find it.

    ``focus`` are the trials with variability and predictions, the ones the detail tabs show.
    """

    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    demo_ids: list[str] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    focus: list[str] = field(default_factory=list)
    variability: list[str] = field(default_factory=list)
    predictions: dict[str, list[tuple[int, list[str]]]] = field(default_factory=dict)
    models: list[str] = field(default_factory=list)
    modes: list[str] = field(default_factory=list)
    scene: bool = False
    entities: list[str] = field(default_factory=list)


def _scene_axes(state_names: Sequence[str]) -> tuple[int, int, int | None] | None:
    """Indices of horizontal position, altitude and attitude in the state: the paper's names, else the first two."""
    names = list(state_names)
    if "x" in names and "y" in names:
        return names.index("x"), names.index("y"), names.index("phi") if "phi" in names else None
    if len(names) >= 2:
        return 0, 1, None
    return None


def _model_for(models: Any, demo: Demonstration) -> Any:
    """The model that explains ``demo``: one model for every trial, or a mapping by strategy label."""
    if models is None:
        return None
    if not isinstance(models, Mapping):
        return models
    return models.get(demo.label)


def _readable_modes(meta: Mapping[str, Any]) -> tuple[np.ndarray, list[str]] | None:
    """Flight-mode changes (time since the trial's start) from its metadata.

    ``meta["modes"]`` as ``{"t": [...], "mode": [...]}`` or ``[[t, mode], ...]``, or one ``meta["mode"]``.
    """
    raw = meta.get("modes")
    if raw is None:
        # adapters keep one flight mode per trial (a trial is cut at mode changes)
        mode = meta.get("mode")
        return (np.array([0.0]), [str(mode)]) if mode is not None else None
    try:
        if isinstance(raw, Mapping):
            t, names = list(raw["t"]), [str(s) for s in raw["mode"]]
        else:
            t, names = [r[0] for r in raw], [str(r[1]) for r in raw]
        t_arr = np.asarray(t, dtype=np.float64)
    except (KeyError, TypeError, ValueError, IndexError):
        return None
    if len(t_arr) != len(names) or not len(t_arr) or not np.isfinite(t_arr).all():
        return None
    return t_arr, names


class SessionLogger:
    """Logs trials, models and predictions of one :class:`DemonstrationSet` into a rerun recording.

    Parameters
    ----------
    rec : rerun.RecordingStream
    demos : DemonstrationSet
        Fixes the state and input names, ``dt`` and the label colors.
    """

    def __init__(self, rec: rr.RecordingStream, demos: DemonstrationSet) -> None:
        self.rec = rec
        self.demos = demos
        self.session = LoggedSession(tuple(demos.state_names), tuple(demos.input_names))
        self.session.labels = list(demos.labels)
        self._styled: set[str] = set()
        self._styles: dict[tuple, Any] = {}

    # -- low-level helpers --------------------------------------------------------------------------------
    def _send(self, path: str, index: list[rr.TimeColumn], columns: Any) -> None:
        # every bulk send goes through the guard: a chunk without rows crashes the viewer
        if send_columns(self.rec, path, index, columns):
            self.session.entities.append(path)

    def _static(self, path: str, archetype: Any) -> None:
        self.rec.log(path, archetype, static=True)
        if path not in self.session.entities:
            self.session.entities.append(path)

    def _shared_style(self, key: tuple, make: Any) -> Any:
        """One styling archetype per key, reused for every trial: building one costs more than logging it."""
        style = self._styles.get(key)
        if style is None:
            style = self._styles[key] = make()
        return style

    def _style(self, path: str, archetype: Any) -> None:
        if path not in self._styled:
            self._styled.add(path)
            self.rec.log(path, archetype, static=True)

    # -- scene ---------------------------------------------------------------------------------------------
    def log_scene(self, demos: Iterable[Demonstration] | None = None) -> None:
        """Domain box, landing pad and start points (static), in a z-up 3-D view of the vertical plane."""
        axes = _scene_axes(self.session.state_names)
        if axes is None:
            return
        from workbench.simulate import DOMAIN, PAD_HALF_WIDTH

        ix, iy, _ = axes
        demos = list(self.demos if demos is None else demos)
        self.rec.log("scene", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        paper_states = tuple(self.session.state_names[:3]) == ("x", "y", "phi")
        if paper_states:
            (x_lo, x_hi), (y_lo, y_hi) = DOMAIN
        else:
            xs = np.concatenate([d.x[:, ix] for d in demos])
            ys = np.concatenate([d.x[:, iy] for d in demos])
            pad = 0.05 * max(np.ptp(xs), np.ptp(ys), 1e-9)
            x_lo, x_hi, y_lo, y_hi = xs.min() - pad, xs.max() + pad, ys.min() - pad, ys.max() + pad
        box = [[x_lo, 0, y_lo], [x_hi, 0, y_lo], [x_hi, 0, y_hi], [x_lo, 0, y_hi], [x_lo, 0, y_lo]]
        self._static("scene/domain", rr.LineStrips3D([box], colors=[(160, 160, 160)], radii=0.01, labels=["domain"]))
        targets = [d.target for d in demos if d.target is not None]
        tx, ty = (float(targets[0][ix]), float(targets[0][iy])) if targets else (0.0, 0.0)
        half = PAD_HALF_WIDTH if paper_states else 0.05 * (x_hi - x_lo)
        self._static(
            "scene/pad",
            rr.Boxes3D(
                centers=[[tx, 0.0, ty - 0.02]], half_sizes=[[half, 0.25, 0.02]], colors=[(90, 90, 90)], labels=["pad"]
            ),
        )
        if demos:
            starts = np.array([[d.x[0, ix], 0.0, d.x[0, iy]] for d in demos])
            colors = [label_color(d.label, self.session.labels) for d in demos]
            self._static(
                "scene/starts",
                rr.Points3D(starts, colors=colors, radii=0.04, labels=[d.id for d in demos], show_labels=False),
            )
        self.session.scene = True

    # -- one trial -----------------------------------------------------------------------------------------
    def log_demonstration(self, demo: Demonstration, model: Any = None, *, variability: bool = True) -> None:
        """States, inputs, the flown path and pose, mode lanes; with a model, ŵ and its GMR bands."""
        s = self.session
        base = f"demos/{_safe(demo.id)}"
        color = label_color(demo.label, s.labels)
        packed = _packed(color)
        t = demo.t - demo.t[0]
        index = _time_index(t)  # one pair of time columns serves every entity of the trial
        # series are named by their entity path (demos/<id>/states/<state>); the color tells the strategy
        state_style = self._shared_style(("state", color), lambda: rr.SeriesLines(colors=packed, widths=[1.5]))
        input_style = self._shared_style(
            ("input", color), lambda: rr.SeriesLines(colors=packed, widths=[1.5], interpolation_mode="StepAfter")
        )
        for j, name in enumerate(s.state_names):
            path = f"{base}/states/{_safe(name)}"
            self._style(path, state_style)
            self._send(path, index, rr.Scalars.columns(scalars=demo.x[:, j]))
        for j, name in enumerate(s.input_names):
            path = f"{base}/inputs/{_safe(name)}"
            self._style(path, input_style)
            self._send(path, index, rr.Scalars.columns(scalars=demo.u[:, j]))
        modes = _readable_modes(demo.meta)
        if modes is not None:
            mt, names = modes
            self._send(
                f"{base}/mode",
                [rr.TimeColumn("time", duration=mt)],
                rr.StateChange.columns(state=names),
            )
            s.modes.append(demo.id)
        axes = _scene_axes(s.state_names)
        if axes is not None:
            ix, iy, iphi = axes
            pos = np.column_stack([demo.x[:, ix], np.zeros(len(demo)), demo.x[:, iy]])
            sbase = f"scene/demos/{_safe(demo.id)}"
            self._static(f"{sbase}/path", rr.LineStrips3D([pos], colors=packed, radii=0.008, labels=[demo.id]))
            phi = demo.x[:, iphi] if iphi is not None else np.zeros(len(demo))
            # a positive bank tilts thrust toward +x (ẍ = g φ): a rotation by +φ about the view's y axis
            quat = np.column_stack([np.zeros(len(demo)), np.sin(phi / 2), np.zeros(len(demo)), np.cos(phi / 2)])
            body = self._shared_style(
                ("vehicle", color),
                lambda: rr.LineStrips3D(
                    [[[-0.18, 0, 0], [0.18, 0, 0]], [[0, 0, 0], [0, 0, 0.12]]],
                    colors=_packed(color, (40, 40, 40)),
                    radii=[0.02, 0.01],
                ),
            )
            self._static(f"{sbase}/vehicle", body)
            self._send(f"{sbase}/vehicle", index, rr.Transform3D.columns(translation=pos, quaternion=quat))
        s.demo_ids.append(demo.id)
        if model is not None and variability:
            self.log_variability(demo, model)

    def log_variability(self, demo: Demonstration, model: Any) -> dict[str, np.ndarray]:
        """ŵ = u − K̂x with the model's GMR mean μ(x) and σ bands (eqs. (24)–(27)), and the 3σ outliers.

        Returns the logged arrays (``w``, ``mu``, ``sigma``, ``outside``) for the caller's summary.
        """
        s = self.session
        base = f"demos/{_safe(demo.id)}/variability"
        residuals = getattr(model, "residuals", None)
        w = residuals(demo) if callable(residuals) else demo.u - demo.x @ np.asarray(model.K_).T
        out: dict[str, np.ndarray] = {"w": w}
        has_gmr = callable(getattr(model, "variability", None))
        if has_gmr:
            mu, Sigma = model.variability(demo.x, x0=demo.x[0], target=demo.target)
            sigma = np.sqrt(np.clip(np.diagonal(Sigma, axis1=1, axis2=2), 0.0, None))
            outside = np.abs(w - mu) > 3.0 * sigma
            out.update(mu=mu, sigma=sigma, outside=outside)
        t = demo.t - demo.t[0]
        for j, name in enumerate(s.input_names):
            p = f"{base}/{_safe(name)}"
            self._style(
                f"{p}/w",
                rr.SeriesLines(names=[f"ŵ {name}"], colors=[_W_COLOR], widths=[1.5], interpolation_mode="StepAfter"),
            )
            self._send(f"{p}/w", _time_index(t), rr.Scalars.columns(scalars=w[:, j]))
            if not has_gmr:
                continue
            m_j, s_j = out["mu"][:, j], out["sigma"][:, j]
            for suffix, k, color in (("gmr", 1.0, _BAND1_COLOR), ("gmr_3sigma", 3.0, _BAND3_COLOR)):
                label = f"GMR μ ± {k:g}σ"
                if HAS_MEASUREMENTS:
                    self._style(
                        f"{p}/{suffix}",
                        rr.Measurements.from_fields(names=[label], colors=[color], interpolation_mode="StepAfter"),
                    )
                    self._send(
                        f"{p}/{suffix}",
                        _time_index(t),
                        rr.Measurements.columns(values=m_j, variances=(k * s_j) ** 2),
                    )
                else:  # older SDKs: the band as two lines
                    self._style(
                        f"{p}/{suffix}",
                        rr.SeriesLines(names=[f"μ − {k:g}σ", f"μ + {k:g}σ"], colors=[color, color]),
                    )
                    self._send(
                        f"{p}/{suffix}",
                        _time_index(t),
                        rr.Scalars.columns(scalars=np.column_stack([m_j - k * s_j, m_j + k * s_j])),
                    )
            idx = np.flatnonzero(out["outside"][:, j])
            self._style(
                f"{p}/outside_3sigma",
                rr.SeriesPoints(names=["ŵ outside 3σ"], colors=[_OUTLIER_COLOR], markers=["cross"], marker_sizes=[4.0]),
            )
            self._send(f"{p}/outside_3sigma", _time_index(t[idx], idx), rr.Scalars.columns(scalars=w[idx, j]))
        if demo.id not in s.variability:
            s.variability.append(demo.id)
        return out

    # -- predictions ---------------------------------------------------------------------------------------
    def log_predictions(
        self,
        demo: Demonstration,
        models: Mapping[str, Any],
        *,
        start: int = 0,
        horizon: int = 60,
        samples: int = 0,
        seed: int | None = 0,
    ) -> dict[str, Any]:
        """Predictions of every model in ``models`` (method name → model) from state ``start`` of ``demo``.

        Time series under ``demos/<id>/predictions/from_<start>/<method>/<state>``, predicted paths as line
        strips under ``scene/predictions/<id>/from_<start>/<method>``; the proposed model's Monte Carlo
        percentile band (``samples > 0``) under ``…/band/<state>``. Returns the predictions by method.
        """
        s = self.session
        if not 0 <= start < len(demo):
            raise DataError(f"demonstration {demo.id!r}: start index {start} outside 0…{len(demo) - 1}")
        x0 = demo.x[start]
        t0 = demo.t[start] - demo.t[0]
        base = f"demos/{_safe(demo.id)}/predictions/from_{start}"
        sbase = f"scene/predictions/{_safe(demo.id)}/from_{start}"
        axes = _scene_axes(s.state_names)
        results: dict[str, Any] = {}
        for method, model in models.items():
            mc = samples if method == "proposed" else 0
            # the task's start frame stays at the trial's first state when predicting from later on
            kwargs: dict[str, Any] = {"target": demo.target, "task_x0": demo.x[0]}
            if mc:
                kwargs.update(samples=mc, seed=seed)
            pred = model.predict(x0, horizon, **kwargs)
            results[method] = pred
            x = np.asarray(pred.x)
            steps = start + np.arange(len(x))
            tp = t0 + np.arange(len(x)) * self.demos.dt
            color = METHOD_COLORS.get(method, (0, 0, 0))
            title = METHOD_TITLES.get(method, method)
            for j, name in enumerate(s.state_names):
                path = f"{base}/{_safe(method)}/{_safe(name)}"
                self._style(path, rr.SeriesLines(names=[f"{title} {name}"], colors=[color], widths=[2.0]))
                self._send(path, _time_index(tp, steps), rr.Scalars.columns(scalars=x[:, j]))
            if axes is not None:
                ix, iy, _ = axes
                strip = np.column_stack([x[:, ix], np.zeros(len(x)), x[:, iy]])
                self._static(f"{sbase}/{_safe(method)}", rr.LineStrips3D([strip], colors=[color], radii=0.012,
                                                                        labels=[title]))
            band = _prediction_band(pred)
            if band is not None:
                lo, hi, level = band
                for j, name in enumerate(s.state_names):
                    path = f"{base}/band/{_safe(name)}"
                    self._style(
                        path,
                        rr.SeriesLines(
                            names=[f"MC {level} lower {name}", f"MC {level} upper {name}"],
                            colors=[METHOD_COLORS["band"], METHOD_COLORS["band"]],
                            widths=[1.0, 1.0],
                        ),
                    )
                    self._send(path, _time_index(tp, steps), rr.Scalars.columns(scalars=np.column_stack([lo[:, j],
                                                                                                         hi[:, j]])))
                if axes is not None:
                    ix, iy, _ = axes
                    strips = [np.column_stack([b[:, ix], np.zeros(len(b)), b[:, iy]]) for b in (lo, hi)]
                    self._static(
                        f"{sbase}/band",
                        rr.LineStrips3D(strips, colors=[_BAND3_COLOR, _BAND3_COLOR], radii=0.006,
                                        labels=[f"MC {level} lower", f"MC {level} upper"]),
                    )
        s.predictions.setdefault(demo.id, []).append((start, list(models)))
        if demo.id not in s.focus:
            s.focus.append(demo.id)
        return results

    # -- model ---------------------------------------------------------------------------------------------
    def log_model(self, name: str, model: Any) -> None:
        """K̂, the normalized Q, R, S as tensors (heatmaps) and α with the fit diagnostics as a text document."""
        s = self.session
        base = f"models/{_safe(name)}"
        K = getattr(model, "K_", None)
        if K is not None:
            self._static(f"{base}/K", rr.Tensor(np.asarray(K), dim_names=["input", "state"]))
        objective = getattr(model, "objective_", None)
        if objective is not None:
            n = len(s.state_names)
            Mn = np.asarray(objective.M_normalized)
            self._static(f"{base}/Q", rr.Tensor(Mn[:n, :n], dim_names=["state", "state"]))
            self._static(f"{base}/R", rr.Tensor(Mn[n:, n:], dim_names=["input", "input"]))
            self._static(f"{base}/S", rr.Tensor(Mn[:n, n:], dim_names=["state", "input"]))
        self._static(f"{base}/summary", rr.TextDocument(model_summary(name, model, s.state_names, s.input_names),
                                                        media_type=rr.MediaType.MARKDOWN))
        s.models.append(name)


def _prediction_band(pred: Any) -> tuple[np.ndarray, np.ndarray, str] | None:
    """The Monte Carlo trajectory band of a prediction as (lower, upper, level text), or None without samples."""
    if pred.x_lower is None:
        return None
    return np.asarray(pred.x_lower), np.asarray(pred.x_upper), f"{100 * float(pred.band_level):g} %"


def _fmt_matrix(M: np.ndarray, rows: Sequence[str], cols: Sequence[str]) -> str:
    head = "| | " + " | ".join(cols) + " |\n|---|" + "---|" * len(cols) + "\n"
    body = [f"| **{r}** | " + " | ".join(f"{v:.3g}" for v in row) + " |" for r, row in zip(rows, M, strict=True)]
    return head + "\n".join(body)


def model_summary(name: str, model: Any, state_names: Sequence[str], input_names: Sequence[str]) -> str:
    """A Markdown summary of a fitted model: gain, task objective (α, diagonal of normalized Q and R), GMM fit."""
    lines = [f"# Model {name}", "", f"`{type(model).__name__}`", ""]
    K = getattr(model, "K_", None)
    if K is not None:
        lines += ["## Gain K̂ (u = K̂ x)", "", _fmt_matrix(np.asarray(K), input_names, state_names), ""]
    objective = getattr(model, "objective_", None)
    if objective is not None:
        n = len(state_names)
        Mn = np.asarray(objective.M_normalized)
        lines += [
            "## Task objective (inverse LQR, eqs. (15)–(19))",
            "",
            f"- α* = {float(objective.alpha):.4g} (condition-number bound of M)",
            f"- forward-gain error ‖K_DARE − K̂‖/‖K̂‖ = {float(objective.forward_gain_error):.2e}",
            f"- solver {getattr(objective, 'solver', '?')}, status {getattr(objective, 'status', '?')}, "
            f"structure {getattr(objective, 'structure', '?')}",
            "",
            "diag normalized Q: "
            + ", ".join(f"{s} {v:.3g}" for s, v in zip(state_names, np.diag(Mn[:n, :n]), strict=True)),
            "",
            "diag normalized R: "
            + ", ".join(f"{s} {v:.3g}" for s, v in zip(input_names, np.diag(Mn[n:, n:]), strict=True)),
            "",
        ]
    diag = []
    for attr, title in (("n_components_", "components G"), ("frames", "frames"), ("n_demos_", "training trials"),
                        ("n_samples_", "training samples"), ("labels_", "labels"), ("noise_rho_", "noise lag-1 ρ")):
        value = getattr(model, attr, None)
        if value is not None:
            diag.append(f"- {title}: {np.array2string(value, precision=3) if isinstance(value, np.ndarray) else value}")
    tp = getattr(getattr(model, "variability_", None), "tpgmm_", None)
    if tp is not None:
        for attr, title in (("n_iter_", "EM iterations"), ("converged_", "EM converged"),
                            ("lower_bound_", "mean log-likelihood")):
            value = getattr(tp, attr, None)
            if value is not None:
                diag.append(f"- {title}: {value:.4g}" if isinstance(value, float) else f"- {title}: {value}")
    if diag:
        lines += ["## Fit", "", *diag, ""]
    return "\n".join(lines)


# -- blueprint ---------------------------------------------------------------------------------------------
def default_blueprint(session: LoggedSession, *, max_overlay: int = 60) -> rrb.Blueprint:
    """Tabs scene, states, inputs & variability, predictions, objective — the first view already useful.

    Trials are overlaid on one time axis (time since each trial's start); the detail tabs show the focus trials
    (those with predictions or variability), at most a handful at a time.
    """
    s = session
    ids = s.demo_ids[:max_overlay]
    focus = (s.focus or s.variability or s.demo_ids)[:3]
    tabs: list[Any] = []
    axes = _scene_axes(s.state_names)
    if s.scene:
        eye = rrb.EyeControls3D(position=[0.0, -9.0, 1.75], look_target=[0.0, 0.0, 1.75], eye_up=[0.0, 0.0, 1.0])
        scene_view = rrb.Spatial3DView(origin="scene", name="landing scene", eye_controls=eye)
        side: list[Any] = []
        if axes is not None and focus:
            for j in axes[:2]:
                name = s.state_names[j]
                side.append(_series_view(name, _state_and_prediction_paths(s, focus, name)))
        tabs.append(rrb.Horizontal(scene_view, rrb.Vertical(*side), column_shares=[3, 2], name="scene")
                    if side else rrb.Horizontal(scene_view, name="scene"))
    state_views = [
        _series_view(name, [f"+ /demos/{_safe(i)}/states/{_safe(name)}" for i in ids]) for name in s.state_names
    ]
    if s.modes:
        state_views.append(
            rrb.StateTimelineView(origin="/demos", contents=[f"+ /demos/{_safe(i)}/mode" for i in s.modes],
                                  name="flight mode")
        )
    tabs.append(rrb.Grid(*state_views, name="states"))
    input_views = []
    for name in s.input_names:
        input_views.append(_series_view(f"input {name}", [f"+ /demos/{_safe(i)}/inputs/{_safe(name)}" for i in ids]))
    for i in [f for f in focus if f in s.variability]:
        for name in s.input_names:
            input_views.append(
                _series_view(f"ŵ {name} — {i}", [f"+ /demos/{_safe(i)}/variability/{_safe(name)}/**"])
            )
    tabs.append(rrb.Grid(*input_views, name="inputs & variability"))
    if s.predictions:
        pred_views = []
        for i in [f for f in focus if f in s.predictions]:
            for name in s.state_names:
                pred_views.append(_series_view(f"{name} — {i}", _state_and_prediction_paths(s, [i], name)))
        tabs.append(rrb.Grid(*pred_views, name="predictions"))
    if s.models:
        model_rows = []
        for m in s.models:
            base = f"models/{_safe(m)}"
            model_rows.append(
                rrb.Horizontal(
                    rrb.TensorView(origin=f"{base}/K", name=f"{m}: K̂"),
                    rrb.TensorView(origin=f"{base}/Q", name=f"{m}: Q / λmax(M)"),
                    rrb.TensorView(origin=f"{base}/R", name=f"{m}: R / λmax(M)"),
                    rrb.TensorView(origin=f"{base}/S", name=f"{m}: S / λmax(M)"),
                    rrb.TextDocumentView(origin=f"{base}/summary", name=f"{m}: summary"),
                    column_shares=[2, 2, 1, 1, 3],
                )
            )
        tabs.append(rrb.Vertical(*model_rows, name="objective"))
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), rrb.TimePanel(timeline="time"), collapse_panels=False)


def _series_view(name: str, contents: list[str]) -> rrb.TimeSeriesView:
    return rrb.TimeSeriesView(origin="/", contents=contents, name=name)


def _state_and_prediction_paths(s: LoggedSession, ids: Sequence[str], name: str) -> list[str]:
    out = []
    for i in ids:
        out.append(f"+ /demos/{_safe(i)}/states/{_safe(name)}")
        for start, methods in s.predictions.get(i, []):
            for method in [*methods, "band"]:
                out.append(f"+ /demos/{_safe(i)}/predictions/from_{start}/{_safe(method)}/{_safe(name)}")
    return out


# -- one call for a whole session ----------------------------------------------------------------------------
def log_session(
    rec: rr.RecordingStream,
    demos: DemonstrationSet,
    *,
    models: Any = None,
    named_models: Mapping[str, Any] | None = None,
    baselines: Mapping[str, Mapping[str, Any]] | None = None,
    focus: Sequence[str] | None = None,
    horizon: int = 60,
    samples: int = 0,
    starts: Sequence[int] = (0,),
    seed: int | None = 0,
) -> LoggedSession:
    """Log a whole session and return what was logged (for :func:`default_blueprint`).

    Parameters
    ----------
    models : model or mapping label → model, optional
        The proposed model(s); a mapping picks each trial's model by its strategy label.
    named_models : mapping name → model, optional
        Models to show in the objective tab (default: ``models``).
    baselines : mapping label → {method: model}, optional
        Extra methods to predict with (``ioc_only``, ``gmr_only``), per label (or under key ``None`` for all).
    focus : ids, optional
        Trials to predict from (at ``starts``); default the first trial of each label.
    """
    logger = SessionLogger(rec, demos)
    logger.log_scene()
    for d in demos:
        logger.log_demonstration(d, _model_for(models, d))
    if named_models is None and models is not None:
        named_models = models if isinstance(models, Mapping) else {"model": models}
    for name, m in (named_models or {}).items():
        logger.log_model(str(name), m)
    if models is not None:
        if focus is None:
            seen: dict[str | None, str] = {}
            for d in demos:
                seen.setdefault(d.label, d.id)
            focus = list(seen.values())
        by_id = {d.id: d for d in demos}
        for fid in focus:
            if fid not in by_id:
                raise DataError(f"no demonstration {fid!r} to predict from; ids present: {demos.ids[:10]}…")
            d = by_id[fid]
            proposed = _model_for(models, d)
            if proposed is None:
                continue
            methods = {"proposed": proposed}
            extra = (baselines or {}).get(d.label) or (baselines or {}).get(None) or {}
            methods.update(extra)
            for k in starts:
                if k < len(d):
                    logger.log_predictions(d, methods, start=int(k), horizon=horizon, samples=samples, seed=seed)
    return logger.session


# -- outputs ---------------------------------------------------------------------------------------------
def has_display() -> bool:
    """Whether a native viewer could open a window here."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def record_session(path: str | os.PathLike, demos: DemonstrationSet, **kwargs: Any) -> tuple[Path, LoggedSession]:
    """Log a session (see :func:`log_session`) into an ``.rrd`` file, atomically, with its default blueprint."""
    path = Path(path)
    rec = new_recording()
    with atomic_path(path) as tmp:
        rec.save(tmp)
        session = log_session(rec, demos, **kwargs)
        rec.send_blueprint(default_blueprint(session))
        rec.flush()
        rec.disconnect()
    return path, session


class open_output:
    """Attach the chosen output to a recording: ``save`` (an .rrd, atomically), ``spawn`` or ``serve``.

    Use as a context manager around the logging; on exit the blueprint (if any) is sent, the stream flushed,
    and a saved file moved into place. ``serve`` hosts a web viewer and gRPC proxy on 127.0.0.1 only (the rerun
    SDK's own server binds every interface) and keeps serving until interrupted.
    """

    def __init__(
        self,
        rec: rr.RecordingStream,
        *,
        save: str | os.PathLike | None = None,
        spawn: bool = False,
        serve: bool = False,
        web_port: int = 9090,
        grpc_port: int = 9876,
    ) -> None:
        if sum((save is not None, spawn, serve)) != 1:
            raise WorkbenchError("choose exactly one output: --save FILE.rrd, --spawn or --serve")
        self.rec = rec
        self.save = None if save is None else Path(save)
        self.spawn = spawn
        self.serve = serve
        self.web_port = web_port
        self.grpc_port = grpc_port
        self.blueprint: rrb.Blueprint | None = None
        self._atomic: atomic_path | None = None
        self._server: subprocess.Popen | None = None

    def __enter__(self) -> open_output:
        if self.save is not None:
            self._atomic = atomic_path(self.save)
            self.rec.save(self._atomic.__enter__())
        elif self.spawn:
            self.rec.spawn(connect=True)
        else:
            self._server = _start_local_server(self.grpc_port, self.web_port)
            self.rec.connect_grpc(f"rerun+http://127.0.0.1:{self.grpc_port}/proxy")
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None and self.blueprint is not None:
                self.rec.send_blueprint(self.blueprint)
            self.rec.flush()
            if self.save is not None:
                self.rec.disconnect()
        finally:
            if self._atomic is not None:
                self._atomic.__exit__(exc_type, exc, tb)

    @property
    def url(self) -> str:
        """For ``serve``: the web viewer's address, connected to the local gRPC proxy."""
        from urllib.parse import quote

        proxy = quote(f"rerun+http://127.0.0.1:{self.grpc_port}/proxy", safe="")
        return f"http://127.0.0.1:{self.web_port}?url={proxy}"

    def wait(self) -> None:
        """For ``serve``: keep the local server up until Ctrl-C (or SIGTERM), then stop it."""
        if self._server is None:
            return
        _wait_then_stop(self._server)


def _wait_then_stop(proc: subprocess.Popen) -> None:
    import signal

    def _interrupt(signum, frame):  # a SIGTERM must stop the server too, not orphan it
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        proc.wait()
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()


def _rerun_executable() -> list[str]:
    exe = Path(sys.executable).with_name("rerun")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("rerun")
    return [found] if found else [sys.executable, "-m", "rerun"]


def _start_local_server(grpc_port: int, web_port: int) -> subprocess.Popen:
    """A rerun gRPC proxy with a web viewer, bound to 127.0.0.1 (never every interface)."""
    cmd = [*_rerun_executable(), "--serve-web", "--bind", "127.0.0.1", "--port", str(grpc_port),
           "--web-viewer-port", str(web_port)]
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL)


def record_study(
    result: StudyResult, path: str | os.PathLike, *, progress: Callable[[], Any] | None = None
) -> Path:
    """One ``.rrd`` with every trial, both models' variability on the test trials and the three predictions."""
    focus = [te[0].id for te in result.test.values() if len(te)]
    bar = progress() if progress is not None else nullcontext()
    with bar as p:
        if p is not None:
            p.add_task(f"writing {path}", total=None)
        out, _ = record_session(
            path, result.demos, models=result.models, baselines=result.baselines, focus=focus,
            horizon=result.horizon, samples=result.samples, seed=result.seed,
        )
    return out
