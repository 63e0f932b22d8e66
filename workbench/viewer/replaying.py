"""Replay a recorded session as if live, with the model's online predictions at every step.

This is the paper's online use of the variability model: at each sample ``k`` of a trial the stream carries
the recorded state and input and, computed from the state alone,

* the one-step input prediction ``û[k] = K̂ x[k] + μ(x[k])`` with its GMR covariance ``Σ(x[k])``
  (eqs. (24)–(27) of the method paper; ``demos/<id>/online/<input>/gmr``, two series: the ±1σ and ±3σ bands),
  and a marker where the operator's actual input leaves the 3σ band (``…/outside_3sigma``);
* a short-horizon rollout from ``x[k]`` (the paper's section "Trajectory Prediction"; ``scene/replay/<id>/rollout``,
  a line strip that moves with the vehicle, and its end point ``demos/<id>/online/rollout_end/<state>``, stamped
  with the time it forecasts so the plot reads as recorded vs. forecast).

The scene is the plane of flight from the vehicle roles (as in :mod:`workbench.viewer.scene`); a plant without
position roles gets plots only.

Samples are logged one by one with ``rr.log`` — a live stream has no columns to send — paced to wall time at
``speed`` × real time, or as fast as possible with ``wait=False``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from workbench.data.demonstrations import Demonstration
from workbench.defaults import ONLINE_N_STEPS
from workbench.errors import DataError
from workbench.viewer import style
from workbench.viewer.entities import entity_part, series_path
from workbench.viewer.scene import Plane, plane_of, scale_bar
from workbench.viewer.session import HAS_MEASUREMENTS, UI
from workbench.viewer.views import online_plots, time_panel

__all__ = ["ReplayStats", "replay", "replay_blueprint"]

_COLOR_REC = style.RECORDED_COLOR
_COLOR_PRED = style.method_color("proposed")
_COLOR_BAND = style.BAND_COLOR  # one band tint in view, replay and live (see workbench.viewer.style)
_COLOR_OUT = style.OUTLIER_COLOR


@dataclass(frozen=True)
class ReplayStats:
    """How a replay went: samples streamed, simulated and wall time, and the online-prediction quality."""

    demo_id: str
    n_steps: int
    sim_time: float
    wall_time: float
    one_step_rmse: np.ndarray
    coverage_3sigma: np.ndarray

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second (≥ 1 keeps up with a live stream)."""
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("inf")


