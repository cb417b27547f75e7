"""Errors for bad input: one line naming the file, the field and what was expected."""

from __future__ import annotations

import os


def _one_line(text: str) -> str:
    """`text` with line breaks and other unprintable characters escaped (a key read from a file may hold them)."""
    return text if text.isprintable() else repr(text)[1:-1]


class InputError(Exception):
    """Bad input from a user-supplied file or argument; the CLI prints it on one line and exits 2."""

    def __init__(self, source: "str | os.PathLike[str]", field: str, expected: str) -> None:
        self.source, self.field, self.expected = str(source), field, expected
        super().__init__(f"{_one_line(self.source)}: {_one_line(field)}: {_one_line(expected)}")
