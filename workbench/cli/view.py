"""``workbench view``, ``replay`` and ``live``: rerun recordings of logs, models and live telemetry.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from workbench import interrupts
from workbench.cli.context import Context
from workbench.cli.inputs import Inputs, input_stem, resolve
from workbench.cli.options import DEFAULT_MAPPING, rollout_budget, steps_of
from workbench.cli.reading import default_output, demos_at_model_dt
from workbench.cli.writing import announce, output_kwargs
from workbench.errors import DataError, UsageError

__all__ = ["VIEW_SAMPLES"]

# Monte Carlo rollouts of `view --model`'s prediction band: its 5th/95th percentiles move by a few percent of
# the band's width between seeds at 50, and the focus trials' rollouts stay under a second
VIEW_SAMPLES = 50


def _log_origins(inputs: Inputs) -> dict[str, float]:
    """Each raw log's start as ``workbench inspect`` reckons it (the first message of any stream), so a
    flight's segments are drawn where ``inspect`` places its flight modes; demonstration files have none."""
    import adapters

    return {str(s.path): float(adapters.inspect(s.path, format=s.format).t_start)
            for s in inputs.sources if not s.demos and not s.stdin and s.path.is_file()}


def _warn(ctx: Context, session: Any) -> None:
    """The recording's warnings (a model that does not fit its data), on stderr where a user looks for them."""
    for w in session.warnings:
        ctx.warn(f"{w}")

def _view_raw(ctx: Context, streams: Any) -> int:
    """``workbench view LOG --raw`` (or a log no mapping makes demonstrations of): the log as it is
    (workbench.viewer.rawlog)."""
    from adapters.rawlog import raw_log
    from workbench import viewer
    from workbench.viewer.rawlog import RAW_APPLICATION_ID, log_raw, raw_blueprint

    a = ctx.args
    raw = raw_log(streams)
    out = output_kwargs(ctx, default_output(a.inputs[0], ".rrd"))
    rec = viewer.new_recording(RAW_APPLICATION_ID)
    with ctx.progress() as progress:
        progress.add_task(f"logging {len(raw.streams)} streams", total=None)
        with viewer.open_output(rec, **out) as sink:
            logged = log_raw(rec, raw)
            sink.blueprint = raw_blueprint(logged)
    n = sum(s.values.size for s in raw.streams)
    announce(ctx, out, sink, f"the raw log: {len(raw.streams)} streams, {n} values, {len(raw.text)} messages"
             + (f", a GPS track ({raw.track.source})" if raw.track is not None else "")
             + (f", {len(raw.parameters)} parameters" if raw.parameters else ""))
    return 0


def _view_overlay(ctx: Context, inputs: Inputs) -> int:
    """``workbench view A B … --raw``: the logs on one clock, one colour each (:mod:`workbench.viewer.overlay`)."""
    import adapters
    from adapters.rawlog import raw_log
    from workbench import viewer
    from workbench.viewer.overlay import OVERLAY_APPLICATION_ID, log_overlay, overlay_blueprint

    a = ctx.args
    raws = []
    for source in inputs.sources:
        if source.demos:
            raise UsageError(f"{source.shown}: --raw overlays logs as they are, not demonstrations")
        raws.append(raw_log(adapters.read(source.path, format=source.format)))
    align = list(a.align or [])
    if not align:  # arming where every log records one: the moment two flights most often share
        align = ["arming" if r.armed else "start" for r in raws]
    stem = "_".join(input_stem(p) for p in a.inputs[:3])
    out = output_kwargs(ctx, Path("out") / f"{stem}.overlay.rrd")  # under out/, never beside the inputs
    rec = viewer.new_recording(OVERLAY_APPLICATION_ID)
    with ctx.progress() as progress:
        progress.add_task(f"logging {len(raws)} logs on one clock", total=None)
        with viewer.open_output(rec, **out) as sink:
            logged = log_overlay(rec, raws, align)
            sink.blueprint = overlay_blueprint(logged)
    for name, how in zip(logged.names, logged.aligned, strict=True):
        ctx.say(f"{name}: 0 s at {how}")
    announce(ctx, out, sink, f"{len(raws)} logs on one clock")
    return 0


