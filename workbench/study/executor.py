"""The one place that maps independent work over workers: in this process, or on a Dask cluster.

Studies are made of independent tasks: one log's import, one subject's fit and evaluation, a block of
bootstrap resamples, one data-efficiency point. Whoever has such a loop builds a list of small task
descriptions and a module-level function that does one, and hands both to an executor:

>>> with make_executor(workers=2) as ex:                       # doctest: +SKIP
...     ref = ex.share(demos, by_subject=True)                 # where workers read the data (Parquet)
...     tables = ex.map(fit_one_subject, [(ref, s) for s in subjects], progress=bar)

* :class:`SerialExecutor` (the default) runs the tasks here, in order, and imports no Dask.
* :class:`DaskExecutor` runs them on ``dask.distributed``: a ``LocalCluster`` of N worker processes
  (``--workers N``) or an existing cluster (``--scheduler ADDRESS``). Dask is imported only when one is made.

What both guarantee:

* **Same results.** :meth:`~SerialExecutor.map` returns the results in task order whatever order they finish in;
  a task that needs randomness derives its seed from the master seed and its own identity (:func:`task_seed`),
  never from a generator shared across tasks; every task runs with one BLAS/OpenMP thread, here as on a worker,
  so that floating-point reductions are the same.
* **Small messages.** Data travel as paths: :meth:`~SerialExecutor.share` turns a set into a
  :class:`~workbench.data.dataset.DataRef` (the set itself here; a Parquet file or a per-subject dataset in the
  staging folder for workers), and a worker reads what its task needs.
* **Failures contained.** :meth:`~SerialExecutor.map_outcomes` reports each failed task (its key and cause) and
  completes the others. On Dask a task whose worker dies is run again on another worker (the scheduler's
  ``allowed-failures``), and a task that raises something other than a
  :class:`~workbench.errors.WorkbenchError` is retried ``retries`` times; a ``WorkbenchError`` (bad data) is
  final at once.
* **Warnings** a task raises on a worker are raised again here, in task order, so callers that count them
  (e.g. EM stopping at ``max_iter``) see the same as in a serial run.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
import uuid
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from workbench import interrupts
from workbench.data.dataset import DataRef, write_dataset
from workbench.data.demonstrations import DemonstrationSet
from workbench.errors import DataError, UsageError, WorkbenchError

__all__ = [
    "Executor", "SerialExecutor", "ProcessExecutor", "DaskExecutor", "Outcome", "make_executor", "local_executor",
    "available_cpus", "task_seed", "serial", "warm_local_workers", "stop_local_workers",
]

Progress = Callable[[int, int], Any]
#: Re-runs of a task that raised something unexpected (an OSError on a network file system, a MemoryError).
DEFAULT_RETRIES = 2
#: Seconds a study waits for a scheduler given by address to have its first worker, then stops with an error.
WORKER_WAIT = 30.0


def task_seed(seed: int, *key: Any) -> np.random.SeedSequence:
    """The seed of one task: the master ``seed`` and a stable hash of the task's identity ``key``.

    The same (seed, key) gives the same stream in any process, on any machine, whatever else runs; Python's
    ``hash()`` would not (it is salted per process). Use it as ``np.random.default_rng(task_seed(seed, "subject",
    name))``.
    """
    text = json.dumps([str(k) for k in key], ensure_ascii=False)
    words = np.frombuffer(hashlib.blake2b(text.encode("utf-8"), digest_size=16).digest(), dtype="<u4")
    return np.random.SeedSequence([int(seed) % 2**64, *(int(w) for w in words)])


@dataclass(frozen=True)
class Outcome:
    """One task's result or, when it failed, its cause (``error``: the exception's type and message)."""

    key: str
    value: Any = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


class Executor(Protocol):
    """What the studies use; :class:`SerialExecutor` and :class:`DaskExecutor` implement it."""

    parallel: bool
    workers: int

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any], *, progress: Progress | None = None) -> list:
        ...

    def map_outcomes(
        self, fn: Callable[[Any], Any], items: Sequence[Any], *, keys: Sequence[str] | None = None,
        progress: Progress | None = None,
    ) -> list[Outcome]:
        ...

    def share(self, demos: Any, *, by_subject: bool = False) -> DataRef:
        ...


# ------------------------------------------------------------------------------------ thread limits

_CONTROLLER: Any = None


def _controller() -> Any:
    global _CONTROLLER
    if _CONTROLLER is None:
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER


_WORKER_LIMIT: Any = None


def _limit_worker_threads() -> None:
    """One BLAS and OpenMP thread for the rest of this worker process (N workers on N cores, not N × cores).

    Called by every task rather than once per worker, so a worker restarted after a crash is limited too.
    """
    global _WORKER_LIMIT
    if _WORKER_LIMIT is None:
        _WORKER_LIMIT = _controller().limit(limits=1)  # held for the life of the process


def _warning_records(caught: list[warnings.WarningMessage]) -> list[tuple[type[Warning], str]]:
    return [(w.category, str(w.message)) for w in caught]


def _run_task(fn: Callable[[Any], Any], item: Any) -> tuple[Any, list[tuple[type[Warning], str]], BaseException | None]:
    """Run one task on a worker: (value, warnings, WorkbenchError or None).

    A ``WorkbenchError`` is returned, not raised: it is a property of the data (a corrupt log), and Dask would
    otherwise retry it. Anything else is raised, so Dask retries it.
    """
    _limit_worker_threads()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            value = fn(item)
        except WorkbenchError as exc:
            return None, _warning_records(caught), exc
    return value, _warning_records(caught), None


def _replay(emitted: list[list[tuple[type[Warning], str]]]) -> None:
    """Raise the warnings the tasks raised on workers again here, in task order, whatever order they finished in."""
    for caught in emitted:
        for category, message in caught:
            warnings.warn(message, category, stacklevel=4)


def _describe(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _keys(items: Sequence[Any], keys: Sequence[str] | None) -> list[str]:
    if keys is None:
        return [f"task {i}" for i in range(len(items))]
    if len(keys) != len(items):
        raise DataError(f"{len(keys)} keys for {len(items)} tasks")
    return [str(k) for k in keys]


#: Temporary staging folders are named ``workbench-staging-<pid>-…``: a folder whose process no longer runs (killed
#: before it could remove it) is removed by the next one made (:func:`remove_stale_staging`).
STAGING_PREFIX = "workbench-staging-"


def remove_stale_staging(folder: str | os.PathLike | None = None) -> list[Path]:
    """Remove the staging folders of processes that no longer run, from ``folder`` (the temporary folder)."""
    from workbench.atomic import LEGACY_AGE, _alive

    folder = Path(folder or tempfile.gettempdir())
    removed = []
    try:
        entries = [e for e in folder.iterdir() if e.name.startswith(STAGING_PREFIX)]
    except OSError:
        return removed
    for entry in entries:
        pid = entry.name[len(STAGING_PREFIX):].split("-", 1)[0]
        try:
            stale = not _alive(int(pid)) if pid.isdigit() else time.time() - entry.lstat().st_mtime > LEGACY_AGE
            if stale and entry.is_dir() and not entry.is_symlink() and entry.stat().st_uid == os.getuid():
                shutil.rmtree(entry, ignore_errors=True)
                removed.append(entry)
        except OSError:
            continue
    return removed


class Staging:
    """The folder where sets are written for worker processes to read (data travel as paths, not in messages).

    ``path`` None: a fresh temporary folder, made on first use and removed by :meth:`close`.
    """

    def __init__(self, path: str | os.PathLike | None = None) -> None:
        self._own = path is None
        self._path = Path(path) if path is not None else None
        self._n = 0
        if self._own:
            remove_stale_staging()

    def _dir(self) -> Path:
        if self._path is None:
            self._path = Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{os.getpid()}-"))
        self._path.mkdir(parents=True, exist_ok=True)
        return self._path

    def share(self, demos: Any, *, by_subject: bool = False) -> DataRef:
        """The set written here, one Parquet file or (with ``by_subject``) a dataset with one partition per subject;
        a path or a path reference is used as it is."""
        if isinstance(demos, DataRef) and demos.path is not None:
            return demos
        if isinstance(demos, str | os.PathLike):
            return DataRef(path=str(demos))
        if isinstance(demos, DataRef):
            demos = demos.demos
        if not isinstance(demos, DemonstrationSet):
            raise DataError(f"can only share a DemonstrationSet or a path with workers, not a {type(demos).__name__}")
        self._n += 1
        target = self._dir() / f"share-{self._n:04d}-{uuid.uuid4().hex[:8]}"
        if by_subject:
            return DataRef(path=str(write_dataset(demos, target)))
        return DataRef(path=str(demos.save(target.with_suffix(".parquet"))))

    def close(self) -> None:
        """Remove the folder if this object made it."""
        if self._own and self._path is not None:
            shutil.rmtree(self._path, ignore_errors=True)


# -------------------------------------------------------------------------------------------- serial


class SerialExecutor:
    """Every task in this process, one after the other: the default, with nothing to start or stop."""

    parallel = False
    workers = 1

    def __enter__(self) -> SerialExecutor:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Nothing to release."""

    def __repr__(self) -> str:
        return "SerialExecutor()"

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any], *, progress: Progress | None = None) -> list:
        """``[fn(item) for item in items]``, one BLAS thread each, reporting ``progress(done, total)``."""
        items, out = list(items), []
        with _controller().limit(limits=1):
            for i, item in enumerate(items):
                out.append(fn(item))
                interrupts.check()  # a Ctrl-C a finaliser swallowed during the task stops the next one
                if progress is not None:
                    progress(i + 1, len(items))
        return out

    def map_outcomes(
        self, fn: Callable[[Any], Any], items: Sequence[Any], *, keys: Sequence[str] | None = None,
        progress: Progress | None = None,
    ) -> list[Outcome]:
        """As :meth:`map`, but a task that raises is an :class:`Outcome` with its error; the others still run."""
        items = list(items)
        names = _keys(items, keys)
        out = []
        with _controller().limit(limits=1):
            for i, item in enumerate(items):
                try:
                    out.append(Outcome(names[i], fn(item)))
                except Exception as exc:  # contained: the caller reports it with the task's key
                    out.append(Outcome(names[i], error=_describe(exc)))
                interrupts.check()  # the task's failure may be the interrupt's doing: report the interrupt
                if progress is not None:
                    progress(i + 1, len(items))
        return out

    def share(self, demos: Any, *, by_subject: bool = False) -> DataRef:
        """A reference to ``demos`` (a set, a path, or a reference) for tasks run here: nothing is copied."""
        if isinstance(demos, DataRef):
            return demos
        if isinstance(demos, str | os.PathLike):
            return DataRef(path=str(demos))
        return DataRef(demos=demos)


