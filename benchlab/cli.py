"""`benchlab` console script: one module per command in benchlab.commands, discovered at start (only the named
command's module where the command line names one: `build_parser`).

A command module defines NAME, HELP, add_arguments(parser) and run(args) -> int, and stays light to import
(argparse and constants: `benchlab --help` loads no numpy); run imports the implementation, holding Ctrl-C
while it does (benchlab.interrupts.interrupts_held, as here around the parser). Bad input
(InputError) is one line on stderr and exit 2; a full disk (benchlab.outputs.OutputError) and any other failure
are one line and exit 1; Ctrl-C, from the
moment `main` runs (imports of the commands included), is one line and exit 130. A reader that leaves
early (`benchlab run table1 --bench sim --dry-run | head -1`) ends the command quietly with 141, as SIGPIPE ends
other tools. The console script (benchlab.console) notes SIGTERM and Ctrl-C before this module loads; main answers
them.
`-v` shows benchlab's log messages (logger `benchlab.*`) on stderr: INFO, and DEBUG with `-vv`; `-v` and `-q` (no
progress bars) are taken before or after the command. A mistyped command or choice is answered with the closest one.
"""

from __future__ import annotations

import argparse
import difflib
import gc
import importlib
import os
import pkgutil
import select
import sys
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

import benchlab
import benchlab.commands
from benchlab import logs
from benchlab.console import command_of
from benchlab.errors import InputError
from benchlab.interrupts import (TERMINATED_EXIT, RedeliverInterrupts, Terminated, interrupts_answered,
                                 interrupts_held, raise_noted, terminate_as_interrupt)
from benchlab.outputs import OutputError, check_log, is_no_space, no_space

#: Exit code when stdout's reader has gone: 128 + SIGPIPE, what a shell reports for a tool SIGPIPE ended.
BROKEN_PIPE_EXIT = 141
#: Exit code after Ctrl-C: 128 + SIGINT, what a shell reports for a tool SIGINT ended.
INTERRUPTED_EXIT = 130


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse's own usage errors: exit 2, one line
        self.exit(2, f"{self.prog}: {message}\n")

    def _check_value(self, action: argparse.Action, value: object) -> None:
        """argparse's check of a choice, naming the closest one for a typo (`identfy`: did you mean 'identify'?)."""
        choices = action.choices
        if choices is not None and isinstance(value, str) and value not in choices:
            names = {str(choice): choice for choice in choices}
            close = difflib.get_close_matches(value, list(names), n=1)
            if close:
                listed = ", ".join(map(repr, choices))
                raise argparse.ArgumentError(action, f"invalid choice: {value!r}, did you mean {names[close[0]]!r}? "
                                                     f"(choose from {listed})")
        super()._check_value(action, value)


