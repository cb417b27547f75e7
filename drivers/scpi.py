"""Strict parsers for SCPI replies: comma-separated NR3 numbers, error-queue entries, channel lists.

Strict on purpose: a reply that is not exactly what the instrument should send raises InstrumentError
instead of becoming a number.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

from drivers.errors import InstrumentError

OVERLOAD = 9.9e37
_NUMBER = re.compile(rb"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d{1,3})?")
_ERROR = re.compile(rb'([+-]?\d{1,6}),"([\x20-\x21\x23-\x7e]*)"')


def parse_values(reply: bytes, count: int) -> list[float]:
    """The `count` numbers of a READ?/FETC? reply (trailing CR/LF allowed); InstrumentError otherwise."""
    fields = reply.rstrip(b"\r\n").split(b",")
    if len(fields) != count or not all(_NUMBER.fullmatch(f) for f in fields):
        raise InstrumentError(f"malformed reading reply {reply[:80]!r} (expected {count} numbers)")
    return [float(f) for f in fields]


def parse_error(reply: bytes) -> tuple[int, str]:
    """One SYST:ERR? entry `-113,"Undefined header"` as (code, text); code 0 means the queue is empty."""
    match = _ERROR.fullmatch(reply.rstrip(b"\r\n"))
    if match is None:
        raise InstrumentError(f"malformed error-queue reply {reply[:80]!r}")
    return int(match.group(1)), match.group(2).decode("ascii")


def channel_list(channels: Sequence[int]) -> str:
    """SCPI channel list `(@101:104,106)` for the given channels, consecutive runs as ranges."""
    runs: list[list[int]] = []
    for ch in sorted(set(channels)):
        if runs and ch == runs[-1][-1] + 1:
            runs[-1].append(ch)
        else:
            runs.append([ch])
    parts = [f"{r[0]}:{r[-1]}" if len(r) > 1 else f"{r[0]}" for r in runs]
    return "(@" + ",".join(parts) + ")"


def parse_channel_list(text: str, max_channels: int | None = None) -> list[int]:
    """Channels of a SCPI channel list `(@101:104,106)`, in instrument (ascending) order; ValueError if malformed
    or, with `max_channels`, naming more channels than that (counted before any range is expanded)."""
    match = re.fullmatch(r"\(@([0-9:,\s]+)\)", text.strip())
    if match is None:
        raise ValueError(f"not a channel list: {text!r}")
    ranges: list[tuple[int, int]] = []
    for part in match.group(1).replace(" ", "").split(","):
        lo, _, hi = part.partition(":")
        first, last = int(lo), int(hi or lo)
        if last < first:
            raise ValueError(f"descending channel range: {part!r}")
        ranges.append((first, last))
    if max_channels is not None and (count := _distinct_channels(ranges)) > max_channels:
        raise ValueError(f"{count} channels, more than the {max_channels} a scan can hold")
    return sorted({ch for first, last in ranges for ch in range(first, last + 1)})


def _distinct_channels(ranges: Sequence[tuple[int, int]]) -> int:
    """How many distinct channels inclusive ranges name, overlaps counted once, without expanding them."""
    total, covered_to = 0, None
    for first, last in sorted(ranges):
        start = first if covered_to is None else max(first, covered_to + 1)
        if last >= start:
            total += last - start + 1
            covered_to = last
    return total
