"""Fixtures of the adapters' tests: small simulated demonstration sets and their logs in every format."""

from __future__ import annotations

import pytest

import adapters
from workbench.sim.landing import simulate_landings


def _quantization(fmt: str, x, u):
    """Per-element tolerances (states, inputs) of a format's round trip, computed from the values.

    tlog: MAVLink fields are float32 (half a float32 ulp of the value, plus the position of an exact negation),
    sticks int16 in thousandths (half a step: 0.0005); MCAP (JSON), CSV (shortest repr) and ULog (double) are
    exact float64.
    """
    import numpy as np

    if fmt == "tlog":
        tol_x = 0.5 * np.spacing(np.abs(x).astype(np.float32)).astype(np.float64) + 1e-300
        tol_u = np.full_like(u, 0.5 * 0.001) + np.spacing(np.abs(u))
        return tol_x, tol_u
    return np.zeros_like(x), np.zeros_like(u)


@pytest.fixture(scope="session")
def quantization():
    """``quantization(fmt, x, u)`` → per-element round-trip tolerances (states, inputs) of a format."""
    return _quantization


@pytest.fixture(scope="session")
def small_set():
    """Three simulated landings: two CS1, one CS2 (a few hundred samples)."""
    return simulate_landings("CS1", 2, seed=3) + simulate_landings("CS2", 1, seed=3)


@pytest.fixture(scope="session")
def tiny_set():
    """Two very short landings (time limit 1 s), for fast property tests on files of a few kB."""
    return simulate_landings("CS1", 2, seed=5, time_limit=1.0)


@pytest.fixture(scope="session")
def written(tmp_path_factory, small_set):
    """``written("mcap")`` → a log of ``small_set`` in that format, written once per session."""
    cache = {}
    ext = {"tlog": "tlog", "mcap": "mcap", "csv": "csv", "ulog": "ulg"}

    def make(fmt: str):
        if fmt not in cache:
            path = tmp_path_factory.mktemp(f"written_{fmt}") / f"small.{ext[fmt]}"
            adapters.write(small_set, path)
            cache[fmt] = path
        return cache[fmt]

    return make
