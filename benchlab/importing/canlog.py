"""A CAN log (`.blf`, `.asc`, `.trc`, `.log`, `.mf4` bus logging: whatever python-can's LogReader reads) decoded
with a DBC (cantools; drivers/bench.dbc by default) into the channels of a run.

Signals are picked by the mapping file (`source = "DM_Speed"` or `"DriveMotor_Status.DM_Speed"`); for a DBC that
holds the bench's own signals (drivers/can_signals.py), the contract channels it names none for are taken as
`benchlab run` takes them (benchlab.runner.devices.bench_layout): engine speed, clutch speed (load speed × the gear
ratio), clutch and load torque, and the actuator's clamp state, from which `clutch_state` and `friction_power`
are derived on the grid (derive_bench_channels). Every frame is decoded by the compiled codecs the drivers use
(drivers/can_codec.py). Error frames, remote frames, frames of ids the DBC does not know and frames shorter than
their message are counted and skipped; a file that stops being readable part-way keeps the frames before.

python-can inflates a BLF log's containers whole, whatever they hold: before it reads one, `blf_inflated_size` sums
what the log's containers declare they inflate to (the objects' headers alone), and more than the bound is refused
(benchlab.importing.child.ReaderLimits, which also runs the reader in a child process within memory and CPU limits).
"""

from __future__ import annotations

import logging
import os
import struct
import zlib
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from benchlab.bounds import MAX_BLF_INFLATION
from benchlab.errors import InputError
from benchlab.importing.child import ReaderLimits, read_in_child
from benchlab.importing.mapping import Mapped
from benchlab.importing.sources import Input, SourceChannel
from benchlab.runfile.schema import ALIGNED_UNITS, unmeasurable_sample
from benchlab.units import to_stored

log = logging.getLogger(__name__)
#: What python-can's LogReader reads (`.mf4` only where it holds CAN bus logging: benchlab.importing.mdf else).
CAN_LOG_SUFFIXES = (".blf", ".asc", ".trc", ".log", ".mf4")
#: Time stamps beyond this (s) are UNIX time (after 1973): the log says when it was recorded.
UNIX_TIME_S = 1e8
#: The internal channel of the actuator's clamp state (0 open, 1 slipping, 2 clamped) on the grid, as the bench's
#: layout names it (drivers.can_signals.CAN_ALIGNED).
CLAMP_STATE = "_clamp_state"
#: A BLF file's header starts with "LOGG" and its own size (python-can's blf.FILE_HEADER_STRUCT); each object with
#: "LOBJ", its header's size and version, its size and its type (OBJ_HEADER_BASE_STRUCT), padded to 4 bytes; a log
#: container (type 10) then with its compression method and uncompressed size (LOG_CONTAINER_STRUCT).
BLF_FILE_START = struct.Struct("<4sL")
BLF_OBJECT = struct.Struct("<4sHHLL")
BLF_CONTAINER = struct.Struct("<H6xL4x")
BLF_LOG_CONTAINER = 10
BLF_ZLIB = 2
#: Frames read from a log kept as python-can's tuples before they become one array of FRAME records.
FRAMES_PER_PART = 1 << 16
#: Bytes inflated at a time when a container's declared size is checked.
INFLATE_PIECE = 1 << 20


def bench_entries(gear_ratio: float) -> list[Mapped]:
    """The contract channels `benchlab run` takes from the bench's CAN signals, as mapping entries (DBC names)."""
    from drivers.can_signals import BENCH_SIGNALS, CAN_ALIGNED, CAN_COLUMN_SIGNALS

    entries = []
    for channel, stream, column, geared in CAN_ALIGNED:
        message, signal = BENCH_SIGNALS[CAN_COLUMN_SIGNALS[(stream, column)]]
        entries.append(Mapped(channel, f"{message}.{signal}", scale=gear_ratio if geared else 1.0,
                              rule="hold" if channel == CLAMP_STATE else None))
    return entries


