"""From the command line's run globs to the batch's tasks: files in order, unique names, groups.

Files are ordered by their paths with numbers compared as numbers (run2 before run10): that order is
the run index of the trends. Each run gets a unique name for its files in the output directory (its
file name without suffix, or its path relative to the runs' common folder where two share a name).
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Sequence
from pathlib import Path

from benchlab.batch import adapter
from benchlab.batch.tasks import RunRef, Task
from benchlab.errors import InputError


def natural_key(path: str) -> list[object]:
    """Sort key: digit runs as numbers, the rest as text."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path)]


def expand(patterns: Sequence[str]) -> list[str]:
    """Every file the patterns (globs, `**` included, or plain paths) match, each once, in natural order.

    A pattern that matches no file is bad input: a typo should not shrink a batch silently.
    """
    found: set[str] = set()
    for pattern in patterns:
        files = [m for m in glob.glob(os.path.expanduser(pattern), recursive=True) if not os.path.isdir(m)]
        if not files:
            raise InputError(pattern, "RUN_GLOB", "a path or glob matching at least one run file (none found)")
        found.update(os.path.normpath(f) for f in files)
    return sorted(found, key=natural_key)


def safe_name(text: str) -> str:
    """`text` as a file-name part: letters, digits, '.', '_' and '-' kept, anything else '_'."""
    return re.sub(r"[^A-Za-z0-9._-]", "_", text).strip(".") or "_"


def unique(names: Sequence[str]) -> list[str]:
    """The names with '-2', '-3', ... appended where one repeats."""
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f"{name}-{seen[name]}")
    return out


def run_names(paths: Sequence[str]) -> list[str]:
    """A unique file-name part per run: its stem, or its path below the common folder where stems repeat."""
    stems = [Path(p).stem for p in paths]
    if len(set(stems)) == len(stems):
        return [safe_name(s) for s in stems]
    root = os.path.commonpath([os.path.abspath(p) for p in paths]) if len(paths) > 1 else ""
    relative = [str(Path(os.path.relpath(os.path.abspath(p), root)).with_suffix("")) for p in paths]
    return unique([safe_name(r.replace(os.sep, "__")) for r in relative])


def group_value(path: str, attr: str) -> str | None:
    """The run's root attribute `attr`, or None where it has none or cannot be read (it is then a task alone)."""
    try:
        return adapter.read_attrs(path).get(attr)
    except Exception:  # noqa: BLE001 - the task reading it will report why, as a row
        return None


def plan(paths: Sequence[str], group_by: str | None = None) -> list[Task]:
    """One task per run, or per value of the root attribute `group_by` (runs without it each alone)."""
    refs = [RunRef(i, p, n) for i, (p, n) in enumerate(zip(paths, run_names(paths)))]
    if group_by is None:
        return [Task(ref.name, (ref,)) for ref in refs]
    ordered: list[tuple[str | None, list[RunRef]]] = []
    members: dict[str, list[RunRef]] = {}
    for ref in refs:
        value = group_value(ref.path, group_by)
        if value is None:
            ordered.append((None, [ref]))
        elif value in members:
            members[value].append(ref)
        else:
            members[value] = [ref]
            ordered.append((value, members[value]))
    names = unique([group[0].name if value is None else f"{safe_name(group_by)}-{safe_name(value)}"
                    for value, group in ordered])
    return [Task(name, tuple(group), value) for name, (value, group) in zip(names, ordered)]
