"""``workbench fit`` and ``predict``: one model from demonstrations, and its predictions.
"""

from __future__ import annotations

import math
import time
from typing import Any

from workbench.atomic import atomic_write_table
from workbench.cli.context import Context
from workbench.cli.inputs import resolve
from workbench.cli.options import rollout_budget, steps_of
from workbench.cli.reading import chosen_plant, demos_at_model_dt, per_group_path, plant_group_parts
from workbench.cli.stdio import STDIN_NAME, is_stdio
from workbench.cli.writing import print_plant
from workbench.defaults import DEFAULT_N_COMPONENTS
from workbench.errors import DataError, ModelError, UsageError

__all__ = []

def cmd_fit(ctx: Context) -> int:
    a = ctx.args
    output = ctx.output_path(a.output, ".npz", "the model")  # before the work: `-o -` to a terminal is refused
    ds = ctx.read(resolve(a, ctx.stdio, [a.demos], purpose="fit")).demos
    parts, said = plant_group_parts(ds, a.plant_group)
    if said:
        ctx.say(said)
    if len(parts) == 1:
        group = parts[0][0]
        source = STDIN_NAME if is_stdio(a.demos) else str(a.demos)
        # the one error line names the file and group, as a group's warning does in a fit of several
        _fit_one(ctx, parts[0][1], output, f"{source}: " + (f"plant group {group}: " if group else "") + "not fitted: ")
        ctx.say(f"wrote {'the model to standard output' if ctx.stdio.writes_stdout else a.output}")
        return 0  # the model is written: the fit succeeded, whatever its intervals could be computed from
    if ctx.stdio.writes_stdout:
        raise UsageError(f"-o - writes one model, but these demonstrations are {len(parts)} plant groups "
                         f"({', '.join(str(g) for g, _ in parts)}): name one with --plant-group")
    written, failed = [], []
    for group, part in parts:
        path = per_group_path(output, group)
        ctx.say(f"[bold]plant group {group}[/bold]", markup=True)
        try:
            _fit_one(ctx, part, path)
        except (DataError, ModelError) as exc:  # one group's failure is that group's: the others still fit
            ctx.warn(f"plant group {group}: not fitted: {exc}")
            failed.append(f"{group}: {exc}")
            continue
        written.append(path)
    if not written:
        raise ModelError(f"no plant group could be fitted: {'; '.join(failed)}")
    ctx.say(f"wrote {len(written)} model(s), one per plant group: {', '.join(str(p) for p in written)}"
            + (f"; {len(failed)} group(s) not fitted (warnings above)" if failed else ""))
    return 0


def _fit_one(ctx: Context, ds: Any, output: Any, where: str = "") -> None:
    """Fit, save and describe one model of one plant group's demonstrations (its own plant); a plant refused for its
    physics is refused with ``where`` first (:func:`~workbench.cli.reading.chosen_plant`)."""
    a = ctx.args
    plant = chosen_plant(ds, a.plant, where=where)
    print_plant(ctx, plant)
    t0 = time.perf_counter()
    with ctx.progress() as progress:
        from workbench.models.registry import method

        kind = method(a.method).load_class()
        # not given: the default model's rule (its baselines take the paper's G)
        components = DEFAULT_N_COMPONENTS if a.n_components is None else a.n_components
        if a.n_components == "cv" and not kind.chooses_settings:
            raise UsageError("--n-components cv chooses the proposed model's settings; use a number, 'bic' or "
                             f"'paper' with --method {a.method}")
        if components == "bic" and kind.has_components:
            from workbench.models.selection import select_components

            progress.add_task("choosing the number of components by BIC", total=None)
            components = select_components(ds, plant, seed=a.seed)
            ctx.say(f"chose {components} components by BIC")
        progress.add_task(f"fitting {a.method} model on {len(ds)} demonstrations", total=None)
        from workbench.models.factory import make_model

        try:
            model = make_model(a.method, plant, n_components=components, random_state=a.seed,
                               gain_method=a.gain, timing=a.timing, task=a.task).fit(ds)
        except ModelError as exc:
            raise ModelError(_physics_first(plant, exc)) from None
    model.save(output)
    ctx.say(f"fitted {type(model).__name__} on {len(ds)} demonstrations in {time.perf_counter() - t0:.1f} s")
    if getattr(model, "task_", None) is not None:
        ctx.say(model.task_.describe(plant.state_names))
    _print_model(ctx, model, ds)
    if a.bootstrap > 0 and model.has_gain:
        _print_intervals(ctx, model, ds, model.plant_regulated, a.bootstrap, a.seed, a.power, output)
    elif model.has_gain and model.objective_ is not None:
        ctx.say("(no intervals: --bootstrap 0; the objective above is a point estimate)")