def is_can_log(path: Path) -> bool:
    """Whether `path` is read as a CAN log: any of CAN_LOG_SUFFIXES but `.mf4`, and an `.mf4` holding CAN bus
    logging (asammdf's `CAN_DataFrame` channel; else it is an MDF file of signals)."""
    if path.suffix.lower() != ".mf4":
        return path.suffix.lower() in CAN_LOG_SUFFIXES
    from asammdf import MDF

    try:
        mdf = MDF(path)
    except Exception:  # not an MDF file asammdf reads: benchlab.importing.mdf says so in one line
        return False
    try:
        return "CAN_DataFrame" in mdf.channels_db
    finally:
        mdf.close()


def blf_inflated_size(path: Path) -> int:
    """The bytes a BLF log's containers declare they inflate to, from the objects' headers (0 where the file is
    not a BLF log: python-can says so); the walk stops where the objects do, as python-can's reader does.
    InputError where a container inflates to more than it declares (inflated piecewise, never held whole)."""
    size, total = path.stat().st_size, 0
    with open(path, "rb") as f:
        head = f.read(BLF_FILE_START.size)
        if len(head) < BLF_FILE_START.size or head[:4] != b"LOGG":
            return 0
        at = BLF_FILE_START.unpack(head)[1]
        while at + BLF_OBJECT.size + BLF_CONTAINER.size <= size:
            f.seek(at)
            block = f.read(BLF_OBJECT.size + BLF_CONTAINER.size)
            signature, _, _, object_size, object_type = BLF_OBJECT.unpack_from(block)
            if signature != b"LOBJ" or object_size < BLF_OBJECT.size:
                break
            if object_type == BLF_LOG_CONTAINER:
                method, declared = BLF_CONTAINER.unpack_from(block, BLF_OBJECT.size)
                total += declared
                if method == BLF_ZLIB and _inflates_beyond(f.read(object_size - len(block)), declared):
                    raise InputError(path, f"log container at byte {at}", f"at most the {declared} bytes it "
                                                                          "declares uncompressed (it inflates to "
                                                                          "more: a compression bomb)")
            at += object_size + object_size % 4
    return total


def _inflates_beyond(data: bytes, declared: int) -> bool:
    """Whether zlib data inflate to more than `declared` bytes, inflated a piece at a time and counted."""
    inflater, produced = zlib.decompressobj(), 0
    try:
        while produced <= declared and data:
            produced += len(inflater.decompress(data, INFLATE_PIECE))
            data = inflater.unconsumed_tail
    except zlib.error:  # damaged data: python-can's reader says so, with the frames before
        return False
    return produced > declared


def _read_log_or_mdf(path: Path, mapped: list[Mapped], dbc: "str | os.PathLike[str]", gear_ratio: float) -> Input:
    """The file as a CAN log (is_can_log) or else as an MDF file of signals."""
    from benchlab.importing.mdf import read_mdf

    return read_can_log(path, dbc, mapped, gear_ratio) if is_can_log(path) else read_mdf(path, mapped)


def read_foreign(path: Path, mapped: list[Mapped], dbc: "str | os.PathLike[str]", gear_ratio: float) -> Input:
    """An MDF file or a CAN log (by its suffix, and for `.mf4` by what it holds), read in a child process within
    the limits its declared sizes give (benchlab.importing.child): a crash, a compression bomb or a reader that
    does not end is one line naming the file."""
    from benchlab.importing.mdf import inflated_size

    if not path.is_file():
        raise InputError(path, "file", "an existing file (not found)" if not path.exists() else "a file, not a "
                                                                                             "directory")
    suffix = path.suffix.lower()
    if suffix == ".blf":
        limits = ReaderLimits.for_input(path, blf_inflated_size(path), "log containers", MAX_BLF_INFLATION)
    elif suffix in CAN_LOG_SUFFIXES and suffix != ".mf4":
        limits = ReaderLimits.for_input(path)
    else:
        limits = ReaderLimits.for_input(path, inflated_size(path), "compressed blocks (##DZ)")
    what = "an MDF file asammdf reads" if suffix in (".mdf", ".dat") else \
        "a CAN log python-can reads" if suffix != ".mf4" else "an MF4 file asammdf reads"
    return read_in_child(path, what, limits, _read_log_or_mdf, path, mapped, dbc, gear_ratio)


