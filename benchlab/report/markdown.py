"""Text from files and arguments (run attributes, channel names, units, file names, model labels, parameter names)
put into benchlab's Markdown pages as text, never as markup: the one boundary between what a stranger wrote and the
pages' own Markdown (report.md, diagnose.md and their HTML, benchlab/report/html.py).

A value keeps to one line (a blank line would start a block of its own), and the characters that make markup are
escaped with a backslash as CommonMark does, so the .md reads the same in any Markdown viewer and in benchlab's HTML.
"""

from __future__ import annotations

import re

#: The characters a backslash may escape (CommonMark's: ASCII punctuation); the renderer shows each as itself.
ESCAPABLE = "!\"#$%&'()*+,-./:;<=>?@[\\]^_`{|}~"
#: The ones `text` escapes: those that open markup anywhere in a line (code, bold, italics, links and images, raw
#: HTML, table cells); the rest only count where a value never stands (a line's start, after one of these).
_ESCAPE = re.compile(r"([\\`*\[\]<|])")
_LINE_BREAKS = re.compile(r"\s+")
_CONTROLS = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f\u2028\u2029]")


def one_line(value: object) -> str:
    """The value as one line of text: control characters dropped, any run of white space (a newline too) one space."""
    return _LINE_BREAKS.sub(" ", _CONTROLS.sub("", str(value))).strip()


def text(value: object) -> str:
    """A stranger's value as plain text in a page: one line, every markup character escaped."""
    return _ESCAPE.sub(r"\\\1", one_line(value))


def literal(value: object) -> str:
    """A stranger's value as a code span (a name, a file, a unit as written); plain escaped text where it holds a
    backtick or a pipe, which no code span of the subset can carry; None (no value: a finding without a signal)
    is a dash."""
    line = one_line(value) if value is not None else ""
    if not line or "`" in line or "|" in line:
        return text(line) or "—"
    return f"`{line}`"
