"""The pilot's timing: a reaction delay and a neuromuscular lag, identified from demonstrations with intervals.

A human acts on what was seen a moment ago and moves the stick through a lag (McRuer's crossover model, the
manual-control literature's reference; the method's "Beyond the paper"). Regressing ``u(t)`` on ``x(t)`` then
cannot tell a slow pilot from a soft one and attenuates ``K̂`` toward zero. The pilot here is

    c(t) = K x(t − d) + w(t)          the command, on the state seen ``d`` seconds late
    τ ṙ(t) + r(t) = c(t)              the stick follows through a first-order lag of time constant ``τ``
    u[k] = r(t_k)                     the recorded input, held by the plant for one sample

with ``x`` between samples taken linearly (a smooth display). Over one sample the lag gives exactly
``r(t_k) = a r(t_{k−1}) + ∫₀^dt (1/τ) e^{−s/τ} c(t_k − s) ds``, ``a = e^{−dt/τ}``, and with ``x`` piecewise linear the
integral is a weighted sum of the samples a few steps back: ``(1 − a) Σ_l β_l(d, τ) x[k − l]`` (the weights of
:func:`seen_weights`, exact up to quadrature; without a lag, interpolation at ``t_k − d``). So

    (u[k] − a u[k−1]) / (1 − a) = K x̃_k + w̄_k,      x̃_k = Σ_l β_l(d, τ) x[k − l]                     (T1)

an ARX model with a dead time, linear in ``K`` for fixed ``(d, τ)``; ``d = τ = 0`` is the paper's ``u = K x``.

Before a trial. Eq. (T1) at its first samples reaches back before the trial. Two starts are modelled (``start``):
``"steady"`` — the vehicle waited at its first state and the stick had settled on its command (a flight cut into
segments, the simulated operators); ``"rest"`` — the stick rests at 0 and the pilot's command starts ``d`` after
the trial does (the collect page: a trial starts with the sticks let go). ``"auto"`` takes ``"rest"`` where every
trial's first input is exactly 0.

Estimation. The closed loop makes every later state depend on the pilot's own autocorrelated variability, so
least squares is biased; what the variability does not move is the start. The instruments are each trial's first
state (and a constant) at each sample time — the mean response of the loop to its start, left free in time — and
``K`` of (T1) at fixed ``(d, τ)`` is limited-information maximum likelihood (LIML) per input, whose criterion
``κ_i(d, τ)`` (the smallest ratio of the instrument-explained to the whole residual variance) is free of the
many-instrument bias of two-stage least squares; ``(d̂, τ̂)`` minimize ``Σ_i κ_i`` over a grid and then locally.
Where the starts explain the seen states no better than chance (the relevance of :meth:`_Metric.relevance` ≤ 0:
they do not move every state), least squares (``"direct"``, biased in closed loop), said so. Everything is a function
of per-trial rows summed with a resample's multiplicities, so a bootstrap over trials re-estimates
``(d̂, τ̂, K̂)`` in each resample: the gain's intervals carry the timing's own uncertainty.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.defaults import OBJECTIVE_RESAMPLES
from workbench.errors import DataError, ModelError
from workbench.frozen import readonly
from workbench.method.closed_loop import as_matrix, single_threaded_blas
from workbench.method.gain import relevance_text
from workbench.method.pilot_loop import (
    lag_decay,
    onset_weight,
    read_through,
    recorded_dead_zone,
    seen_states,
    seen_weights,
    stick_of,
    timed_spectral_radius,
)

__all__ = ["TimingData", "TimingFit", "PilotTiming", "fit_timing", "identify_timing", "lag_decay", "seen_weights",
           "seen_states", "refusal", "timed_spectral_radius", "recorded_dead_zone", "stick_of",
           "read_through", "DELAY_MAX_S", "LAG_MAX_S", "STARTS"]

#: The longest reaction delay and lag searched (seconds): human delays are 0.1-0.3 s, lags 0.05-0.15 s (METHOD.md).
DELAY_MAX_S = 0.5
LAG_MAX_S = 0.3
#: How a trial starts (see the module docstring).
STARTS = ("steady", "rest", "auto")
#: The first search's grid (seconds), refined by Nelder-Mead: its steps are finer than the criterion's valley around
#: the truth (about ±0.03 s in the delay and ±0.02 s in the lag on the simulated operators).
_DELAY_STEP_S = 0.02
_LAG_GRID = np.linspace(0.0, LAG_MAX_S, 16)
_REFINE = 5  # to 0.08 ms: finer than the intervals a rest start gives (about ±0.5 ms on the simulated pilots)
#: Relative eigenvalue below which a direction of the instruments carries nothing (the starts never move it).
_RANK_TOL = 1e-10
#: Rows of all trials per block of the instruments' sums (bounds memory on long flights).
_BLOCK_ROWS = 100_000


def refusal(fit: TimingFit, plant: Any, delay_s: float | None = None, lag_s: float | None = None) -> str:
    """Why a LIML fit of the timing is not a model of this pilot (``""``: it is): its starts explain the seen
    states no better than chance, its best fit lies at the end of the range searched (no interior optimum: a
    pilot the timing model does not fit, the longest lag wins), or the pilot's own loop at that timing
    (:func:`timed_spectral_radius`, for a plant with ``A`` and ``B``) would not be stable though the
    demonstrations were flown. ``delay_s``/``lag_s``: values given, not searched."""
    if fit.method != "liml":
        return ""
    if not fit.relevance > 0:
        return ("the trials' starts explain the seen states no better than chance (relevance "
                f"{relevance_text(fit.relevance)}): they do not move every state")
    ends = [f"{name} {v:.3g} s" for name, v, top, given in (("delay", fit.delay_s, DELAY_MAX_S, delay_s),
                                                            ("lag", fit.lag_s, LAG_MAX_S, lag_s))
            if given is None and v >= top - 1e-6]
    if ends:
        return (f"the best-fitting timing lies at the end of the range searched ({', '.join(ends)}; a human's delay "
                "is 0.1-0.3 s, a lag 0.05-0.15 s): the timing model does not fit this pilot")
    if hasattr(plant, "A") and hasattr(plant, "B"):
        rho = timed_spectral_radius(plant.A, plant.B, fit.K, fit.delay_s, fit.lag_s, float(plant.dt))
        if not rho < 1.0:
            return (f"at the best-fitting timing (delay {fit.delay_s:.3g} s, lag {fit.lag_s:.3g} s) the pilot's own "
                    f"loop would not be stable (spectral radius {rho:.4g} with the delay and the lag), though the "
                    "demonstrations were flown: the timing model does not fit this pilot")
    return ""


# ------------------------------------------------------------------------------------------------ the rows


def _trials(demos: Iterable[Any], n: int, m: int) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Each demonstration's ``(x, stick, dead zone)``, checked (the stick is the input read back through the dead
    zone its device recorded); a single sample (no transition) is left out."""
    out = []
    for j, d in enumerate(demos):
        ident = getattr(d, "id", None)
        name = f"demonstration {j}" + (f" ({ident!r})" if ident is not None else "")
        x = as_matrix(getattr(d, "x", None), f"{name}: x", (None, n))
        u = as_matrix(getattr(d, "u", None), f"{name}: u", (None, m))
        if len(x) != len(u):
            raise DataError(f"{name}: x has {len(x)} samples but u has {len(u)}")
        if len(x) >= 2:
            width = recorded_dead_zone(d)
            out.append((x, stick_of(u, width), width))
    return out


