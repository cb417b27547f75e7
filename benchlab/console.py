"""The `benchlab` console script: SIGTERM and Ctrl-C are noted from its first line, before the command line's
imports (benchlab.cli loads argparse, logging and every command module: a few hundred ms on a busy PC), and
answered by benchlab.cli.main (exit 143 or 130, one line) instead of the default handlers killing the process.

A command loads only what it uses: pandas imports pyarrow (and pyarrow.compute) whenever it is installed, a quarter
of pandas' own start-up, though only Parquet needs it; every command but the ones that read or write Parquet runs
with pyarrow hidden (pandas then keeps strings in Python objects, as without pyarrow).
"""

from __future__ import annotations

import importlib.abc
import sys

from benchlab.interrupts import note_interrupts

class _Hidden(importlib.abc.MetaPathFinder):
    """An import of `package` (or a module of it) fails as if it were not installed."""

    def __init__(self, package: str) -> None:
        self.package = package

    def find_spec(self, name: str, path: object = None, target: object = None) -> None:
        if name == self.package or name.startswith(self.package + "."):
            raise ModuleNotFoundError(f"No module named {name!r} (benchlab: not needed by this command)", name=name)
        return None


def command_of(argv: list[str]) -> str | None:
    """The command the command line names: its first word that is not an option (the global options take no value)."""
    return next((word for word in argv if not word.startswith("-")), None)


def needs_parquet(argv: list[str]) -> bool:
    """Whether the command line may read or write Parquet: batch (its table), or an export to a .parquet file."""
    command = command_of(argv)
    return command == "batch" or (command == "export" and any(word.endswith(".parquet") for word in argv))


def main() -> int:
    """Note interrupts, hide pyarrow from a command without Parquet, then run the command line (benchlab.cli.main
    answers the interrupts noted)."""
    note_interrupts()
    if not needs_parquet(sys.argv[1:]):
        sys.meta_path.insert(0, _Hidden("pyarrow"))
    from benchlab.cli import main_of_process

    return main_of_process()


if __name__ == "__main__":
    sys.exit(main())