def replay(
    demo: Demonstration,
    model: Any,
    rec: rr.RecordingStream,
    *,
    state_names: tuple[str, ...] | None = None,
    input_names: tuple[str, ...] | None = None,
    speed: float = 1.0,
    wait: bool = True,
    n_steps: int = ONLINE_N_STEPS,
    rollout_every: int = 1,
    clock: Callable[[], float] = time.perf_counter,
    sleep: Callable[[float], None] = time.sleep,
    on_step: Callable[[int], None] | None = None,
    roles: Any = None,
) -> ReplayStats:
    """Stream ``demo`` into ``rec`` sample by sample with the model's online predictions.

    Parameters
    ----------
    demo : Demonstration
    model : fitted HumanBehaviorModel
        Needs ``K_``, ``variability(X, x0, target)`` and ``predict(x0, n_steps, target)``.
    speed : float
        Multiple of real time (``2.0`` plays twice as fast).
    wait : bool
        ``False`` streams as fast as possible (tests, benchmarks).
    n_steps : int
        Steps of the rollout from each state; ``0`` turns rollouts off.
    rollout_every : int
        Roll out at every k-th sample only (the one-step prediction runs at every sample).
    roles : workbench.data.roles.Roles, optional
        The vehicle roles that place the scene (default the model's plant's); none, no scene.
    """
    if not speed > 0:
        raise DataError(f"replay speed must be positive, got {speed!r}")
    if rollout_every < 1:
        raise DataError(f"rollout_every must be at least 1, got {rollout_every!r}")
    n, m = demo.x.shape[1], demo.u.shape[1]
    state_names = tuple(state_names or (f"x{i}" for i in range(n)))
    input_names = tuple(input_names or (f"u{i}" for i in range(m)))
    sbase = f"scene/replay/{entity_part(demo.id)}"
    # every path once, before the loop (rerun's log call per step is the cost; a path built per step adds to it)
    states = [series_path(demo.id, "states", n) for n in state_names]
    inputs = [series_path(demo.id, "inputs", n) for n in input_names]
    online = [series_path(demo.id, "online", n) for n in input_names]
    rollout_end = [series_path(demo.id, "online", "rollout_end", n) for n in state_names]
    x_start, target = demo.x[0], demo.target
    if roles is None:
        roles = getattr(getattr(model, "plant", None), "roles", None)
    plane = plane_of(roles, state_names)
    _log_styles(rec, demo, (states, inputs, online, rollout_end), sbase, state_names, plane, roles)

    t_rel = demo.t - demo.t[0]
    dt = float(np.median(np.diff(demo.t))) if len(demo) > 1 else 0.0
    err = np.zeros((len(demo), m))
    inside = np.zeros((len(demo), m), dtype=bool)
    wall0 = clock()
    for k in range(len(demo)):
        if wait:
            delay = wall0 + t_rel[k] / speed - clock()
            if delay > 0:
                sleep(delay)
        x, u = demo.x[k], demo.u[k]
        rec.set_time("time", duration=float(t_rel[k]))
        rec.set_time("step", sequence=k)
        for j, path in enumerate(states):
            rec.log(path, rr.Scalars(x[j]))
        for j, path in enumerate(inputs):
            rec.log(path, rr.Scalars(u[j]))
        # the model's one-step input Gaussian: K̂(x − r) + μ̂(x) and Σ̂(x), r the goal where the model is goal-relative
        # (a model with the pilot's timing: the stick from the one before toward the command for the state it saw)
        past = model.pasts(demo, [k]) if hasattr(model, "pasts") else None
        u_mean, Sigma = model.input_distribution(x[None, :], x0=x_start, target=target, steps=[k], pasts=past)
        u_hat = u_mean[0]
        sigma = np.sqrt(np.clip(np.diagonal(Sigma[0]), 0.0, None))
        err[k] = u - u_hat
        inside[k] = np.abs(u - u_hat) <= 3.0 * sigma
        for j, p in enumerate(online):
            # one entity, two series (±1σ and ±3σ bands): half the log calls of two entities per step
            rec.log(f"{p}/mean", rr.Scalars(u_hat[j]))
            if HAS_MEASUREMENTS:
                rec.log(f"{p}/gmr", rr.Measurements(values=[u_hat[j], u_hat[j]],
                                                    variances=[sigma[j] ** 2, (3 * sigma[j]) ** 2]))
            else:
                rec.log(f"{p}/gmr", rr.Scalars([u_hat[j] - 3 * sigma[j], u_hat[j] - sigma[j], u_hat[j] + sigma[j],
                                                u_hat[j] + 3 * sigma[j]]))
            if not inside[k, j]:
                rec.log(f"{p}/outside_3sigma", rr.Scalars(u[j]))
        if plane is not None:
            (px, py), phi = plane.view(x)[0], float(plane.angle(x)[0])
            rec.log(f"{sbase}/vehicle",
                    rr.Transform3D(translation=[px, py, 0.0], quaternion=[0.0, 0.0, np.sin(phi / 2), np.cos(phi / 2)]))
        if n_steps > 0 and k % rollout_every == 0:
            pred = model.predict(x, n_steps, target=target, task_x0=x_start, task_step=int(k),
                                 past=None if past is None else past[0])
            xp = np.asarray(pred.x)
            # stamped with the time it forecasts, so the plot compares x(t) with its forecast from t − H·dt
            rec.set_time("time", duration=float(t_rel[k] + n_steps * dt))
            rec.set_time("step", sequence=k + n_steps)
            for j, path in enumerate(rollout_end):
                rec.log(path, rr.Scalars(xp[-1, j]))
            rec.set_time("time", duration=float(t_rel[k]))
            rec.set_time("step", sequence=k)
            if plane is not None:
                # color and radius are logged once, static: per call they would cost ten times the strip itself
                rec.log(f"{sbase}/rollout", rr.LineStrips2D(plane.view(xp)[np.newaxis]))
        if on_step is not None:
            on_step(k)
    wall = clock() - wall0
    rec.reset_time()
    return ReplayStats(
        demo_id=demo.id,
        n_steps=len(demo),
        sim_time=float(t_rel[-1] + dt),
        wall_time=float(wall),
        one_step_rmse=np.sqrt(np.mean(err**2, axis=0)),
        coverage_3sigma=inside.mean(axis=0),
    )