def cmd_view(ctx: Context) -> int:
    import adapters
    from workbench import viewer

    a = ctx.args
    if a.align and not (a.raw and len(a.inputs) > 1):
        raise UsageError("--align puts several raw logs on one clock: give two or more logs with --raw")
    if a.raw and len(a.inputs) > 1 and (a.mapping or a.model or a.label):
        raise UsageError("--raw shows the logs as they are: leave out --mapping, --model and --label")
    if a.raw and (a.mapping or a.model):
        raise UsageError("--raw shows the log as it is: leave out --mapping and --model")
    inputs = resolve(a, ctx.stdio, a.inputs, models=a.model or [], labelled_models=True, allow_still=True,
                     mapping=not a.raw, mapping_hint="--mapping chooses another, --raw shows the log alone")
    if a.raw and len(inputs.sources) > 1:
        return _view_overlay(ctx, inputs)
    first = inputs.sources[0]
    one_log = len(inputs.sources) == 1 and not a.label and not first.demos
    raw_streams = adapters.read(first.path, format=first.format) if one_log else None
    if a.raw:
        if raw_streams is None:
            raise UsageError("--raw shows one raw log as it is: give one log (not demonstrations), no --label")
        return _view_raw(ctx, raw_streams)
    try:
        got = ctx.read(inputs)
    except DataError as e:
        if raw_streams is not None and not a.mapping:
            # the mapping chosen for the log's vehicle makes no demonstrations of it: the log opens as it is, with
            # the cause
            ctx.warn(f"{e}; showing the raw log alone")
            return _view_raw(ctx, raw_streams)
        if len(inputs.sources) < 2 or " dt " not in f" {e} ":
            raise
        # logs of several rates in one view: on one grid, or the way out named
        got = None
    ds = got.demos if got is not None else _several_on_one_grid(ctx, inputs, a.resample)
    mapping = first.mapping
    source_dt = float(ds.dt)
    models, named = None, None
    by_label = ctx.models(inputs) if inputs.models else {}
    ds = _of_plant_group(ctx, ds, a.plant_group, by_label.values())
    if by_label:
        if "" in by_label:
            models = by_label[""]
            named = {Path(inputs.models[0].given).stem: models}
        else:
            models = named = by_label
        ds, note = demos_at_model_dt(ds, list(by_label.values()), a.resample, inputs.names)
        if note:
            ctx.say(note)
    n_steps = steps_of(a.horizon_s, ds.dt)
    if models is not None:
        rollout_budget(a.samples, n_steps)
    out = output_kwargs(ctx, default_output(a.inputs[0], ".rrd"))
    rec = viewer.new_recording(viewer.APPLICATION_IDS["session" if models is not None else "log"])
    with ctx.progress() as progress:
        progress.add_task(f"logging {len(ds)} demonstrations", total=None)
        origins = _log_origins(inputs)
        with viewer.open_output(rec, **out) as sink:
            session = viewer.log_session(
                rec, ds, models=models, named_models=named, focus=a.focus or None, n_steps=n_steps,
                samples=a.samples, starts=a.starts or (0,), seed=a.seed, origins=origins, source_dt=source_dt,
                color_by=a.color_by,
            )
            extra = (_raw_beside(rec, raw_streams, mapping, ds, origins.get(str(first.path)))
                     if raw_streams is not None and mapping else [])
            sink.blueprint = viewer.default_blueprint(session, extra_tabs=extra)
    _warn(ctx, session)
    announce(ctx, out, sink, f"{len(ds)} demonstrations")
    return 0


