"""argparse types that check command-line values at parse time: bounded numbers, channel lists, output files'
directories (the output rule itself is benchlab.outputs', applied when --force is known).

A value they refuse is argparse's usage error: one line `benchlab CMD: argument --NAME: what was expected,
got ...` and exit 2, before anything is read, opened or moved. The bounds live in benchlab.bounds.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

from benchlab.bounds import MAX_SCAN_CHANNELS
from drivers import scpi
from sim_bench import faults


def _bounded_float(what: str, low: float, maximum: float, expected: str) -> Callable[[str], float]:
    """A finite number with low < value <= maximum (low exclusive only where it is 0: positive numbers)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and (low < value if low == 0 else low <= value) and value <= maximum):
            raise argparse.ArgumentTypeError(f"{what}: a number {expected}, got {text!r}")
        return value
    return parse


def positive_float(what: str, maximum: float) -> Callable[[str], float]:
    """A finite number in (0, maximum]; `what` says what it is, e.g. "a duration in s"."""
    return _bounded_float(what, 0.0, maximum, f"in (0, {maximum:g}]")


def ranged_float(what: str, minimum: float, maximum: float) -> Callable[[str], float]:
    """A finite number in [minimum, maximum]; `what` says what it is, e.g. "a speed-up over real time"."""
    return _bounded_float(what, minimum, maximum, f"in [{minimum:g}, {maximum:g}]")


def attribute_name(text: str) -> str:
    """The name of a run file's root attribute (`--group-by bench`): not empty, no white space around it."""
    if not text.strip() or text != text.strip() or not text.isprintable():
        raise argparse.ArgumentTypeError(f"a run attribute's name (e.g. bench, specimen), got {text!r}")
    return text


def signed_float(what: str, maximum: float) -> Callable[[str], float]:
    """A finite number in [-maximum, maximum]; `what` says what it is, e.g. "a run time in s"."""
    return _bounded_float(what, -maximum, maximum, f"within ±{maximum:g}")


def count(what: str, maximum: int | None, minimum: int = 1) -> Callable[[str], int]:
    """An integer in [minimum, maximum] (no upper bound for None); `what` says what it counts, e.g. "cycles"."""
    expected = f"an integer in [{minimum}, {maximum}]" if maximum is not None else f"an integer >= {minimum}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = minimum - 1
        if not (minimum <= value and (maximum is None or value <= maximum)):
            raise argparse.ArgumentTypeError(f"{what}: {expected}, got {text!r}")
        return value
    return parse


#: A random seed: numpy takes any non-negative integer.
seed = count("a seed", None, minimum=0)


def channel_list(text: str) -> list[int]:
    """A SCPI channel list such as (@101:104), at most MAX_SCAN_CHANNELS channels (counted before expanding)."""
    try:
        return scpi.parse_channel_list(text, max_channels=MAX_SCAN_CHANNELS)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"a SCPI channel list like (@101:104) of at most {MAX_SCAN_CHANNELS} "
                                         f"channels, got {text!r} ({exc})") from None


def name_values(text: str) -> list[str]:
    """NAME=VALUE items of a repeatable option, several in one value separated by commas (`--fix A=1,B=2`).

    One value per flag keeps a positional argument after the option from being taken for one of its values; each
    item's NAME=VALUE form is the command's to check (it names the item)."""
    items = [item.strip() for item in text.split(",") if item.strip()]
    if not items:
        raise argparse.ArgumentTypeError(f"NAME=VALUE[,NAME=VALUE...], got {text!r}")
    return items


def output_file(text: str) -> str:
    """A file to write in a directory that exists (at parse time; what may be replaced is benchlab.outputs')."""
    path = Path(text)
    if not path.parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: a file in an existing directory ({path.parent} not found)")
    return text


def fault(text: str) -> faults.Fault:
    """A simulated-bench fault KIND@SECONDS[:key=value,...], checked against sim_bench.faults.KINDS."""
    try:
        return faults.parse_fault(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"a fault {faults.SPEC}: {exc}, got {text!r}") from None
