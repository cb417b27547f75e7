"""The ClutchSensorNode radio frame (see NODE_FRAME.md): pack/unpack, CRC-16/CCITT-FALSE, COBS framing.

Pure functions on bytes, no I/O; shared by the gateway driver and the node emulator.
"""

from __future__ import annotations

import binascii
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
PAYLOAD_LEN = _BODY.size + 2
ENCODED_LEN = PAYLOAD_LEN + 1

CH1_OPEN = 0x01
CH1_SHORT = 0x02
CH2_OPEN = 0x04
CH2_SHORT = 0x08
LOW_SUPPLY = 0x10
ADC_FAULT = 0x20
NODE_RESET = 0x40


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
    return binascii.crc_hqx(data, 0xFFFF)


def pack(frame: NodeFrame) -> bytes:
    """The payload: little-endian fields followed by the big-endian CRC over them (PAYLOAD_LEN bytes)."""
    body = _BODY.pack(frame.version, frame.flags, frame.seq, frame.node_time_ms, frame.r_mohm[0],
                      frame.r_mohm[1], frame.supply_mv, frame.rssi_dbm, frame.lqi)
    return body + crc16(body).to_bytes(2, "big")


def encode(frame: NodeFrame) -> bytes:
    """The frame as sent on the wire: COBS(payload) + 0x00 delimiter."""
    return cobs.encode(pack(frame)) + DELIMITER


def encode_many(frames: Sequence[NodeFrame]) -> bytes:
    """`encode` of each frame, one after the other, in one compiled pass (a sender with many frames at once)."""
    if not frames:
        return b""
    fields = np.array([(f.version, f.flags, f.seq, f.node_time_ms, f.r_mohm[0], f.r_mohm[1], f.supply_mv,
                        f.rssi_dbm, f.lqi) for f in frames], dtype=np.int64)
    return _encode_rows(fields).tobytes()


@njit(cache=True, nogil=True)
def _encode_rows(fields: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Wire bytes (n, ENCODED_LEN + 1) of frames given as rows (version, flags, seq, node_time_ms, r1, r2, supply_mv,
    rssi_dbm, lqi): the _BODY layout (little-endian), CRC-16/CCITT-FALSE big-endian, COBS, the 0x00 delimiter."""
    sizes = (1, 1, 2, 4, 4, 4, 2, 1, 1)
    out = np.zeros((fields.shape[0], PAYLOAD_LEN + 2), dtype=np.uint8)
    payload = np.empty(PAYLOAD_LEN, dtype=np.uint8)
    for i in range(fields.shape[0]):
        at = 0
        for j in range(9):
            value = fields[i, j]
            for b in range(sizes[j]):
                payload[at] = (value >> (8 * b)) & 0xFF
                at += 1
        crc = 0xFFFF
        for b in range(at):
            crc ^= np.int64(payload[b]) << 8
            for _ in range(8):
                crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
        payload[at], payload[at + 1] = crc >> 8, crc & 0xFF
        code_at, code, w = 0, 1, 1  # COBS for a payload shorter than 254 bytes: one code byte per zero-free run
        for b in range(PAYLOAD_LEN):
            if payload[b] == 0:
                out[i, code_at] = code
                code_at, code = w, 1
            else:
                out[i, w] = payload[b]
                code += 1
            w += 1
        out[i, code_at] = code  # the delimiter after it is the row's last byte, left 0
    return out


def unpack(payload: bytes) -> NodeFrame:
    """Check length, CRC and version of a COBS-decoded payload and return its fields; FrameError otherwise."""
    if len(payload) != PAYLOAD_LEN:
        raise MalformedFrame(f"payload is {len(payload)} bytes, expected {PAYLOAD_LEN}")
    if crc16(payload) != 0:
        raise CrcMismatch("CRC mismatch")
    version, flags, seq, t_ms, r1, r2, supply, rssi, lqi = _BODY.unpack_from(payload)
    if version != VERSION:
        raise MalformedFrame(f"unknown frame version {version}")
    return NodeFrame(seq, t_ms, (r1, r2), supply, rssi, lqi, flags, version)


def decode(chunk: bytes) -> NodeFrame:
    """A frame from one delimiter-free chunk of the byte stream; FrameError if it is not a valid frame."""
    if len(chunk) != ENCODED_LEN:
        raise MalformedFrame(f"chunk is {len(chunk)} bytes, expected {ENCODED_LEN}")
    try:
        payload = cobs.decode(chunk)
    except cobs.CobsError as exc:
        raise MalformedFrame(str(exc)) from None
    return unpack(payload)
