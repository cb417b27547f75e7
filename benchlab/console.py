"""The `benchlab` console script: SIGTERM and Ctrl-C are noted from its first line, before the command line's
imports (benchlab.cli loads argparse, logging and every command module: a few hundred ms on a busy PC), and
answered by benchlab.cli.main (exit 143 or 130, one line) instead of the default handlers killing the process.
"""

from __future__ import annotations

import sys

from benchlab.interrupts import note_interrupts


def main() -> int:
    """Note interrupts, then run the command line (benchlab.cli.main answers the ones noted)."""
    note_interrupts()
    from benchlab.cli import main as run_command_line

    return run_command_line()


if __name__ == "__main__":
    sys.exit(main())
