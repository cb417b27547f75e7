"""The ClutchSensorNode radio frame (see NODE_FRAME.md): pack/unpack, CRC-16/CCITT-FALSE, COBS framing.

Pure functions on bytes, no I/O; shared by the gateway driver and the node emulator. One compiled implementation
serves one frame (`decode`, `unpack`, `crc16`) and many (`decode_stream`, `encode_rows`: frames as integer rows in
FIELDS order).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from drivers import cobs
from drivers.errors import CrcMismatch, MalformedFrame

VERSION = 1
DELIMITER = b"\x00"
NO_VALUE = 0xFFFFFFFF
_BODY = struct.Struct("<BBHIIIHbB")
FIELDS = ("version", "flags", "seq", "node_time_ms", "r1_mohm", "r2_mohm", "supply_mv", "rssi_dbm", "lqi")  # _BODY's
_SIZES = (1, 1, 2, 4, 4, 4, 2, 1, 1)  # bytes of each of FIELDS in _BODY
_RSSI = FIELDS.index("rssi_dbm")
PAYLOAD_LEN = _BODY.size + 2
ENCODED_LEN = PAYLOAD_LEN + 1

CH1_OPEN = 0x01
CH1_SHORT = 0x02
CH2_OPEN = 0x04
CH2_SHORT = 0x08
LOW_SUPPLY = 0x10
ADC_FAULT = 0x20
NODE_RESET = 0x40

OK, EMPTY, BAD_LENGTH, BAD_COBS, BAD_PAYLOAD, BAD_CRC, BAD_VERSION = range(7)  # what a chunk of the stream is


@dataclass(frozen=True, slots=True)
class NodeFrame:
    """Raw content of one frame; resistances in mΩ, NO_VALUE where the node measured nothing."""

    seq: int
    node_time_ms: int
    r_mohm: tuple[int, int]
    supply_mv: int
    rssi_dbm: int
    lqi: int
    flags: int = 0
    version: int = VERSION


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor); '123456789' → 0x29B1."""
    return _crc16(np.frombuffer(data, dtype=np.uint8), 0, len(data))


def pack(frame: NodeFrame) -> bytes:
    """The payload: little-endian fields followed by the big-endian CRC over them (PAYLOAD_LEN bytes)."""
    body = _BODY.pack(*_fields(frame))
    return body + crc16(body).to_bytes(2, "big")


def encode(frame: NodeFrame) -> bytes:
    """The frame as sent on the wire: COBS(payload) + 0x00 delimiter."""
    return cobs.encode(pack(frame)) + DELIMITER


def encode_rows(fields: np.ndarray) -> bytes:
    """`encode` of frames given as integer rows in FIELDS order, one after the other, in one compiled pass."""
    return wire_of_rows(fields.astype(np.int64, copy=False)).tobytes() if len(fields) else b""


def frame_of(row: Sequence[int]) -> NodeFrame:
    """The NodeFrame of one row in FIELDS order."""
    version, flags, seq, t_ms, r1, r2, supply, rssi, lqi = (int(v) for v in row)
    return NodeFrame(seq, t_ms, (r1, r2), supply, rssi, lqi, flags, version)


def _fields(frame: NodeFrame) -> tuple[int, ...]:
    """A frame's fields in FIELDS order (the _BODY layout)."""
    return (frame.version, frame.flags, frame.seq, frame.node_time_ms, frame.r_mohm[0], frame.r_mohm[1],
            frame.supply_mv, frame.rssi_dbm, frame.lqi)


@njit(cache=True, nogil=True)
def _crc16(data: np.ndarray, start: int, stop: int) -> int:  # pragma: no cover - compiled
    """CRC-16/CCITT-FALSE of data[start:stop]; 0 over a payload with its CRC appended."""
    crc = 0xFFFF
    for b in range(start, stop):
        crc ^= np.int64(data[b]) << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


