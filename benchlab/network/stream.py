"""A long run simulated block by block: cost flat in the run's length, the numbers of the whole-run solver.

`solver.discretise` keys, discretises and stacks the whole run at once: a dozen run-sized temporaries per call
(law values, keys, a hash table twice the run, the input matrix), each above glibc's mmap threshold on a long
run, so each is a fresh mapping the kernel zero-fills page by page (half the CPU of a 10 M-sample simulate).
Here the run goes through in blocks of `BLOCK` samples: laws, keys and inputs are block-sized (cache-resident,
reused by the allocator), operating points are numbered across blocks in one growing table and each distinct
point is discretised once, when first met; the only run-sized array is the result. Every law of a model file but a
switch with hysteresis is pointwise (a sample's value depends on that sample's channels), so a block's laws are the
run's laws on it, and the states are those of `propagate(discretise(...))` bit for bit (tests/test_stream.py); a
network with a switch (`structure.sequential_laws`: its state is carried from sample to sample over the whole
run) is not streamed in blocks but keyed whole by the solver.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping

import numpy as np
import pandas as pd
from benchlab.jit import njit

from benchlab.network.solver import (_assembly, _capacity_terms, _coefficient_terms, _conductance, _factors, _quantised,
                                     _system_matrices, _zoh, _propagate_combined44, propagate_into)
from benchlab.network.memo import float_bits
from benchlab.network.structure import Channels, Params, ThermalNetwork, as_samples, sample_matrix, sequential_laws

BLOCK = 1 << 14  # samples per block: a block's float64 column is 128 KiB, inside the core's L2 cache (16,384 measured best of 4,096..131,072)


def samples(channels: Channels) -> int:
    """The number of samples the channels hold."""
    counted = getattr(channels, "samples", None)
    return counted if counted is not None else len(next(iter(channels.values())))


def window(channels: Channels, start: int, stop: int) -> Channels:
    """Samples start..stop of every channel (views where the channels allow)."""
    if hasattr(channels, "window"):
        return channels.window(start, stop)
    return {name: values[start:stop] for name, values in channels.items()}


class _Points:
    """Operating points met so far: their integer keys (one column per varying law) numbered in order of first
    appearance, and the discrete matrices of each."""

    def __init__(self, columns: int, n: int, m: int) -> None:
        self.columns = columns
        self.count = 0
        self.bits = 12
        self.table = np.full((1 << self.bits, columns + 1), -1, dtype=np.int64)  # per slot: the key, then its point
        # room for the points a stream keeps (MAX_POINTS) and a run's worth beyond, reserved, not touched: the pages a
        # point's matrices take are mapped when it is written (growing from a few rows copied 20 MB on the
        # reference plant)
        rows = 2 * MAX_POINTS
        self.keys = np.empty((rows, columns), dtype=np.int64)
        # the paper's clutch (4 states, 4 inputs): [Ad Bd] side by side, one contiguous record per step; else apart
        self.ABd = np.empty((rows, n, n + m)) if (n, m) == (4, 4) else None
        self.Ad, self.Bd = (None, None) if self.ABd is not None else (np.empty((rows, n, n)), np.empty((rows, n, m)))

    def clear(self) -> None:
        """Forget every point, keeping the buffers (their pages already mapped: a fresh set faults them in again)."""
        self.count = 0
        self.table.fill(-1)

    def number(self, keys: np.ndarray) -> np.ndarray:
        """Each row's point index; rows not met before become new points (numbered after the known ones)."""
        if self.count + len(keys) > len(self.keys):
            self.keys = _grown(self.keys, self.count + len(keys))
        codes = np.empty(len(keys), dtype=np.int64)
        done = 0
        while done < len(keys):  # the table is kept at most half full: grown (and refilled) when it would not be
            self.count, done = _number(keys, done, self.table, self.bits, self.keys, self.count, codes)
            if done < len(keys):
                self.bits += 1
                self.table = np.full((1 << self.bits, self.table.shape[1]), -1, dtype=np.int64)
                _number(self.keys[:self.count].copy(), 0, self.table, self.bits, self.keys, 0,
                        np.empty(self.count, dtype=np.int64))
        return codes

    def add_matrices(self, start: int, Ad: np.ndarray, Bd: np.ndarray) -> None:
        """The discrete matrices of points start..count."""
        if self.ABd is not None:
            if self.count > len(self.ABd):
                self.ABd = _grown(self.ABd, self.count)
            self.ABd[start:self.count, :, :4], self.ABd[start:self.count, :, 4:] = Ad, Bd
            return
        if self.count > len(self.Ad):
            self.Ad, self.Bd = _grown(self.Ad, self.count), _grown(self.Bd, self.count)
        self.Ad[start:self.count], self.Bd[start:self.count] = Ad, Bd

    def propagate(self, op_index: np.ndarray, inputs: np.ndarray, out: np.ndarray, offset: int) -> None:
        """States from out[:, offset] over the samples of `op_index` into `out` (`solver.propagate_into`)."""
        x0 = np.ascontiguousarray(out[:, offset])
        if self.ABd is not None:
            _propagate_combined44(op_index, self.ABd, inputs, x0, out, offset)
        else:
            propagate_into(op_index, self.Ad, self.Bd, inputs, x0, out, offset)