def _log_styles(rec, demo, series: tuple[list[str], ...], sbase, state_names, plane: Plane | None,
                roles: Any = None) -> None:
    states, inputs, online, rollout_end = series
    for state, end in zip(states, rollout_end, strict=True):
        rec.log(state, rr.SeriesLines(names=["recorded"], colors=[_COLOR_REC]), static=True)
        rec.log(end, rr.SeriesLines(names=["forecast (rollout end)"], colors=[_COLOR_PRED], widths=[1.5]), static=True)
    for inp, p in zip(inputs, online, strict=True):
        rec.log(inp, rr.SeriesLines(names=["recorded"], colors=[_COLOR_REC], interpolation_mode="StepAfter"),
                static=True)
        label = "K̂x + μ(x)"
        rec.log(f"{p}/mean", rr.SeriesLines(names=[label], colors=[_COLOR_PRED], widths=[1.5],
                                            interpolation_mode="StepAfter"), static=True)
        if HAS_MEASUREMENTS:  # fills only, in the neutral band tint: the mean is the proposed model's line above
            rec.log(f"{p}/gmr", rr.Measurements.from_fields(names=[f"{label} ± 1σ", f"{label} ± 3σ"],
                                                            colors=[_COLOR_BAND, _COLOR_BAND], widths=[0.0, 0.0],
                                                            interpolation_mode="StepAfter"), static=True)
        else:
            rec.log(f"{p}/gmr", rr.SeriesLines(names=[f"{label} − 3σ", f"{label} − 1σ", f"{label} + 1σ",
                                                      f"{label} + 3σ"],
                                               colors=[_COLOR_BAND, _COLOR_PRED, _COLOR_PRED, _COLOR_BAND]),
                    static=True)
        rec.log(f"{p}/outside_3sigma", rr.SeriesPoints(names=["outside 3σ"], colors=[_COLOR_OUT],
                                                       markers=["cross"], marker_sizes=[6.0]), static=True)
    if plane is not None:
        path = plane.view(demo.x)
        (x_lo, x_hi), (y_lo, y_hi) = plane.bounds([path])
        size = 0.045 * max(x_hi - x_lo, y_hi - y_lo)  # as the session's vehicle: it reads at a glance
        rec.log(f"{sbase}/rollout", rr.LineStrips2D.from_fields(colors=[_COLOR_PRED], radii=[UI(2.0)],
                                                                draw_order=[6.0]), static=True)
        rec.log(f"{sbase}/path", rr.LineStrips2D([path], colors=[(150, 150, 150)], radii=UI(1.0), draw_order=3.0),
                static=True)
        if demo.target is not None:  # a pad only where the data declare a landing target
            from workbench.sim.landing import PAD_HALF_WIDTH

            tx, ty = plane.view(np.asarray(demo.target))[0]
            rec.log("scene/pad", rr.LineStrips2D([[[tx - PAD_HALF_WIDTH, ty], [tx + PAD_HALF_WIDTH, ty]]],
                                                 colors=[(200, 200, 200)], radii=UI(4.0), draw_order=2.0), static=True)
        # a scale bar, as in the session's scene: a track of a few centimetres must not read as one of metres
        ends, text = scale_bar(((x_lo, x_hi), (y_lo, y_hi)), roles.unit(state_names[plane.across]) if roles else "")
        rec.log("scene/scale", rr.LineStrips2D([ends], colors=[(230, 230, 230)], radii=UI(2.0), labels=[text],
                                               draw_order=style.SCENE_ORDER["scale"]), static=True)
        rec.log(f"{sbase}/vehicle", rr.LineStrips2D([[[-size, 0], [size, 0]], [[0, 0], [0, -0.6 * size]]],
                                                    colors=[_COLOR_REC, _COLOR_REC], radii=[UI(3.0), UI(1.5)],
                                                    draw_order=10.0), static=True)


def replay_blueprint(
    demo_ids: list[str],
    state_names: tuple[str, ...],
    input_names: tuple[str, ...],
    *,
    roles: Any = None,
    demos: list[Demonstration] | None = None,
) -> rrb.Blueprint:
    """The replay's layout: the plane of flight (fitted to ``demos``' tracks) beside the inputs with the online
    GMR prediction, then the states with the forecast. Without position ``roles`` the plots only."""
    def unit(name: str) -> str:
        return style.with_unit(name, roles.unit(name) if roles else "")

    def y_range(values: list[np.ndarray], name: str) -> tuple[float, float] | None:
        """The plot's y-range: the recorded values, at least their unit's minimum span (quantization noise must
        not fill a plot); the viewer's own autoscale without ``demos``."""
        if not values:
            return None
        return style.data_range(*values, margin=0.05, min_span=style.min_span(roles.unit(name) if roles else ""))

    shown = list(demos or [])
    ids = [entity_part(i) for i in demo_ids]
    inputs = online_plots(
        ids, input_names, "inputs",
        # short: a title longer than its plot is cut ("outside 3σ m…", seen with rrd-look)
        [f"{unit(n)} · recorded {style.color_name(_COLOR_REC)} · K̂x+μ {style.color_name(_COLOR_PRED)} "
         f"· {style.color_name(_COLOR_OUT)} × outside 3σ" for n in input_names],
        [y_range([d.u[:, j] for d in shown], n) for j, n in enumerate(input_names)],
    )
    states = online_plots(
        ids, state_names, "states",
        [f"{unit(n)}: recorded {style.color_name(_COLOR_REC)}, rollout end {style.color_name(_COLOR_PRED)}"
         for n in state_names],
        [y_range([d.x[:, j] for d in shown], n) for j, n in enumerate(state_names)],
    )
    plane = plane_of(roles, state_names)
    if plane is not None:
        bounds = None
        if demos:
            targets = [plane.view(np.asarray(d.target)) for d in demos if d.target is not None]
            x_range, y_range = plane.bounds([*(plane.view(d.x) for d in demos), *targets])
            bounds = rrb.VisualBounds2D(x_range=x_range, y_range=y_range)
        title = (f"plane of flight: {unit(state_names[plane.across])} → / {unit(state_names[plane.up])} ↑ — "
                 f"online rollout {style.color_name(_COLOR_PRED)}")
        live = rrb.Horizontal(rrb.Spatial2DView(origin="/scene", name=title, visual_bounds=bounds),
                              rrb.Vertical(*inputs), column_shares=[3, 2], name="replay")
    else:
        live = rrb.Vertical(*inputs, name="replay")
    return rrb.Blueprint(rrb.Tabs(live, rrb.Grid(*states, name="states")), time_panel(), collapse_panels=True)