def _of_plant_group(ctx: Context, ds: Any, name: str | None, models: Any) -> Any:
    """The segments a view shows: the plant group ``name`` (``--plant-group``), else the groups the models' plants
    were identified for (a model predicts only where its stick commands what it did), else every segment; said."""
    from workbench.data.plant_groups import describe_groups, plant_groups, select_plant_group

    if name:
        return select_plant_group(ds, name)
    wanted = {getattr(m.plant, "plant_group", None) for m in models}
    if None in wanted or not wanted or set(plant_groups(ds)) <= wanted:
        return ds
    kept = ds.with_demos([d for d in ds if d.meta.get("plant_group") in wanted])
    if not len(kept):
        raise DataError(f"the model's plant group ({', '.join(sorted(wanted))}) is none of these segments' "
                        f"({describe_groups(ds)}); --plant-group names the segments to show")
    ctx.say(f"showing plant group {describe_groups(kept)}: the model's (--plant-group shows another)")
    return kept


def _several_on_one_grid(ctx: Context, inputs: Inputs, resample: bool) -> Any:
    """Several logs or demonstration files in one view: on one time grid, the finest of theirs, where
    ``--resample`` is given; without it, logs of different dt are one line naming both ways out."""
    import math
    from dataclasses import replace

    parts = [ctx.read(replace(inputs, sources=(s,))).demos for s in inputs.sources]
    steps = sorted({float(d.dt) for d in parts})
    if len(steps) > 1 and not all(math.isclose(steps[0], s, rel_tol=1e-6) for s in steps):
        shown = ", ".join(f"{s.shown} dt {d.dt:g} s" for s, d in zip(inputs.sources, parts, strict=True))
        if not resample:
            raise DataError(f"{shown}: sampled at different dt; --resample puts them on the finest grid "
                            f"({steps[0]:g} s, states linear, inputs held), --raw overlays the logs as recorded")
        parts = [d if math.isclose(float(d.dt), steps[0], rel_tol=1e-6) else d.resample(steps[0]) for d in parts]
        ctx.say(f"resampled to dt = {steps[0]:g} s ({shown})")
    ds = parts[0]
    for d in parts[1:]:
        ds = ds + d
    return ds


def _raw_beside(rec: Any, streams: Any, mapping: str, ds: Any, origin: float | None) -> list[Any]:
    """The raw log under a mapped flight, on the flight's clock, with what the mapping kept and dropped.

    ``origin``: the log's start as the session's segments reckon it (:func:`_log_origins`); else, as the session
    does without one, the first mapped sample's time."""
    from adapters.explain import explain
    from adapters.mapping import load_mapping
    from adapters.rawlog import raw_log
    from workbench.viewer.rawlog import log_raw, raw_views

    meta = ds[0].meta
    if origin is None and "t0" in meta and "t_start" in meta:
        origin = float(meta["t0"]) - float(meta["t_start"])
    pieces = explain(streams, load_mapping(mapping).for_format(streams.format))
    return raw_views(log_raw(rec, raw_log(streams), origin=origin, segments=pieces))


