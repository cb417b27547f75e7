"""The simulated bench's own recording of its true states on disk (sim_bench.truth_store): what is written is read
back exactly, rows written again replace theirs, and rows never written read NaN."""

from __future__ import annotations

import numpy as np

from sim_bench.truth_store import TruthStore


def test_rows_round_trip_overwrite_and_read_nan_where_nothing_was_written():
    store = TruthStore(3)
    first = np.arange(30, dtype=float).reshape(10, 3) + 0.125
    store.write(0, first)
    again = -np.ones((4, 3))
    store.write(8, again)  # rows 8 and 9 replaced, 10 and 11 new
    assert store.rows == 12
    whole = store.read(1, 0, 14)
    assert np.array_equal(whole[:8], first[:8, 1]) and np.array_equal(whole[8:12], again[:, 1])
    assert np.isnan(whole[12:]).all() and len(whole) == 14
    assert np.array_equal(store.read(2, 3, 9), np.concatenate([first[3:8, 2], again[:1, 2]]))
    assert store.read(0, 20, 30).shape == (10,) and np.isnan(store.read(0, 20, 30)).all()
