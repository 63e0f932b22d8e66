"""The adaptive experiment's ``fit`` step: this subject's model, fitted on their own trials while they rest.

When a subject reaches a ``fit = { label = "CS1", from = "train" }`` step, :class:`FitJobs` starts
:func:`fit_subject` in a worker process (the study's :class:`~workbench.study.executor.ProcessExecutor`, the one
place that maps work to workers), so the server keeps answering while the model is fitted. The task reads the
subject's partitions from the session folder, keeps their trials of the label with role ``from``, landed and not
excluded, and fits the library's one default model (:func:`workbench.models.factory.default_model`: the model
``workbench fit`` builds and ``evaluate`` judges, G and the regularizer by cross-validation over the trials, with the
fallback to ``K̂x``; issue 40 §5). The paper's G = 5 is a model by name, fitted outside the session
(``workbench fit --n-components paper``) and given to the assisted blocks with ``--model``. It then
checks the model on the subject's held-out trials of the label (role test, not excluded): the position error of its
prediction from each one's start over :data:`~workbench.defaults.HORIZON_S`, the study's own score
(:func:`workbench.study.evaluate.compare`).

The model goes to ``DIR/_collect/models/<subject>/<label>.npz`` and its record (the file's SHA-256, the trials'
digest, their IDs, the held-out error) to ``<label>.json``, both atomically: the record's existence is what makes
the step done. A server killed while fitting leaves neither; the step fits again when the subject comes back (the
same trials and seed give the same model). A fit that fails writes ``<label>.failed.json`` with its one-line
reason; the experimenter can ask for it again (the experimenter's page).
"""

from __future__ import annotations

import hashlib
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from workbench.collect.subjects import now, read_json, write_json
from workbench.defaults import HORIZON_S
from workbench.errors import DataError, WorkbenchError

__all__ = ["Jobs", "FitJobs", "fit_subject", "model_paths", "file_digest", "in_process", "load_fitted"]


def model_paths(out: Path, subject: str, label: str) -> tuple[Path, Path, Path]:
    """The model file, its record and its failure record of one subject's fit of ``label``."""
    folder = Path(out) / "_collect" / "models" / subject
    return folder / f"{label}.npz", folder / f"{label}.json", folder / f"{label}.failed.json"


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes: a model's identity in every trial it assisted."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _usable(d: Any) -> bool:
    return not d.meta.get("excluded", False)


def fit_subject(task: tuple) -> dict[str, Any]:
    """One fit step, in a worker: ``(out, subject, label, source, min_trials, seed)`` → the fit's record.

    Raises
    ------
    DataError
        Fewer than ``min_trials`` landed, not excluded trials of the label and role to fit on.
    """
    from workbench.data.dataset import load_dataset
    from workbench.models.factory import default_model
    from workbench.plant.system import planar_quadrotor
    from workbench.study.evaluate import compare, primary_metric

    out, subject, label, source, min_trials, seed = task
    t0 = time.perf_counter()
    ds = load_dataset(out, subjects=[subject])
    mine = ds.filter(lambda d: d.meta.get("label") == label and _usable(d))
    train = mine.filter(lambda d: d.meta.get("role") == source and d.meta.get("outcome") == "landed")
    test = mine.filter(lambda d: d.meta.get("role") == "test" and not d.meta.get("assist"))  # flown unassisted
    if len(train) < min_trials:
        raise DataError(f"subject {subject}: {len(train)} landed, not excluded {label} {source} trial(s); the fit "
                        f"step needs at least {min_trials}")
    plant = planar_quadrotor()
    model = default_model(plant, random_state=seed).fit(train)
    path, record_path, _ = model_paths(Path(out), subject, label)
    model.save(path)
    n_steps = max(1, round(HORIZON_S / plant.dt))
    held: list[dict[str, Any]] = []
    metric = primary_metric(plant)
    if len(test):
        table = compare({"proposed": model}, test, n_steps=n_steps)
        rows = table[(table["metric"] == metric) & (table["method"] == "proposed")]
        held = [{"id": str(r.trial), "error": float(r.value)} for r in rows.itertuples(index=False)]
    errors = [h["error"] for h in held]
    record = {
        "kind": "fit", "subject": subject, "label": label, "from": source, "model": path.name,
        "digest": file_digest(path), "data_digest": model.data_digest_, "train_ids": list(model.train_ids_),
        "n_train": len(train),
        "metric": metric, "horizon_s": n_steps * plant.dt, "held_out": held,
        "held_out_error": (sum(errors) / len(errors)) if errors else None,
        **_settings(model), "fitted": now(),
        "seconds": round(time.perf_counter() - t0, 2),
    }
    write_json(record_path, record)
    return record


def _settings(model: Any) -> dict[str, Any]:
    """What the default model chose, for the fit's record: the G it fitted, and what cross-validation chose and
    whether it fell back to ``K̂x`` (``settings``: its one line; ``None`` where too few trials left nothing to
    cross-validate, the model's warning then says which defaults it took)."""
    auto = model.auto_ if model.chooses_settings else None
    return {"n_components": int(model.n_components_), "reg_covar": float(model.reg_covar_),
            "settings": None if auto is None else auto.describe(),
            "fallback": None if auto is None else bool(auto.fallback)}


