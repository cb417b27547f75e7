"""Per-message CAN codecs compiled from a cantools DBC at start-up: integer shifts instead of generic decoding.

Same results as cantools for plain integer signals (Intel or Motorola, signed or not, linear scaling);
messages with multiplexed or float signals fall back to cantools. Encoding saturates each signal to its raw
range instead of raising. Output keys can be renamed (DBC signal → logical name), unmapped signals are skipped.
`CodecTable` holds several messages' layouts as arrays so that a batch of frames of any of them is decoded or
encoded by one compiled loop (numba), with the same numbers as the per-frame methods.
"""

from __future__ import annotations

from collections.abc import Mapping

import cantools
import numpy as np
from numba import njit


class MessageCodec:
    """Decode/encode one message's payload to/from {key: physical value}."""

    def __init__(self, message: cantools.database.Message, names: Mapping[str, str] | None = None) -> None:
        self.message = message
        self.length = message.length
        self.names = dict(names) if names is not None else {s.name: s.name for s in message.signals}
        self._fallback = message.is_multiplexed() or any(s.is_float for s in message.signals)
        self._fields = [] if self._fallback else [self._field(s) for s in message.signals]
        self._limits = [(-sign, sign - 1) if sign else (0, mask) for _, _, _, mask, sign, _, _ in self._fields]
        # key of each column of the vectorised paths' value matrices (None: a DBC signal without a logical name)
        self.columns: tuple[str | None, ...] = (tuple(self.names.values()) if self._fallback
                                                else tuple(f[0] for f in self._fields))
        self._table: CodecTable | None = None

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
        """Vectorised decode of raw frames, an (N, length) uint8 array: key → float64 column.

        ValueError if a row does not decode (only messages that fall back to cantools can refuse one).
        """
        n = len(payloads)
        padded = np.zeros((n, self.table.payload_bytes), dtype=np.uint8)
        padded[:, :self.length] = payloads
        values, valid = self.table.decode(np.zeros(n, dtype=np.intp), padded)
        if not valid.all():
            raise ValueError(f"{self.message.name}: row {int(np.argmin(valid))} does not decode")
        return {key: values[:, j] for j, key in enumerate(self.columns) if key is not None}

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

    @property
    def table(self) -> "CodecTable":
        """This message alone as a CodecTable (the vectorised paths)."""
        if self._table is None:
            self._table = CodecTable([self])
        return self._table

    def _field(self, s: cantools.database.Signal) -> tuple:
        if s.byte_order == "little_endian":
            is_big, shift = False, s.start
        else:
            msb = (s.start // 8) * 8 + (7 - s.start % 8)
            is_big, shift = True, self.length * 8 - msb - s.length
        integer = s.scale == int(s.scale) == 1 and s.offset == 0
        return (self.names.get(s.name), is_big, shift, (1 << s.length) - 1,
                (1 << (s.length - 1)) if s.is_signed else 0, None if integer else s.scale, s.offset)


class CodecTable:
    """Several messages' codecs as one table: a batch of frames of any of them decoded or encoded in one compiled
    pass. Row i of a batch belongs to message `which[i]` (its index in `codecs`); values are an (n, width) matrix
    whose column j holds the signal `codecs[which[i]].columns[j]`; payloads are (n, 8+) uint8 rows, each
    message's bytes first and zeros after. Messages that fall back to cantools or are longer than 8 bytes go row
    by row through MessageCodec.decode/encode. Same numbers as MessageCodec.decode/encode, bit for bit.
    """

    def __init__(self, codecs: "list[MessageCodec]") -> None:
        self.codecs = codecs
        self.width = max([len(c.columns) for c in codecs] + [1])
        # per message and column: [big-endian word?, shift in the padded 8-byte word, mask, sign bit] and
        # [scale, offset, lowest raw, highest raw]; columns without a field keep mask 0 (value 0)
        self.bits = np.zeros((len(codecs), 4, self.width), dtype=np.uint64)
        self.linear = np.zeros((len(codecs), 4, self.width))
        self.linear[:, 0] = 1.0
        self._row_by_row = [m for m, c in enumerate(codecs) if c._fallback or c.length > 8]
        self.compiled = np.array([m not in self._row_by_row for m in range(len(codecs))])
        self.payload_bytes = max([8] + [c.length for c in codecs])
        for m, c in enumerate(codecs):
            if m in self._row_by_row:
                continue
            for j, ((_, is_big, shift, mask, sign, scale, offset), (lo, hi)) in enumerate(zip(c._fields, c._limits)):
                self.bits[m, :, j] = is_big, shift + (8 * (8 - c.length) if is_big else 0), mask, sign
                self.linear[m, :, j] = 1.0 if scale is None else scale, offset, lo, hi

    def decode(self, which: np.ndarray, payloads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values (n, width) of each row's message, and which rows decoded (the others are NaN)."""
        values = np.empty((len(which), self.width))
        valid = np.ones(len(which), dtype=bool)
        _decode_rows(which, payloads, self.bits, self.linear, self.compiled, values)
        for m in self._row_by_row:
            codec = self.codecs[m]
            for i in np.flatnonzero(which == m).tolist():
                try:
                    decoded = codec.decode(bytes(payloads[i, :codec.length]))
                except ValueError:
                    values[i], valid[i] = np.nan, False
                    continue
                values[i] = np.nan
                values[i, :len(codec.columns)] = [decoded.get(key, np.nan) for key in codec.columns]
        return values, valid

    def encode(self, which: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Payloads (n, payload_bytes) of each row's message from its values; out-of-range values saturate."""
        payloads = np.zeros((len(which), self.payload_bytes), dtype=np.uint8)
        encode_rows(which, values, self.bits, self.linear, self.compiled, payloads)
        for m in self._row_by_row:
            codec = self.codecs[m]
            for i in np.flatnonzero(which == m).tolist():
                data = codec.encode(dict(zip(codec.columns, values[i].tolist())))
                payloads[i, :len(data)] = np.frombuffer(data, dtype=np.uint8)
        return payloads


@njit(cache=True, nogil=True)
def _words(payload: np.ndarray) -> tuple:  # pragma: no cover - compiled
    """The first 8 bytes of a payload as little-endian and as big-endian unsigned words."""
    little = np.uint64(0)
    big = np.uint64(0)
    for b in range(8):
        byte = np.uint64(payload[b])
        little |= byte << np.uint64(8 * b)
        big = (big << np.uint64(8)) | byte
    return little, big


@njit(cache=True, nogil=True)
def _decode_rows(which: np.ndarray, payloads: np.ndarray, bits: np.ndarray, linear: np.ndarray,
                 compiled: np.ndarray, values: np.ndarray) -> None:  # pragma: no cover - compiled
    """CodecTable.decode of the rows whose message is compiled."""
    for i in range(which.shape[0]):
        if compiled[which[i]]:
            decode_row(payloads[i], which[i], bits, linear, values[i])


@njit(cache=True, nogil=True)
def decode_row(payload: np.ndarray, m: int, bits: np.ndarray, linear: np.ndarray,
               out: np.ndarray) -> None:  # pragma: no cover - compiled
    """One frame of compiled message `m` (a CodecTable's `bits`, `linear`): each field out of its 8-byte word, sign,
    scale, into `out` (the frame's row of values); for other compiled kernels that decode frames on the way."""
    little, big = _words(payload)
    for j in range(out.shape[0]):
        raw = ((big if bits[m, 0, j] else little) >> bits[m, 1, j]) & bits[m, 2, j]
        signed = np.int64(raw - ((raw & bits[m, 3, j]) << np.uint64(1)))  # two's complement: minus 2 × sign bit
        out[j] = signed * linear[m, 0, j] + linear[m, 1, j]


@njit(cache=True, nogil=True)
def encode_rows(which: np.ndarray, values: np.ndarray, bits: np.ndarray, linear: np.ndarray,
                compiled: np.ndarray, payloads: np.ndarray) -> None:  # pragma: no cover - compiled
    """CodecTable.encode of the rows whose message is compiled: scale, round half to even, saturate, place (other
    kernels call it with a table's `bits`, `linear` and `compiled`)."""
    for i in range(which.shape[0]):
        m = which[i]
        if not compiled[m]:
            continue
        little = np.uint64(0)
        big = np.uint64(0)
        for j in range(values.shape[1]):
            raw = np.rint((values[i, j] - linear[m, 1, j]) / linear[m, 0, j])
            raw = min(max(raw, linear[m, 2, j]), linear[m, 3, j])
            field = (np.uint64(np.int64(raw)) & bits[m, 2, j]) << bits[m, 1, j]
            if bits[m, 0, j]:
                big |= field
            else:
                little |= field
        for b in range(8):
            payloads[i, b] = ((little >> np.uint64(8 * b)) | (big >> np.uint64(8 * (7 - b)))) & np.uint64(0xFF)


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


def prime() -> None:
    """Compile (or load from numba's cache) CodecTable's kernels for the one signature each is called with, on
    zero-length arrays of the table's dtypes (nothing decoded or encoded)."""
    which, bits, linear, compiled = np.zeros(0, np.int64), np.zeros((0, 4, 0), np.uint64), np.zeros((0, 4, 0)), \
        np.zeros(0, bool)
    _decode_rows(which, np.zeros((0, 8), np.uint8), bits, linear, compiled, np.zeros((0, 0)))
    encode_rows(which, np.zeros((0, 0)), bits, linear, compiled, np.zeros((0, 8), np.uint8))
