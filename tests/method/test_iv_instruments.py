"""The IV gain's instruments built for every demonstration at once are the per-demonstration ones, values and memory
order alike (the first stage's products then round the same way: a C-ordered copy moved ρ̂'s interval by 1e-15)."""

from __future__ import annotations

import numpy as np

from workbench.method.gain import IV_BASIS, iv_instruments


def _one_at_a_time(X: np.ndarray, lengths: list[int]) -> np.ndarray:
    taus = np.geomspace(2.0, max(4.0, max(lengths) / 2.0), IV_BASIS)
    blocks = []
    for start, L in zip(np.cumsum([0, *lengths[:-1]]), lengths, strict=True):
        basis = np.exp(-np.arange(L)[:, None] / taus[None, :])
        blocks.append((basis[:, :, None] * X[:, start][None, None, :]).reshape(L, -1).T)
    return np.concatenate(blocks, axis=1)


def test_instruments_of_all_demonstrations_at_once_are_the_one_at_a_time_ones():
    rng = np.random.default_rng(0)
    for lengths in ([57], [40, 13, 90, 2]):
        X = rng.standard_normal((4, sum(lengths)))
        got, want = iv_instruments(X, lengths), _one_at_a_time(X, lengths)
        assert np.array_equal(got, want)
        assert got.flags["F_CONTIGUOUS"] == want.flags["F_CONTIGUOUS"]
        assert got.flags["C_CONTIGUOUS"] == want.flags["C_CONTIGUOUS"]
