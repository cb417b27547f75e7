"""The DBC's value tables (VAL_) of a run's raw CAN columns: what an export shows as text beside the number
(`can_clutch.clamp_state` 1 = "Slipping"). The DBC is the one the run used (`bench_config`'s `dbc`, else
drivers/bench.dbc); a DBC that is no longer where the run found it gives no tables, and the numbers stay."""

from __future__ import annotations

import json
from pathlib import Path


def value_texts(attrs: dict[str, str]) -> dict[str, dict[int, str]]:
    """Export channel name (`can_drive.state`) -> {raw value: text} for every raw CAN column whose DBC signal has a
    value table."""
    import cantools

    from benchlab.runner.devices import CAN_COLUMN_SIGNALS
    from drivers.can_signals import BENCH_DBC, BENCH_SIGNALS

    try:
        configured = json.loads(attrs.get("bench_config", "{}")).get("dbc")
    except (json.JSONDecodeError, AttributeError):
        configured = None
    path = Path(configured) if configured else BENCH_DBC
    try:
        db = cantools.database.load_file(str(path))
    except (OSError, cantools.database.UnsupportedDatabaseFormatError):
        return {}
    texts = {}
    for (stream, column), key in CAN_COLUMN_SIGNALS.items():
        message, signal = BENCH_SIGNALS[key]
        try:
            choices = db.get_message_by_name(message).get_signal_by_name(signal).choices
        except KeyError:
            continue
        if choices:
            texts[f"{stream}.{column}"] = {int(v): str(t) for v, t in choices.items()}
    return texts
