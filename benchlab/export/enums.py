"""What the bench's DBC says about a run's raw CAN columns: the value tables (VAL_) an export shows as text beside
the number (`can_clutch.clamp_state` 1 = "Slipping"), and where each column comes from on the bus (message and
sending node: MDF source information). The DBC is the one the run used (`bench_config`'s `dbc`, else
drivers/bench.dbc); a DBC that is no longer where the run found it gives none of this, and the numbers stay."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class BusSource:
    """Where a channel comes from on a bus: bus kind, message, sending node(s), and the raw value's texts."""

    bus: str
    message: str
    node: str
    texts: dict[int, str] | None = None


def can_sources(attrs: dict[str, str]) -> dict[str, BusSource]:
    """Export channel name (`can_drive.state`) -> its BusSource for every raw CAN column of the bench's layout."""
    import cantools

    from drivers.can_signals import BENCH_DBC, BENCH_SIGNALS, CAN_COLUMN_SIGNALS

    try:
        configured = json.loads(attrs.get("bench_config", "{}")).get("dbc")
    except (json.JSONDecodeError, AttributeError):
        configured = None
    path = Path(configured) if configured else BENCH_DBC
    try:
        db = cantools.database.load_file(str(path))
    except (OSError, cantools.database.UnsupportedDatabaseFormatError):
        return {}
    sources = {}
    for (stream, column), key in CAN_COLUMN_SIGNALS.items():
        message_name, signal_name = BENCH_SIGNALS[key]
        try:
            message = db.get_message_by_name(message_name)
            choices = message.get_signal_by_name(signal_name).choices
        except KeyError:
            continue
        texts = {int(v): str(t) for v, t in choices.items()} if choices else None
        sources[f"{stream}.{column}"] = BusSource("CAN", f"{message.name}.{signal_name}", ", ".join(message.senders),
                                                  texts)
    return sources
