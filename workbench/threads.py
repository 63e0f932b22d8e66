"""How many threads the linear-algebra libraries (OpenBLAS, MKL, OpenMP) may use in a workbench run.

The workbench's matrices are small (a 6 × 6 Riccati equation, 8 × 8 covariances, a few thousand samples per
GMR query): a BLAS call on them takes microseconds, less than waking a second thread. With the libraries'
default of one thread per core, a fit of 60 demonstrations ran 1.6× slower than with one thread (issue 11), and
on a machine shared with other work the extra threads only contend. So the CLI runs single-threaded unless
``WORKBENCH_THREADS`` asks for more; an explicit ``OPENBLAS_NUM_THREADS`` / ``MKL_NUM_THREADS`` /
``OMP_NUM_THREADS`` of the user is kept.
"""

from __future__ import annotations

import os
import sys
from contextlib import AbstractContextManager, nullcontext

__all__ = ["ENV", "limit_threads", "thread_count"]

#: Environment variable that sets the thread count of a CLI run (default 1).
ENV = "WORKBENCH_THREADS"
_LIBRARY_VARS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")


def thread_count() -> int:
    """The thread count asked for by ``WORKBENCH_THREADS`` (a positive integer; anything else means 1)."""
    try:
        return max(1, int(os.environ.get(ENV, "1")))
    except ValueError:
        return 1


def limit_threads() -> AbstractContextManager:
    """Limit the BLAS and OpenMP thread pools for the rest of the process; a context that restores them.

    Before numpy is imported the limit is set through the libraries' environment variables (they read them
    once, when they load, and loading threadpoolctl costs nothing then). When numpy is already loaded (the CLI
    called in-process, e.g. from tests) the running pools are limited with :mod:`threadpoolctl` instead, for
    the duration of the returned context.
    """
    n = str(thread_count())
    explicit = any(v in os.environ for v in _LIBRARY_VARS) and ENV not in os.environ
    if explicit:
        return nullcontext()
    if "numpy" not in sys.modules:
        for var in _LIBRARY_VARS:
            os.environ[var] = n
        return nullcontext()
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=int(n))
