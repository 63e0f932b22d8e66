"""Alignment (adapters/align.py): linear states, held inputs, common span, gaps, different rates."""

from __future__ import annotations

import numpy as np

from adapters.align import GRID_TOLERANCE, Series, align


def _series(name, t, v, hold=False):
    return Series(name, np.asarray(t, float), np.asarray(v, float), hold)


def test_states_are_interpolated_and_inputs_held_on_the_common_span():
    rng = np.random.default_rng(0)
    t_state = np.sort(rng.uniform(0.0, 10.0, 500))  # irregular, ~50 Hz
    t_input = np.arange(0.3, 9.0, 0.2)  # 5 Hz, starts later and ends earlier
    state = np.sin(t_state)
    stick = rng.uniform(-1, 1, t_input.size)
    (piece,) = align([_series("x", t_state, state), _series("u", t_input, stick, hold=True)], -np.inf, np.inf,
                     dt=0.05, gap=1.0)
    lo, hi = max(t_state[0], t_input[0]), min(t_state[-1], t_input[-1])
    assert piece.t[0] == lo and piece.t[-1] <= hi + GRID_TOLERANCE * 0.05
    np.testing.assert_allclose(np.diff(piece.t), 0.05)
    np.testing.assert_allclose(piece.values[:, 0], np.interp(piece.t, t_state, state))
    held = stick[np.searchsorted(t_input, piece.t + GRID_TOLERANCE * 0.05, side="right") - 1]
    np.testing.assert_array_equal(piece.values[:, 1], held)


def test_an_input_is_never_interpolated():
    (piece,) = align([_series("x", [0, 1, 2], [0, 1, 2]), _series("u", [0, 1, 2], [0.0, 10.0, 20.0], True)],
                     -np.inf, np.inf, dt=0.25, gap=5.0)
    assert piece.values[:, 1].tolist() == [0, 0, 0, 0, 10, 10, 10, 10, 20]
    np.testing.assert_allclose(piece.values[:, 0], np.arange(9) * 0.25)


def test_samples_at_grid_points_are_taken_exactly_despite_clock_rounding():
    t = 1.7e9 + 0.05 * np.arange(100)  # float rounding of absolute UNIX times
    v = np.random.default_rng(1).standard_normal(100)
    (piece,) = align([_series("x", t, v), _series("u", t, v, True)], -np.inf, np.inf, dt=0.05, gap=0.5)
    np.testing.assert_array_equal(piece.values[:, 0], v)
    np.testing.assert_array_equal(piece.values[:, 1], v)


def test_a_gap_splits_instead_of_being_interpolated_across():
    t = np.r_[np.arange(0, 5, 0.1), np.arange(8, 12, 0.1)]
    pieces = align([_series("x", t, t), _series("u", np.arange(0, 12, 0.05), np.zeros(240), True)],
                   -np.inf, np.inf, dt=0.1, gap=1.0)
    assert len(pieces) == 2
    assert pieces[0].t[-1] <= 4.9 + 1e-9 and pieces[1].t[0] >= 8.0 - 1e-9
    for p in pieces:  # no grid point inside the silence
        assert not np.any((p.t > 4.9 + 1e-9) & (p.t < 8.0 - 1e-9))
        np.testing.assert_allclose(p.values[:, 0], p.t)


def test_a_span_restricts_the_grid_and_no_data_means_no_piece():
    t = np.arange(0, 10, 0.1)
    (piece,) = align([_series("x", t, t)], 2.0, 4.0, dt=0.5, gap=1.0)
    np.testing.assert_allclose(piece.t, [2.0, 2.5, 3.0, 3.5, 4.0])
    assert align([_series("x", t, t)], 20.0, 30.0, dt=0.5, gap=1.0) == []
    assert align([_series("x", [], [])], -np.inf, np.inf, dt=0.5, gap=1.0) == []
