"""`benchlab` console script: one module per command in benchlab.commands, discovered at start.

A command module defines NAME, HELP, add_arguments(parser) and run(args) -> int. Bad input
(InputError) is one line on stderr and exit 2; any other failure is one line and exit 1; Ctrl-C, from the
moment `main` runs (imports of the commands included), is one line and exit 130.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence

import benchlab.commands
from benchlab.errors import InputError
from benchlab.interrupts import RedeliverInterrupts


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse's own usage errors: exit 2, one line
        self.exit(2, f"{self.prog}: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="benchlab", description="Dry-clutch test bench: acquire, simulate, identify, diagnose.")
    parser.add_argument("--debug", action="store_true", help="show a traceback on unexpected failures")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for info in sorted(pkgutil.iter_modules(benchlab.commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"benchlab.commands.{info.name}")
        cmd = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(cmd)
        cmd.add_argument("--quiet", "-q", action="store_true", help="no progress bars (there are none on a pipe)")
        cmd.set_defaults(handler=module.run)
    return parser


def _caused_by_interrupt(exc: BaseException) -> bool:
    """Whether Ctrl-C is behind `exc` (its cause or the exception being handled when it was raised)."""
    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        if isinstance(link, KeyboardInterrupt):
            return True
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return False


def _interrupted(args: argparse.Namespace | None) -> int:
    print(f"benchlab{'' if args is None else ' ' + args.command}: interrupted", file=sys.stderr)
    return 130


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; the exit code (0, 1 failure, 2 bad input, 130 Ctrl-C)."""
    try:
        with RedeliverInterrupts() as guard:
            code = _dispatch(argv)
    except KeyboardInterrupt:  # a Ctrl-C sent again (see benchlab.interrupts) just as the command ended
        return _interrupted(None)
    return _interrupted(None) if guard.swallowed else code


def _dispatch(argv: Sequence[str] | None) -> int:
    args = None
    try:
        args = build_parser().parse_args(argv)  # imports every command module: Ctrl-C may land here too
        return int(args.handler(args) or 0)
    except InputError as exc:
        print(f"benchlab {args.command}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return _interrupted(args)
    except Exception as exc:  # noqa: BLE001 - the CLI's last line of defence
        if _caused_by_interrupt(exc):  # Ctrl-C while a class is being created: Python 3.11 wraps it (__set_name__)
            return _interrupted(args)
        if args is None or args.debug:  # a failure while building the parser is a bug: show it
            raise
        print(f"benchlab {args.command}: failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