def _n_lags(dt: float) -> int:
    # eq. (T1) reaches l0 + 2 = ⌊d/dt⌋ + 2 samples back
    return int(math.floor(DELAY_MAX_S / dt + 1e-9)) + 2


def _rows(x: np.ndarray, u: np.ndarray, n_lags: int, rest: bool) -> np.ndarray:
    """The rows ``v = [u[k−1], u[k], x[k], x[k−1], …, x[k−L]]`` of eq. (T1) of one trial, one per sample ``k``;
    before the trial a steady start's first input and state (a rest start's rows there are replaced per delay)."""
    k = np.arange(len(x))
    xs = x[np.maximum(k[:, None] - np.arange(n_lags + 1)[None, :], 0)]  # (N, L+1, n)
    u_prev = np.concatenate([np.zeros((1, u.shape[1])) if rest else u[:1], u[:-1]])
    return np.concatenate([u_prev, u, xs.reshape(len(x), -1)], axis=1)


class TimingData:
    """Demonstrations as the rows of eq. (T1) and their instruments, from which every fit and resample is summed.

    Parameters
    ----------
    demos : iterable of Demonstration (anything with ``.x`` (N, n) and ``.u`` (N, m))
        In the coordinates the gain acts on (goal-relative states: minus their targets).
    n, m : int
    dt : float
        Sampling step (s).
    start : {"steady", "rest", "auto"}
        How the trials start (module docstring).

    Where a trial's device recorded a dead zone (:func:`recorded_dead_zone`), eq. (T1) is written for the stick
    behind its inputs (:func:`stick_of`); a sample inside the dead zone reads 0 whatever the stick did there, so a
    dead zone wide against the pilot's inputs leaves the gain biased (a censored sample is taken as 0).
    """

    def __init__(self, demos: Iterable[Any], n: int, m: int, dt: float, start: str = "auto") -> None:
        if not (isinstance(dt, int | float) and dt > 0 and math.isfinite(dt)):
            raise DataError(f"the sampling step must be a positive number of seconds, got {dt!r}")
        if start not in STARTS:
            raise DataError(f"start must be one of {', '.join(STARTS)}, got {start!r}")
        trials = _trials(demos, n, m)
        if not trials:
            raise DataError("no demonstration has two or more samples: there is no transition to fit a timing to")
        if start == "auto":
            scale = max(float(np.abs(u).max()) for _, u, _ in trials) or 1.0
            start = "rest" if all(np.abs(u[0]).max() <= 1e-12 * scale for _, u, _ in trials) else "steady"
        self.start, self.n, self.m, self.dt = start, n, m, float(dt)
        widths = sorted({w for _, _, w in trials})
        #: The dead zone the devices recorded (the largest, where trials differ), 0 where none did.
        self.dead_zone = float(widths[-1])
        self.n_lags = _n_lags(dt)
        rest = start == "rest"
        self.rows = [_rows(x, u, self.n_lags, rest) for x, u, _ in trials]
        self.lengths = np.array([len(r) for r in self.rows])
        # the instruments: each trial's first state and a constant, at every sample time
        self.z0 = np.array([np.append(x[0], 1.0) for x, _, _ in trials])
        self.q = self.rows[0].shape[1]
        with single_threaded_blas():
            self.VV = np.array([r.T @ r for r in self.rows])

    @property
    def n_trials(self) -> int:
        return len(self.rows)

    def metric(self, counts: np.ndarray | None = None, instruments: bool = True) -> _Metric:
        """The sums of eq. (T1) over the trials, each counted ``counts[j]`` times (a resample's multiplicities)."""
        c = np.ones(self.n_trials) if counts is None else np.asarray(counts, dtype=float)
        rows = float(c @ self.lengths)
        early = self._early_raw(c) if self.start == "rest" else None
        VV = np.tensordot(c, self.VV, axes=1)
        if not instruments:
            return _Metric(self, {"VV": VV, "MP": VV}, rows, early={"VV": early, "MP": early}, iv=False)
        MP, MD, early_p, early_r = self._instrumented(c)
        sums = {"VV": VV, "MP": MP, "MR": MP - MD}
        return _Metric(self, sums, rows, early={"VV": early, "MP": early_p, "MR": early_r}, iv=True)

    def _onset_rows(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Trials with a row ``k``, their rows ``v`` there and their ``b = [u_prev, u, x0]`` (the onset row)."""
        active = np.flatnonzero(self.lengths > k)
        v = np.array([self.rows[j][k] for j in active]).reshape(len(active), self.q)
        b = np.concatenate([v[:, : 2 * self.m], self.z0[active, : self.n]], axis=1)
        return active, v, b

    def _early_raw(self, c: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Per early row ``k`` (a rest start's rows up to the first sample after the pilot's reaction), its raw
        moments as stored and as ``[u_prev, u, x0]``."""
        out = {}
        for k in range(self.n_lags):
            active, v, b = self._onset_rows(k)
            w = c[active]
            out[k] = ((v * w[:, None]).T @ v, (b * w[:, None]).T @ b)
        return out

    def _instrumented(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, Any, Any]:
        """``Σ_k A_kᵀ S_k⁺ A_k`` (the instruments' projection, per sample time ``k``: ``S_k = Σ_j c_j z_j z_jᵀ``,
        ``A_k = Σ_j c_j z_j v_jkᵀ``) and its part from each trial's own rows (the leverage ``h_jk = z_jᵀ S_k⁺ z_j``
        times ``c_j² v vᵀ``): by chance alone the instruments "explain" that much of any noise, which the criterion
        and the relevance leave out; for a rest start, the early times' terms of both (as stored and as onset
        rows)."""
        q, m, n = self.q, self.m, self.n
        keep = c > 0
        z, lengths = self.z0[keep], self.lengths[keep]
        rows = [r for r, k in zip(self.rows, keep, strict=True) if k]
        cw = c[keep]
        T = int(lengths.max())
        MP, MD = np.zeros((q, q)), np.zeros((q, q))
        early: dict[int, tuple[np.ndarray, np.ndarray]] | None = {} if self.start == "rest" else None
        early_r: dict[int, tuple[np.ndarray, np.ndarray]] | None = {} if self.start == "rest" else None
        step = max(self.n_lags, _BLOCK_ROWS // max(len(rows), 1))
        for k0 in range(0, T, step):
            k1 = min(T, k0 + step)
            V = np.zeros((len(rows), k1 - k0, q))
            for j, r in enumerate(rows):
                seg = r[k0:k1]
                V[j, : len(seg)] = seg
            w = cw[:, None] * (lengths[:, None] > np.arange(k0, k1)[None, :])  # (J, C)
            S = np.einsum("jt,ja,jb->tab", w, z, z)
            lam, Q = np.linalg.eigh(S)
            ok = lam > _RANK_TOL * np.maximum(lam[:, -1:], 1e-300)
            inv_sqrt = np.where(ok, 1.0 / np.sqrt(np.where(ok, lam, 1.0)), 0.0)
            R = np.swapaxes(Q, 1, 2) * inv_sqrt[:, :, None]  # S⁺ = RᵀR
            Rz = R @ z.T  # (C, a, J)
            RA = (Rz * w.T[:, None, :]) @ np.swapaxes(V, 0, 1)  # R_k A_k: (C, a, q)
            MP += RA.reshape(-1, q).T @ RA.reshape(-1, q)
            h = (Rz**2).sum(axis=1).T  # z_jᵀ S_k⁺ z_j, (J, C)
            own = np.sqrt(cw[:, None] ** 2 * (w > 0) * h)  # (J, C)
            Vw = V * own[..., None]
            MD += Vw.reshape(-1, q).T @ Vw.reshape(-1, q)
            if early is not None and early_r is not None and k0 == 0:
                for k in range(min(self.n_lags, k1)):
                    b = np.concatenate([V[:, k, : 2 * m], z[:, :n]], axis=1)
                    RB = (Rz[k] * w[:, k][None, :]) @ b
                    bw = b * own[:, k][:, None]
                    early[k] = (RA[k].T @ RA[k], RB.T @ RB)
                    early_r[k] = (RA[k].T @ RA[k] - Vw[:, k].T @ Vw[:, k], RB.T @ RB - bw.T @ bw)
        return MP, MD, early, early_r


# ------------------------------------------------------------------------------------------------ one fit


class _Metric:
    """Summed rows of eq. (T1) in the metrics a fit needs: ``"MP"`` the instruments' projection (least squares: the
    raw moments), ``"VV"`` the raw moments, ``"MR"`` the projection without each trial's own rows (relevance).

    A rest start's rows up to its onset row — the first sample after the pilot's reaction, ``k_o = ⌊d/dt⌋ + 1`` —
    are not sums of stored columns: before it the pilot has seen nothing (``x̃ = 0``), and at it the stick moved for
    only part of the sample, ``x̃ = w x[0]`` (:func:`onset_weight`; the vehicle rests until the pilot acts). Their
    stored rows are taken out of the sums (``early``) and these put in.
    """

    def __init__(self, data: TimingData, sums: dict[str, np.ndarray], rows: float,
                 early: dict[str, dict[int, tuple[np.ndarray, np.ndarray]] | None], iv: bool) -> None:
        self.data, self.sums, self.rows, self.early, self.iv = data, sums, rows, early, iv
        self._cache: dict[tuple[str, int], tuple[np.ndarray, ...]] = {}

    def _split(self, kind: str, onset: int) -> tuple[np.ndarray, ...]:
        """The blocks of a metric that eq. (T1) combines at any ``(d, τ)`` (``onset`` ≥ 0: without rows 0…onset)."""
        key = (kind, onset)
        if key in self._cache:
            return self._cache[key]
        M = self.sums[kind]
        pre_uu = np.zeros((2 * self.data.m, 2 * self.data.m))
        if onset >= 0:
            early = self.early[kind]
            M = M - sum(early[k][0] for k in range(onset + 1))
            pre_uu = sum((early[k][1][: 2 * self.data.m, : 2 * self.data.m] for k in range(onset)), pre_uu)
        n, m, L = self.data.n, self.data.m, self.data.n_lags

        def x(lag: int) -> slice:
            return slice(2 * m + n * lag, 2 * m + n * (lag + 1))

        out = (
            np.stack([[M[x(lag), x(min(lag + j, L))] for j in range(3)] for lag in range(L + 1)]),  # (L+1, 3, n, n)
            np.stack([M[x(lag), : 2 * m] for lag in range(L + 1)]),  # x_l [u_prev, u]
            _uu_diag(M[: 2 * m, : 2 * m]),
            _uu_diag(pre_uu),  # the rows before a rest start's onset: their inputs alone (x̃ = 0)
        )
        self._cache[key] = out
        return out

    def blocks(self, kind: str, delay: np.ndarray, lag_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(H_xx, H_xc, diag H_cc)`` of eq. (T1) at every ``(d, τ)`` pair (batched) in the metric ``kind``, with
        ``x̃ = Σ_j β_j x[k − l0 − j]`` (:func:`seen_weights`) and ``c = (u − a u_prev) / (1 − a)``."""
        delay = np.atleast_1d(np.asarray(delay, dtype=float))
        tau = np.atleast_1d(np.asarray(lag_s, dtype=float))
        d = self.data
        lagged = tau > 1e-9 * d.dt  # as seen_weights
        a = np.where(lagged, np.exp(-d.dt / np.where(lagged, tau, 1.0)), 0.0)
        alpha, beta_c = 1.0 / (1.0 - a), a / (1.0 - a)
        l0, beta = seen_weights(delay, tau, d.dt)
        if d.start != "rest":
            return self._generic(self._split(kind, -1), l0, beta, alpha, beta_c)
        onset = l0 + 1
        B, n, m = len(delay), d.n, d.m
        H_xx, H_xc, H_cc = np.empty((B, n, n)), np.empty((B, n, m)), np.empty((B, m))
        weight = onset_weight(delay, tau, d.dt)
        for k in np.unique(onset):
            i = np.flatnonzero(onset == k)
            split = self._split(kind, int(k))
            al, be, w = alpha[i], beta_c[i], weight[i]
            hx, hc, cc = self._generic(split, l0[i], beta[i], al, be)
            O = self.early[kind][int(k)][1]  # the onset row as [u_prev, u, x0]
            xo, uo = O[2 * m :, 2 * m :], O[2 * m :, : 2 * m]
            H_xx[i] = hx + (w**2)[:, None, None] * xo
            H_xc[i] = hc + w[:, None, None] * (al[:, None, None] * uo[:, m:] - be[:, None, None] * uo[:, :m])
            H_cc[i] = cc + self._cc(_uu_diag(O[: 2 * m, : 2 * m]), al, be) + self._cc(split[3], al, be)
        return H_xx, H_xc, H_cc

    @staticmethod
    def _cc(uu: tuple[np.ndarray, np.ndarray, np.ndarray], alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
        """``diag H_cc`` of ``c = α u − β u_prev`` from :func:`_uu_diag`."""
        d11, d00, d10 = uu
        return alpha[:, None] ** 2 * d11 - 2 * (alpha * beta)[:, None] * d10 + beta[:, None] ** 2 * d00

    def _generic(self, split: tuple[np.ndarray, ...], l0: np.ndarray, beta: np.ndarray, alpha: np.ndarray,
                 beta_c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        xx, xu, uu, _ = split
        m, L = self.data.m, self.data.n_lags
        l0 = np.clip(l0, 0, L - 2)
        H_xx = np.zeros((len(l0), self.data.n, self.data.n))
        xu_t = np.zeros((len(l0), self.data.n, 2 * m))
        for j in range(3):
            bj = beta[:, j][:, None, None]
            H_xx += bj**2 * xx[l0 + j, 0]
            xu_t += bj * xu[l0 + j]
            for jj in range(j + 1, 3):
                blk = xx[l0 + j, jj - j]
                H_xx += (bj * beta[:, jj][:, None, None]) * (blk + np.swapaxes(blk, 1, 2))
        H_xc = alpha[:, None, None] * xu_t[:, :, m:] - beta_c[:, None, None] * xu_t[:, :, :m]
        return H_xx, H_xc, self._cc(uu, alpha, beta_c)

    def evaluate(self, delay: np.ndarray, lag_s: np.ndarray, gains: bool = True
                 ) -> tuple[np.ndarray, np.ndarray | None]:
        """The criterion and (with ``gains``) the gains (batch, m, n) at every ``(d, τ)`` pair.

        With instruments: LIML per input, ``κ_i = min_K (c_i − x̃K)ᵀP(c_i − x̃K) / (c_i − x̃K)ᵀ(c_i − x̃K)``, the
        smallest generalized eigenvalue of the ``[c_i, x̃]`` moments, summed over the inputs: the share of the
        residual the trials' starts explain, which for noise alone is the same at any ``(d, τ)`` (the
        instruments' leverage), so a wrong timing can only add to it. On a pilot the model does not fit (the
        landing simulator's cascade) the misfit counts for less where the lag amplifies the noise, and the
        longest lag wins with a gain that does not stabilize the plant: :func:`identify_timing` refuses that.
        Without instruments: least squares, the residual sum of squares relative to ``c_i``'s (scale-free, as κ).
        """
        Hr = self.blocks("VV", delay, lag_s)
        n, m = self.data.n, self.data.m
        if not self.iv:
            G = np.linalg.solve(Hr[0], Hr[1])
            ssr = Hr[2] - np.einsum("bni,bni->bi", Hr[1], G)
            return (ssr / np.maximum(Hr[2], 1e-300)).sum(axis=1), np.swapaxes(G, 1, 2)
        Hp = self.blocks("MP", delay, lag_s)
        B = Hr[0].shape[0]
        crit = np.zeros(B)
        K = np.empty((B, m, n)) if gains else None
        for i in range(m):
            Gp, Gr = _joint(Hp, i), _joint(Hr, i)
            Li = np.linalg.inv(np.linalg.cholesky(Gr))
            S = Li @ Gp @ np.swapaxes(Li, 1, 2)
            S = 0.5 * (S + np.swapaxes(S, 1, 2))
            if K is None:
                crit += np.linalg.eigvalsh(S)[:, 0]
                continue
            lam, V = np.linalg.eigh(S)
            v = (np.swapaxes(Li, 1, 2) @ V[:, :, :1])[:, :, 0]  # [1, −K_i] up to scale
            crit += lam[:, 0]
            K[:, i, :] = -v[:, 1:] / v[:, :1]
        return crit, K

    def relevance(self, delay: float, lag_s: float) -> float:
        """The smallest squared canonical correlation of the seen states ``x̃`` with the instruments, beyond what
        each trial's own rows give by chance (1 for least squares; NaN where not computed)."""
        if not self.iv:
            return 1.0
        H_iv = self.blocks("MR", np.array([delay]), np.array([lag_s]))[0][0]
        H_raw = self.blocks("VV", np.array([delay]), np.array([lag_s]))[0][0]
        Lc = np.linalg.cholesky(H_raw)
        W = np.linalg.solve(Lc, np.linalg.solve(Lc, H_iv).T)
        return float(np.linalg.eigvalsh(0.5 * (W + W.T))[0])


def _uu_diag(uu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The diagonals of ``[u_prev, u]``'s moments that ``diag H_cc`` needs: ``u u``, ``u_prev u_prev``, the cross."""
    m = uu.shape[0] // 2
    return np.diag(uu[m:, m:]).copy(), np.diag(uu[:m, :m]).copy(), 0.5 * (np.diag(uu[m:, :m]) + np.diag(uu[:m, m:]))


def _joint(H: tuple[np.ndarray, np.ndarray, np.ndarray], i: int) -> np.ndarray:
    """The moments of ``[c_i, x̃]`` (batch, n+1, n+1) from the blocks of :meth:`_Metric.blocks`."""
    H_xx, H_xc, H_cc = H
    B, n = H_xx.shape[:2]
    G = np.empty((B, n + 1, n + 1))
    G[:, 0, 0] = H_cc[:, i]
    G[:, 0, 1:] = G[:, 1:, 0] = H_xc[:, :, i]
    G[:, 1:, 1:] = H_xx
    return G


@dataclass(frozen=True, eq=False)
class TimingFit:
    """One fit of eq. (T1): the delay, the lag and the gain on the seen state.

    Attributes
    ----------
    delay_s, lag_s : float
        ``d̂`` and ``τ̂`` (seconds).
    K : ndarray, shape (m, n)
        The gain of ``c = K x(t − d̂)``.
    method : str
        ``"liml"`` (instruments) or ``"direct"`` (least squares).
    relevance : float
        Smallest squared canonical correlation of the seen states with the instruments beyond chance (1 for
        ``"direct"``).
    delays, profile : ndarray
        The criterion over the delay grid (its minimum over the lag), relative to its minimum.
    """

    delay_s: float
    lag_s: float
    K: np.ndarray
    method: str
    relevance: float
    delays: np.ndarray
    profile: np.ndarray


def _search(metric: _Metric, delay_s: float | None, lag_s: float | None
            ) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray]:
    """Minimize the criterion over ``(d, τ)`` (a given value stays): a grid over the whole box, then
    :data:`_REFINE` ever finer 7 × 7 grids around the best point so far (each a third of the last one's cell:
    0.08 ms in the delay and the lag at the end), each one batched call."""
    dt = metric.data.dt
    d_step = min(_DELAY_STEP_S, dt / 2)
    d_grid = (np.array([float(delay_s)]) if delay_s is not None else
              np.linspace(0.0, DELAY_MAX_S, int(round(DELAY_MAX_S / d_step)) + 1))
    t_grid = np.array([float(lag_s)]) if lag_s is not None else _LAG_GRID
    D, Tg = np.meshgrid(d_grid, t_grid, indexing="ij")
    crit, _ = metric.evaluate(D.ravel(), Tg.ravel(), gains=False)
    crit = crit.reshape(D.shape)
    i, j = np.unravel_index(int(np.argmin(crit)), crit.shape)
    d_hat, t_hat, best = float(d_grid[i]), float(t_grid[j]), float(crit[i, j])
    steps = np.array([0.0 if delay_s is not None else d_step, 0.0 if lag_s is not None else _LAG_GRID[1]])
    for _ in range(_REFINE):
        if not steps.any():
            break
        steps = steps / 3.0
        offsets = np.arange(-3, 4)
        dd = np.clip(d_hat + steps[0] * offsets, 0.0, DELAY_MAX_S)
        tt = np.clip(t_hat + steps[1] * offsets, 0.0, LAG_MAX_S)
        D2, T2 = np.meshgrid(np.unique(dd), np.unique(tt), indexing="ij")
        c2, _ = metric.evaluate(D2.ravel(), T2.ravel(), gains=False)
        k = int(np.argmin(c2))
        if c2[k] < best:
            d_hat, t_hat, best = float(D2.ravel()[k]), float(T2.ravel()[k]), float(c2[k])
    _, K = metric.evaluate(np.array([d_hat]), np.array([t_hat]))
    prof = crit.min(axis=1)
    return d_hat, t_hat, K[0], d_grid, prof - prof.min()


def fit_timing(data: TimingData, method: str = "liml", *, delay_s: float | None = None,
               lag_s: float | None = None, counts: np.ndarray | None = None) -> TimingFit:
    """Fit eq. (T1): ``(d̂, τ̂)`` by the criterion (or the ones given), and ``K̂`` at them.

    Parameters
    ----------
    data : TimingData
    method : {"liml", "direct"}
        Instruments (LIML) or least squares.
    delay_s, lag_s : float, optional
        Fixed values instead of estimated ones (both 0: the paper's ``u = K x``).
    counts : ndarray, shape (n_trials,), optional
        Each trial's multiplicity (a bootstrap resample).
    """
    if method not in ("liml", "direct"):
        raise DataError(f"the timing is fitted by 'liml' or 'direct', not {method!r}")
    for name, v, top in (("delay_s", delay_s, DELAY_MAX_S), ("lag_s", lag_s, LAG_MAX_S)):
        if v is not None and not (0.0 <= v <= top):
            raise DataError(f"{name} must lie in [0, {top:g}] s, got {v!r}")
    with single_threaded_blas():
        metric = data.metric(counts, instruments=method == "liml")
        try:
            d_hat, t_hat, K, delays, profile = _search(metric, delay_s, lag_s)
        except np.linalg.LinAlgError as exc:
            raise ModelError(f"the timing fit ({method}) is singular: the demonstrations do not excite every state "
                             f"({exc})") from None
        rel = metric.relevance(d_hat, t_hat)
    return TimingFit(delay_s=d_hat, lag_s=t_hat, K=K, method=method, relevance=rel, delays=delays, profile=profile)


# ------------------------------------------------------------------------------------------------ intervals


@dataclass(frozen=True, eq=False)
class PilotTiming:
    """The pilot's reaction delay and neuromuscular lag with their intervals, and the gain on the seen state.

    Attributes
    ----------
    delay_s, lag_s : float
        Point estimates ``d̂``, ``τ̂`` (seconds) on all trials.
    delay_lo, delay_hi, lag_lo, lag_hi : float
        Their ``ci`` % intervals over resamples of whole trials (:func:`_interval`; equal to the point where fixed).
    K : ndarray, shape (m, n)
        The gain of ``c = K x(t − d̂)`` on all trials.
    K_samples : ndarray, shape (n_ok, m, n)
        The gain of every resample (each with its own ``d̂``, ``τ̂``).
    delay_samples, lag_samples : ndarray, shape (n_ok,)
    method : str
        ``"liml"`` or ``"direct"`` (see :func:`fit_timing`).
    reason : str
        Why that method (the instruments' relevance, or the cause of the fallback to least squares).
    dead_zone : float
        The dead zone the devices recorded (0: none), through which the inputs were read back to the stick.
    start : str
        How the trials were taken to start (``"steady"`` or ``"rest"``).
    relevance : float
        The instruments' relevance at the point estimate (:class:`TimingFit`).
    fixed : tuple of str
        Which of ``"delay"``, ``"lag"`` were given, not estimated.
    n_trials, n_boot, n_failed : int
    ci : float
    seed : int
    """

    delay_s: float
    lag_s: float
    delay_lo: float
    delay_hi: float
    lag_lo: float
    lag_hi: float
    K: np.ndarray
    K_samples: np.ndarray
    delay_samples: np.ndarray
    lag_samples: np.ndarray
    method: str
    start: str
    relevance: float
    fixed: tuple[str, ...]
    n_trials: int
    n_boot: int
    n_failed: int
    ci: float
    seed: int
    reason: str = ""
    dead_zone: float = 0.0
    n_timed: int = -1  # resamples fitted with timing (0 where all trials decided none: the rule's); -1: all
    #: resamples whose own trials would have decided the rule (``fallback``) the other way; each followed the
    #: decision on all trials all the same (:func:`identify_timing`), so this says how sure that decision is
    n_otherwise: int = 0

    def describe(self) -> str:
        """One line for the terminal: the delay and the lag with their intervals, and how they were found."""
        def part(name: str, key: str, v: float, lo: float, hi: float) -> str:
            if key in self.fixed:
                return f"{name} {v:.3g} s (given)"
            if not self.n_boot:
                return f"{name} {v:.3g} s"
            return f"{name} {v:.3g} s [{lo:.3g}, {hi:.3g}]"

        how = ("instrumental variables on the trials' starts (LIML)" if self.method == "liml" else
               "least squares (the starts do not move every state: biased in closed loop)")
        start = "at rest" if self.start == "rest" else "steady"
        if self.dead_zone:
            start += f"; the inputs read back through the devices' recorded dead zone {self.dead_zone:.3g}"
        boot = (f"{self.ci:g} % intervals over {self.n_boot - self.n_failed} resamples of {self.n_trials} trials"
                if self.n_boot else "no intervals")
        if self.n_otherwise:
            other = "identified a timing" if self.method == "none" else "refused the timing"
            boot += (f"; each resample follows the decision on all trials, though {self.n_otherwise} of them would "
                     f"have {other} on their own")
        if self.method == "none":
            return f"pilot timing: none ({self.reason.removeprefix('no timing: ')}); {boot}"
        return (f"pilot timing: {part('reaction delay', 'delay', self.delay_s, self.delay_lo, self.delay_hi)}, "
                f"{part('neuromuscular lag', 'lag', self.lag_s, self.lag_lo, self.lag_hi)} — by {how}, the trials "
                f"starting {start}; {boot}")

    def to_dict(self) -> dict[str, Any]:
        """The timing's numbers as plain JSON (for ``PilotTask.extra`` and a model file)."""
        return {"delay_s": self.delay_s, "delay_ci": [self.delay_lo, self.delay_hi], "lag_s": self.lag_s,
                "lag_ci": [self.lag_lo, self.lag_hi], "method": self.method, "start": self.start,
                "relevance": self.relevance, "reason": self.reason, "fixed": list(self.fixed),
                "dead_zone": self.dead_zone,
                "n_trials": self.n_trials,
                "n_boot": self.n_boot, "n_failed": self.n_failed, "ci": self.ci}


def _interval(value: float, samples: np.ndarray, n_trials: int, ci: float) -> tuple[float, float]:
    """The ``ci`` % interval of a delay or a lag: ``value ± t_{J−1} · SD`` of its resamples, from 0 up (as K̂'s,
    :func:`workbench.method.resampling.gain_interval`). The resamples' distribution is skewed (a few land on
    another basin of the criterion), so their percentiles sit beside the estimate: on seeds 9000-9019 of the rest
    start pilots the percentile interval held the true delay 15 times in 20, this one 19 (the "basic", reflected,
    interval 19 too). With fewer than two resamples, the value itself at both ends."""
    if len(samples) < 2:
        return value, value
    import scipy.stats

    half = float(scipy.stats.t.ppf(0.5 + ci / 200.0, max(n_trials - 1, 1))) * float(np.std(samples, ddof=1))
    return max(0.0, value - half), value + half


def identify_timing(
    demos: Iterable[Any],
    plant: Any,
    *,
    method: str = "liml",
    delay_s: float | None = None,
    lag_s: float | None = None,
    start: str = "auto",
    n_boot: int = OBJECTIVE_RESAMPLES,
    seed: int = 0,
    ci: float = 95.0,
    progress: Callable[[int, int], None] | None = None,
    fallback: Callable[[np.ndarray], np.ndarray] | None = None,
) -> PilotTiming:
    """Identify the pilot's delay and lag with intervals, and the gain on the seen state (module docstring).

    Parameters
    ----------
    demos : iterable of Demonstration
        In the coordinates the gain acts on (goal-relative: states minus their targets).
    plant : LinearSystem
        Anything with ``n``, ``m`` and ``dt``.
    method : {"liml", "direct"}
        ``"liml"``: instrumental variables on the trials' starts, refused (``ModelError``, which says why) where
        they explain the seen states no better than chance (relevance ≤ 0), where the best fit lies at the end of
        the range searched (:data:`DELAY_MAX_S`, :data:`LAG_MAX_S`: no interior optimum) or, for a plant with
        ``A`` and ``B``,
        where the pilot's own loop at the best-fitting timing would not be stable
        (:func:`timed_spectral_radius`: a pilot the model does not fit, whose best fit is the longest lag with a
        gain no pilot could fly with); ``"direct"``: least squares, biased in closed loop.
    delay_s, lag_s : float, optional
        Given values instead of estimated ones (``0, 0``: the paper's ``u = K x``, the gain alone resampled).
    start : {"auto", "steady", "rest"}
    n_boot : int
        Resamples of whole trials (0: the point estimate alone, intervals equal to it).
    seed : int
        The resampling generator's seed.
    ci : float
        Interval level in percent (the delay's and the lag's: the estimate ± t standard deviations of the
        resamples, as K̂'s).
    progress : callable(done, total), optional
    fallback : callable(counts) -> K, optional
        Where the timing model does not fit all trials (:func:`refusal`), this gain instead, of the same trials
        (their multiplicities ``counts``), rather than a refusal: the model's rule ("iv-or-direct": the paper's
        gain where the timing is refused), ``method`` ``"none"``. The rule is decided once, on all trials, and every
        resample follows that decision: the fallback's gain in every resample where all trials refused the timing,
        the timed gain in every resample where they did not. Deciding again per resample would mix two estimators
        in the gain's resamples, the printed one and the other, and the interval would describe neither: a
        pretest estimator's bootstrap is not consistent near the test's threshold (Andrews 2000, Econometrica 68;
        Leeb & Pötscher 2005, Econometric Theory 21), and on a real flight whose starts explain the seen states no
        better than chance (the dronekit log, relevance −0.02) the 10 resamples of 100 that identified a timing
        were LIML fits on irrelevant instruments — an estimator without finite moments (Mariano & Sawa 1972,
        JASA 67) — whose spread alone made K̂[u2, φ̇]'s interval [−20.3, 19.6] around the paper's gain −0.357. The
        interval is therefore conditional on the decision (the gain actually printed); how sure the decision is
        is said beside it: ``n_otherwise``, the resamples whose own trials would have decided the other way.

    Raises
    ------
    ModelError
        If the fit on all trials fails (a singular problem: the demonstrations do not excite every state), or is
        refused (``method="liml"``).
    """
    if not 0 < ci < 100:
        raise DataError(f"ci must be a percentage in (0, 100), got {ci}")
    if isinstance(n_boot, bool) or not isinstance(n_boot, int | np.integer) or n_boot < 0:
        raise DataError(f"n_boot must be a non-negative integer, got {n_boot!r}")
    if method not in ("liml", "direct"):
        raise DataError(f"the timing is identified by 'liml' or 'direct', not {method!r}")
    demos = list(demos)
    data = TimingData(demos, int(plant.n), int(plant.m), float(plant.dt), start)
    point = fit_timing(data, method, delay_s=delay_s, lag_s=lag_s)
    reason = "least squares, as requested"
    K_point = point.K
    timed = True
    if method == "liml":
        reason = f"instruments relevant: {relevance_text(point.relevance)} beyond chance"
        why = refusal(point, plant, delay_s, lag_s)
        if why and fallback is None:
            raise ModelError(why)
        if why:  # the rule's other gain, and the reason
            K_point, timed, reason = np.asarray(fallback(np.ones(data.n_trials, dtype=int))), False, f"no timing: {why}"
    rng = np.random.default_rng(seed)
    J = data.n_trials
    fits, failed, K_all, otherwise = [], 0, [], 0
    for b in range(int(n_boot)):
        counts = np.bincount(rng.integers(0, J, size=J), minlength=J)
        try:
            if timed:
                fit = fit_timing(data, method, delay_s=delay_s, lag_s=lag_s, counts=counts)
                if fallback is not None:  # the decision on all trials stands; how often this resample disagrees
                    otherwise += bool(refusal(fit, plant, delay_s, lag_s))
                fits.append(fit)
                K_all.append(fit.K)
            else:  # the rule's gain, as on all trials (the fallback's own failure fails the resample)
                K_all.append(np.asarray(fallback(counts)))
                otherwise += _would_time(data, method, delay_s, lag_s, counts, plant)
        except (ModelError, np.linalg.LinAlgError):
            failed += 1
        if progress is not None:
            progress(b + 1, int(n_boot))
    d_s = np.array([f.delay_s for f in fits])
    t_s = np.array([f.lag_s for f in fits])
    d_lo, d_hi = _interval(point.delay_s, d_s, J, ci)
    t_lo, t_hi = _interval(point.lag_s, t_s, J, ci)
    fixed = tuple(name for name, v in (("delay", delay_s), ("lag", lag_s)) if v is not None)
    return PilotTiming(
        delay_s=point.delay_s, lag_s=point.lag_s, delay_lo=float(d_lo), delay_hi=float(d_hi), lag_lo=float(t_lo),
        lag_hi=float(t_hi), K=readonly(K_point),
        K_samples=readonly(np.array(K_all).reshape(len(K_all), data.m, data.n)),
        delay_samples=readonly(d_s), lag_samples=readonly(t_s), method=method if timed else "none", start=data.start,
        relevance=point.relevance, fixed=fixed, n_trials=J, n_boot=int(n_boot), n_failed=failed, ci=float(ci),
        seed=int(seed), reason=reason, dead_zone=data.dead_zone, n_timed=len(fits), n_otherwise=otherwise)


def _would_time(data: TimingData, method: str, delay_s: float | None, lag_s: float | None, counts: np.ndarray,
                plant: Any) -> bool:
    """Whether a resample's own trials would have identified the timing that all trials refused (for
    :attr:`PilotTiming.n_otherwise` only: the resample takes the rule's gain either way)."""
    try:
        return not refusal(fit_timing(data, method, delay_s=delay_s, lag_s=lag_s, counts=counts), plant, delay_s,
                           lag_s)
    except (ModelError, np.linalg.LinAlgError):
        return False