def _grown(array: np.ndarray, needed: int) -> np.ndarray:
    """`array` with room for at least `needed` rows (doubling), its rows kept."""
    rows = len(array)
    while rows < needed:
        rows *= 2
    out = np.empty((rows, *array.shape[1:]), dtype=array.dtype)
    out[:len(array)] = array
    return out


@njit(cache=True, nogil=True)
def _number(keys, first, table, bits, known, count, codes):  # pragma: no cover - compiled
    """Number the rows of `keys` from `first` on by an open-addressing table whose slots hold a key and its row
    in `known` (one cache line per probe): codes[i] = index of keys[i] in `known` (`count` rows so far; room for
    every new one), new rows appended. Stops where the table would become more than half full. Returns (the new
    count, the first row not numbered)."""
    columns = keys.shape[1]
    mask = (1 << bits) - 1
    for i in range(first, keys.shape[0]):
        if i > first:  # runs of one point are the usual case
            same = True
            for c in range(columns):
                if keys[i, c] != keys[i - 1, c]:
                    same = False
                    break
            if same:
                codes[i] = codes[i - 1]
                continue
        h = np.uint64(0)
        for c in range(columns):
            h = (h ^ np.uint64(keys[i, c])) * np.uint64(0x9E3779B97F4A7C15)
        slot = np.int64(h >> np.uint64(64 - bits)) & mask
        while True:
            j = table[slot, columns]
            if j < 0:
                if 2 * (count + 1) > mask + 1:
                    return count, i
                for c in range(columns):
                    table[slot, c] = keys[i, c]
                    known[count, c] = keys[i, c]
                table[slot, columns] = count
                codes[i] = count
                count += 1
                break
            same = True
            for c in range(columns):
                if table[slot, c] != keys[i, c]:
                    same = False
                    break
            if same:
                codes[i] = j
                break
            slot = (slot + 1) & mask
    return count, keys.shape[0]


def _blocks(n: int, block: int) -> Iterator[tuple[int, int]]:
    for start in range(0, n, block):
        yield start, min(start + block, n)


def stream_network(network: ThermalNetwork, params: Params, channels: Channels, dt: float, x0: np.ndarray,
                   resolution: float, block: int | None = None) -> np.ndarray | None:
    """States state-major (n, N + 1), column k at time k*dt from x0, as `solver.run_network` without a memo gives
    them (transposed); None where the network has temperature-affine sources (their keys are scaled by the whole
    run's largest value, so the whole-run solver keys them) or a capacity law (keyed by the whole-run solver too), or,
    on more than one block, a switch with hysteresis
    (its state runs through the whole run)."""
    return NetworkStream(network, params, dt, resolution).run(channels, x0, block)


MAX_POINTS = 1 << 13  # operating points a NetworkStream keeps between runs (13 states, 8 inputs: 1.7 KiB each)
_ABSENT = object()  # a channel a law asked for that the channels do not hold