def _print_intervals(ctx: Context, model: Any, ds: Any, plant: Any, n_boot: int, seed: int, power: int,
                     output: Any) -> None:
    """The model's intervals, each part on its own: a part that cannot be computed (no task objective to resample,
    every resample failing) is said to be not computed, with its reason, and the others are still printed; the
    model, already written, stands either way (rewritten to ``output`` where the resamples gave the pilot's delay
    and lag intervals, which its task carries)."""
    from workbench.errors import WorkbenchError
    from workbench.models.fitting import timing_setting

    fitted = _as_fitted(ds, model)
    timing = timing_setting(model)

    def with_timing(boot: Any) -> None:
        if _with_timed_stability(ctx, model, plant, boot) | _with_timing_intervals(model, boot):
            model.save(output)

    def with_objective() -> None:
        with_timing(_print_bootstrap(ctx, fitted, plant, n_boot, seed, model.gain_method_, timing))

    if model.objective_ is None and getattr(model, "objective_error_", None):
        ctx.say("intervals of the task objective (Q, R): not computed, since inverse LQR found no objective for the "
                "gain (above); the gain's own intervals follow")
        parts = [("intervals of K̂", lambda: with_timing(_print_gain_intervals(ctx, fitted, plant, n_boot, seed,
                                                                              model.gain_method_, timing)))]
    else:
        parts = [("intervals of K̂, Q and R", with_objective)]
    parts.append(("weight ratios", lambda: _print_ratios(ctx, model, ds, n_boot, seed, power)))
    for what, run in parts:
        try:
            run()
        except WorkbenchError as exc:
            # a warning where a user looks for what went wrong (stderr), naming the part; the model stands
            ctx.warn(f"intervals not computed: {' '.join(str(exc).split())} ({what}; the model is written)")


def _print_gain_intervals(ctx: Context, ds: Any, plant: Any, n_boot: int, seed: int, gain: str,
                          timing: Any = "none") -> Any:
    """K̂'s intervals alone (:func:`~workbench.method.resampling.gain_interval`), over resamples of whole trials (no
    inverse LQR per resample)."""
    from workbench.method.resampling import GAIN_INTERVAL, bootstrap_gain

    with ctx.executor() as ex, ctx.progress() as progress:
        task = progress.add_task(f"bootstrap: {n_boot} resamples of {len(ds)} trials", total=n_boot)
        result = bootstrap_gain(ds, plant, n_boot=n_boot, seed=seed, method=gain, executor=ex, jackknife=False,
                                timing=timing,
                                progress=lambda done, total: progress.update(task, completed=done, total=total))
    if result.n_failed:
        from workbench.method.resampling import failure_note

        ctx.warn(f"bootstrap: {failure_note(result.failures)}")
    lo, hi = result.interval(95.0)
    ctx.say(f"bootstrap ({result.n_ok} of {result.n_boot} resamples fitted, 95 % intervals, {GAIN_INTERVAL}):")
    if result.timing is not None:
        ctx.say(f"  {result.timing.describe()}")
    for i, u in enumerate(plant.input_names):
        ctx.say(f"  K̂ row {u}: " + ", ".join(
            f"{s} [{a:.3g}, {b:.3g}]" for s, a, b in zip(plant.state_names, lo[i], hi[i], strict=True)))
    return result


def _physics_first(plant: Any, exc: Exception) -> str:
    """A fit's failure on a plant that fails its physics check: the physics first (the real cause: no gain fitted
    on such a plant means anything), then what the fit said."""
    report = getattr(plant, "identification", None)
    failure = report.physics_failure if report is not None else ""
    return f"the identified plant is not physics: {failure}; so the fit failed: {exc}" if failure else str(exc)


