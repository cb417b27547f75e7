"""The simulated bench's true states, kept on disk as they are computed: a run's memory stays flat in its length.

One anonymous temporary file per state (removed by the system when the store is dropped, a crash included),
float64 rows at their grid index, written with `os.pwrite`: the bytes go to the page cache, not to the process's
memory, and a chunk recomputed after a cut simply overwrites its rows. A column is read back a slice at a time
(`TruthColumn`), as the run writer's closing compaction reads it (benchlab.acquire.writer._dataset): a 4 h run's
truth (150 MB of it on the reference plant) is never held whole.
"""

from __future__ import annotations

import os
import tempfile
import numpy as np

ITEM = np.dtype("<f8")


class TruthStore:
    """Rows of true states (degC), one column per state, from grid row 0 of the recording onwards."""

    def __init__(self, columns: int) -> None:
        self._files = [tempfile.TemporaryFile(prefix="benchlab-truth-") for _ in range(columns)]
        self.rows = 0  # rows [0, rows) have been written

    @property
    def columns(self) -> int:
        return len(self._files)

    def write(self, start: int, states: np.ndarray) -> None:
        """The rows `start` … `start + len(states)` (a (n, columns) array), over whatever they held."""
        for i, file in enumerate(self._files):
            os.pwrite(file.fileno(), np.ascontiguousarray(states[:, i], dtype=ITEM).tobytes(), start * ITEM.itemsize)
        self.rows = max(self.rows, start + len(states))

    def read(self, column: int, start: int, stop: int, valid: int | None = None) -> np.ndarray:
        """Rows [start, stop) of one column; NaN where nothing was written, and from row `valid` on (rows a cut
        took back, not computed again yet)."""
        out = np.full(max(stop - start, 0), np.nan)
        have = max(min(stop, self.rows, self.rows if valid is None else valid) - start, 0)
        if have:
            data = os.pread(self._files[column].fileno(), have * ITEM.itemsize, start * ITEM.itemsize)
            out[:have] = np.frombuffer(data, dtype=ITEM)
        return out

    def column(self, index: int, rows: int, valid: int | None = None) -> "TruthColumn":
        """The first `rows` rows of a column, read lazily; NaN from row `valid` on (`read`)."""
        return TruthColumn(self, index, rows, valid)


class TruthColumn:
    """A column of a TruthStore read a slice at a time; `np.asarray` reads it whole (for small uses and tests)."""

    def __init__(self, store: TruthStore, index: int, rows: int, valid: int | None = None) -> None:
        self.store, self.index, self.rows, self.valid = store, index, int(rows), valid
        self.dtype, self.shape, self.size = ITEM, (self.rows,), self.rows

    def __len__(self) -> int:
        return self.rows

    def __getitem__(self, part: "slice | int | np.ndarray") -> "np.ndarray | float":
        if isinstance(part, slice) and part.step in (None, 1):
            start, stop, _ = part.indices(self.rows)
            return self.store.read(self.index, start, max(start, stop), self.valid)
        return np.asarray(self)[part]

    def __array__(self, dtype: "np.dtype | None" = None, copy: "bool | None" = None) -> np.ndarray:
        whole = self.store.read(self.index, 0, self.rows, self.valid)
        return whole if dtype is None else whole.astype(dtype, copy=False)
