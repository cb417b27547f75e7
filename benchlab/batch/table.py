"""The batch's results table: one row per task (or per run for wear), Parquet where pyarrow is installed, else CSV."""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from benchlab.outputs import replacing

#: Columns first in this order; parameters, figures and the rest follow as the tasks wrote them.
LEADING = ("index", "run", "group", "task", "status", "error", "created")
#: Counts: integers, empty where a run failed (not floats with NaN).
COUNTS = ("index", "runs", "warnings", "findings", "engagements")


def table_format() -> str:
    """'parquet' where pyarrow can write it, else 'csv'."""
    return "parquet" if importlib.util.find_spec("pyarrow") is not None else "csv"


def frame(rows: Sequence[dict]) -> pd.DataFrame:
    """The rows as one table ordered by run index, the leading columns first."""
    table = pd.DataFrame(list(rows))
    if table.empty:
        return table
    first = [c for c in LEADING if c in table.columns]
    table = table[first + [c for c in table.columns if c not in first]]
    for column in COUNTS:
        if column in table:
            table[column] = table[column].astype("Int64")
    return table.sort_values("index", kind="stable").reset_index(drop=True)


def write(table: pd.DataFrame, out_dir: Path, stem: str = "batch") -> Path:
    """`out_dir/stem.parquet` or `.csv` (see table_format); the path written."""
    kind = table_format()
    path = out_dir / f"{stem}.{kind}"
    with replacing(path) as tmp:
        if kind == "parquet":
            table.to_parquet(tmp, index=False)
        else:
            table.to_csv(tmp, index=False)
    return path


def read(path: "str | Path") -> pd.DataFrame:
    """A table written by `write`."""
    return pd.read_parquet(path) if str(path).endswith(".parquet") else pd.read_csv(path)