def _frames(path: Path) -> tuple[np.ndarray, int, str | None]:
    """Every frame of the log as FRAME records, the count of unreadable ends (0 or 1), and why."""
    import can

    from drivers.can_frames import frames_from_records, join, record

    try:
        reader = can.LogReader(path)
    except (ValueError, OSError, EOFError) as exc:
        raise InputError(path, "file", f"a CAN log python-can reads ({type(exc).__name__}: {exc})") from None
    parts, records, broken = [], [], None
    try:
        with reader:
            for msg in reader:
                records.append(record(msg))
                if len(records) == FRAMES_PER_PART:  # as FRAME records: a third of the memory of the tuples
                    parts.append(frames_from_records(records))
                    records = []
    except Exception as exc:  # a truncated or corrupt container, a line no reader parses: the frames before stay
        broken = f"{type(exc).__name__}: {exc}"
    parts.append(frames_from_records(records))
    frames = join(parts)
    if not len(frames):
        raise InputError(path, "file", "a CAN log with frames" + (f" ({broken})" if broken else " (it holds none)"))
    return frames, int(broken is not None), broken


def _signal(path: Path, db: Any, entry: Mapped) -> tuple[Any, Any] | None:
    """(message, signal) of the DBC the entry names, None where the DBC has none; InputError where ambiguous."""
    message_name, _, signal_name = entry.source.rpartition(".")
    found = [(m, s) for m in db.messages for s in m.signals
             if s.name == signal_name and message_name in ("", m.name)]
    if len(found) > 1:
        raise InputError(path, f"channel {entry.channel} ← {entry.source}", "one signal: messages "
                         f"{', '.join(m.name for m, _ in found)} hold it, say which as MESSAGE.SIGNAL")
    return found[0] if found else None


def read_can_log(path: "str | os.PathLike[str]", dbc: "str | os.PathLike[str]", mapped: list[Mapped],
                 gear_ratio: float) -> Input:
    """The log's frames decoded with `dbc`: the signals the mapping names and, for the bench's DBC, the bench's
    contract channels (module docstring), each at its frames' time stamps."""
    from benchlab.runner.devices import duplicate_message, load_dbc
    from drivers.can_codec import compile_codecs
    from drivers.can_frames import ERROR, EXTENDED, REMOTE

    path = Path(path)
    try:
        db = load_dbc(str(dbc))
    except Exception as exc:  # cantools raises its own errors, and OSError, for a file it cannot parse
        raise InputError(dbc, "file", f"a CAN database (DBC) cantools reads ({type(exc).__name__})") from None
    if (twice := duplicate_message(db)) is not None:
        raise InputError(dbc, "messages", f"each message defined once (the {twice})")
    frames, broken, why = _frames(path)
    if broken:
        log.warning("%s: unreadable from frame %d on (%s); the frames before are imported", path, len(frames), why)
    named = {m.channel for m in mapped}
    bench = [e for e in bench_entries(gear_ratio) if e.channel not in named]
    entries = [(e, hit) for e in mapped if (hit := _signal(path, db, e)) is not None]
    bench_hits = [(e, _signal(path, db, e)) for e in bench]
    if all(hit is not None for _, hit in bench_hits):  # the bench's DBC (or one holding its signals)
        entries += bench_hits
    flags = frames["flags"]
    usable = (flags & (ERROR | REMOTE)) == 0
    ids = frames["arbitration_id"].astype(np.int64) | np.where(flags & EXTENDED, 1 << 31, 0)
    known = {(m.frame_id | (1 << 31 if m.is_extended_frame else 0)): m for m in db.messages}
    is_known = np.isin(ids, list(known))
    skipped = {"error or remote frames": int((~usable).sum()),
               "frames of ids the DBC does not know": int((usable & ~is_known).sum()),
               "unreadable rest of the file": broken}
    codecs = compile_codecs(db)
    first = float(np.nanmin(frames["timestamp"]))
    unix = first > UNIX_TIME_S  # the log's start is known: its stamps from then on
    stamps = frames["timestamp"] - first if unix else frames["timestamp"]
    wanted = {message.name for _, (message, _) in entries}
    decoded: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]] = {}
    skipped["frames shorter than their message"] = skipped["frames that do not decode"] = 0
    for key, message in known.items():
        rows = np.flatnonzero(usable & (ids == key))
        whole = frames["length"][rows] >= message.length
        skipped["frames shorter than their message"] += int((~whole).sum())
        if message.name in wanted and whole.any():
            rows = rows[whole]
            values, ok = _decode(codecs[message.name], frames["data"][rows])
            skipped["frames that do not decode"] += int((~ok).sum())
            decoded[message.name] = (stamps[rows][ok], {k: v[ok] for k, v in values.items()})
    channels, streams = [], {}
    for entry, (message, signal) in entries:
        if message.name not in decoded:
            continue
        time, values = decoded[message.name]
        channels.append(_channel(path, entry, message, signal, time, values[signal.name]))
        streams[channels[-1].stream] = {"source_file": path.name, "bus": "CAN", "message": message.name,
                                        "frame_id": int(message.frame_id), "node": ", ".join(message.senders)}
    start = datetime.fromtimestamp(first, timezone.utc) if unix else None
    return Input(path, channels, start, {}, streams, skipped)


