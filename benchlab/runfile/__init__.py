"""Run files (contract section 1, docs/runfile.md): the one home of their reading and writing.

Nothing outside this package and the acquisition writer opens a run file. Organised like python-can's can/io,
by what each module reads or writes:

- schema.py: schema string, channels and units, the tables' columns, which stored values are valid (numpy only)
- read.py: open_run, root attributes, /aligned (load_run), /events, progress record, /schedule, /truth, and
  where a stopped run stands (`--resume`)
- groups.py: the time-stamped groups besides /aligned (/raw/<stream>, /events, /simulated, /estimated) for an export
- analysis.py: /analysis (`benchlab cooldown` writes it, into its own file or the run's; `benchlab report` reads it)
- write.py: whole files at once (`benchlab import`; `simulate` and `observe`, a run file each)
- live.py: a file still being written, read without HDF5's caches (`benchlab watch`)
- benchlab/acquire/writer.py: the crash-safe file `benchlab run` writes as data arrives

The names below load their module on first use, so `benchlab.runfile.schema` costs no pandas or h5py.
"""

import typing as _typing

from benchlab._lazy import lazy_exports as _lazy_exports

if _typing.TYPE_CHECKING:  # what type checkers see; at run time `__getattr__` imports them on first use
    from benchlab.runfile.analysis import StoredAnalysis, load_analysis, write_analysis, write_analysis_file
    from benchlab.runfile.groups import StoredColumn, StoredGroup, StoredStreams, load_streams
    from benchlab.runfile.read import (Event, StoppedRun, event_steps, load_attrs, load_events, load_progress,
                                       load_run, load_schedule, load_stopped_run, load_truth, open_run,
                                       read_progress, read_schedule)
    from benchlab.runfile.schema import (ALIGNED_MEANING, ALIGNED_UNITS, COOLDOWN_UNITS, EQ11_UNITS,
                                         EVENT_COLUMNS, REQUIRED, SCHEDULE_UNITS, SCHEMA, time_step_tolerance,
                                         unmeasurable_sample)
    from benchlab.runfile.write import RawStream, write_beside_run, write_run

_HOMES = {
    "analysis": ("StoredAnalysis", "load_analysis", "write_analysis", "write_analysis_file"),
    "groups": ("StoredColumn", "StoredGroup", "StoredStreams", "load_streams"),
    "read": ("Event", "StoppedRun", "event_steps", "load_attrs", "load_events", "load_progress", "load_run",
             "load_schedule", "load_stopped_run", "load_truth", "open_run", "read_progress", "read_schedule"),
    "schema": ("ALIGNED_MEANING", "ALIGNED_UNITS", "COOLDOWN_UNITS", "EQ11_UNITS", "EVENT_COLUMNS", "REQUIRED",
               "SCHEDULE_UNITS", "SCHEMA", "time_step_tolerance", "unmeasurable_sample"),
    "write": ("RawStream", "write_beside_run", "write_run"),
}
__all__ = sorted(name for names in _HOMES.values() for name in names)
__getattr__, __dir__ = _lazy_exports(__name__, {f".{module}": names for module, names in _HOMES.items()})
