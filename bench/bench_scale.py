"""Scaling out on Dask: speed-up of a per-subject study at 2 workers, a 200-subject study, and a worked estimate.

Three measurements (``python bench/bench_scale.py`` writes ``bench/results_scale.md``; ``run()`` gives the
summary rows to ``bench/run_all.py``):

1. **Speed-up at 2 workers**: the paper's multi-subject design (10 training + 1 test trial per subject, 5 s
   horizon, the default models) for 20 simulated subjects, in this process (serial) and on a 2-worker
   ``LocalCluster`` that is already running (its start-up is reported on its own). The machine is shared: the
   load average before and after each run is reported with it.
2. **A 200-subject study** on 2 workers (in a subprocess, so that its peak memory is its own): wall time, peak
   resident memory of the client and of each worker.
3. **A worked estimate of 2,000 subjects on a 32-node cluster**, from measured task sizes: the seconds of one
   subject's task, the bytes of a task message, of a result and of a subject's Parquet partition, and the
   scheduler's cost per task.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from harness import markdown_table  # noqa: E402

from workbench.atomic import atomic_write_text  # noqa: E402
from workbench.models import make_models  # noqa: E402
from workbench.plant.system import planar_quadrotor  # noqa: E402
from workbench.sim.landing import simulate_study  # noqa: E402
from workbench.study import evaluate as ev  # noqa: E402

HORIZON = 100  # 5 s at dt = 0.05 s, the paper's multi-subject horizon
TRIALS = 11  # 10 training + 1 test per subject, the paper's design


def _load() -> str:
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


def _study(n_subjects: int):
    return simulate_study(n_subjects=n_subjects, n_trials=TRIALS, strategy="CS1", seed=0)


def _make_models():
    return functools.partial(make_models, planar_quadrotor(), n_components=5, random_state=0)


def _trivial(i: int) -> int:
    return i


def _warm(i: int) -> int:
    """Start-up of a worker: import what a per-subject task imports (the model stack, cvxpy, scikit-learn)."""
    import cvxpy  # noqa: F401
    import sklearn.cluster  # noqa: F401

    import workbench.models.proposed  # noqa: F401
    import workbench.study.evaluate  # noqa: F401

    return i


def _maxrss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def speedup(n_subjects: int = 20, workers: int = 2) -> dict:
    """Serial vs ``workers`` on a running LocalCluster; per-subject task times from the serial run."""
    from workbench.data.dataset import write_dataset
    from workbench.study.executor import DaskExecutor

    # Both sides read one dataset directory, as a study imported with `workbench import -o DATASET/` does:
    # each worker task then reads its own subject's partition, and nothing is staged inside the timing.
    tmp = tempfile.TemporaryDirectory()
    study = str(write_dataset(_study(n_subjects), Path(tmp.name) / "study"))
    make = _make_models()
    stamps: list[float] = []
    load0 = _load()
    t0 = time.perf_counter()
    serial = ev.per_subject(make, study, n_steps=HORIZON, seed=0,
                            progress=lambda d, n: stamps.append(time.perf_counter()))
    t_serial = time.perf_counter() - t0
    load1 = _load()
    task_s = [b - a for a, b in zip([t0, *stamps], stamps, strict=False)]
    t0 = time.perf_counter()
    with DaskExecutor(workers=workers) as ex:
        ex.map(_warm, list(range(workers * 4)))  # workers import the model stack once: part of start-up
        t_start = time.perf_counter() - t0
        load2 = _load()
        t0 = time.perf_counter()
        parallel = ev.per_subject(make, study, n_steps=HORIZON, seed=0, executor=ex)
        t_parallel = time.perf_counter() - t0
        load3 = _load()
        # the scheduler's cost per task: many empty tasks
        n_empty = 2000
        t0 = time.perf_counter()
        ex.map(_trivial, list(range(n_empty)))
        overhead_ms = 1000 * (time.perf_counter() - t0) / n_empty
    tmp.cleanup()
    import numpy as np
    import pandas as pd

    rest = [c for c in serial.table.columns if c != "value"]
    pd.testing.assert_frame_equal(serial.table[rest], parallel.table[rest], check_exact=True)  # same rows
    a, b = serial.table["value"].to_numpy(), parallel.table["value"].to_numpy()
    max_rel = float(np.nanmax(np.abs(a - b) / np.maximum(np.abs(a), 1e-300)))
    return {
        "subjects": n_subjects, "workers": workers, "serial_s": t_serial, "parallel_s": t_parallel,
        "speedup": t_serial / t_parallel, "cluster_start_s": t_start, "task_mean_s": statistics.mean(task_s),
        "task_max_s": max(task_s),
        "load_serial": f"{load0} → {load1}", "load_parallel": f"{load2} → {load3}",
        "scheduler_ms_per_task": overhead_ms, "max_rel_diff": max_rel, "cpus": os.cpu_count(),
    }


def task_sizes(n_subjects: int = 20) -> dict:
    """Bytes of one task message, one result and one subject's partition (what moves, and where)."""
    import cloudpickle

    from workbench.data.dataset import DataRef, read_manifest, write_dataset

    study = _study(n_subjects)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        path = write_dataset(study, Path(tmp) / "ds")
        t_stage = time.perf_counter() - t0
        parts = read_manifest(path).partitions
        part_bytes = statistics.mean((path / p.file).stat().st_size for p in parts)
        ref = DataRef(path=str(path))
        task = (ref, "s01", 1, 0, _make_models(), 5, HORIZON, "initial")
        task_bytes = len(cloudpickle.dumps(task))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            table, _, _ = ev._subject_task(task)
        result_bytes = len(cloudpickle.dumps((table, [], "rmse_position")))
    return {"task_bytes": task_bytes, "result_bytes": result_bytes, "partition_bytes": part_bytes,
            "stage_s_per_subject": t_stage / n_subjects, "samples_per_subject": study.n_samples / n_subjects}


