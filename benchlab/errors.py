"""Errors for bad input: one line naming the file, the field and what was expected."""

from __future__ import annotations

import os


class InputError(Exception):
    """Bad input from a user-supplied file or argument; the CLI prints it on one line and exits 2."""

    def __init__(self, source: "str | os.PathLike[str]", field: str, expected: str) -> None:
        self.source, self.field, self.expected = str(source), field, expected
        super().__init__(f"{self.source}: {field}: {expected}")
