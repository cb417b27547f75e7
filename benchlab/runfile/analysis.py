"""/analysis of a cooldown-sweep run: the per-cool-down table and the eq. (11) fit `benchlab cooldown` stores,
read back by `benchlab report` (docs/runfile.md). It goes into a file of its own (`write_analysis_file`,
`benchlab cooldown --out`) or, asked explicitly, into the run file (`write_analysis`, `--store`); either way the
file is rebuilt beside its destination and renamed into place (benchlab.outputs)."""

from __future__ import annotations

import os
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from benchlab.errors import InputError
from benchlab.outputs import replacing
from benchlab.runfile.read import open_run, text
from benchlab.runfile.schema import COOLDOWN_UNITS, EQ11_UNITS


@dataclass(frozen=True)
class StoredAnalysis:
    """What /analysis holds: one row per cool-down (COOLDOWN_UNITS' columns), the table's attributes (coverage_k,
    params, method) and eq. (11)'s scalars (None when too few cool-downs were fitted)."""

    cooldowns: list[dict[str, float]]
    attrs: dict[str, str]
    eq11: dict[str, float] | None


def write_analysis(path: "str | os.PathLike[str]", cooldowns: Sequence[Mapping[str, float]],
                   eq11: Mapping[str, float] | None, attrs: Mapping[str, object]) -> None:
    """Replace /analysis/cooldowns (one float64 dataset per column, with units, and `attrs`) and /analysis/eq11
    (scalars with units; removed when `eq11` is None) in the run file: a copy with them replaces it whole."""
    open_run(path).close()  # a missing or non-HDF5 file is InputError, as for every reader
    with replacing(path, run_file=True) as tmp:
        shutil.copy2(path, tmp)
        with h5py.File(tmp, "r+") as f:
            _fill(f, cooldowns, eq11, attrs)


def write_analysis_file(path: "str | os.PathLike[str]", run: "str | os.PathLike[str]",
                        cooldowns: Sequence[Mapping[str, float]], eq11: Mapping[str, float] | None,
                        attrs: Mapping[str, object]) -> None:
    """Write a new file holding only /analysis (as write_analysis) and the root attribute `source_run`: the run
    file analysed stays as it was measured. `benchlab report --sweep` reads it like a run file's /analysis."""
    with replacing(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["source_run"] = str(run)
        _fill(f, cooldowns, eq11, attrs)


def _fill(f: h5py.File, cooldowns: Sequence[Mapping[str, float]], eq11: Mapping[str, float] | None,
          attrs: Mapping[str, object]) -> None:
    """/analysis/cooldowns and /analysis/eq11 in the open file `f`, replacing any there."""
    group = f.require_group("analysis")
    if "cooldowns" in group:
        del group["cooldowns"]
    table = group.create_group("cooldowns")
    table.attrs.update(attrs)
    for key, units in COOLDOWN_UNITS.items():
        ds = table.create_dataset(key, data=np.array([row[key] for row in cooldowns], dtype=float))
        ds.attrs["units"] = units
    if "eq11" in group:
        del group["eq11"]
    if eq11 is not None:
        g = group.create_group("eq11")
        for k, v in eq11.items():
            ds = g.create_dataset(k, data=float(v))
            ds.attrs["units"] = EQ11_UNITS.get(k.removesuffix("_se"), "1")


def load_analysis(path: "str | os.PathLike[str]") -> StoredAnalysis | None:
    """/analysis as `write_analysis` stored it; None for a run without /analysis/cooldowns. InputError naming the
    dataset if the table lacks a column or its columns differ in length."""
    path = Path(path)
    with open_run(path) as f:
        table = f.get("analysis/cooldowns")
        if not isinstance(table, h5py.Group):
            return None
        columns: dict[str, np.ndarray] = {}
        for key in COOLDOWN_UNITS:
            ds = table.get(key)
            if not isinstance(ds, h5py.Dataset) or ds.ndim != 1 or not np.issubdtype(ds.dtype, np.number):
                raise InputError(path, f"/analysis/cooldowns/{key}", "a 1-D numeric column (benchlab cooldown)")
            columns[key] = ds[()].astype(np.float64)
        n = len(columns["cycle"])
        for key, values in columns.items():
            if len(values) != n:
                raise InputError(path, f"/analysis/cooldowns/{key}", f"{n} rows like /analysis/cooldowns/cycle")
        attrs = {k: text(v) for k, v in table.attrs.items()}
        eq11_group = f.get("analysis/eq11")
        eq11 = ({k: float(ds[()]) for k, ds in eq11_group.items() if isinstance(ds, h5py.Dataset) and ds.ndim == 0}
                if isinstance(eq11_group, h5py.Group) else None)
    rows = [{key: float(values[i]) for key, values in columns.items()} for i in range(n)]
    return StoredAnalysis(rows, attrs, eq11)