class _Reading(Mapping):
    """The channels as a law sees them, noting each channel it reads (or asks about) and the array it got."""

    def __init__(self, channels: Channels) -> None:
        self.channels = channels
        self.read: dict[str, object] = {}
        self.whole = False  # the law went through all channels: what it depends on is not known

    def __getitem__(self, name: str) -> np.ndarray:
        value = self.channels.get(name, _ABSENT)
        self.read[name] = value
        if value is _ABSENT:
            raise KeyError(name)
        return value

    def __contains__(self, name: object) -> bool:
        return self.get(name, _ABSENT) is not _ABSENT

    def __iter__(self) -> Iterator[str]:
        self.whole = True
        return iter(self.channels)

    def __len__(self) -> int:
        self.whole = True
        return len(self.channels)


class NetworkStream:
    """One network with its parameters and step run over channels after channels (`run`): a whole run block by
    block (`stream_network`), or the simulated bench's plant chunk after chunk and pass after pass of its
    fixed-point iteration, where most of each run repeats the one before.

    Kept from run to run, none changing a result bit (tests/test_stream.py): the matrix assembly and its factors;
    the operating points met so far with their discrete matrices (a point's matrices depend on its key and the
    constant laws alone; started over past MAX_POINTS, or when the constant laws change); each law's value while
    every channel it read is the very array it read before (a caller hands a changed channel as a new array, never
    changes one in place); and a run of one block whose laws, inputs and start equal the previous run's gets that
    run's states again.
    """

    def __init__(self, network: ThermalNetwork, params: Params, dt: float, resolution: float) -> None:
        self.network, self.params, self.dt, self.resolution = network, params, dt, resolution
        # temperature-affine sources and capacity laws: keyed by the whole run
        self.affine = bool(_coefficient_terms(network) or _capacity_terms(network))
        self.sequential = bool(sequential_laws(network))  # a switch's state runs through the run: never split
        self.assembly = _assembly(network)
        self.factors = _factors(self.assembly[1], params)
        self.states = len(network.state_names)
        self.inputs = len(network.sources) + len(network.boundaries)
        self.points: _Points | None = None
        self.keyed_by: tuple = ()  # which laws vary, and the constant laws' values, the points were made with
        # each distinct resistance law once (links that share one law object share its value), then the sources'
        # heat flows and the boundaries' temperatures
        resistances: dict[int, int] = {}
        self._resistances: list[_Law] = []
        for link in network.links:
            if id(link.resistance) not in resistances:
                resistances[id(link.resistance)] = len(self._resistances)
                self._resistances.append(_Law(lambda ch, link=link: _conductance(link, params, ch)))
        self._link_law = [resistances[id(link.resistance)] for link in network.links]
        self._flows = [_Law(lambda ch, s=s: s.heat_flow(params, ch)) for s in network.sources]
        self._flows += [_Law(lambda ch, b=b: b.temperature(ch)) for b in network.boundaries]
        self._last: tuple | None = None  # (samples, laws, inputs, x0, states) of the last run of one block

    def run(self, channels: Channels, x0: np.ndarray, block: int | None = None) -> np.ndarray | None:
        """States state-major (n, N + 1) over the channels from x0 (see `stream_network`); the caller does not
        change them (a repeated run hands back the same array)."""
        n = samples(channels)
        if self.affine or (self.sequential and n > (block or BLOCK)):
            return None
        x0 = np.asarray(x0, dtype=np.float64)
        if self.points is not None and self.points.count > MAX_POINTS:
            self.points.clear()
        out: np.ndarray | None = None
        run_pattern = None
        decode = None
        for start, stop in _blocks(n, block or BLOCK):
            part = channels if stop - start == n else window(channels, start, stop)  # one block: the very arrays
            size = stop - start
            values = [law.value_on(part) for law in self._resistances]
            laws = [values[i] for i in self._link_law]  # 1/R of every link (`solver._conductances`)
            flows = [as_samples(law.value_on(part), size) for law in self._flows]
            if size == n and self._repeats(n, laws, flows, x0):
                return self._last[-1]
            if out is None:
                out = np.empty((self.states, n + 1))
                out[:, 0] = x0
            pattern = tuple(i for i, g in enumerate(laws) if isinstance(g, np.ndarray))
            if run_pattern is None:
                run_pattern = pattern
            elif pattern != run_pattern:
                return None  # a law constant on one block and not on another: key the run as a whole
            keyed_by = (pattern, tuple(g for g in laws if not isinstance(g, np.ndarray)))
            columns = _key_columns(laws, pattern)
            if self.points is None or self.points.columns != max(len(columns), 1):
                self.points, self.keyed_by = _Points(max(len(columns), 1), self.states, self.inputs), keyed_by
            elif keyed_by != self.keyed_by:
                self.points.clear()
                self.keyed_by = keyed_by
            keys = np.empty((size, max(len(columns), 1)), dtype=np.int64)
            if columns:
                for c, (column, _) in enumerate(columns):
                    keys[:, c], decode = _quantised(column, True, self.resolution)
            else:
                keys[:] = 0
            known = self.points.count
            op_index = self.points.number(keys)
            if self.points.count > known:
                _discretise_points(self.network, self.params, laws, columns, self.points, known, decode, self.dt,
                                   self.assembly, self.factors)
            self.points.propagate(op_index, sample_matrix(flows, size), out, start)
        if out is None:  # no sample
            out = np.empty((self.states, 1))
            out[:, 0] = x0
        self._last = (n, laws, flows, x0.copy(), out) if 0 < n <= (block or BLOCK) else None
        return out

    def _repeats(self, n: int, laws: list, flows: list, x0: np.ndarray) -> bool:
        """Whether a run of one block of n samples with these laws, inputs and start is the last one's again."""
        if self._last is None:
            return False
        last_n, last_laws, last_flows, last_x0, _ = self._last
        return (n == last_n and _identical(x0, last_x0) and all(_identical(a, b) for a, b in zip(laws, last_laws))
                and all(_identical(a, b) for a, b in zip(flows, last_flows)))


