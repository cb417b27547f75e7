"""Per-message CAN codecs compiled from a cantools DBC at start-up: integer shifts instead of generic decoding.

Same results as cantools for plain integer signals (Intel or Motorola, signed or not, linear scaling);
messages with multiplexed or float signals fall back to cantools. Encoding saturates each signal to its raw
range instead of raising. Output keys can be renamed (DBC signal → logical name), unmapped signals are skipped.
"""

from __future__ import annotations

from collections.abc import Mapping

import cantools
import numpy as np


class MessageCodec:
    """Decode/encode one message's payload to/from {key: physical value}."""

    def __init__(self, message: cantools.database.Message, names: Mapping[str, str] | None = None) -> None:
        self.message = message
        self.length = message.length
        self.names = dict(names) if names is not None else {s.name: s.name for s in message.signals}
        self._fallback = message.is_multiplexed() or any(s.is_float for s in message.signals)
        self._fields = [] if self._fallback else [self._field(s) for s in message.signals]
        self._limits = [(-sign, sign - 1) if sign else (0, mask) for _, _, _, mask, sign, _, _ in self._fields]

    def decode(self, data: bytes) -> dict[str, float]:
        """Physical values of the mapped signals; ValueError if `data` is not `length` bytes."""
        if len(data) != self.length:
            raise ValueError(f"{self.message.name}: {len(data)} bytes, expected {self.length}")
        if self._fallback:
            try:
                raw = self.message.decode(data, decode_choices=False)
            except cantools.database.DecodeError as exc:
                raise ValueError(f"{self.message.name}: {exc}") from None
            return {key: raw[name] for name, key in self.names.items()}
        little, big = int.from_bytes(data, "little"), int.from_bytes(data, "big")
        out = {}
        for key, is_big, shift, mask, sign, scale, offset in self._fields:
            if key is None:
                continue
            v = ((big if is_big else little) >> shift) & mask
            if v & sign:
                v -= mask + 1
            out[key] = v if scale is None else v * scale + offset
        return out

    def decode_array(self, payloads: np.ndarray) -> dict[str, np.ndarray]:
        """Vectorised decode of stored raw frames, an (N, length) uint8 array: key → float64 column."""
        if self._fallback:
            rows = [self.decode(bytes(row)) for row in payloads]
            return {key: np.array([r[key] for r in rows], dtype=float) for key in self.names.values()}
        padded = np.zeros((len(payloads), 8), dtype=np.uint8)
        padded[:, :self.length] = payloads
        little, big = padded.view("<u8").ravel(), padded.view(">u8").ravel()
        out = {}
        for key, is_big, shift, mask, sign, scale, offset in self._fields:
            if key is None:
                continue
            shift += (8 - self.length) * 8 if is_big else 0
            v = ((big if is_big else little) >> np.uint64(shift)) & np.uint64(mask)
            col = v.astype(np.int64) - np.where(v & np.uint64(sign), mask + 1, 0) if sign else v.astype(np.int64)
            out[key] = col.astype(float) if scale is None else col * scale + offset
        return out

    def encode(self, values: Mapping[str, float]) -> bytes:
        """Payload for the mapped keys in `values`; missing signals are 0, out-of-range values saturate."""
        if self._fallback:
            by_name = {name: values.get(key, 0) for name, key in self.names.items()}
            return self.message.encode({s.name: by_name.get(s.name, 0) for s in self.message.signals}, strict=False)
        little = big = 0
        for (key, is_big, shift, mask, sign, scale, offset), (lo, hi) in zip(self._fields, self._limits):
            value = values.get(key, 0)
            raw = round(value if scale is None else (value - offset) / scale)
            raw = (lo if raw < lo else hi if raw > hi else raw) & mask
            if is_big:
                big |= raw << shift
            else:
                little |= raw << shift
        data = little.to_bytes(self.length, "little")
        return (int.from_bytes(data, "big") | big).to_bytes(self.length, "big") if big else data

    def encode_array(self, columns: Mapping[str, "np.ndarray | float"], n: int) -> np.ndarray:
        """Vectorised `encode` of n frames: key → column (or one value for all); an (n, length) uint8 array."""
        if self._fallback:
            rows = [{k: (v[i] if np.ndim(v) else v) for k, v in columns.items()} for i in range(n)]
            return np.frombuffer(b"".join(self.encode(r) for r in rows), dtype=np.uint8).reshape(n, self.length)
        little, big = np.zeros(n, dtype=np.uint64), np.zeros(n, dtype=np.uint64)
        for (key, is_big, shift, mask, sign, scale, offset), (lo, hi) in zip(self._fields, self._limits):
            value = np.broadcast_to(np.asarray(columns.get(key, 0), dtype=float), (n,))
            raw = np.clip(np.round(value if scale is None else (value - offset) / scale), lo, hi).astype(np.int64)
            field = (raw & mask).astype(np.uint64) << np.uint64(shift)
            if is_big:
                big |= field
            else:
                little |= field
        data = little.astype("<u8").view(np.uint8).reshape(n, 8)[:, :self.length]
        if self.length and big.any():
            data = data | big.astype(">u8").view(np.uint8).reshape(n, 8)[:, 8 - self.length:]
        return np.ascontiguousarray(data)

    def _field(self, s: cantools.database.Signal) -> tuple:
        if s.byte_order == "little_endian":
            is_big, shift = False, s.start
        else:
            msb = (s.start // 8) * 8 + (7 - s.start % 8)
            is_big, shift = True, self.length * 8 - msb - s.length
        integer = s.scale == int(s.scale) == 1 and s.offset == 0
        return (self.names.get(s.name), is_big, shift, (1 << s.length) - 1,
                (1 << (s.length - 1)) if s.is_signed else 0, None if integer else s.scale, s.offset)


def compile_codecs(db: cantools.database.Database, signals: Mapping[str, tuple[str, str]] | None = None
                   ) -> dict[str, MessageCodec]:
    """A codec per message; with `signals` (logical key → (message, signal)) keys are the logical names."""
    if signals is None:
        return {m.name: MessageCodec(m) for m in db.messages}
    names: dict[str, dict[str, str]] = {}
    for key, (message, signal) in signals.items():
        db.get_message_by_name(message).get_signal_by_name(signal)  # KeyError names a bad mapping
        names.setdefault(message, {})[signal] = key
    return {m: MessageCodec(db.get_message_by_name(m), n) for m, n in names.items()}
