"""The quadrotor landing simulator with synthetic human operators: the source of every sample log.

The plant is the paper's linearized planar quadrotor (:func:`~workbench.plant.system.planar_quadrotor`), started at
``x0 ~ U[-2, 2]``, ``y0 ~ U[2.5, 3]`` with every other state zero, inputs clipped to ``[-1, 1]²`` and the
position domain ``[-3, 3] × [0, 3.5]``. A trial ends on landing (``y ≤ 0`` with speed below 0.1 m/s and
``|phi|`` below 5°: ``meta["success"] = True``), on a crash or leaving the domain, or at a time limit.

The operator is not white noise around an LQR. It is a cascaded, saturating pilot model (position → velocity
→ attitude → stick) whose structure differs by control strategy:

* **CS1** centres horizontally first and only then descends (altitude is held while ``|x|`` is large);
* **CS2** flies a straight line to the pad with little attitude (small bank limit, coordinated descent).

Its variability ``w`` is what makes a human a human and what the workbench's GMM has to find: it is
state-dependent (larger and biased far from the pad, tighter near it), temporally correlated (an AR(1)
"drift" of the hand), non-Gaussian (occasional corrective bursts, heavy-tailed), and it differs per
:class:`OperatorProfile` (a subject), each a seeded variation of gains and variability.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from workbench.data.demonstrations import Demonstration, DemonstrationSet
from workbench.errors import DataError
from workbench.plant.system import LinearSystem, planar_quadrotor

__all__ = [
    "OperatorProfile",
    "operator_profile",
    "simulate_landings",
    "simulate_trial",
    "simulate_study",
    "STRATEGIES",
    "DOMAIN",
]

STRATEGIES = ("CS1", "CS2")
DOMAIN = ((-3.0, 3.0), (0.0, 3.5))  # position domain of the paper, metres
PAD_HALF_WIDTH = 0.5
LANDING_SPEED = 0.1  # m/s
LANDING_ATTITUDE = np.deg2rad(5.0)
START_BOX = ((-2.0, 2.0), (2.5, 3.0))  # x0, y0 drawn uniformly in these ranges (metres), every other state zero
TIME_LIMIT = 30.0  # s, a trial that has neither landed nor crashed by then ends


@dataclass(frozen=True)
class OperatorProfile:
    """One synthetic operator: gains of a cascaded pilot model and the shape of its variability.

    All gains are in SI units of the planar quadrotor. ``sigma_far`` and ``sigma_near`` are the
    standard deviations of the stick noise (stick units) far from and at the pad; ``rho`` is its AR(1)
    correlation per step; ``burst_rate`` the probability per step of starting a corrective burst.
    """

    subject: str = "s00"
    k_pos: float = 0.5  # 1/s, horizontal position → desired velocity
    v_max: float = 0.8  # m/s, cruise speed cap
    k_vel: float = 2.5  # 1/s, velocity error → desired acceleration
    phi_max: float = 0.25  # rad, bank limit (CS2 uses a fraction of it)
    k_phi: float = 0.8  # stick per rad of attitude error
    k_phidot: float = 0.005  # stick per rad/s of attitude rate
    k_alt: float = 0.45  # 1/s, altitude → desired sink rate
    sink_max: float = 0.6  # m/s
    k_vy: float = 0.9  # stick per m/s of vertical speed error
    centre_gate: float = 0.35  # m, CS1 descends only within this horizontal distance
    sigma_far: float = 0.05
    sigma_near: float = 0.01
    bias_far: float = 0.03  # stick units, a lean toward the pad when far away
    rho: float = 0.9
    burst_rate: float = 0.012
    burst_gain: float = 0.12

    def varied(self, rng: np.random.Generator, spread: float = 0.15) -> OperatorProfile:
        """A seeded variation of this profile: every gain and noise figure scaled by a log-normal factor."""
        changes = {}
        for name in (
            "k_pos", "v_max", "k_vel", "phi_max", "k_phi", "k_alt", "sink_max", "k_vy", "centre_gate",
            "sigma_far", "sigma_near", "bias_far", "burst_rate", "burst_gain",
        ):
            changes[name] = getattr(self, name) * math.exp(spread * rng.standard_normal())
        changes["rho"] = float(np.clip(self.rho + 0.04 * rng.standard_normal(), 0.7, 0.97))
        return replace(self, **changes)


def _seed_of(*parts: object) -> int:
    # crc32 rather than hash(): Python salts str hashes per process, and runs must repeat across processes
    return zlib.crc32("/".join(map(str, parts)).encode())


def operator_profile(subject: str | None = None) -> OperatorProfile:
    """The profile of a named subject: ``None`` or ``"s00"`` is the reference expert, others vary from it."""
    if subject is None or subject == "s00":
        return OperatorProfile()
    return OperatorProfile(subject=str(subject)).varied(np.random.default_rng(_seed_of("subject", subject)))


def _operator_command(
    x: np.ndarray, strategy: str, p: OperatorProfile, target: np.ndarray
) -> np.ndarray:
    """The operator's intended stick ``[u1, u2]`` for state ``x``: the deterministic part of the pilot."""
    px, py, phi, vx, vy, phidot = x - target
    if strategy == "CS1":
        # centre first: horizontal speed from horizontal distance alone; hold altitude until centred, then
        # descend, easing into it through a softened gate as a pilot does
        phi_max = p.phi_max
        vx_des = -np.clip(p.k_pos * px, -p.v_max, p.v_max)
        gate = 1.0 / (1.0 + math.exp((abs(px) - p.centre_gate) / 0.06))
        vy_des = -gate * min(p.sink_max, p.k_alt * py + 0.04)
    else:
        # straight line: one speed along the line of sight to the pad, so both axes arrive together,
        # with a small bank limit ("little attitude") and a slow final sink
        phi_max = 0.4 * p.phi_max
        dist = math.hypot(px, py) + 1e-9
        speed = min(0.8 * p.v_max, 0.8 * p.k_alt * dist)
        vx_des = -speed * px / dist
        vy_des = -speed * py / dist - 0.04 * math.exp(-py / 0.3)
    # the horizontal axis is flown through the attitude: x'' = g phi
    phi_des = np.clip(p.k_vel * (vx_des - vx) / 9.8, -phi_max, phi_max)
    u1 = p.k_phi * (phi_des - phi) - p.k_phidot * phidot
    u2 = p.k_vy * (vy_des - vy)
    return np.array([u1, u2])


