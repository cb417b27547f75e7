"""The simulated bench's own recording of its final true states, on disk: its memory stays flat in the run's length.

The sink of `SimPhysics` when no run file takes the true states (tests, analysis; `benchlab run` writes them into
the run file's /truth instead, `RunWriter.put_truth`). One anonymous temporary file per state (removed by the
system when the store is dropped, a crash included), float64 rows at their grid index, written with `os.pwrite`:
the bytes go to the page cache, not to the process's memory.
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

    def read(self, column: int, start: int, stop: int) -> np.ndarray:
        """Rows [start, stop) of one column; NaN where nothing was written."""
        out = np.full(max(stop - start, 0), np.nan)
        have = max(min(stop, self.rows) - start, 0)
        if have:
            data = os.pread(self._files[column].fileno(), have * ITEM.itemsize, start * ITEM.itemsize)
            out[:have] = np.frombuffer(data, dtype=ITEM)
        return out
