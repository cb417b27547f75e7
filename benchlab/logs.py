"""Where log messages go: `-v` INFO, `-vv` DEBUG on stderr, `--log FILE` everything at DEBUG into a file.

The project's own loggers, one per module (`benchlab.*`, `drivers.*` with the SCPI dialogue at DEBUG, `sim_bench.*`,
`protocols.*`), show their warnings without `-v`. The libraries underneath (python-can's backends, pyvisa) and
Python warnings they raise say nothing on the terminal unless `-v` (then their warnings, with `-vv` their INFO):
a missing vendor library is explained once, in the line that names the setting (benchlab.runner.opening).
"""

from __future__ import annotations

import errno
import io
import logging
import os
import stat
import sys

#: The project's top-level packages: their loggers follow -v/-vv.
OWN_LOGGERS = ("benchlab", "drivers", "protocols", "sim_bench")
_FORMAT = "%(levelname)s %(name)s: %(message)s"


class _TerminalShare(logging.Filter):
    """The records the terminal shows: the project's from `own`, the libraries' from `libraries` (None: none)."""

    def __init__(self) -> None:
        super().__init__()
        self.own, self.libraries = logging.WARNING, None

    def filter(self, record: logging.LogRecord) -> bool:
        if record.name.split(".", 1)[0] in OWN_LOGGERS:
            return record.levelno >= self.own
        return self.libraries is not None and record.levelno >= self.libraries


_SHARE = _TerminalShare()
_TERMINAL = logging.StreamHandler()
_TERMINAL.setFormatter(logging.Formatter(_FORMAT))
_TERMINAL.addFilter(_SHARE)
_files: dict[str, logging.Handler] = {}


def configure(verbosity: int) -> None:
    """The terminal's share: the project's loggers at WARNING, INFO (-v) or DEBUG (-vv) on stderr; the libraries'
    (and Python warnings) only from -v on, at WARNING (INFO with -vv)."""
    _SHARE.own = {0: logging.WARNING, 1: logging.INFO}.get(verbosity, logging.DEBUG)
    _SHARE.libraries = None if verbosity <= 0 else logging.WARNING if verbosity == 1 else logging.INFO
    _TERMINAL.stream = sys.stderr  # not setStream: it flushes the old stream, which may be closed by now
    root = logging.getLogger()
    if _TERMINAL not in root.handlers:  # also keeps Python's last-resort printing of library warnings off
        root.addHandler(_TERMINAL)
    logging.captureWarnings(True)  # a library's warnings.warn goes through logging (py.warnings), as above
    _set_levels()


def _open_log(path: str, append: bool) -> "io.TextIOWrapper":
    """`path` opened for writing as a regular file only: never through a symbolic link, never blocking on a FIFO
    (the output rule has refused those by name already; this holds if one appeared since). OSError otherwise."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | (os.O_APPEND if append else os.O_TRUNC)
    fd = os.open(path, flags, 0o644)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file")
        os.set_blocking(fd, True)
        return open(fd, "a", encoding="utf-8", closefd=True)
    except BaseException:
        os.close(fd)
        raise


def keep_in_file(path: "str | os.PathLike[str]", append: bool = True) -> logging.Handler:
    """Everything the project logs at DEBUG (libraries from INFO), with times, in `path` (appended to, else
    replaced) besides the terminal's share; a file that cannot be opened, or is no regular file, is OSError.
    Which file may be a log is the output rule's (benchlab.outputs `check_log`)."""
    key = os.fspath(path)
    if key not in _files:
        handler = logging.StreamHandler(_open_log(key, append))
        handler.setFormatter(logging.Formatter("%(asctime)s " + _FORMAT))
        logging.getLogger().addHandler(handler)
        _files[key] = handler
    _set_levels()
    return _files[key]


def stop_file(path: "str | os.PathLike[str]") -> None:
    """Close the log file `keep_in_file` opened (the run is over)."""
    handler = _files.pop(os.fspath(path), None)
    if handler is not None:
        logging.getLogger().removeHandler(handler)
        handler.close()
        handler.stream.close()
    _set_levels()


def _set_levels() -> None:
    """Each logger as low as its most talkative destination needs (the filters do the rest)."""
    own = logging.DEBUG if _files else _SHARE.own
    libraries = min(logging.INFO if _files else logging.WARNING, _SHARE.libraries or logging.WARNING)
    for name in OWN_LOGGERS:
        logging.getLogger(name).setLevel(own)
    logging.getLogger().setLevel(libraries)
