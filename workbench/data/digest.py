"""Content digests of demonstrations: what a model file records about the data it was fitted on.

A trial's digest is a SHA-256 of its id, its step count and its time stamps, states and inputs as little-endian
float64 (the first 16 hex digits: enough to tell trials apart, short enough for a model file's header); a set's
digest hashes its trials' digests in order. Two trials with equal samples have equal digests whatever file they
came from, so a model met with its own training trials under other ids still knows them.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable

import numpy as np

from workbench.data.demonstrations import Demonstration

__all__ = ["trial_digest", "set_digest"]


def _content(demo: Demonstration) -> bytes:
    parts = [np.ascontiguousarray(a, dtype="<f8").tobytes() for a in (demo.t - demo.t[0], demo.x, demo.u)]
    return b"\0".join([str(demo.x.shape).encode(), str(demo.u.shape).encode(), *parts])


def trial_digest(demo: Demonstration) -> str:
    """The first 16 hex digits of a SHA-256 of the trial's samples (time since its start, states, inputs).

    The id is left out on purpose: the same samples read again under another id are still the same trial.
    """
    return hashlib.sha256(_content(demo)).hexdigest()[:16]


def set_digest(demos: Iterable[Demonstration]) -> str:
    """A SHA-256 (hex) of the trials' digests in order: one value that changes with any sample of any trial."""
    h = hashlib.sha256()
    for d in demos:
        h.update(trial_digest(d).encode() + b"\n")
    return h.hexdigest()