def _step(plant: LinearSystem, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``A x + B u`` without BLAS: sample logs must regenerate bit-identically on any CPU, and BLAS kernels
    (chosen per processor) may order the sums differently. Elementwise products summed along rows do not."""
    return np.add.reduce(plant.A * x, axis=1) + np.add.reduce(plant.B * u, axis=1)


def simulate_trial(
    strategy: str,
    rng: np.random.Generator,
    profile: OperatorProfile | None = None,
    *,
    plant: LinearSystem | None = None,
    x0: Sequence[float] | None = None,
    target: Sequence[float] | None = None,
    time_limit: float = 30.0,
    trial_id: str = "trial",
) -> Demonstration:
    """Fly one landing with a synthetic operator and return it as a :class:`Demonstration`.

    ``u[k]`` is the (clipped) stick the operator held while the plant was in ``x[k]``; the last sample is
    the state at touchdown with the stick the operator held then.
    """
    if strategy not in STRATEGIES:
        raise DataError(f"unknown control strategy {strategy!r}; choose one of {STRATEGIES}")
    p = profile or OperatorProfile()
    sys_ = plant or planar_quadrotor()
    target_vec = np.zeros(sys_.n) if target is None else np.asarray(target, dtype=np.float64)
    if x0 is None:
        x = np.zeros(sys_.n)
        x[0] = rng.uniform(*START_BOX[0])
        x[1] = rng.uniform(*START_BOX[1])
    else:
        x = np.asarray(x0, dtype=np.float64).copy()
    n_max = int(round(time_limit / sys_.dt))
    drift = np.zeros(2)
    burst = np.zeros(2)
    burst_left = 0
    xs, us = [], []
    outcome = "time limit"
    for _ in range(n_max + 1):
        rel = x - target_vec
        dist = math.hypot(rel[0], rel[1])
        closeness = math.exp(-dist / 0.8)  # 1 at the pad, → 0 far away
        sigma = p.sigma_near + (p.sigma_far - p.sigma_near) * (1.0 - closeness)
        # temporally correlated hand drift (AR(1)); the roll stick is the sensitive one, so it drifts less
        innovation = rng.standard_normal(2) * np.array([0.3, 1.0])
        drift = p.rho * drift + np.sqrt(1.0 - p.rho**2) * sigma * innovation
        # occasional corrective bursts toward the pad: short, strong, one-sided (non-Gaussian)
        if burst_left == 0 and dist > 0.8 and rng.random() < p.burst_rate * (1.0 - closeness):
            burst_left = int(rng.integers(4, 10))
            toward_pad = -np.sign(rel[0] + 0.5 * rel[3])
            burst = p.burst_gain * rng.uniform(0.5, 1.0) * np.array([0.15 * toward_pad, -0.5])
        burst_term = burst if burst_left > 0 else np.zeros(2)
        burst_left = max(0, burst_left - 1)
        # a lean toward the pad when far away: biased, state-dependent, not a linear function of the state
        bias = p.bias_far * (1.0 - closeness) * np.array([0.0, -1.0])
        u = _operator_command(x, strategy, p, target_vec) + drift + burst_term + bias
        u = sys_.clip(u)
        xs.append(x.copy())
        us.append(u)
        if rel[1] <= 0.0:
            speed = math.hypot(rel[3], rel[4])
            landed = speed < LANDING_SPEED and abs(rel[2]) < LANDING_ATTITUDE and abs(rel[0]) <= PAD_HALF_WIDTH
            outcome = "landed" if landed else "crashed"
            break
        (x_lo, x_hi), (y_lo, y_hi) = DOMAIN
        if not (x_lo <= x[0] <= x_hi and x[1] <= y_hi):
            outcome = "left the domain"
            break
        x = _step(sys_, x, u)
    X, U = np.array(xs), np.array(us)
    return Demonstration(
        sys_.dt * np.arange(len(X)),
        X,
        U,
        {
            "id": trial_id,
            "label": strategy,
            "subject": p.subject,
            "source": "simulator",
            "target": target_vec.tolist(),
            "success": outcome == "landed",
            "outcome": outcome,
        },
    )


def simulate_landings(
    strategy: str = "CS1",
    n_trials: int = 30,
    seed: int = 0,
    subject: str | OperatorProfile | None = None,
    *,
    target: Sequence[float] | None = None,
    time_limit: float = 30.0,
) -> DemonstrationSet:
    """Simulate ``n_trials`` landings of one operator with one strategy; deterministic for ``seed``.

    Parameters
    ----------
    strategy : {"CS1", "CS2"}
        CS1: centre horizontally first, then descend. CS2: straight line to the pad, little attitude.
    subject : str or OperatorProfile, optional
        The operator; default the reference expert ``"s00"``. A name gives a seeded variation.
    target : sequence of 6 floats, optional
        The pad state (default the origin). Recorded in every demonstration's ``meta["target"]``.
    """
    if strategy not in STRATEGIES:
        raise DataError(f"unknown control strategy {strategy!r}; choose one of {STRATEGIES}")
    if n_trials < 1:
        raise DataError(f"n_trials must be at least 1, got {n_trials}")
    profile = subject if isinstance(subject, OperatorProfile) else operator_profile(subject)
    plant = planar_quadrotor()
    rng = np.random.default_rng([seed, _seed_of(strategy, profile.subject)])
    demos = [
        simulate_trial(
            strategy,
            rng,
            profile,
            plant=plant,
            target=target,
            time_limit=time_limit,
            trial_id=f"{profile.subject}-{strategy.lower()}-{j:03d}",
        )
        for j in range(n_trials)
    ]
    return DemonstrationSet(demos, plant.state_names, plant.input_names, plant.dt, roles=plant.roles)


def simulate_study(
    n_subjects: int = 10,
    n_trials: int = 11,
    strategy: str = "CS1",
    seed: int = 0,
) -> DemonstrationSet:
    """A multi-subject study: ``n_subjects`` seeded operators (``s01``, ``s02``, …) × ``n_trials`` each."""
    sets = [simulate_landings(strategy, n_trials, seed, subject=f"s{i + 1:02d}") for i in range(n_subjects)]
    out = sets[0]
    for s in sets[1:]:
        out = out + s
    return out