def cmd_replay(ctx: Context) -> int:
    if getattr(ctx.args, "to", None):  # a stand-in vehicle: the log's raw MAVLink frames, no model
        return _replay_to(ctx)
    from workbench import viewer
    from workbench.viewer import replay, replay_blueprint

    a = ctx.args
    if not a.model:
        raise UsageError("replay needs --model MODEL.npz (predictions) or --to CONNECTION (send the log to a link)")
    inputs = resolve(a, ctx.stdio, [a.log], models=[a.model])
    got = ctx.read(inputs)
    model = ctx.models(inputs)[""]
    ds, note = demos_at_model_dt(got.demos, [model], a.resample, a.log)
    if note:
        ctx.say(note)
    ids = ds.ids
    chosen = a.demo or [ids[0]]
    missing = [i for i in chosen if i not in ids]
    if missing:
        why = got.selected.why_left_out(missing[0]) if got.selected is not None else None
        if why is not None:
            raise DataError(f"{a.log}: trial {missing[0]!r} is left out ({why}); --role, --outcome and "
                            "--include-excluded choose which trials count")
        raise DataError(f"{a.log}: no demonstration {missing[0]!r}; ids present: {ids[:10]}")
    out = output_kwargs(ctx, default_output(a.log, ".replay.rrd"))
    rec = viewer.new_recording(viewer.APPLICATION_IDS["replay"])
    stats = []
    with viewer.open_output(rec, **out) as sink:
        sink.blueprint = replay_blueprint(chosen, ds.state_names, ds.input_names, roles=ds.roles,
                                          demos=[ds[ids.index(i)] for i in chosen])
        if not out["save"]:
            rec.send_blueprint(sink.blueprint)
        with ctx.progress() as progress:
            for demo_id in chosen:
                demo = ds[ids.index(demo_id)]
                task = progress.add_task(f"replaying {demo_id} at {a.speed:g}×", total=len(demo))
                stats.append(
                    replay(demo, model, rec, state_names=ds.state_names, input_names=ds.input_names, roles=ds.roles,
                           speed=a.speed, wait=not a.no_wait,
                           n_steps=steps_of(a.horizon_s, ds.dt) if a.horizon_s else 0,
                           on_step=lambda k, task=task: progress.update(task, completed=k + 1))
                )
    for s in stats:
        cover = ", ".join(f"{n} {100 * c:.1f} %" for n, c in zip(ds.input_names, s.coverage_3sigma, strict=True))
        ctx.say(f"{s.demo_id}: {s.n_steps} steps, {s.sim_time:.1f} s of flight in {s.wall_time:.2f} s "
                f"({s.realtime_factor:.1f}× real time); actual input inside the online 3σ band: {cover}")
    announce(ctx, out, sink, f"replay of {', '.join(chosen)}")
    return 0


def _replay_to(ctx: Context) -> int:
    from adapters.link.mavlink import send_tlog

    a = ctx.args
    log = resolve(a, ctx.stdio, [a.log], mapping=False, what="the log").sources[0].path
    ctx.say(f"sending {log} to {a.to} at {a.speed:g}× real time (Ctrl-C to stop)")
    with ctx.progress() as progress:
        task = progress.add_task(f"replaying {log.name} to {a.to}", total=None)
        try:
            report = send_tlog(log, a.to, speed=a.speed,
                               on_frame=lambda n, t: progress.update(task, completed=n) if n % 200 == 0 else None)
        except KeyboardInterrupt:
            interrupts.clear()  # handled here, with its own line
            ctx.say("stopped")
            return 130
    ctx.say(f"sent {report.n_frames} MAVLink frames ({report.log_seconds:.1f} s of log) in {report.wall_seconds:.1f} s "
            f"({report.speed:.1f}× real time)")
    if report.gaps_capped:
        from adapters.link.mavlink import MAX_REPLAY_GAP

        ctx.say(f"shortened {report.gaps_capped} gap(s) in the log's timestamps to {MAX_REPLAY_GAP:g} s each "
                f"({report.seconds_skipped:.0f} s of log clock not waited for: a damaged stamp or a paused recording)")
    return 0


