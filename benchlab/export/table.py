"""/aligned as one table: CSV for spreadsheets, Parquet for data tools. One column per channel, time first.

CSV: comma-separated, `.` as decimal point, one header line of `name [unit]` (`time [s]`,
`T_flywheel [degC]`), the way asammdf and most logger tools write units into a CSV header: a spreadsheet
shows the unit above each column and pandas reads it with plain `read_csv`; `benchlab import` reads it
back. A sample that was not measured is an empty cell.
Parquet: the contract's channel names as column names, float64; each field's metadata holds `unit` and
`description`, the schema's metadata `benchlab` a JSON object with dt, the source file and its root
attributes. Needs pyarrow (`pip install 'benchlab[export]'`).
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from benchlab.errors import InputError
from benchlab.export.content import RunContent
from benchlab.runfile import ALIGNED_MEANING


def csv_header(name: str, unit: str) -> str:
    """The CSV column title of a channel: `name [unit]`."""
    return f"{name} [{unit}]"


def _frame(content: RunContent) -> pd.DataFrame:
    aligned = content.aligned
    return pd.DataFrame({aligned.master: aligned.time, **{c.name: c.values for c in aligned.channels}})


def write_csv(content: RunContent, out: Path) -> Path:
    """Write /aligned as CSV at `out`, units in the header."""
    frame = _frame(content)
    units = {content.aligned.master: "s", **{c.name: c.unit for c in content.aligned.channels}}
    frame.columns = [csv_header(name, units[name]) for name in frame.columns]
    frame.to_csv(out, index=False, na_rep="", lineterminator="\n")
    return out


def write_parquet(content: RunContent, out: Path) -> Path:
    """Write /aligned as Parquet at `out`, units and descriptions in the schema's field metadata."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise InputError(out, "--to", "pyarrow for Parquet export (pip install 'benchlab[export]'), "
                                      "or a .mf4 or .csv file") from None
    aligned = content.aligned
    fields = [pa.field(aligned.master, pa.float64(), metadata={"unit": "s", "description": ALIGNED_MEANING["time"]})]
    fields += [pa.field(c.name, pa.float64(), metadata={"unit": c.unit, "description": c.comment})
               for c in aligned.channels]
    meta = {"dt": content.dt, "source": str(content.source), "attrs": content.attrs}
    schema = pa.schema(fields, metadata={"benchlab": json.dumps(meta)})
    table = pa.Table.from_arrays([aligned.time, *(c.values for c in aligned.channels)], schema=schema)
    pq.write_table(table, out)
    return out
