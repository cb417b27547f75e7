"""Consistent Overhead Byte Stuffing: removes every 0x00 from a packet so 0x00 can delimit frames.

The compiled `encode_into`/`decode_into` are the one implementation; `encode`/`decode` wrap them for bytes, and the
node frame's kernels (drivers/node_frame.py) call them directly for many frames at once.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from drivers.errors import CobsError

OK, EMPTY, BAD_CODE, ZERO_IN_BLOCK = 0, 1, 2, 3  # decode_into's outcomes


def encode(data: bytes) -> bytes:
    """COBS-encode `data` (no delimiter appended); the result contains no 0x00."""
    src = np.frombuffer(data, dtype=np.uint8)
    out = np.empty(len(src) + len(src) // 254 + 1, dtype=np.uint8)
    return out[:encode_into(src, 0, len(src), out, 0)].tobytes()


def decode(encoded: bytes) -> bytes:
    """Invert `encode` (input without delimiter); CobsError on a 0x00, a truncated block or empty input."""
    src = np.frombuffer(encoded, dtype=np.uint8)
    out = np.empty(len(src), dtype=np.uint8)
    length, error, offset = decode_into(src, 0, len(src), out)
    if error != OK:
        raise CobsError(error_text(error, src, offset))
    return out[:length].tobytes()


def error_text(error: int, src: np.ndarray, offset: int) -> str:
    """What a failed `decode_into` found, in words."""
    if error == EMPTY:
        return "empty COBS block"
    if error == BAD_CODE:
        return f"bad COBS code {src[offset]} at offset {offset}"
    return "0x00 inside a COBS block"


@njit(cache=True, nogil=True)
def encode_into(src: np.ndarray, start: int, stop: int, out: np.ndarray, at: int) -> int:  # pragma: no cover - compiled
    """COBS of src[start:stop] written to `out` from `at` (room for n + n // 254 + 1 bytes); returns the end."""
    code_at, w, code = at, at + 1, 1
    for i in range(start, stop):
        if src[i] == 0:
            out[code_at] = code
            code_at, w, code = w, w + 1, 1
        else:
            out[w] = src[i]
            w += 1
            code += 1
            if code == 0xFF:  # a full block of 254 data bytes
                out[code_at] = code
                code_at, w, code = w, w + 1, 1
    out[code_at] = code
    return w


@njit(cache=True, nogil=True)
def decode_into(src: np.ndarray, start: int, stop: int,
                out: np.ndarray) -> tuple[int, int, int]:  # pragma: no cover - compiled
    """Decode src[start:stop] into `out` (room for stop - start bytes): (length, OK, 0) or (0, error, offset of the
    bad code relative to `start`)."""
    if stop == start:
        return 0, EMPTY, 0
    i, w = start, 0
    while i < stop:
        code = np.int64(src[i])
        end = i + code
        if code == 0 or end > stop:
            return 0, BAD_CODE, i - start
        for k in range(i + 1, end):
            if src[k] == 0:
                return 0, ZERO_IN_BLOCK, i - start
            out[w] = src[k]
            w += 1
        i = end
        if code != 0xFF and i < stop:
            out[w] = 0
            w += 1
    return w, OK, 0
