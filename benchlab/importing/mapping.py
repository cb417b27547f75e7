"""The mapping file of `benchlab import --mapping MAP.toml`: which source channel becomes which run-file channel.

```toml
[channels]
T_air = "Temp_Kammerluft"                        # run-file channel = source channel
[channels.engine_speed]                          # or a table
source = "n_Motor"
group = 1                                        # the channel group (index) where several hold the name
unit = "1/min"                                   # the source's unit where the file gives none or a wrong one
scale = 1.0                                      # value = source value * scale + offset, in `unit`
offset = 0.0
rule = "interpolate"                             # or "hold" (states, set-points)
time = "Zeit"                                    # a CSV's time column (in s, or its title's unit); an MDF
                                                 # file's and a CAN log's stamps are their own
```
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass

from benchlab.bounds import MAX_MAPPED_CHANNELS
from benchlab.errors import InputError, read_document
from benchlab.model.definition import is_name
from benchlab.values import check_keys, finite_number

RULES = ("interpolate", "hold")
#: How many of an input's own channel names a "required channels missing" line shows.
OFFERED_SHOWN = 20
ENTRY_KEYS = ("source", "group", "unit", "scale", "offset", "rule")


@dataclass(frozen=True)
class Mapped:
    """One run-file channel taken from a source channel (unit None: the source file's own)."""

    channel: str
    source: str
    group: int | None = None
    unit: str | None = None
    scale: float = 1.0
    offset: float = 0.0
    rule: str | None = None


def _entry(path: str, channel: str, value: object) -> Mapped:
    """One `[channels]` entry, checked field by field."""
    field = f"channels.{channel}"
    if not is_name(channel):
        raise InputError(path, "channels", f"run-file channel names of letters, digits and _ (as in a model file), "
                                           f"got {channel!r}")
    if isinstance(value, str):
        value = {"source": value}
    if not isinstance(value, dict):
        raise InputError(path, field, f"a source channel name or a table of {', '.join(ENTRY_KEYS)}")
    check_keys(path, field, value, ENTRY_KEYS)
    source = value.get("source")
    if not isinstance(source, str) or not source:
        raise InputError(path, f"{field}.source", "the source channel's name (text)")
    group = value.get("group")
    if group is not None and (isinstance(group, bool) or not isinstance(group, int) or not 0 <= group < 2**31):
        raise InputError(path, f"{field}.group", f"a channel group index (a whole number ≥ 0), got {group!r}")
    unit = value.get("unit")
    if unit is not None and not isinstance(unit, str):
        raise InputError(path, f"{field}.unit", f"a unit (text, e.g. \"°C\"), got {unit!r}")
    numbers = {}
    for key, default in (("scale", 1.0), ("offset", 0.0)):
        numbers[key] = finite_number(value.get(key, default))
        if numbers[key] is None:
            raise InputError(path, f"{field}.{key}", f"a finite number, got {value[key]!r}")
    rule = value.get("rule")
    if rule is not None and rule not in RULES:
        raise InputError(path, f"{field}.rule", f"one of {', '.join(RULES)}, got {rule!r}")
    return Mapped(channel, source, group, unit, numbers["scale"], numbers["offset"], rule)


def read_mapping(path: "str | os.PathLike[str]") -> list[Mapped]:
    """The mapping file's entries; InputError naming the first bad field."""
    doc = read_document(path, "mapping file", tomllib.loads, (tomllib.TOMLDecodeError,), "TOML")
    check_keys(path, "", doc, ("channels",))
    channels = doc.get("channels")
    if not isinstance(channels, dict) or not channels:
        raise InputError(path, "channels", "a table: run-file channel = source channel")
    if len(channels) > MAX_MAPPED_CHANNELS:
        raise InputError(path, "channels", f"at most {MAX_MAPPED_CHANNELS} channels, got {len(channels)}")
    return [_entry(str(path), name, value) for name, value in channels.items()]


def missing_channels(where: "str | os.PathLike[str]", kind: str, missing: list[str], offered: list[str]) -> InputError:
    """The one line for required channels an input lacks: which, and up to OFFERED_SHOWN of the channels it does
    offer, so that a mapping file can be written from the message alone."""
    shown = ", ".join(offered[:OFFERED_SHOWN]) or "none"
    if len(offered) > OFFERED_SHOWN:
        shown += f" and {len(offered) - OFFERED_SHOWN} more"
    return InputError(where, f"{kind} {', '.join(missing)}",
                      f"required channels (missing; the input offers {shown}): channels of those names, or a "
                      "mapping file (--mapping MAP.toml: run-file channel = source channel)")