#: The default executor of every ``executor=`` keyword.
serial = SerialExecutor()


# ---------------------------------------------------------------------------------------------- Dask


def _settle(name: str, returned: Any, exc: BaseException | None, contain: bool) -> tuple[Outcome, list]:
    """One task's :class:`Outcome` and warnings, from what its worker returned (:func:`_run_task`'s triple) or the
    exception that ended it; the error is raised instead where ``contain`` is false."""
    caught: list[tuple[type[Warning], str]] = []
    if exc is None:
        value, caught, exc = returned
    if exc is not None:
        if not contain:
            raise exc
        return Outcome(name, error=_describe(exc)), caught
    return Outcome(name, value), caught


class _Workers:
    """What the executors with workers share: :meth:`map` and :meth:`map_outcomes` over their ``_run``."""

    def _run(self, fn: Callable[[Any], Any], items: Sequence[Any], names: list[str], progress: Progress | None,
             contain: bool) -> list[Outcome]:
        raise NotImplementedError

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any], *, progress: Progress | None = None) -> list:
        """``[fn(item) for item in items]`` on the workers, in task order; the first failure is raised."""
        items = list(items)
        return [o.value for o in self._run(fn, items, _keys(items, None), progress, contain=False)]

    def map_outcomes(
        self, fn: Callable[[Any], Any], items: Sequence[Any], *, keys: Sequence[str] | None = None,
        progress: Progress | None = None,
    ) -> list[Outcome]:
        """One :class:`Outcome` per task, in task order; a failed task is reported, the others complete."""
        items = list(items)
        return self._run(fn, items, _keys(items, keys), progress, contain=True)