def large(n_subjects: int = 200, workers: int = 2) -> dict:
    """The whole study on a fresh ``workers`` cluster: wall time (start-up included) and peak memory."""
    from workbench.study.executor import DaskExecutor

    t0 = time.perf_counter()
    study = _study(n_subjects)
    t_sim = time.perf_counter() - t0
    load0 = _load()
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with DaskExecutor(workers=workers) as ex:
            t_start = time.perf_counter() - t0
            res = ev.per_subject(_make_models(), study, n_steps=HORIZON, seed=0, executor=ex)
            worker_mb = [v / 1024.0 for v in ex.client.run(
                lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss).values()]
    wall = time.perf_counter() - t0
    return {"subjects": n_subjects, "workers": workers, "wall_s": wall, "cluster_start_s": t_start,
            "simulate_s": t_sim, "client_peak_mb": _maxrss_mb(), "worker_peak_mb": worker_mb,
            "rows": len(res.table), "anova": str(res.rm_anova), "load": f"{load0} → {_load()}"}


def estimate(sp: dict, sizes: dict, n_subjects: int = 2000, nodes: int = 32, cores_per_node: int = 16) -> dict:
    """2,000 subjects on ``nodes`` × ``cores_per_node`` single-threaded workers, from the measured numbers."""
    workers = nodes * cores_per_node
    t_task, t_max = sp["task_mean_s"], sp["task_max_s"]
    waves = math.ceil(n_subjects / workers)
    compute = waves * t_task + (t_max - t_task)  # full waves, and the slowest task as the tail
    scheduler = n_subjects * sp["scheduler_ms_per_task"] / 1000.0
    stage = n_subjects * sizes["stage_s_per_subject"]
    to_workers = n_subjects * sizes["task_bytes"]
    reads = n_subjects * sizes["partition_bytes"]
    results = n_subjects * sizes["result_bytes"]
    return {"subjects": n_subjects, "nodes": nodes, "cores_per_node": cores_per_node, "workers": workers,
            "t_task_s": t_task, "t_task_max_s": t_max, "waves": waves, "compute_s": compute,
            "scheduler_s": scheduler, "stage_s": stage, "task_mb": to_workers / 1e6, "read_mb": reads / 1e6,
            "result_mb": results / 1e6, "total_s": compute + scheduler, "total_staged_s": compute + scheduler + stage,
            "serial_one_core_s": n_subjects * t_task}