@njit(cache=True, nogil=True)
def wire_of_rows(fields: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """`encode_rows` for compiled callers: wire bytes (n, ENCODED_LEN + 1) of frames given as rows in FIELDS order:
    the _BODY layout (little-endian), CRC-16/CCITT-FALSE big-endian, COBS, the 0x00 delimiter."""
    out = np.zeros((fields.shape[0], PAYLOAD_LEN + 2), dtype=np.uint8)
    payload = np.empty(PAYLOAD_LEN, dtype=np.uint8)
    for i in range(fields.shape[0]):
        at = np.int64(0)  # int64 from the start, not the literal 0: one signature of _crc16 (see _unpack_into)
        for j in range(len(_SIZES)):
            value = fields[i, j]
            for b in range(_SIZES[j]):
                payload[at] = (value >> (8 * b)) & 0xFF
                at += 1
        crc = _crc16(payload, np.int64(0), at)
        payload[at], payload[at + 1] = crc >> 8, crc & 0xFF
        cobs.encode_into(payload, 0, PAYLOAD_LEN, out[i], 0)  # the delimiter after it is the row's last byte, left 0
    return out


@njit(cache=True, nogil=True)
def _unpack_into(payload: np.ndarray, length: int, row: np.ndarray) -> tuple[int, int]:  # pragma: no cover - compiled
    """Check length, CRC and version of a payload and write its fields (FIELDS order) to `row`: (status, detail)
    with detail the length (BAD_PAYLOAD) or the version (BAD_VERSION)."""
    if length != PAYLOAD_LEN:
        return BAD_PAYLOAD, length
    # from an int64 0, not the literal: a kernel called with a literal compiles a signature of its own
    if _crc16(payload, np.int64(0), length) != 0:
        return BAD_CRC, 0
    at = 0
    for j in range(len(_SIZES)):
        value = np.int64(0)
        for b in range(_SIZES[j]):
            value |= np.int64(payload[at]) << (8 * b)
            at += 1
        row[j] = value
    row[_RSSI] = row[_RSSI] - 256 if row[_RSSI] >= 128 else row[_RSSI]  # the one signed byte
    if row[0] != VERSION:
        return BAD_VERSION, row[0]
    return OK, 0


@njit(cache=True, nogil=True)
def _decode_into(src: np.ndarray, start: int, stop: int, payload: np.ndarray,
                 row: np.ndarray) -> tuple[int, int]:  # pragma: no cover - compiled
    """Decode the delimiter-free chunk src[start:stop] into `row` (FIELDS order): (status, detail), detail the
    chunk length (BAD_LENGTH) or the failing COBS outcome × 2**16 + its offset (BAD_COBS)."""
    if stop - start != ENCODED_LEN:
        return (EMPTY if stop == start else BAD_LENGTH), stop - start
    length, error, offset = cobs.decode_into(src, start, stop, payload)
    if error != cobs.OK:
        return BAD_COBS, error * 65536 + offset
    return _unpack_into(payload, length, row)


@njit(cache=True, nogil=True)
def decode_chunks(src: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:  # pragma: no cover - compiled
    """`decode_stream` for compiled callers: every 0x00-terminated chunk of `src` decoded: rows (FIELDS order), a
    status per chunk, and where the unterminated rest begins."""
    count = 0
    for i in range(src.shape[0]):
        if src[i] == 0:
            count += 1
    rows = np.zeros((count, len(_SIZES)), dtype=np.int64)
    status = np.empty(count, dtype=np.int8)
    payload = np.empty(ENCODED_LEN, dtype=np.uint8)
    start, k = np.int64(0), 0  # int64, not the literal 0: _decode_into's one signature (as from `decode`)
    for i in range(src.shape[0]):
        if src[i] == 0:
            status[k] = _decode_into(src, start, i, payload, rows[k])[0]
            start, k = i + 1, k + 1
    return rows, status, start


def decode_stream(data: bytes) -> tuple[np.ndarray, np.ndarray, bytes]:
    """Every delimited chunk of a piece of byte stream: rows (FIELDS order), a status per chunk (OK, EMPTY or the
    reason it is not a frame: BAD_LENGTH, BAD_COBS, BAD_PAYLOAD, BAD_CRC, BAD_VERSION), and the undelimited rest."""
    rows, status, rest = decode_chunks(np.frombuffer(data, dtype=np.uint8))
    return rows, status, data[rest:]


def _raise(status: int, detail: int, src: np.ndarray) -> None:
    """The FrameError for a failed decode, in words."""
    if status in (EMPTY, BAD_LENGTH):
        raise MalformedFrame(f"chunk is {detail} bytes, expected {ENCODED_LEN}")
    if status == BAD_COBS:
        raise MalformedFrame(cobs.error_text(detail >> 16, src, detail & 0xFFFF))
    if status == BAD_PAYLOAD:
        raise MalformedFrame(f"payload is {detail} bytes, expected {PAYLOAD_LEN}")
    if status == BAD_CRC:
        raise CrcMismatch("CRC mismatch")
    raise MalformedFrame(f"unknown frame version {detail}")


def unpack(payload: bytes) -> NodeFrame:
    """Check length, CRC and version of a COBS-decoded payload and return its fields; FrameError otherwise."""
    src, row = np.frombuffer(payload, dtype=np.uint8), np.zeros(len(_SIZES), dtype=np.int64)
    status, detail = _unpack_into(src, len(src), row)
    if status != OK:
        _raise(status, detail, src)
    return frame_of(row.tolist())


def decode(chunk: bytes) -> NodeFrame:
    """A frame from one delimiter-free chunk of the byte stream; FrameError if it is not a valid frame."""
    src, row = np.frombuffer(chunk, dtype=np.uint8), np.zeros(len(_SIZES), dtype=np.int64)
    status, detail = _decode_into(src, 0, len(src), np.empty(ENCODED_LEN, dtype=np.uint8), row)
    if status != OK:
        _raise(status, detail, src)
    return frame_of(row.tolist())


def prime() -> None:
    """Compile (or load from numba's cache) the stream decoder as `decode_stream` calls it, on no bytes."""
    decode_stream(b"")
