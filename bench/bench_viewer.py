"""Viewer benchmarks: columnar vs per-row logging of a 60-demonstration session, and the replay rate.

1. The same session (states, inputs and the vehicle pose of 60 simulated landings, both strategies) logged to an
   ``.rrd`` once through ``send_columns`` (what :class:`workbench.viewer.SessionLogger` does) and once row by row
   with ``set_time`` + ``rr.log`` — the ratio is what the columnar path buys (target ≥ 20×).
2. :func:`workbench.viewer.replaying` without waiting, with the model's online predictions on (one-step GMR and a
   1 s rollout at every sample): simulated seconds per wall-clock second (target ≥ 20× real time).

``python bench/bench_viewer.py`` prints the rows; ``bench/run_all.py`` collects them into ``bench/results.md``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rerun as rr  # noqa: E402
from harness import markdown_table, verdict  # noqa: E402

from workbench import viewer  # noqa: E402
from workbench.data.demonstrations import DemonstrationSet  # noqa: E402
from workbench.sim.landing import simulate_landings  # noqa: E402
from workbench.viewer import replay  # noqa: E402


def _session() -> DemonstrationSet:
    return simulate_landings("CS1", 30, seed=0) + simulate_landings("CS2", 30, seed=0)


def _columnar(ds: DemonstrationSet, path: Path) -> float:
    rec = viewer.new_recording()
    t0 = time.perf_counter()
    rec.save(path)
    logger = viewer.SessionLogger(rec, ds)
    for d in ds:
        logger.log_demonstration(d)
    rec.flush()
    rec.disconnect()
    return time.perf_counter() - t0


def _per_row(ds: DemonstrationSet, path: Path) -> float:
    """The same entities and values as :meth:`SessionLogger.log_demonstration`, one ``rr.log`` per sample."""
    rec = viewer.new_recording()
    t0 = time.perf_counter()
    rec.save(path)
    sn, un = ds.state_names, ds.input_names
    # the same static styling as the columnar path (built once, logged per entity): only the bulk data differ
    state_style = rr.SeriesLines(widths=[1.5])
    input_style = rr.SeriesLines(widths=[1.5], interpolation_mode="StepAfter")
    body = rr.LineStrips3D([[[-0.18, 0, 0], [0.18, 0, 0]], [[0, 0, 0], [0, 0, 0.12]]], radii=[0.02, 0.01])
    for d in ds:
        base = f"demos/{d.id}"
        for name in sn:
            rec.log(f"{base}/states/{name}", state_style, static=True)
        for name in un:
            rec.log(f"{base}/inputs/{name}", input_style, static=True)
        pos = np.column_stack([d.x[:, 0], np.zeros(len(d)), d.x[:, 1]])
        rec.log(f"scene/demos/{d.id}/path", rr.LineStrips3D([pos], radii=0.008, labels=[d.id]), static=True)
        rec.log(f"scene/demos/{d.id}/vehicle", body, static=True)
        t = d.t - d.t[0]
        for k in range(len(d)):
            rec.set_time("time", duration=float(t[k]))
            rec.set_time("step", sequence=k)
            for j, name in enumerate(sn):
                rec.log(f"{base}/states/{name}", rr.Scalars(d.x[k, j]))
            for j, name in enumerate(un):
                rec.log(f"{base}/inputs/{name}", rr.Scalars(d.u[k, j]))
            phi = d.x[k, 2]
            rec.log(f"scene/demos/{d.id}/vehicle",
                    rr.Transform3D(translation=pos[k], quaternion=[0.0, np.sin(phi / 2), 0.0, np.cos(phi / 2)]))
    rec.flush()
    rec.disconnect()
    return time.perf_counter() - t0


def run() -> list[dict]:
    rows: list[dict] = []
    ds = _session()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t_col = _columnar(ds, tmp / "col.rrd")  # one run each side: like for like
        t_row = _per_row(ds, tmp / "row.rrd")
        rows.append({
            "benchmark": "log 60-demonstration session",
            "demos": len(ds),
            "samples": ds.n_samples,
            "send_columns s": t_col,
            "per-row rr.log s": t_row,
            "ratio (×)": t_row / t_col,
            "target": "≥ 20×",
            "met": verdict(t_row / t_col, 20.0, True),
        })

        from workbench.models import HumanBehaviorModel
        from workbench.plant.system import planar_quadrotor

        train = ds.by_label("CS1")
        model = HumanBehaviorModel(planar_quadrotor(), n_components=5).fit(train)
        for horizon in (20, 60):
            rec = viewer.new_recording()
            rec.save(tmp / f"replay{horizon}.rrd")
            sim = wall = 0.0
            steps = 0
            for d in list(train)[:5]:
                stats = replay(d, model, rec, state_names=ds.state_names, input_names=ds.input_names, wait=False,
                               n_steps=horizon)
                sim += stats.sim_time
                wall += stats.wall_time
                steps += stats.n_steps
            rec.flush()
            rec.disconnect()
            rows.append({
                "benchmark": f"replay with predictions (one-step GMR + {horizon}-step rollout per sample)",
                "demos": 5,
                "samples": steps,
                "steps/s": steps / wall,
                "sim s": sim,
                "wall s": wall,
                "ratio (×)": sim / wall,
                **({"target": "≥ 20× real time (3 s rollouts)", "met": verdict(sim / wall, 20.0, True)}
                   if horizon == 60 else {}),
            })
    return rows


if __name__ == "__main__":
    print(markdown_table(run()))
