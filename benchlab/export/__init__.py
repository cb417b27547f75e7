"""`benchlab export`: a run file as MDF4 (every group, own time bases), CSV or Parquet (/aligned); all of it, or
some channels, a time range, on one raster."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from pathlib import Path

from benchlab.errors import InputError
from benchlab.export.content import RunContent, read_content
from benchlab.export.mdf import write_mdf
from benchlab.export.select import select
from benchlab.export.table import write_csv, write_parquet
from benchlab.outputs import check_output, replacing

#: Output suffix -> writer.
WRITERS: dict[str, Callable[[RunContent, Path], Path]] = {".mf4": write_mdf, ".csv": write_csv,
                                                           ".parquet": write_parquet}
log = logging.getLogger(__name__)


def check_target(run: "str | os.PathLike[str]", out: "str | os.PathLike[str]", force: bool) -> Path:
    """The output path if its suffix is known and the output rule lets it be written (benchlab.outputs); else
    InputError."""
    out = Path(out)
    if out.suffix.lower() not in WRITERS:
        raise InputError(out, "--to", f"a file ending in {', '.join(WRITERS)}, got {out.suffix or 'no suffix'!r}")
    return check_output(out, "--to", force, inputs=[run])


def export(run: "str | os.PathLike[str]", out: "str | os.PathLike[str]", force: bool = False,
           channels: list[str] | None = None, start: float | None = None, stop: float | None = None,
           raster: float | None = None) -> RunContent:
    """Export the run file `run` to `out` (format from its suffix), only the `channels` named (all if None), from
    `start` to `stop` (s), on a `raster` (s) if given (benchlab.export.select); built beside it, then moved into
    place."""
    out = check_target(run, out, force)
    content = read_content(run)
    if channels is not None or start is not None or stop is not None or raster is not None:
        content = select(content, channels, start, stop, raster)
    for group in content.groups:
        log.info("%s %s: %d channels, %d rows", run, group.path, len(group.channels), len(group.time))
    with replacing(out) as tmp:
        WRITERS[out.suffix.lower()](content, tmp)
    log.info("wrote %s (%.1f MB)", out, out.stat().st_size / 1e6)
    return content