class _Law:
    """One law of a network (a link's conductance, a source's heat flow, a boundary's temperature) as a stream
    evaluates it: its value kept while every channel it read is the very array it read before (a caller hands a
    changed channel as a new array, never changes one in place), for good once it read none (the parameters do not
    change)."""

    __slots__ = ("compute", "reads", "value", "fixed")

    def __init__(self, compute) -> None:
        self.compute = compute  # channels -> value
        self.reads: tuple | None = None  # (name, array) of each channel read; None: not evaluated, or read all
        self.value: object = None
        self.fixed = False

    def value_on(self, channels: Channels):
        """The law's value on the channels, computed only where a channel it read is not the array it read."""
        if self.fixed:
            return self.value
        if self.reads is not None:
            get = channels.get
            for name, before in self.reads:
                if get(name, _ABSENT) is not before:
                    break
            else:
                return self.value
        reading = _Reading(channels)
        self.value = self.compute(reading)
        self.reads = None if reading.whole else tuple(reading.read.items())
        self.fixed = self.reads == ()
        return self.value


def _identical(a: object, b: object) -> bool:
    """Whether two values (float64 arrays, numbers, or absent) are the same bits (-0.0 and 0.0 apart)."""
    if a is b:
        return True
    if isinstance(a, np.ndarray) and isinstance(b, np.ndarray):
        return (a.dtype == b.dtype == np.float64 and a.shape == b.shape
                and bool((a.view(np.uint64) == b.view(np.uint64)).all()))
    if isinstance(a, float) and isinstance(b, float):
        return float_bits((a,)) == float_bits((b,))
    return False


def _key_columns(laws: list, varying: tuple[int, ...]) -> list[tuple[np.ndarray, list[int]]]:
    """The varying laws' values as key columns, each with the laws it keys; laws that share one array (one law
    object, R_PA = R_FA) share one column."""
    columns: list[tuple[np.ndarray, list[int]]] = []
    for i in varying:
        for values, keyed in columns:
            if values is laws[i]:
                keyed.append(i)
                break
        else:
            columns.append((laws[i], [i]))
    return columns


