"""An MDF file (`.mf4`, `.mdf`, `.dat`: whatever asammdf reads) as the channels of a run file on one grid.

Channels are picked by a mapping file (benchlab.importing.mapping) and, where it names none, by the contract's
names the MDF holds (what `benchlab export --to X.mf4` writes). Each is read with its own master (time stamps),
its invalidation bits as NaN, scaled as the mapping says and converted to the contract's unit (benchlab.units);
benchlab.importing.sources puts it on the grid `--dt` by its rule, from the header's start time, and keeps it as
the file held it under /raw/<file>.<group>. The header comment becomes `source_comment`.

asammdf trusts the sizes an MF4 file declares: before it opens one, `inflated_size` walks the file's blocks (MDF 4:
every block reachable from the header by any link, so data lists ##DL, header lists ##HL and signal data too) and
sums what its compressed blocks ##DZ declare they inflate to; more than the bound (benchlab.bounds MAX_INFLATION)
is refused, and the reader runs in a child process within memory and CPU limits (benchlab.importing.child,
through benchlab.importing.canlog.read_foreign, which also tells an MF4 of CAN bus logging from one of signals).
"""

from __future__ import annotations

import mmap
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

from benchlab.errors import InputError
from benchlab.importing.mapping import Mapped
from benchlab.importing.sources import Input, SourceChannel
from benchlab.runfile.schema import ALIGNED_UNITS, unmeasurable_sample
from benchlab.units import to_stored


#: An MDF 4 block's header (id "##XX", 4 reserved bytes, length, link count), then its links (file offsets, 0 none).
BLOCK_HEADER = struct.Struct("<4s4xQQ")
#: A ##DZ block after its header: original block type, zip type, reserved, zip parameter, original size, compressed
#: size (ASAM MDF 4.2, DZBLOCK; asammdf's v4_constants.DZ_COMMON_INFO reads the last four).
DZ_FIELDS = struct.Struct("<2sBxIQQ")
#: The identification block before the header block (MDF 4: "MDF     " and the version, e.g. "4.10").
HEADER_BLOCK_AT = 64
LINK = struct.Struct("<Q")
#: Blocks whose first link is the next block of their kind (ASAM MDF 4: data groups, channel groups, channels, data
#: lists, attachments, events, channel hierarchies, file histories, sample reductions): readers follow it to its end.
CHAINED_BLOCKS = frozenset({b"##DG", b"##CG", b"##CN", b"##DL", b"##AT", b"##EV", b"##CH", b"##FH", b"##SR"})


