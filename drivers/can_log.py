"""The raw CAN log fed with frame arrays (drivers/can_frames.py): many frames per call into python-can's writers.

Into python-can's `BLFWriter`, `log_frames()` packs the CAN_MESSAGE objects of a batch in one compiled pass instead
of one `struct.pack` per frame and puts them into the writer's own container buffer: byte for byte what
`on_message_received()` writes for the same frames (tests/test_drivers_can.py checks it). The bench's log is an
`IsalBLFWriter`: python-can's writer whose containers are deflated by ISA-L instead of zlib (at level 1 under half
of zlib's CPU for the same size; a standard zlib stream, which BLF readers inflate). The deflate call is ours,
because python-can's `_flush` calls `zlib.compress` itself; the file header, containers, their cuts, flushing and
`stop()` stay python-can's. Error and CAN FD frames go through `on_message_received()`, in order; so does every
frame for any other listener (ASC, ...).
"""

from __future__ import annotations

import os
from typing import Any, BinaryIO

import can
import numpy as np
from can.io import blf
from isal import isal_zlib
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


class IsalBLFWriter(can.BLFWriter):
    """python-can's BLF writer, its containers deflated by ISA-L: under half of zlib's CPU at level 1, the same size.

    `compression_level` as python-can's: 0 stores the containers uncompressed; 1 to 3 are ISA-L's levels (ISA-L has
    no 4 to 9, and its own level 0 is not used: 0 keeps python-can's meaning).
    """

    def __init__(self, file: "str | os.PathLike[str] | BinaryIO", *,
                 compression_level: int = isal_zlib.ISAL_DEFAULT_COMPRESSION, **kwargs: Any) -> None:
        """python-can's writer on `file`; a level ISA-L lacks is one ValueError line before the file is made."""
        if not 0 <= compression_level <= isal_zlib.ISAL_BEST_COMPRESSION:
            raise ValueError(f"BLF compression_level {compression_level}: 0 (uncompressed) to "
                             f"{isal_zlib.ISAL_BEST_COMPRESSION} (ISA-L's levels)")
        super().__init__(file, compression_level=compression_level, **kwargs)

    def _flush(self) -> None:
        """Compress and write the buffer's first container: an intended copy of python-can 4.6.1's
        `BLFWriter._flush` (constraints.txt), which calls its module's `zlib.compress` directly, with that one call
        ISA-L's. Like python-can's, it writes nothing into a closed file (`_add_can_objects` checks for that)."""
        if self.file.closed:
            return
        buffer = b"".join(self._buffer)
        if not buffer:
            return
        uncompressed_data = memoryview(buffer)[: self.max_container_size]
        tail = buffer[self.max_container_size :]
        self._buffer = [tail]
        self._buffer_size = len(tail)
        if not self.compression_level:
            data: bytes | memoryview = uncompressed_data
            method = blf.NO_COMPRESSION
        else:
            data = isal_zlib.compress(uncompressed_data, self.compression_level)
            method = blf.ZLIB_DEFLATE
        obj_size = blf.OBJ_HEADER_BASE_STRUCT.size + blf.LOG_CONTAINER_STRUCT.size + len(data)
        base_header = blf.OBJ_HEADER_BASE_STRUCT.pack(b"LOBJ", blf.OBJ_HEADER_BASE_STRUCT.size, 1, obj_size,
                                                      blf.LOG_CONTAINER)
        container_header = blf.LOG_CONTAINER_STRUCT.pack(method, len(uncompressed_data))
        self.file.write(base_header)
        self.file.write(container_header)
        self.file.write(data)
        self.file.write(b"\x00" * (obj_size % 4))
        self.uncompressed_size += blf.OBJ_HEADER_BASE_STRUCT.size
        self.uncompressed_size += blf.LOG_CONTAINER_STRUCT.size
        self.uncompressed_size += len(uncompressed_data)


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