def _discretise_points(network: ThermalNetwork, params: Params, laws: list, columns: list, points: _Points,
                       known: int, decode, dt: float, assembly: tuple, factors: np.ndarray) -> None:
    """Discrete matrices of the points numbered known..count: each varying law at its key, the rest as they are."""
    new = points.count - known
    per_point: list = [g if not isinstance(g, np.ndarray) else None for g in laws]  # a constant law stays a scalar
    for c, (_, keyed) in enumerate(columns):
        values = decode(points.keys[known:points.count, c])
        for i in keyed:
            per_point[i] = values
    A, B = _system_matrices(network, params, per_point, [], new, assembly, factors)
    points.add_matrices(known, *_zoh(A, B, dt))


class RunChannels(Mapping):
    """A run's channels as the network's laws read them, held on demand: a channel's drop-outs (NaN) at the last
    valid value (leading ones at the first), a channel never measured left out (`simulation.input_channels`'s
    values), without copying a block that has no drop-out or converting a channel no law asks for."""

    def __init__(self, frame: pd.DataFrame, start: int = 0, stop: int | None = None,
                 read: dict[str, tuple[np.ndarray, bool] | None] | None = None) -> None:
        self._frame = frame
        self._start = start
        self._stop = stop if stop is not None else len(frame)
        self._read = read if read is not None else {}  # name -> (float64 column, has a NaN), None if never measured
        self._held: dict[str, np.ndarray] = {}  # name -> this window's samples with drop-outs held, once asked for
        self.samples = self._stop - self._start

    def _column(self, name: str) -> tuple[np.ndarray, bool] | None:
        """The channel's float64 column and whether it has a drop-out (a NaN makes the sum NaN: one pass, no
        temporary), None where it was never measured."""
        if name not in self._read:
            values = self._frame[name].to_numpy(np.float64) if name in self._frame.columns else None
            measured = values is not None and (name == "time" or first_valid_index(values) >= 0)
            self._read[name] = (values, bool(np.isnan(np.add.reduce(values)))) if measured else None
        return self._read[name]

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self._column(name) is not None

    def __getitem__(self, name: str) -> np.ndarray:
        column = self._column(name)
        if column is None:
            raise KeyError(name)
        raw, gaps = column
        part = raw[self._start:self._stop]
        if not gaps:
            return part
        if name not in self._held:  # several laws may read it (the clutch: both heat shares)
            self._held[name] = np.empty(len(part))
            hold(part, _carried(raw, self._start), self._held[name])
        return self._held[name]

    def __iter__(self) -> Iterator[str]:
        return (name for name in self._frame.columns if self._column(name) is not None)

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def window(self, start: int, stop: int) -> "RunChannels":
        """Samples start..stop (of this window) of every channel."""
        return RunChannels(self._frame, self._start + start, self._start + stop, self._read)

    def first_valid(self, name: str) -> float | None:
        """The channel's first finite sample in the window, None where it has none."""
        column = self._column(name)
        at = -1 if column is None else first_valid_index(column[0][self._start:self._stop])
        return None if at < 0 else float(column[0][self._start + at])


def first_valid_index(values: np.ndarray) -> int:
    """Index of the first finite value, -1 if none; looked for in growing windows, since it is usually near the
    start (a whole-column test would allocate and scan the whole run for every channel)."""
    start, size = 0, 256
    while start < len(values):
        finite = np.isfinite(values[start:start + size])
        if finite.any():
            return start + int(finite.argmax())
        start, size = start + size, size * 4
    return -1


@njit(cache=True, nogil=True)
def hold(part, carried, out):  # pragma: no cover - compiled
    """out = part with each NaN replaced by the last valid value before it (`carried` before the first)."""
    last = carried
    for i in range(part.shape[0]):
        v = part[i]
        if v == v:
            last = v
        out[i] = last


def _carried(raw: np.ndarray, start: int) -> float:
    """The last valid value before sample `start`, else the column's first valid value."""
    stop = start
    while stop > 0:  # looked for backwards a window at a time: it is usually just before
        low = max(stop - 4096, 0)
        valid = np.flatnonzero(~np.isnan(raw[low:stop]))
        if len(valid):
            return float(raw[low + valid[-1]])
        stop = low
    return float(raw[first_valid_index(raw)])