def _large_in_subprocess(n_subjects: int, workers: int) -> dict:
    out = subprocess.run([sys.executable, __file__, "--large-only", str(n_subjects), "--workers", str(workers)],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(n_subjects: int = 20, workers: int = 2) -> list[dict]:
    """Summary rows for ``bench/run_all.py`` (the 20-subject speed-up only; ``main`` runs the rest)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sp = speedup(n_subjects, workers)
    return [{"benchmark": "scale", "case": f"per-subject study, {n_subjects} subjects × {TRIALS} trials",
             "serial_s": sp["serial_s"], f"{workers}_workers_s": sp["parallel_s"], "speedup": sp["speedup"],
             "target": ">= 1.7", "met": sp["speedup"] >= 1.7, "load (1/5/15 min)": sp["load_parallel"],
             "max_rel_diff_vs_serial": sp["max_rel_diff"]}]


def _report(sp: dict, sizes: dict, lg: dict, est: dict) -> str:
    rows = [
        {"measurement": f"per-subject study, {sp['subjects']} subjects, serial (in process)", "value": sp["serial_s"],
         "unit": "s", "load (1/5/15 min) before → after": sp["load_serial"]},
        {"measurement": f"same study, {sp['workers']} workers (running LocalCluster)", "value": sp["parallel_s"],
         "unit": "s", "load (1/5/15 min) before → after": sp["load_parallel"]},
        {"measurement": "speed-up (target ≥ 1.7)", "value": sp["speedup"], "unit": "×"},
        {"measurement": "LocalCluster start-up incl. worker imports", "value": sp["cluster_start_s"], "unit": "s"},
        {"measurement": "same rows as serial; largest relative difference of a value", "value": sp["max_rel_diff"],
         "unit": ""},
        {"measurement": f"{lg['subjects']}-subject study, {lg['workers']} workers, wall (incl. start-up)",
         "value": lg["wall_s"], "unit": "s", "load (1/5/15 min) before → after": lg["load"]},
        {"measurement": f"{lg['subjects']}-subject study: client peak RSS", "value": lg["client_peak_mb"],
         "unit": "MB"},
        {"measurement": f"{lg['subjects']}-subject study: worker peak RSS (each)",
         "value": ", ".join(f"{v:.0f}" for v in lg["worker_peak_mb"]), "unit": "MB"},
    ]
    t = est
    per_task_20 = sp["parallel_s"] * sp["workers"] / sp["subjects"]
    waves_200 = math.ceil(lg["subjects"] / lg["workers"])
    staging_200 = lg["subjects"] * sizes["stage_s_per_subject"]
    per_task_200 = (lg["wall_s"] - lg["cluster_start_s"] - staging_200) / waves_200
    predicted_200 = lg["cluster_start_s"] + staging_200 + waves_200 * per_task_20
    lines = [
        "# Scaling out (bench/bench_scale.py)",
        "",
        f"Written by `python bench/bench_scale.py` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
        f"Python {platform.python_version()}, {sp['cpus']} CPUs, **shared with other agents' jobs** (the load "
        "average beside each timing; a load above the CPU count means the workers waited for a core).",
        "",
        f"Study: the paper's multi-subject design, {TRIALS} simulated CS1 trials per subject (10 train, 1 test), "
        f"{HORIZON}-step (5 s) horizon, the default models (proposed G=5, IOC-only, GMR-only, persistence); one "
        "task per subject, which reads its own Parquet partition.",
        "",
        markdown_table(rows),
        "",
        "## Measured task sizes",
        "",
        markdown_table([
            {"quantity": "one subject's fit-and-evaluate (mean of the serial run)", "value": t["t_task_s"],
             "unit": "s"},
            {"quantity": "slowest subject", "value": t["t_task_max_s"], "unit": "s"},
            {"quantity": "task message (pickled: data path, subject, settings, model factory)",
             "value": sizes["task_bytes"], "unit": "B"},
            {"quantity": "result (pickled tidy table of one subject)", "value": sizes["result_bytes"], "unit": "B"},
            {"quantity": "a subject's Parquet partition (read by the worker)", "value": sizes["partition_bytes"],
             "unit": "B"},
            {"quantity": "staging a subject's partition (client writes Parquet)",
             "value": 1000 * sizes["stage_s_per_subject"], "unit": "ms"},
            {"quantity": "scheduler round trip per task (2,000 empty tasks, 2 workers)",
             "value": sp["scheduler_ms_per_task"], "unit": "ms"},
        ]),
        "",
        f"## Estimate: {t['subjects']:,} subjects on a {t['nodes']}-node cluster",
        "",
        f"Assume {t['cores_per_node']} cores per node, one single-threaded worker process per core: "
        f"W = {t['nodes']} × {t['cores_per_node']} = {t['workers']} workers, and a core as fast as this machine's "
        "under its load (so the estimate is pessimistic on an idle cluster).",
        "",
        f"* **Compute**: {t['subjects']:,} tasks / {t['workers']} workers = {t['waves']} waves × "
        f"{t['t_task_s']:.2f} s + the slowest task's excess ({t['t_task_max_s'] - t['t_task_s']:.2f} s) "
        f"≈ **{t['compute_s']:.0f} s** (one core alone: {t['serial_one_core_s'] / 3600:.1f} h).",
        f"* **Scheduler**: {t['subjects']:,} × {sp['scheduler_ms_per_task']:.2f} ms ≈ {t['scheduler_s']:.1f} s of "
        "round trips, spread over the run (the Dask scheduler handles thousands of tasks per second; 2,000 tasks "
        "are far from its limits). Messages: "
        f"{t['task_mb']:.1f} MB of tasks out, {t['result_mb']:.1f} MB of results back to the client.",
        f"* **Data**: the workers read {t['read_mb']:.0f} MB of partitions from the shared file system in total "
        f"({sizes['partition_bytes'] / 1e3:.0f} kB each): seconds at any network file system's rate. "
        f"If the client stages the set (``--staging``), writing it costs {t['stage_s']:.0f} s up front; a "
        "dataset imported to shared storage (``workbench import LOGS -o /shared/ds/``) needs none.",
        f"* **Memory**: a worker holds one subject at a time (peak {max(lg['worker_peak_mb']):.0f} MB here); the "
        f"client holds the result tables ({t['result_mb']:.0f} MB) and the repeated-measures ANOVA.",
        f"* **Total** ≈ compute + scheduler ≈ **{t['total_s']:.0f} s** (≈ {t['total_s'] / 60:.1f} min) from a "
        f"dataset on shared storage, ≈ {t['total_staged_s']:.0f} s when the client stages an in-memory set first; "
        "plus the cluster's start-up (workers importing the workbench: "
        f"{sp['cluster_start_s']:.0f} s here, in parallel on every node). The run is compute-bound: "
        f"{t['waves']} waves of single-subject tasks; more nodes shorten it until W ≈ {t['subjects']:,} "
        f"(one wave, ≈ {t['t_task_max_s']:.0f} s, the slowest subject). Each node needs "
        f"{t['cores_per_node']} × {max(lg['worker_peak_mb']):.0f} MB ≈ "
        f"{t['cores_per_node'] * max(lg['worker_peak_mb']) / 1024:.1f} GB for its workers.",
        "",
        "How far the machine's load moves such an estimate, from the two runs above: a task took "
        f"{per_task_20:.1f} s per worker in the {sp['subjects']}-subject run on {sp['workers']} workers and "
        f"{per_task_200:.1f} s in the {lg['subjects']}-subject run (its wall time less start-up and staging, over "
        f"{math.ceil(lg['subjects'] / lg['workers'])} waves); the same model with the first figure predicts "
        f"{predicted_200:.0f} s for the {lg['subjects']}-subject run, which took {lg['wall_s']:.0f} s. On a shared "
        "machine per-task times vary by tens of percent; the estimate scales linearly with whichever is taken.",
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subjects", type=int, default=20)
    parser.add_argument("--large", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--large-only", type=int, metavar="N", help=argparse.SUPPRESS)
    parser.add_argument("--render", action="store_true",
                        help="write results_scale.md again from results_scale.json (the last run's measurements)")
    a = parser.parse_args(argv)
    if a.large_only:
        print(json.dumps(large(a.large_only, a.workers)))
        return 0
    raw = HERE / "results_scale.json"
    if a.render:  # the report again from the measurements of the last run
        sp, sizes, lg = (json.loads(raw.read_text())[k] for k in ("speedup", "sizes", "large"))
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sp = speedup(a.subjects, a.workers)
            print(json.dumps(sp), flush=True)
            sizes = task_sizes(a.subjects)
            print(json.dumps(sizes), flush=True)
        lg = _large_in_subprocess(a.large, a.workers)
        print(json.dumps(lg), flush=True)
        atomic_write_text(raw, json.dumps({"speedup": sp, "sizes": sizes, "large": lg}, indent=1))
    est = estimate(sp, sizes)
    text = _report(sp, sizes, lg, est)
    atomic_write_text(HERE / "results_scale.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