def _decode(codec: Any, data: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Frames' data bytes (n, 64) decoded by a compiled codec (drivers/can_codec.py): signal -> values, and which
    rows decoded (a multiplexed message's row cantools refuses does not)."""
    table = codec.table
    payload = np.zeros((len(data), table.payload_bytes), dtype=np.uint8)  # the message's bytes, zeros after
    payload[:, :codec.length] = data[:, :codec.length]
    values, ok = table.decode(np.zeros(len(data), dtype=np.intp), payload)
    return {key: values[:, j] for j, key in enumerate(codec.columns) if key is not None}, ok


def _channel(path: Path, entry: Mapped, message: Any, signal: Any, time: np.ndarray,
             raw: np.ndarray) -> SourceChannel:
    """One decoded signal as a source channel in the run file's unit."""
    field = f"channel {entry.channel} ← {message.name}.{signal.name}"
    unit = entry.unit if entry.unit is not None else str(signal.unit or "")
    if entry.channel == CLAMP_STATE:
        values, stored = raw.copy(), "1"
    else:
        if not unit and entry.channel not in ALIGNED_UNITS:
            raise InputError(path, field, "a unit (the DBC gives none): unit in the mapping file, \"1\" for a number")
        values, stored = to_stored(path, f"{field} [{unit}]", entry.channel, raw * entry.scale + entry.offset,
                                   unit or ALIGNED_UNITS[entry.channel])
        if (problem := unmeasurable_sample(entry.channel, stored, values)) is not None:
            raise InputError(path, f"{field}, frame {problem[0]}", f"{problem[1]}, got {problem[2]!r}")
    held = entry.channel == "clutch_state" or bool(signal.choices) or signal.length == 1
    return SourceChannel(entry.channel, time, values, stored, entry.rule or ("hold" if held else "interpolate"),
                         f"{path.name}: CAN {message.name}.{signal.name}", f"{path.stem}.{message.name}",
                         signal.name, raw, str(signal.unit or "1"))


def derive_bench_channels(frame: pd.DataFrame) -> pd.DataFrame:
    """`clutch_state` and `friction_power` from the actuator's clamp state on the grid, as the bench derives them
    (benchlab.runner.devices.derive_aligned); the frame without the internal clamp-state channel."""
    from benchlab.runner.devices import derive_aligned

    if CLAMP_STATE not in frame.columns:
        return frame
    nan = np.full(len(frame), np.nan)
    derived = derive_aligned({CLAMP_STATE: frame[CLAMP_STATE].to_numpy(), **{
        name: frame[name].to_numpy() if name in frame.columns else nan
        for name in ("clutch_torque", "engine_speed", "clutch_speed", "T_flywheel_1", "T_flywheel_2")}})
    out = frame.drop(columns=CLAMP_STATE)
    for name in ("clutch_state", "friction_power"):
        if name not in out.columns:
            out[name] = derived[name]
    return out
