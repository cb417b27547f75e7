"""The raw CAN log fed with frame arrays (drivers/can_frames.py): many frames per call into python-can's writers.

Into python-can's `BLFWriter` (what `can.Logger("x.blf")` returns), `log_frames()` packs the CAN_MESSAGE objects
of a batch in one compiled pass instead of one `struct.pack` per frame and puts them into the writer's own container
buffer: byte for byte what `on_message_received()` writes for the same frames (tests/test_drivers_can.py checks
it); the file header, containers, compression, flushing and `stop()` stay python-can's. Error and CAN FD frames
go through `on_message_received()`, in order; so does every frame for any other listener (ASC, ...).
"""

from __future__ import annotations

import can
import numpy as np
from can.io import blf
from numba import njit

from drivers.can_frames import ERROR, EXTENDED, FD, FRAME, REMOTE, RX, messages_from_frames

_HEADER_SIZE = blf.OBJ_HEADER_BASE_STRUCT.size + blf.OBJ_HEADER_V1_STRUCT.size
_CAN_OBJECT = np.dtype([("signature", "S4"), ("header_size", "<u2"), ("header_version", "<u2"),
                        ("object_size", "<u4"), ("object_type", "<u4"), ("time_flags", "<u4"),
                        ("client_index", "<u2"), ("object_version", "<u2"), ("timestamp", "<u8"),
                        ("channel", "<u2"), ("flags", "u1"), ("dlc", "u1"), ("arbitration_id", "<u4"),
                        ("data", "u1", (8,))])
assert _CAN_OBJECT.itemsize == _HEADER_SIZE + blf.CAN_MSG_STRUCT.size  # python-can's layout, no padding
_TEMPLATE = np.zeros((), _CAN_OBJECT)  # what every CAN_MESSAGE object's headers hold
_TEMPLATE[()] = (b"LOBJ", _HEADER_SIZE, 1, _CAN_OBJECT.itemsize, blf.CAN_MESSAGE, blf.TIME_ONE_NANS,
                 0, 0, 0, 0, 0, 0, 0, np.zeros(8, np.uint8))
_TEMPLATE_BYTES = _TEMPLATE.tobytes()  # repeated as bytes: numpy's structured assignment costs 40x more
CAN_MSG_EXT, REMOTE_FLAG, DIR = blf.CAN_MSG_EXT, blf.REMOTE_FLAG, blf.DIR  # python-can's BLF constants, for the kernel


def log_frames(listener: can.Listener, frames: np.ndarray) -> None:
    """Hand FRAME records to a python-can listener in order: in bulk to a BLFWriter, else message by message."""
    if not isinstance(listener, can.BLFWriter):
        for msg in messages_from_frames(frames):
            listener.on_message_received(msg)
        return
    if not _any_flag(frames, ERROR | FD):
        _add_can_objects(listener, frames)
        return
    special = (frames["flags"] & (ERROR | FD)) != 0
    starts = np.r_[0, np.flatnonzero(np.diff(special.astype(np.int8))) + 1]
    for a, b in zip(starts, np.r_[starts[1:], len(frames)]):
        if special[a]:
            for msg in messages_from_frames(frames[a:b]):
                listener.on_message_received(msg)
        else:
            _add_can_objects(listener, frames[a:b])


def _add_can_objects(writer: can.BLFWriter, frames: np.ndarray) -> None:
    """Classic CAN frames as CAN_MESSAGE objects into the writer's container buffer, as its `_add_object` does."""
    if not len(frames):
        return
    stamps = frames["timestamp"]
    if writer.start_timestamp is None:
        writer.start_timestamp = int(float(stamps[0]) * 1000) / 1000
    writer.stop_timestamp = float(stamps[-1])
    objects = np.frombuffer(bytearray(_TEMPLATE_BYTES * len(frames)), _CAN_OBJECT)
    _fill_can_objects(frames, writer.start_timestamp, writer.channel, objects)
    writer._buffer.append(objects.tobytes())  # noqa: SLF001 - python-can's container buffer, as _add_object fills it
    writer._buffer_size += objects.nbytes  # noqa: SLF001
    writer.object_count += len(frames)
    while writer._buffer_size >= writer.max_container_size:  # noqa: SLF001 - containers cut where python-can cuts them
        left = writer._buffer_size  # noqa: SLF001
        writer._flush()  # noqa: SLF001
        if writer._buffer_size >= left:  # noqa: SLF001 - python-can silently writes nothing into a closed file
            raise ValueError(f"{getattr(writer.file, 'name', 'BLF log')}: closed, frames cannot be written")


@njit(cache=True, nogil=True)
def _any_flag(frames: np.ndarray, mask: int) -> bool:  # pragma: no cover - compiled
    """Whether any FRAME record has a flag of `mask`."""
    for i in range(frames.shape[0]):
        if frames[i].flags & mask:
            return True
    return False


@njit(cache=True, nogil=True)
def _fill_can_objects(frames: np.ndarray, start: float, default_channel: int,
                      objects: np.ndarray) -> None:  # pragma: no cover - compiled
    """The per-frame fields of CAN_MESSAGE objects from FRAME records, as BLFWriter.on_message_received computes them."""
    for i in range(frames.shape[0]):
        frame, out = frames[i], objects[i]
        flags = frame.flags
        out.timestamp = max(np.int64((frame.timestamp - start) * 1e9), 0)
        out.arbitration_id = frame.arbitration_id | (np.uint32(CAN_MSG_EXT) if flags & EXTENDED else np.uint32(0))
        out.flags = (REMOTE_FLAG if flags & REMOTE else 0) | (0 if flags & RX else DIR)
        out.dlc = frame.dlc
        out.channel = default_channel if frame.channel < 0 else frame.channel + 1
        for b in range(8):
            out.data[b] = frame.data[b]


def prime() -> None:
    """Compile (or load from numba's cache) the BLF packing kernels on zero frames (nothing is logged)."""
    frames = np.zeros(0, FRAME)
    _any_flag(frames, ERROR)
    _fill_can_objects(frames, 0.0, 0, np.zeros(0, _CAN_OBJECT))
