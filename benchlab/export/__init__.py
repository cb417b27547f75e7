"""`benchlab export`: a run file as MDF4 (every group, own time bases), CSV or Parquet (/aligned)."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from pathlib import Path

from benchlab.errors import InputError
from benchlab.export.content import RunContent, read_content
from benchlab.export.mdf import write_mdf
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


def export(run: "str | os.PathLike[str]", out: "str | os.PathLike[str]", force: bool = False) -> RunContent:
    """Export the run file `run` to `out` (format from its suffix); built beside it, then moved into place."""
    out = check_target(run, out, force)
    content = read_content(run)
    for group in content.groups:
        log.info("%s %s: %d channels, %d rows", run, group.path, len(group.channels), len(group.time))
    with replacing(out) as tmp:
        WRITERS[out.suffix.lower()](content, tmp)
    log.info("wrote %s (%.1f MB)", out, out.stat().st_size / 1e6)
    return content
