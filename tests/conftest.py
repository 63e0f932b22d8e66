"""Shared fixtures: simulated demonstrations, the planar quadrotor, and the real logs of shared/external."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from workbench.plant.system import planar_quadrotor
from workbench.sim.landing import simulate_landings

REPO = Path(__file__).resolve().parents[1]
EXTERNAL = (REPO / ".." / "shared" / "external").resolve()


def external_file(name: str) -> Path:
    """A real log recorded by others; skipped on a user's fresh clone, but a failure in CI (CI=true)."""
    path = EXTERNAL / name
    if not path.is_file():
        reason = f"{path} is absent (the shared/external folder beside the repository holds real logs)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(f"CI must have the external logs: {reason}")
        pytest.skip(reason)
    return path


@pytest.fixture(scope="session")
def quadrotor():
    return planar_quadrotor()


@pytest.fixture(scope="session")
def cs1_demos():
    return simulate_landings("CS1", n_trials=30, seed=0)


@pytest.fixture(scope="session")
def cs2_demos():
    return simulate_landings("CS2", n_trials=30, seed=0)


@pytest.fixture(scope="session")
def external():
    """``external("dronekit_flight.tlog")`` → the path, skipping (or failing in CI) where it is absent."""
    return external_file
