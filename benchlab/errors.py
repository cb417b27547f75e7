"""Errors for bad input: one line naming the file, the field and what was expected."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any


def _one_line(text: str) -> str:
    """`text` with line breaks and other unprintable characters escaped (a key read from a file may hold them)."""
    return text if text.isprintable() else repr(text)[1:-1]


class InputError(Exception):
    """Bad input from a user-supplied file or argument; the CLI prints it on one line and exits 2."""

    def __init__(self, source: "str | os.PathLike[str]", field: str, expected: str) -> None:
        self.source, self.field, self.expected = str(source), field, expected
        super().__init__(f"{_one_line(self.source)}: {_one_line(field)}: {_one_line(expected)}")


def read_document(path: "str | os.PathLike[str]", what: str, parse: Callable[[str], Any],
                  malformed: tuple[type[Exception], ...], form: str, encoding: str | None = None) -> Any:
    """A user's file parsed by `parse`; InputError on its `file` field where it is missing, a directory, not text,
    nested deeper than the parser goes, or (one of `malformed`) not `form`. `what` names the file for the
    message, e.g. "parameter file"."""
    path = Path(path)
    try:
        return parse(path.read_text(encoding=encoding))
    except FileNotFoundError:
        raise InputError(path, "file", f"an existing {what} (not found)") from None
    except IsADirectoryError:
        raise InputError(path, "file", f"a {what}, not a directory") from None
    except RecursionError:
        raise InputError(path, "file", f"{form} of tables and lists nested a few levels deep (nested too deeply "
                                       "to read)") from None
    except (UnicodeDecodeError, *malformed) as exc:
        raise InputError(path, "file", f"{form} ({exc})") from None