def _connect(client_class: Any, scheduler: str, timeout: float, attempts: int = 2) -> Any:
    """A client of the scheduler at ``scheduler``; a connection the client library itself finds malformed (an
    ``AssertionError`` inside distributed's handshake, seen once in a loaded test run while another client of the
    same cluster closed) is tried again once, then said in one line like any failure to reach it."""
    for _ in range(max(1, attempts) - 1):
        try:
            return _client(client_class, scheduler, timeout)
        except AssertionError:
            continue
    try:
        return _client(client_class, scheduler, timeout)
    except AssertionError:
        raise WorkbenchError(f"cannot reach the Dask scheduler at {scheduler}: its answers to {max(1, attempts)} "
                             "connections were not a Dask scheduler's") from None


def _client(client_class: Any, scheduler: str, timeout: float) -> Any:
    try:
        return client_class(scheduler, timeout=f"{timeout}s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise WorkbenchError(f"cannot reach the Dask scheduler at {scheduler}: {_describe(exc)}") from None


class DaskExecutor(_Workers):
    """Tasks on ``dask.distributed``: a ``LocalCluster`` of ``workers`` processes, or the cluster at ``scheduler``.

    Parameters
    ----------
    workers : int, optional
        Start a local cluster of this many single-threaded worker processes (stopped by :meth:`close`).
    scheduler : str, optional
        Instead, connect to a running scheduler, e.g. ``tcp://10.0.0.5:8786``. Its workers must have the
        workbench installed and must reach ``staging`` (and any input paths) under the same names.
    staging : path, optional
        Folder where :meth:`share` writes the sets workers read. Default: a fresh temporary folder (removed by
        :meth:`close`), which only a local cluster can see; on a real cluster give a shared file system path.
    retries : int
        Re-runs of a task that raised an unexpected exception (a ``WorkbenchError`` is not retried).
    timeout : float
        Seconds to wait for the scheduler at ``scheduler``.
    worker_wait : float
        Seconds to wait for the scheduler at ``scheduler`` to have a worker (:data:`WORKER_WAIT`); a scheduler
        still without one then is an error, where tasks sent to it would wait forever.

    Raises
    ------
    WorkbenchError
        Neither or both of ``workers`` and ``scheduler``, a worker count below 1, or a scheduler that cannot
        be reached.
    """

    parallel = True

    def __init__(
        self, workers: int | None = None, scheduler: str | None = None, *, staging: str | os.PathLike | None = None,
        retries: int = DEFAULT_RETRIES, timeout: float = 15.0, worker_wait: float | None = None,
    ) -> None:
        if (workers is None) == (scheduler is None):
            raise WorkbenchError("give either a number of local workers or a scheduler address")
        if workers is not None and int(workers) < 1:
            raise WorkbenchError(f"the number of workers must be at least 1, got {workers}")
        import logging

        from dask.distributed import Client, LocalCluster

        self.retries = int(retries)
        self._cluster = None
        self._staging = Staging(staging)
        if scheduler is not None:
            from workbench.study.handshake import check_scheduler

            check_scheduler(scheduler, min(float(timeout), 10.0))  # a server that is not Dask: one line, not a hang
            self._client = _connect(Client, scheduler, float(timeout))
            self.address = str(scheduler)
            wait = WORKER_WAIT if worker_wait is None else float(worker_wait)
            try:
                self._client.wait_for_workers(1, timeout=wait)
            except (TimeoutError, OSError) as exc:
                self._client.close()
                why = (f"has no worker (waited {wait:g} s); start one with `dask worker {scheduler}`"
                       if isinstance(exc, TimeoutError) else f"cannot be reached: {_describe(exc)}")
                raise WorkbenchError(f"the Dask scheduler at {scheduler} {why}") from None
        else:
            self._cluster = LocalCluster(
                # any free port for the scheduler's HTTP endpoint: two studies at once must not collide on 8787
                n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=":0",
                silence_logs=logging.ERROR,
            )
            self._client = Client(self._cluster)
            self.address = self._cluster.scheduler_address

    @property
    def client(self) -> Any:
        """The ``dask.distributed.Client``."""
        return self._client

    @property
    def workers(self) -> int:
        """Worker threads the scheduler knows now (one per process on a local cluster)."""
        info = self._client.scheduler_info()
        return max(1, sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()))

    def __repr__(self) -> str:
        return f"DaskExecutor({self.address}, {self.workers} workers)"

    def __enter__(self) -> DaskExecutor:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Disconnect, stop the local cluster (if this executor started one) and remove its own staging folder."""
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._staging.close()

    def share(self, demos: Any, *, by_subject: bool = False) -> DataRef:
        """A path reference workers read (:meth:`Staging.share`)."""
        return self._staging.share(demos, by_subject=by_subject)

    # -- tasks -------------------------------------------------------------------------------------------
    def _run(self, fn: Callable[[Any], Any], items: Sequence[Any], names: list[str], progress: Progress | None,
             contain: bool) -> list[Outcome]:
        from dask.distributed import as_completed

        token = uuid.uuid4().hex[:8]
        label = getattr(fn, "__name__", "task").strip("_") or "task"
        # one batched submission: the scheduler hears of every task in one message, not one message per task
        futures = self._client.map(_run_task, [fn] * len(items), items, key=[f"{label}-{token}-{i}" for i in
                                                                              range(len(items))],
                                   pure=False, retries=self.retries)
        position = {f.key: i for i, f in enumerate(futures)}
        results: list[Outcome | None] = [None] * len(items)
        emitted: list[list[tuple[type[Warning], str]]] = [[] for _ in items]
        done = 0
        try:
            # results come in batches as they finish (one round trip per batch, not per task)
            for fut, result in as_completed(futures, with_results=True, raise_errors=False):
                interrupts.check()
                i = position[fut.key]
                if fut.status != "finished":  # retries used up, every worker that tried it died, or cancelled
                    if isinstance(result, tuple) and len(result) == 3:  # dask gives (type, exception, traceback)
                        result = result[1]
                    exc = result if isinstance(result, BaseException) else RuntimeError(f"task {fut.status}")
                    results[i], emitted[i] = _settle(names[i], None, exc, contain)
                else:
                    results[i], emitted[i] = _settle(names[i], result, None, contain)
                fut.release()
                done += 1
                if progress is not None:
                    progress(done, len(items))
        finally:
            self._client.cancel([f for f in futures if not f.done()])
        _replay(emitted)
        return [r for r in results if r is not None]



class ProcessExecutor(_Workers):
    """Tasks in a pool of local worker processes (``concurrent.futures``, started with ``spawn``): no Dask and no
    cluster to start, for a handful of big tasks on one machine (e.g. a study's strategies).

    Each worker imports what its first task needs (about 2 s, while this process works on), runs with one BLAS
    thread, and reads the sets :meth:`share` wrote to a temporary folder: for many machines use
    :class:`DaskExecutor`. ``spawn``, not ``fork``: a fork would copy this process's threads'
    locks (the progress bar's, BLAS's) in whatever state they are. After :func:`warm_local_workers` they are forked
    from its server instead, a process without such threads that imported the study's modules once.
    """

    parallel = True

    def __init__(self, workers: int | None = None) -> None:
        n = available_cpus() if workers is None else int(workers)
        if n < 1:
            raise WorkbenchError(f"the number of worker processes must be at least 1, got {workers}")
        self.workers = n
        self._pool: Any = None
        self._staging = Staging()

    def __repr__(self) -> str:
        return f"ProcessExecutor({self.workers} processes)"

    def __enter__(self) -> ProcessExecutor:
        return self

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        self.close(abort=exc_type is not None)

    def close(self, abort: bool = False) -> None:
        """Stop the workers; tasks not started are cancelled. ``abort`` (an error or Ctrl-C here): running tasks
        are not waited for either, their workers are ended."""
        try:
            if self._pool is not None:
                if abort:
                    terminate = getattr(self._pool, "terminate_workers", None)  # Python 3.14+
                    if terminate is not None:
                        terminate()
                    else:  # before 3.14 the pool's processes are only reachable through its attribute
                        for proc in list(getattr(self._pool, "_processes", {}).values()):
                            proc.terminate()
                self._pool.shutdown(wait=True, cancel_futures=True)
                self._pool = None
        finally:  # Ctrl-C while the workers stop must not leave the shared sets behind
            self._staging.close()

    def share(self, demos: Any, *, by_subject: bool = False) -> DataRef:
        """A path reference workers read (:meth:`Staging.share`, in a temporary folder)."""
        return self._staging.share(demos, by_subject=by_subject)

    def _run(self, fn: Callable[[Any], Any], items: Sequence[Any], names: list[str], progress: Progress | None,
             contain: bool) -> list[Outcome]:
        import multiprocessing
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

        if self._pool is None:
            self._pool = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context(_START_METHOD),
                                             initializer=_quiet_interrupts)
        with _spawning_without_interrupts():
            futures = [self._pool.submit(_run_task, fn, item) for item in items]
        position = {f: i for i, f in enumerate(futures)}
        results: list[Outcome | None] = [None] * len(items)
        emitted: list[list[tuple[type[Warning], str]]] = [[] for _ in items]
        pending, done = set(futures), 0
        try:
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                # Ctrl-C reaches the workers too: their deaths (BrokenProcessPool) are the interrupt, not a failure,
                # also when the KeyboardInterrupt itself was swallowed (workbench.interrupts)
                interrupts.check()
                for fut in sorted(finished, key=position.__getitem__):
                    i = position[fut]
                    exc = fut.exception()  # the worker died (BrokenProcessPool) or the task raised
                    results[i], emitted[i] = _settle(names[i], None if exc else fut.result(), exc, contain)
                    done += 1
                    if progress is not None:
                        progress(done, len(items))
        finally:
            for fut in pending:
                fut.cancel()
        _replay(emitted)
        return [r for r in results if r is not None]



@contextmanager
def _spawning_without_interrupts() -> Iterator[None]:
    """Start worker processes with Ctrl-C blocked until their initializer (:func:`_quiet_interrupts`) unblocks it.

    A process inherits its parent thread's signal mask across ``fork`` and ``exec``, so a Ctrl-C during a worker's
    interpreter start-up stays pending instead of printing a traceback from ``site``, and ends the worker quietly
    once its initializer runs. Blocked, not ignored: an ignored Ctrl-C was lost to the command too, which then went
    on (a hang) or failed on its workers' deaths (``BrokenProcessPool``), as the attack round found under load; a
    blocked one reaches the command when its mask is restored, or at once through another of its threads.
    """
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    # Another thread of this process (the progress bar's, the pool's) may take the Ctrl-C that this one blocks;
    # Python then runs the handler here at once, and a KeyboardInterrupt between a worker's start and the write of
    # its start-up data left that worker reading an empty pipe (EOFError traceback from multiprocessing's
    # spawn_main, found by the merged suite). Held until every worker is started, then raised as it would have been.
    held: list[int] = []
    handler = signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum))
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)
        signal.signal(signal.SIGINT, handler)
        if held:
            signal.raise_signal(signal.SIGINT)


def _quiet_interrupts() -> None:
    """In a worker process: Ctrl-C (the terminal sends it to the whole process group) ends the worker at once and
    silently; the command that started it reports the interrupt, in one line, and stops the pool. A Ctrl-C that
    came during the worker's start-up (blocked, :func:`_spawning_without_interrupts`) is delivered here."""
    _die_with_parent()
    signal.signal(signal.SIGINT, _exit_interrupted)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """In a worker process: be killed when the command that started it dies, however it dies (SIGKILL included).

    Linux's parent-death signal (``prctl(PR_SET_PDEATHSIG)``), through ctypes: without it a killed command left
    its workers and their resource tracker running under PID 1 (~575 MiB, for minutes). A parent already gone
    by now (reparented) ends the worker at once. Elsewhere nothing happens: the pool's own pipes end workers
    whose parent exited cleanly.
    """
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    parent = os.getppid()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent or parent == 1:
        os._exit(1)


def _exit_interrupted(signum: int, frame: Any) -> None:
    os._exit(128 + signum)  # no traceback of a worker waiting for its next task, no clean-up to run


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity mask where the system has one, else the CPU count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


#: How local worker processes start: ``"spawn"``, a fresh interpreter that imports what its tasks need (~2 s of CPU
#: each), or, once :func:`warm_local_workers` started its server, ``"forkserver"``: forked from a process that
#: imported them once, while the command read its input.
_START_METHOD = "spawn"


def warm_local_workers(modules: Sequence[str]) -> bool:
    """Start the server that local workers (:class:`ProcessExecutor`) are forked from, importing ``modules`` there
    now: a command that will run a study on local workers calls this before it reads its input, so the imports
    run beside that on another core, once instead of once per worker. False where it cannot (no ``forkserver``
    start method): workers are then spawned as before.

    The server starts with Ctrl-C blocked (:func:`_spawning_without_interrupts`) and its workers inherit that, so a
    Ctrl-C during a worker's start-up still reaches it only in :func:`_quiet_interrupts`; the server ends with this
    process, and its workers with it (:func:`_die_with_parent`).
    """
    global _START_METHOD
    import multiprocessing

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return False
    try:
        from multiprocessing import forkserver, resource_tracker

        # this module too: every worker runs its tasks through it (_run_task, _quiet_interrupts)
        multiprocessing.get_context("forkserver").set_forkserver_preload([__name__, *modules])
        # the resource tracker first: starting it unblocks Ctrl-C (SIG_UNBLOCK, not the mask it found), which would
        # let a Ctrl-C kill the server in its interpreter's start-up ("Fatal Python error: init_import_site")
        resource_tracker.ensure_running()
        with _spawning_without_interrupts():
            forkserver.ensure_running()
    except (OSError, ValueError):
        return False
    _START_METHOD = "forkserver"
    return True


def stop_local_workers() -> None:
    """Stop the server of :func:`warm_local_workers` and wait for it (later workers are spawned again): its memory is
    freed, and the CPU time of the workers it forked counts in this process's children's, as a spawned worker's
    does (``bench_demo``'s CPU column)."""
    global _START_METHOD
    if _START_METHOD != "forkserver":
        return
    from multiprocessing import forkserver

    stop = getattr(getattr(forkserver, "_forkserver", None), "_stop", None)
    if stop is not None:
        stop()
    _START_METHOD = "spawn"


def local_executor(tasks: int) -> SerialExecutor | ProcessExecutor:
    """For ``tasks`` big independent tasks on this machine: a :class:`ProcessExecutor` with a worker per task (up
    to the CPUs available), or serial where there is one task or one CPU (a worker would only add its start-up)."""
    n = min(int(tasks), available_cpus())
    return ProcessExecutor(n) if n >= 2 else SerialExecutor()


def make_executor(
    workers: int | None = None, scheduler: str | None = None, *, staging: str | os.PathLike | None = None,
    retries: int = DEFAULT_RETRIES,
) -> SerialExecutor | DaskExecutor:
    """The executor the options ask for: serial without either, else a :class:`DaskExecutor`.

    ``workers=0`` also means serial (in this process).
    """
    if scheduler is None and not workers:
        return SerialExecutor()
    if scheduler is not None and workers:
        raise UsageError("give --workers N (a local cluster) or --scheduler ADDRESS (a running one), not both")
    return DaskExecutor(workers if scheduler is None else None, scheduler, staging=staging, retries=retries)