def cmd_live(ctx: Context) -> int:
    import signal

    import numpy as np

    from adapters.link.mavlink import open_link
    from workbench import viewer
    from workbench.live.predictor import OnlinePredictor, listen
    from workbench.viewer.live import LIVE_APPLICATION_ID, LiveLogger, live_blueprint
    from workbench.viewer.scene import plane_of

    a = ctx.args
    model = ctx.models(resolve(a, ctx.stdio, models=[a.model]))[""]
    predictor = OnlinePredictor(model, a.mapping or DEFAULT_MAPPING, horizon_s=a.horizon_s, system=a.sysid,
                                clock=a.clock, silence=a.silence)
    m = predictor.mapping
    scene = plane_of(m.roles, m.state_names)  # the plane of flight the replay and the session draw
    plane = None if scene is None else (scene.across, scene.up, scene.heading)
    out = output_kwargs(ctx, Path("out") / "live.rrd")
    rec = viewer.new_recording(LIVE_APPLICATION_ID)
    link = open_link(a.connection)
    logger: Any = None
    shown: list[str] = []

    def on_prediction(p: Any) -> None:
        logger.log(p)
        if not out["save"] and logger.demo_ids[-1:] != shown[-1:]:  # a new segment: show it in the viewer
            shown.append(p.demo_id)
            rec.send_blueprint(live_blueprint(logger.demo_ids, m.state_names, m.input_names, scene=plane is not None,
                                              bounds=logger.scene_bounds(), following=True))

    def on_event(ev: Any) -> None:
        logger.event(ev)
        print(f"{ev.kind}: {ev.text}", file=sys.stderr)

    with link, viewer.open_output(rec, **out) as sink:
        logger = LiveLogger(rec, m.state_names, m.input_names, plane=plane, connection=a.connection,
                            vertical=scene is not None and scene.vertical,
                            units={n: m.roles.unit(n) for n in m.state_names} if m.roles else None,
                            watched=not out["save"])
        if not out["save"]:
            rec.send_blueprint(live_blueprint([], m.state_names, m.input_names, scene=plane is not None,
                                              following=True))
        ctx.say(f"listening on {a.connection} (mapping {m.name}, dt {m.dt:g} s, rollout {a.horizon_s:g} s)"
                + (f" for {a.duration:g} s" if a.duration else "; Ctrl-C to stop"))
        def on_tick(stats: Any) -> None:  # the viewer gets the steps in batches, a few times a second
            logger.flush()
            logger.status(stats)

        def on_term(signum: int, frame: Any) -> None:  # a SIGTERM ends the session as cleanly as Ctrl-C
            raise KeyboardInterrupt

        previous = signal.signal(signal.SIGTERM, on_term)
        try:
            summary = listen(link, predictor, duration=a.duration, on_prediction=on_prediction, on_event=on_event,
                             on_tick=on_tick, tick=0.25)
        finally:
            signal.signal(signal.SIGTERM, previous)
        logger.finish()
        sink.blueprint = live_blueprint(logger.demo_ids, m.state_names, m.input_names, scene=plane is not None,
                                        bounds=logger.scene_bounds(), span=logger.link_span)
    c50, c99 = summary.percentiles("compute")
    l50, l99 = summary.percentiles("latency")
    timing = (f"per step p50 {c50:.2f} ms, p99 {c99:.2f} ms" if summary.n_steps else "no step predicted, no timing")
    if summary.n_steps and np.isfinite(l50):
        timing += f"; message to prediction p50 {l50:.2f} ms, p99 {l99:.2f} ms"
    ctx.say(f"{summary.n_steps} steps in {summary.n_segments} segment(s) over {summary.wall_seconds:.1f} s "
            f"({'interrupted' if summary.ended_by == 'interrupt' else 'duration reached'}); {timing}")
    st = summary.stats
    ctx.say("link: " + (", ".join(f"{k} {v}" for k, v in sorted(st.counts.items()) if v) or "nothing received"))
    if st.received:
        ctx.say("received: " + ", ".join(f"{k} {v}" for k, v in sorted(st.received.items(), key=lambda kv: -kv[1])[:12])
                + (f" and {len(st.received) - 12} other types" if len(st.received) > 12 else ""))
    ctx.say(f"kernel drops: {st.counts.get('kernel drops', 0)} (from the {st.drops_source})" if st.drops_source
            else "kernel drops: not known on this link")
    if st.counts.get("shed (backlog)"):
        ctx.say(f"behind the link: {st.counts['shed (backlog)']} datagrams that carry nothing the mapping reads "
                "were dropped unparsed to keep predictions current")
    if st.never_received:
        ctx.say(f"never received (from any system): {', '.join(st.never_received)}; no vehicle can be followed "
                f"without them (mapping {m.name})")
    elif st.waiting_for and not summary.n_steps:
        ctx.say(f"no sample yet for: {', '.join(st.waiting_for)}")
    if summary.ended_by == "interrupt" and out["serve"]:
        return 0
    announce(ctx, out, sink, f"live session ({summary.n_steps} steps)")
    return 0
