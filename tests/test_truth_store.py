"""The simulated bench's true states kept on disk (sim_bench.truth_store): what is written is read back exactly, a
recomputed chunk overwrites its rows, rows not computed read NaN, and a column slices as the run writer reads it."""

from __future__ import annotations

import numpy as np

from sim_bench.truth_store import TruthStore


def test_rows_round_trip_overwrite_and_read_nan_where_nothing_was_written():
    store = TruthStore(3)
    first = np.arange(30, dtype=float).reshape(10, 3) + 0.125
    store.write(0, first)
    again = -np.ones((4, 3))
    store.write(8, again)  # a chunk recomputed after a cut: rows 8 and 9 replaced, 10 and 11 new
    assert store.rows == 12
    column = store.column(1, 14)
    whole = np.asarray(column)
    assert np.array_equal(whole[:8], first[:8, 1]) and np.array_equal(whole[8:12], again[:, 1])
    assert np.isnan(whole[12:]).all() and len(column) == 14 and column.shape == (14,)
    assert np.array_equal(column[3:9], whole[3:9]) and np.array_equal(column[::5], whole[::5], equal_nan=True)
    assert np.array_equal(column[20:30], np.array([]))


def test_rows_a_cut_took_back_read_nan_until_computed_again():
    store = TruthStore(1)
    store.write(0, np.arange(10, dtype=float)[:, None])
    column = np.asarray(store.column(0, 10, valid=6))  # the bench cut back to row 6: rows 6-9 are not computed now
    assert np.array_equal(column[:6], np.arange(6.0)) and np.isnan(column[6:]).all()