def _print_bootstrap(ctx: Context, ds: Any, plant: Any, n_boot: int, seed: int, gain: str = "direct",
                     timing: Any = "none") -> Any:
    from workbench.method.resampling import GAIN_INTERVAL, bootstrap

    with ctx.executor() as ex, ctx.progress() as progress:
        task = progress.add_task(f"bootstrap: {n_boot} resamples of {len(ds)} trials", total=n_boot)
        result = bootstrap(ds, plant, n_boot=n_boot, seed=seed, method=gain if gain in ("direct", "dmd") else "iv",
                           executor=ex, timing=timing,
                           progress=lambda done, total: progress.update(task, completed=done, total=total))
    if result.stopped:
        ctx.warn(f"bootstrap {result.stopped}")
    elif result.n_failed:
        from workbench.method.resampling import failure_note

        ctx.warn(f"bootstrap: {failure_note(result.failures)}")
    ctx.say(f"bootstrap ({result.n_boot - result.n_failed} of {result.n_boot} resamples fitted, {result.ci:g} % "
            f"intervals: the objective's percentiles, K̂'s {GAIN_INTERVAL}):")
    if result.timing is not None:
        ctx.say(f"  {result.timing.describe()}")
    for names, lo, hi, what in ((plant.state_names, result.Q_diag_lo, result.Q_diag_hi, "Q/λmax"),
                                (plant.input_names, result.R_diag_lo, result.R_diag_hi, "R/λmax")):
        ctx.say(f"  diag {what}: " + ", ".join(
            f"{s} [{a:.3g}, {b:.3g}]" for s, a, b in zip(names, lo, hi, strict=True)))
    for i, u in enumerate(plant.input_names):
        ctx.say(f"  K̂ row {u}: " + ", ".join(
            f"{s} [{a:.3g}, {b:.3g}]" for s, a, b in zip(plant.state_names, result.K_lo[i], result.K_hi[i],
                                                         strict=True)))
    return result


def _with_timed_stability(ctx: Context, model: Any, plant: Any, result: Any) -> bool:
    """The stability of a gain on the state the pilot saw, with ρ's interval from the bootstrap's resampled delays,
    lags and gains (:func:`~workbench.method.stability.with_timing_resamples`): printed, and kept in the model;
    whether there was one."""
    from workbench.method.stability import with_timing_resamples

    stability = getattr(model, "stability_", None)
    pt = getattr(result, "timing", None)
    if stability is None or pt is None or getattr(model, "timing_", None) is None or stability.loop == "A + BK̂":
        return False
    judged = with_timing_resamples(stability, plant.A, plant.B, plant.dt, pt)
    if judged is stability:
        return False
    model.stability_ = judged
    ctx.say(f"  {judged.describe()}")
    return True


def _with_timing_intervals(model: Any, result: Any) -> bool:
    """Write the bootstrap's intervals of the pilot's delay and lag into the model's task (``task_.extra``:
    ``delay_s_interval``, ``lag_s_interval``); whether there were any."""
    pt = getattr(result, "timing", None)
    task = getattr(model, "task_", None)
    if pt is None or task is None or getattr(model, "timing_", None) is None:
        return False
    bounds = {"delay_s_interval": (pt.delay_lo, pt.delay_hi), "lag_s_interval": (pt.lag_lo, pt.lag_hi)}
    extra = {k: [float(lo), float(hi)] for k, (lo, hi) in bounds.items()
             if lo is not None and hi is not None and math.isfinite(lo) and math.isfinite(hi)}
    if not extra:
        return False
    model.task_ = task.with_(extra={**task.extra, **extra})
    return True


def _as_fitted(ds: Any, model: Any) -> Any:
    """The trials as the model's regulator saw them (the regulated states relative to the goal or the reference,
    the input net of its feedforward: :meth:`~workbench.models.behavior.BehaviorModel.pilot_view`), so the
    bootstrap's point estimate is the model's own gain and objective."""
    return model.pilot_view(ds)