class Jobs:
    """Background work of a session (fit steps, stopping rules' checks), at most one running per key, each task
    run by ``runner(fn, task)`` (default: in a worker process); ``on_done(result)`` is told of each end, from the
    job's thread. A task's record file is written by the task itself; a failure is written here, in one line."""

    def __init__(self, on_done: Callable[[dict[str, Any]], None] | None = None,
                 runner: Callable[[Callable, tuple], dict[str, Any]] | None = None) -> None:
        self.on_done = on_done
        self._runner = runner or _in_worker
        self._lock = threading.Lock()
        self._running: dict[tuple, threading.Thread] = {}

    def running(self, key: tuple) -> bool:
        with self._lock:
            return key in self._running

    def start(self, key: tuple, fn: Callable[[tuple], dict[str, Any]], task: tuple, failed: Path,
              what: dict[str, Any]) -> None:
        """Run ``fn(task)`` unless a job of ``key`` is running; ``what`` names it in a failure's record."""
        with self._lock:
            if key in self._running:
                return
            thread = threading.Thread(target=self._job, args=(key, fn, task, failed, what), daemon=True,
                                      name="-".join(map(str, key)))
            self._running[key] = thread
        thread.start()

    def _job(self, key: tuple, fn: Callable, task: tuple, failed: Path, what: dict[str, Any]) -> None:
        try:
            result = {"state": "ready", **self._runner(fn, task)}
        except WorkbenchError as exc:
            result = {"state": "failed", **what, "reason": " ".join(str(exc).split()), "at": now()}
            write_json(failed, result)
        except Exception as exc:  # a worker that died (BrokenProcessPool) or a bug: said, never lost
            result = {"state": "failed", **what, "reason": f"{type(exc).__name__}: {' '.join(str(exc).split())}",
                      "at": now()}
            write_json(failed, result)
        finally:
            with self._lock:
                self._running.pop(key, None)
        if self.on_done is not None:
            self.on_done(result)

    def wait(self, timeout_s: float = 120.0) -> None:
        """Wait for every running job (tests, and the server's shutdown)."""
        deadline = time.monotonic() + timeout_s
        while True:
            with self._lock:
                threads = list(self._running.values())
            if not threads or time.monotonic() > deadline:
                return
            threads[0].join(timeout=max(0.0, deadline - time.monotonic()))


class FitJobs:
    """The fit steps of a session: :func:`fit_subject` per (subject, label), on :class:`Jobs`."""

    def __init__(self, out: Path, seed: int, jobs: Jobs) -> None:
        self.out, self.seed, self.jobs = Path(out), seed, jobs

    def state(self, subject: str, label: str) -> dict[str, Any]:
        """``{"state": "ready"|"failed"|"fitting"|"waiting", …}`` with the record or the failure's reason."""
        _, record, failed = model_paths(self.out, subject, label)
        if record.is_file():
            return {"state": "ready", **read_json(record, "fit record")}
        if failed.is_file():
            return {"state": "failed", **read_json(failed, "fit failure")}
        return {"state": "fitting" if self.jobs.running(("fit", subject, label)) else "waiting"}

    def start(self, subject: str, label: str, source: str, min_trials: int) -> None:
        """Start the fit unless it is done, failed or running (a resumed session starts it again)."""
        if self.state(subject, label)["state"] != "waiting":
            return
        task = (str(self.out), subject, label, source, min_trials, self.seed)
        self.jobs.start(("fit", subject, label), fit_subject, task, model_paths(self.out, subject, label)[2],
                        {"kind": "fit", "subject": subject, "label": label})

    def retry(self, subject: str, label: str) -> None:
        """Forget a failed fit, so that the subject's next status starts it again."""
        model_paths(self.out, subject, label)[2].unlink(missing_ok=True)

    def wait(self, timeout_s: float = 120.0) -> None:
        self.jobs.wait(timeout_s)


def _in_worker(fn: Callable[[tuple], dict[str, Any]], task: tuple) -> dict[str, Any]:
    from workbench.study.executor import ProcessExecutor

    with ProcessExecutor(workers=1) as ex:
        (record,) = ex.map(fn, [task])
    return record


def in_process(fn: Callable[[tuple], dict[str, Any]], task: tuple) -> dict[str, Any]:
    """A runner of :class:`Jobs` that runs the task here (tests, scripts)."""
    return fn(task)


def load_fitted(out: Path, subject: str, label: str, cache: dict) -> tuple[Any, dict[str, Any]]:
    """The fitted model of a subject's label and its record, loaded once (keyed by the file's digest)."""
    from workbench.models import load_model

    path, record_path, _ = model_paths(out, subject, label)
    if not record_path.is_file():
        raise DataError(f"subject {subject}: the model of {label} is not fitted yet")
    record = read_json(record_path, "fit record")
    key = (subject, label, record["digest"])
    if key not in cache:
        if file_digest(path) != record["digest"]:
            raise DataError(f"{path}: not the model its record names (digest differs); fit it again")
        cache[key] = load_model(path)
    return cache[key], record