class _DefaultsShown(argparse.HelpFormatter):
    """`--help` names each option's default where it has one worth saying (not None, off or empty) and its own
    help text does not already."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (default is None or default is False or default == [] or default == argparse.SUPPRESS or "default" in text
                or not action.option_strings):
            return text
        return f"{text} (default: %(default)s)"


def _command_modules(command: str | None) -> list[ModuleType]:
    """The command modules the parser needs: only `command`'s where a module of that name holds it (the others'
    imports and arguments cost every command 60 ms CPU), every one otherwise (`--help`, a typo's closest name)."""
    names = sorted(info.name for info in pkgutil.iter_modules(benchlab.commands.__path__))
    if command in names:
        module = importlib.import_module(f"benchlab.commands.{command}")
        if module.NAME == command:
            return [module]
    return [importlib.import_module(f"benchlab.commands.{name}") for name in names]


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser; given the command a command line names (`console.command_of`), with only that
    command where it is one (its usage, help and errors as in the whole parser's)."""
    parser = _Parser(prog="benchlab", description="Dry-clutch test bench: acquire, simulate, identify, diagnose.")
    parser.add_argument("--debug", action="store_true", help="show a traceback on unexpected failures")
    parser.add_argument("--version", action="version", version=f"%(prog)s {benchlab.__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log what benchlab does on stderr (-v: info, -vv: debug)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars (there are none on a pipe)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for module in _command_modules(command):
        cmd = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP, formatter_class=_DefaultsShown)
        module.add_arguments(cmd)
        cmd.add_argument("--quiet", "-q", action="store_true", default=argparse.SUPPRESS,
                         help="no progress bars (there are none on a pipe; as before the command)")
        cmd.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                         help="log what benchlab does on stderr (-v: info, -vv: debug, as before the command)")
        cmd.add_argument("--log", nargs="?", const="", metavar="FILE", help="keep the log (debug) in FILE; without "
                         "FILE beside the run file (--out/--resume RUN.h5 -> RUN.log)")
        cmd.set_defaults(handler=module.run)
    return parser


def _caused_by_interrupt(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C (or SIGTERM) behind `exc` (its cause or the exception being handled when it was raised), if any."""
    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        if isinstance(link, KeyboardInterrupt):
            return link
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return None


def configure_logging(verbosity: int) -> None:
    """The project's loggers to stderr at INFO (-v) or DEBUG (-vv), WARNING without -v; the libraries' warnings
    only with -v (benchlab.logs)."""
    logs.configure(verbosity)


#: The parsed arguments that hold no path of the command's (what check_log compares the log with).
_NOT_PATHS = ("log", "handler", "command", "verbose", "debug", "quiet", "force")


def _argument_names(parser: argparse.ArgumentParser, command: str) -> dict[str, str]:
    """The command's arguments as the user wrote them: dest -> option (`--out`) or positional name (`run`)."""
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[command]
    return {a.dest: a.option_strings[-1] if a.option_strings else a.dest for a in commands._actions}


def _log_file(args: argparse.Namespace, names: dict[str, str]) -> Path | None:
    """The file `--log` asks for (FILE, or the run file's name with .log), checked by the output rule; None without
    --log."""
    log = getattr(args, "log", None)
    if log is None:
        return None
    run_file = getattr(args, "out", None) or getattr(args, "resume", None)
    if not log and not run_file:
        raise InputError("command line", "--log", "a FILE (this command writes no run file to put it beside)")
    path = Path(log) if log else Path(run_file).with_suffix(".log")
    arguments = {names.get(k, k): v for k, v in vars(args).items() if k not in _NOT_PATHS}
    return check_log(path, arguments, force=bool(getattr(args, "force", False)),
                     resume=bool(getattr(args, "resume", None)))


def _stdout_reader_gone() -> bool:
    """Whether stdout is a pipe whose reader has left (the kernel reports an error on its write end); if so,
    stdout is pointed at /dev/null so that the interpreter's last flush at exit stays quiet."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # stdout replaced by an object without a descriptor
        return False
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    if not any(events & select.POLLERR for _, events in poller.poll(0)):
        return False
    os.dup2(os.open(os.devnull, os.O_WRONLY), fd)
    return True


def _interrupted(args: argparse.Namespace | None, exc: BaseException | None = None) -> int:
    """The one answer to Ctrl-C (130) or SIGTERM (143): later ones are ignored from here on (see
    interrupts_answered), one line."""
    interrupts_answered()
    terminated = isinstance(exc, Terminated)
    print(f"benchlab{'' if args is None else ' ' + args.command}: {'terminated' if terminated else 'interrupted'}",
          file=sys.stderr)
    return TERMINATED_EXIT if terminated else INTERRUPTED_EXIT


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; the exit code (0, 1 failure, 2 bad input, 130 Ctrl-C).

    Having answered a Ctrl-C, main leaves SIGINT ignored: the process is ending (an in-process caller that
    carries on puts its own handler back)."""
    try:
        with terminate_as_interrupt(), RedeliverInterrupts() as guard:
            code = _dispatch(argv)
    except KeyboardInterrupt as exc:  # a Ctrl-C sent again (see benchlab.interrupts) just as the command ended
        return _interrupted(None, exc)
    if guard.swallowed and code != INTERRUPTED_EXIT:  # a Ctrl-C still to be sent again, not answered yet
        return _interrupted(None)
    return code


def _dispatch(argv: Sequence[str] | None) -> int:
    args = None
    try:
        raise_noted()  # SIGTERM or Ctrl-C before this module had loaded (benchlab.console): answered here
        with interrupts_held():  # imports the command modules; a Ctrl-C meanwhile comes right after
            parser = build_parser(command_of(sys.argv[1:] if argv is None else list(argv)))
        args = parser.parse_args(argv)
        configure_logging(args.verbose)
        log_file = _log_file(args, _argument_names(parser, args.command))
        if log_file is not None:
            try:
                logs.keep_in_file(log_file, append=bool(getattr(args, "resume", None)))
            except OSError as exc:
                raise InputError(log_file, "--log", f"a file that can be written ({exc.strerror or exc})") from None
        try:
            code = int(args.handler(args) or 0)
        finally:
            if log_file is not None:
                logs.stop_file(log_file)
        sys.stdout.flush()  # a reader that has left shows here, not in the interpreter's last flush
        return code
    except BrokenPipeError as exc:
        return BROKEN_PIPE_EXIT if _stdout_reader_gone() else _failed(args, exc)
    except InputError as exc:
        print(f"benchlab {args.command}: {exc}", file=sys.stderr)
        return 2
    except OutputError as exc:  # a full disk: the file named, no partial output left
        print(f"benchlab {args.command}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        return _interrupted(args, exc)
    except Exception as exc:  # noqa: BLE001 - the CLI's last line of defence
        if (interrupt := _caused_by_interrupt(exc)) is not None:  # Ctrl-C while a class is being created: Python
            return _interrupted(args, interrupt)  # 3.11 wraps it (__set_name__)
        return _failed(args, exc)


def _failed(args: argparse.Namespace | None, exc: Exception) -> int:
    """An unexpected failure: one line and exit 1 (a traceback with --debug, or while building the parser)."""
    if args is None or args.debug:  # a failure while building the parser is a bug: show it
        raise exc
    text = " ".join(str(exc).split())  # one line, whatever the library's text (HDF5's spans several)
    if is_no_space(exc):  # a file some library writes (the CAN log, a figure): one line, as benchlab.outputs says
        print(f"benchlab {args.command}: {no_space(getattr(exc, 'filename', None) or 'a file', text)}",
              file=sys.stderr)
        return 1
    print(f"benchlab {args.command}: failed: {type(exc).__name__}: {text}", file=sys.stderr)
    return 1


def main_of_process(argv: Sequence[str] | None = None) -> int:
    """main() in a process that ends when it returns (the console script, `python -m benchlab.cli`): what is left
    is then frozen out of the garbage collector, whose passes at the interpreter's exit would otherwise walk every
    object numpy, pandas, h5py and numba made (0.1-0.3 s CPU of a command; the memory goes back with the process
    all the same, and atexit handlers still run)."""
    code = main(argv)
    gc.freeze()
    return code


if __name__ == "__main__":
    sys.exit(main_of_process())