def _print_ratios(ctx: Context, model: Any, ds: Any, n_boot: int, seed: int, power: int = 0) -> None:
    """Weight ratios inside each coupled part of the plant (minimum-distance diagonal cost), with intervals; with
    ``power`` > 0 the demonstrations a simulated power curve says each wide one would need."""
    from workbench.study.weights import ratio_bootstrap, with_power

    with ctx.progress() as progress:
        task = progress.add_task(f"weight ratios: {n_boot} resampled gains", total=n_boot)
        def advance(done: int, total: int) -> None:
            progress.update(task, completed=done, total=total)

        ratios, gain, note = ratio_bootstrap(model, ds, n_boot=n_boot, seed=seed, progress=advance)
    if ratios is None:
        ctx.say(f"weight ratios: none ({note})")
        return
    curve = None
    if power > 0:
        with ctx.progress() as progress:
            progress.add_task("power curve: simulating demonstrations from the model", total=None)
            ratios, curve = with_power(model, ds, ratios, power, seed)
    g = ratios.gains
    if getattr(g, "stopped", ""):
        ctx.warn(f"weight ratios' bootstrap {g.stopped}")
    ctx.say(f"weight ratios inside coupled parts (S = 0, diagonal cost closest to the {gain} gain in the metric of "
            f"its covariance over {g.n_ok} of {g.n_boot} resamples; {ratios.ci:g} % profile intervals; "
            f"forward-gain error {ratios.forward_gain_error:.2g}):")
    for r in ratios.intervals:
        ctx.say(f"  {r.describe()}")
    for f in ratios.fits:
        ctx.say(f"  {f.describe()}")
    if curve is not None:
        ctx.say("power curve (simulated from the model; the median interval span of the simulated sets of each "
                "size, and the number needed with its interval over resampled sets):")
        for line in curve.describe():
            ctx.say(f"  {line}")
    elif power <= 0 and any(not r.identifiable and r.explained for r in ratios.intervals):
        ctx.say("  (--power 1 simulates how many demonstrations the ratios that are not identifiable would need)")


def _print_model(ctx: Context, model: Any, ds: Any) -> None:
    import numpy as np

    o = None
    if model.has_gain:
        K = np.asarray(model.K_)
        reg = set(getattr(model, "regulated_idx", range(K.shape[1])))  # "—": a state the pilot does not regulate
        ctx.say_table(["K̂ (u = K̂ x)", *ds.state_names],
                      [[name, *(f"{v:.3g}" if j in reg else "—" for j, v in enumerate(row))]
                       for name, row in zip(ds.input_names, K, strict=True)])
        ctx.say(str(model.gain_choice_))
        if getattr(model, "stability_", None) is not None:
            ctx.say(model.stability_.describe())
        o = model.objective_
    if o is None and model.has_gain and model.objective_error_:
        ctx.say(f"task objective: not found ({model.objective_error_}); the model predicts without it")
    if o is not None:
        names = model.plant_regulated.state_names  # the objective weighs the regulated states
        n = len(names)
        q = np.diag(np.asarray(o.M_normalized)[:n, :n])
        r = np.diag(np.asarray(o.M_normalized)[n:, n:])
        ctx.say(f"α* = {o.alpha:.4g}, forward-gain error {o.forward_gain_error:.1e}")
        ctx.say("diag Q/λmax: " + ", ".join(f"{s} {v:.3g}" for s, v in zip(names, q, strict=True)))
        ctx.say("diag R/λmax: " + ", ".join(f"{s} {v:.3g}" for s, v in zip(ds.input_names, r, strict=True)))
    if model.has_components:
        ctx.say(f"GMM components: {model.n_components_}")
    auto = model.auto_ if model.chooses_settings else None
    if auto is not None:
        # what was chosen and whether the model fell back to K̂x (said, never silent), then every candidate's score
        ctx.say(f"the default model: {auto.describe()}")
        ctx.say(candidate_scores(auto.scores, model.noise_horizon_s))


def candidate_scores(scores: Any, horizon_s: float) -> str:
    """The cross-validation's held-out RMSE per candidate in one line; a candidate some fold could not fit or score
    (NaN, :class:`~workbench.models.autoconfig.AutoSettings`) is said to be not scored, never "nan"."""
    return f"held-out {horizon_s:g} s RMSE per candidate: " + ", ".join(
        f"G{r['n_components']}/{r['reg_covar']:g} "
        + (f"{r['heldout_rmse']:.3g}" if math.isfinite(r["heldout_rmse"]) else "not scored on every fold")
        for r in scores)