def inflated_size(path: Path) -> int:
    """The bytes an MDF 4 file's ##DZ blocks declare they inflate to, read from the block headers alone; 0 for an
    older MDF (no compressed blocks). InputError where the blocks overlap (more of them than the file can hold) or
    a chain of them loops back (a reader following it would never end)."""
    size = path.stat().st_size
    if size < HEADER_BLOCK_AT + BLOCK_HEADER.size:
        return 0
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
        if data[:3] != b"MDF" or data[8:9] != b"4":
            return 0
        pending, seen, total, chained, kinds = [HEADER_BLOCK_AT], set(), 0, {}, {}
        while pending:
            at = pending.pop()
            if at in seen or not 0 < at <= size - BLOCK_HEADER.size:
                continue
            seen.add(at)
            if len(seen) > size // BLOCK_HEADER.size:
                raise InputError(path, "blocks", "MDF blocks that do not overlap (more blocks than the file holds)")
            block_id, _, links = BLOCK_HEADER.unpack_from(data, at)
            if block_id[:2] != b"##":
                continue
            first = at + BLOCK_HEADER.size
            count = min(links, (size - first) // LINK.size)
            links = struct.unpack_from(f"<{count}Q", data, first)
            pending.extend(links)
            if block_id in CHAINED_BLOCKS and links:
                chained[at], kinds[at] = links[0], block_id.decode(errors="replace")
            if block_id == b"##DZ" and first + DZ_FIELDS.size <= size:
                total += DZ_FIELDS.unpack_from(data, first)[3]
    if (looped := _loop(chained)) is not None:
        raise InputError(path, "blocks", f"chains of MDF blocks that end (the {kinds[looped]} block at byte {looped} "
                                         "is reached again from its own next links)")
    return total


def _loop(following: dict[int, int]) -> int | None:
    """A block whose chain of next links (`following`: block -> next block) comes back to it, None if none does."""
    done: set[int] = set()
    for start in following:
        path: dict[int, None] = {}
        at = start
        while at in following and at not in done:
            if at in path:
                return at
            path[at] = None
            at = following[at]
        done.update(path)
    return None


def _open(path: Path) -> Any:
    """asammdf's MDF of `path`; InputError where it is missing or not an MDF file."""
    from asammdf import MDF

    if not path.is_file():
        raise InputError(path, "file", "an existing MDF file (not found)" if not path.exists() else "an MDF file")
    try:
        return MDF(path)
    except Exception as exc:  # asammdf raises anything from struct.error to MdfException on a file it cannot read
        raise InputError(path, "file", f"an MDF file asammdf reads ({type(exc).__name__}: {exc})") from None


def numbers(mdf: Any, **where: Any) -> tuple[Any, np.ndarray | None]:
    """A channel (asammdf's `get` arguments: name, or group and index) as a run file stores it: its Signal, and its
    samples as float64 with NaN where the invalidation bit is set (an enum: the numbers behind its texts); None for
    samples that are not 1-D numbers."""
    sig = mdf.get(**where, ignore_invalidation_bits=True)  # every sample, with its bit
    if sig.samples.dtype.kind in "SUO":  # an enum shown as its value table's texts: the numbers behind them
        sig = mdf.get(**where, ignore_invalidation_bits=True, raw=True)
    if sig.samples.dtype.kind not in "iufb" or sig.samples.ndim != 1:
        return sig, None
    values = sig.samples.astype(np.float64)
    if sig.invalidation_bits is not None:
        values[np.asarray(sig.invalidation_bits, dtype=bool)] = np.nan
    return sig, values


def _location(path: Path, mdf: Any, entry: Mapped) -> tuple[int, int] | None:
    """(group, index) of the entry's source channel, None where the file has none; InputError where ambiguous."""
    found = [(g, i) for g, i in mdf.channels_db.get(entry.source, ()) if entry.group in (None, g)]
    if len(found) > 1:
        raise InputError(path, f"channel {entry.channel} ← {entry.source}", f"one channel: groups "
                         f"{sorted({g for g, _ in found})} hold {entry.source!r}, say which with group in the "
                         "mapping file")
    return found[0] if found else None


def _stream(path: Path, mdf: Any, group: int) -> str:
    """The /raw stream of an MDF channel group: the file's stem and the group's acquisition name (or index)."""
    name = str(mdf.groups[group].channel_group.acq_name or f"group {group}")
    return f"{path.stem}.{name}".replace("/", "_").strip(".") or f"{path.stem}.{group}"


def _channel(path: Path, mdf: Any, entry: Mapped, group: int, index: int) -> SourceChannel:
    """One source channel: time stamps, values in the run file's unit (invalid samples NaN), that unit, the rule,
    and its samples as the file held them."""
    sig, raw = numbers(mdf, group=group, index=index)
    field = f"channel {entry.channel} ← {entry.source}"
    if raw is None:
        raise InputError(path, field, f"a numeric channel, got samples of type {sig.samples.dtype}")
    unit = entry.unit if entry.unit is not None else str(sig.unit or "")
    if not unit and entry.channel not in ALIGNED_UNITS:
        raise InputError(path, field, "a unit (the MDF file gives none): unit in the mapping file, \"1\" for a number")
    values, stored = to_stored(path, f"{field} [{unit}]", entry.channel, raw * entry.scale + entry.offset, unit)
    if (problem := unmeasurable_sample(entry.channel, stored, values)) is not None:
        raise InputError(path, f"{field}, sample {problem[0]}", f"{problem[1]}, got {problem[2]!r}")
    held = entry.channel == "clutch_state" or sig.samples.dtype.kind in "iub"
    return SourceChannel(entry.channel, np.asarray(sig.timestamps, dtype=np.float64), values, stored,
                         entry.rule or ("hold" if held else "interpolate"),
                         f"{path.name}: {entry.source} (group {group})", _stream(path, mdf, group), entry.source,
                         raw, unit)


def read_mdf(path: "str | os.PathLike[str]", mapped: list[Mapped]) -> Input:
    """The MDF's channels the mapping names (those it holds) and the contract's channels it holds by name, each at
    its own time stamps from the header's start time; its header comment as `source_comment`."""
    path = Path(path)
    mdf = _open(path)
    try:
        named = {m.channel for m in mapped}
        entries = mapped + [Mapped(name, name) for name in ALIGNED_UNITS
                            if name != "time" and name not in named and name in mdf.channels_db]
        channels, streams = [], {}
        for entry in entries:
            if (where := _location(path, mdf, entry)) is not None:
                channels.append(_channel(path, mdf, entry, *where))
                streams[channels[-1].stream] = {"source_file": path.name, "mdf_group": where[0]}
        start, comment = mdf.header.start_time, str(mdf.header.description or "")
        offered = tuple(name for name, places in mdf.channels_db.items()
                        if any(mdf.masters_db.get(group) != index for group, index in places))
    finally:
        mdf.close()
    return Input(path, channels, start, {"source_comment": comment} if comment else {}, streams, offered=offered)
