"""Consistent Overhead Byte Stuffing: removes every 0x00 from a packet so 0x00 can delimit frames."""

from __future__ import annotations

from drivers.errors import CobsError


def encode(data: bytes) -> bytes:
    """COBS-encode `data` (no delimiter appended); the result contains no 0x00."""
    out = bytearray()
    for segment in data.split(b"\x00"):
        while len(segment) >= 254:
            out += b"\xff" + segment[:254]
            segment = segment[254:]
        out.append(len(segment) + 1)
        out += segment
    return bytes(out)


def decode(encoded: bytes) -> bytes:
    """Invert `encode` (input without delimiter); CobsError on a 0x00, a truncated block or empty input."""
    out = bytearray()
    i, n = 0, len(encoded)
    if n == 0:
        raise CobsError("empty COBS block")
    while i < n:
        code = encoded[i]
        end = i + code
        if code == 0 or end > n:
            raise CobsError(f"bad COBS code {code} at offset {i}")
        block = encoded[i + 1:end]
        if 0 in block:
            raise CobsError("0x00 inside a COBS block")
        out += block
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)