def cmd_predict(ctx: Context) -> int:
    import numpy as np
    import pandas as pd

    a = ctx.args
    output = ctx.output_path(a.output, ".parquet", "the prediction")
    if a.x0 is None and not a.demos:
        raise UsageError("predict needs DEMOS (with --demo ID and --start K) or --x0 x,y,…")
    inputs = resolve(a, ctx.stdio, [a.demos] if a.x0 is None else [], models=[a.model])
    model = ctx.models(inputs)[""]
    if a.x0 is not None:
        try:
            x0 = np.array([float(v) for v in a.x0.split(",")])
        except ValueError:
            raise UsageError(f"--x0 must be comma-separated numbers, got {a.x0!r}") from None
        target, t0, demo_id, task_x0, start = None, 0.0, "x0", None, 0
        names, in_names = model.plant.state_names, model.plant.input_names
    else:
        got = ctx.read(inputs)
        ds = got.demos
        ids = ds.ids
        if a.demo and a.demo not in ids:
            why = got.selected.why_left_out(a.demo) if got.selected is not None else None
            if why is not None:
                raise DataError(f"{a.demos}: trial {a.demo!r} is left out ({why}); --role, --outcome and "
                                "--include-excluded choose which trials count")
            raise DataError(f"{a.demos}: no demonstration {a.demo!r}; ids present: {ids[:10]}")
        demo = ds[ids.index(a.demo)] if a.demo else ds[0]
        if not 0 <= a.start < len(demo):
            raise DataError(f"{a.demos}: --start {a.start} outside trial {demo.id!r} (0…{len(demo) - 1})")
        t0 = float(demo.t[a.start])
        at_dt, note = demos_at_model_dt(ds, [model], a.resample, a.demos)
        if note:
            ctx.say(note)
        if at_dt is not ds:
            # --start counts samples of the file; on the model's grid the start is the sample nearest its time
            demo = at_dt[ids.index(demo.id)]
            start = int(np.argmin(np.abs(demo.t - t0)))
            ctx.say(f"step {a.start} (t = {t0:.3f} s) of {demo.id} is step {start} on the model's grid")
            t0 = float(demo.t[start])
        else:
            start = a.start
        x0, target, demo_id, task_x0 = demo.x[start], demo.target, demo.id, demo.x[0]
        names, in_names = ds.state_names, ds.input_names
    dt = model.plant.dt  # the model steps at its own dt, whatever the demonstrations' sampling
    n_steps = steps_of(a.horizon_s, dt)
    rollout_budget(a.samples, n_steps)
    # from inside a trial, the task's start frame stays at the trial's first state
    kwargs: dict[str, Any] = {"target": target, "task_x0": task_x0, "task_step": int(start)}
    if a.samples:
        kwargs.update(samples=a.samples, seed=a.seed)
    pred = model.predict(x0, n_steps, **kwargs)
    x, u = np.asarray(pred.x), np.asarray(pred.u)
    names = list(names or [f"x{i}" for i in range(x.shape[1])])
    in_names = list(in_names or [f"u{i}" for i in range(u.shape[1])])
    cols: dict[str, Any] = {"demo": demo_id, "step": np.arange(len(x)), "t": t0 + dt * np.arange(len(x))}
    cols.update({s: x[:, j] for j, s in enumerate(names)})
    u_full = np.vstack([u, np.full((1, u.shape[1]), np.nan)])  # the last state has no input yet
    cols.update({s: u_full[:, j] for j, s in enumerate(in_names)})
    if pred.x_lower is not None:
        cols.update({f"{s}_lower": pred.x_lower[:, j] for j, s in enumerate(names)})
        cols.update({f"{s}_upper": pred.x_upper[:, j] for j, s in enumerate(names)})
    out = atomic_write_table(pd.DataFrame(cols), output)
    # the end position where the plant declares positions, else the whole end state
    shown = model.plant.r.position or range(len(names))
    ctx.say(
        f"predicted {n_steps} steps ({n_steps * dt:.2f} s) from {demo_id} step {start}: "
        "end " + ", ".join(f"{names[j]} = {x[-1, j]:.3f}" for j in shown)
    )
    ctx.say(f"wrote {'the prediction to standard output' if ctx.stdio.writes_stdout else out}")
    return 0
