"""Progress of long work (fits, diagnosis, runs): a bar with an ETA on a terminal, nothing on a pipe.

Library functions take a `Progress` and default to `SILENT`, so they print nothing unless a command
asks: the commands pass `for_terminal(quiet)`, which draws tqdm bars on stderr only when stderr is a
terminal and `--quiet` was not given.
"""

from __future__ import annotations

import sys
from typing import Any


class Task:
    """One piece of work with a known total; `advance` as parts finish. This base reports nothing."""

    def advance(self, amount: float = 1.0) -> None:
        """`amount` more of the total is done."""

    def note(self, text: str) -> None:
        """A short status shown beside the bar (the current stage, a figure of merit)."""

    def close(self) -> None:
        """The work is over (done or abandoned)."""

    def __enter__(self) -> "Task":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Progress:
    """Where long work reports; this base is silent (what libraries get by default)."""

    def task(self, what: str, total: float, unit: str = "it") -> Task:
        """A new task `what` of `total` units."""
        return Task()


SILENT = Progress()


class _TqdmTask(Task):
    """A bar counting whole units (`1031/3840 s`, never `1031.0500000000002/3840.0`) of work done in any fractions."""

    def __init__(self, bar: Any) -> None:
        self.bar, self._done = bar, 0.0

    def advance(self, amount: float = 1.0) -> None:
        self._done += amount
        whole = int(self._done)
        if whole != self.bar.n:
            self.bar.update(whole - self.bar.n)

    def note(self, text: str) -> None:
        self.bar.set_postfix_str(text, refresh=False)

    def close(self) -> None:
        self.bar.close()


class TerminalProgress(Progress):
    """tqdm bars on stderr, one per task, each with its rate and ETA."""

    def task(self, what: str, total: float, unit: str = "it") -> Task:
        from tqdm import tqdm

        return _TqdmTask(tqdm(total=int(total), desc=what, unit=unit, file=sys.stderr, leave=True, dynamic_ncols=True,
                              mininterval=0.5))


def for_terminal(quiet: bool = False) -> Progress:
    """Bars when stderr is a terminal and the user did not ask for quiet; silent otherwise (pipes, files, CI, and a
    stderr an embedding program replaced with a stream that cannot say: no `isatty`)."""
    isatty = getattr(sys.stderr, "isatty", None)
    return TerminalProgress() if not quiet and isatty is not None and isatty() else SILENT
