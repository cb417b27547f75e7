"""Exact zero-order-hold simulation of a thermal network driven by sampled channels.

Between two samples the inputs (heat flows, boundary temperatures) and the operating point
(link resistances) are held, so the state update over one step is exactly
x[k+1] = Ad x[k] + Bd u[k] with [Ad Bd] the matrix exponential of the augmented continuous
system, computed for all operating points in one compiled loop (Taylor series with scaling
and squaring: no BLAS call per point, 3-8x faster than scipy.linalg.expm for n = 4..7). Operating points are keyed by their conductances, quantised to a relative
resolution of `resolution` (1e-6 by default: far below any sensor's error), and
each distinct one is discretised once. A node whose capacity is a law (`Node.capacity_law`, a capacity that varies
with its temperature) is held likewise: its value per sample is one more key, and its row of the system is divided
by it, so the state follows dϑ/dt = Q/C(ϑ) with C held over each step as a resistance is.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from benchlab.jit import njit

from benchlab.network.structure import Channels, Link, Node, Params, Source, ThermalNetwork, as_samples, sample_matrix
from benchlab.network.memo import NO_MEMO, LawMemo, float_bits, parameter_bits

DEFAULT_RESOLUTION = 1e-6


@dataclass(frozen=True)
class Discretised:
    """Per-sample operating point index plus the discrete matrices of every distinct point."""

    op_index: np.ndarray  # (N,) int64 into Ad/Bd
    Ad: np.ndarray  # (M, n, n)
    Bd: np.ndarray  # (M, n, m)
    inputs: np.ndarray  # (N, m) heat flows (W) then boundary temperatures (degC)


def _conductances(network: ThermalNetwork, params: Params, channels: Channels, n: int,
                  memo: LawMemo = NO_MEMO) -> list[np.ndarray | float]:
    """1/R of every link; links that share one law object (R_PA, R_FA) get the same array, evaluated once."""
    out: list[np.ndarray | float] = []
    by_law: dict[int, np.ndarray | float] = {}
    for link in network.links:
        if id(link.resistance) in by_law:
            out.append(by_law[id(link.resistance)])
            continue
        g = memo.value(link.resistance, params, lambda: _conductance(link, params, channels))
        by_law[id(link.resistance)] = g
        out.append(g)
    return out


def _conductance(link: Link, params: Params, channels: Channels) -> np.ndarray | float:
    """1/R of one link, its resistance checked positive and finite."""
    r = np.asarray(link.resistance(params, channels), dtype=np.float64)
    if not (_all_positive_finite(r.ravel()) if r.ndim else math.isfinite(float(r)) and float(r) > 0):
        raise ValueError(f"resistance of link {link.label or (link.a, link.b)} is not positive and finite")
    return float(1.0 / r) if r.ndim == 0 else 1.0 / r


@njit(cache=True, nogil=True)
def _all_positive_finite(values: np.ndarray) -> bool:  # pragma: no cover - compiled
    """Whether every value is finite and > 0, in one pass (a law's resistances are checked on every call)."""
    for v in values:
        if not (math.isfinite(v) and v > 0):
            return False
    return True


def _system_matrices(network: ThermalNetwork, params: Params, conductances: list[np.ndarray | float],
                     coefficients: list[np.ndarray], n_ops: int,
                     assembly: tuple[np.ndarray, list[tuple[int, str]]] | None = None,
                     factors: np.ndarray | None = None,
                     capacities: "list[np.ndarray | float]" = ()) -> tuple[np.ndarray, np.ndarray]:
    """Continuous A (n_ops, n, n) and B (n_ops, n, m) for each operating point.

    `conductances`: per link, its value at each point (or one for all). `coefficients`: per (source, node) term of
    `_coefficient_terms`, the heat flow per kelvin of that node
    (an affine source, e.g. copper loss rising with winding temperature), which goes into A.
    The entries are written as a list of steps (`_assembly`) applied in one compiled pass, in the order and with
    the operations of writing them one by one; `assembly`: the network's, and `factors` its `_factors`, where the
    caller keeps them. `capacities`: per node of `_capacity_terms`, its capacity (J/K) at each point (or one for
    all), whose row is then divided by it in place of its capacity parameter.
    """
    steps, recipe = assembly or _assembly(network)
    n, m = len(network.state_names), len(network.sources) + len(network.boundaries)
    factors = _factors(recipe, params) if factors is None else factors
    laws = np.empty((len(conductances) + len(coefficients), n_ops))
    for row, g in enumerate(list(conductances) + list(coefficients)):
        laws[row] = g
    A = np.zeros((n_ops, n, n))
    B = np.zeros((n_ops, n, m))
    _assemble(steps, factors, laws, A, B)
    for (i, node), capacity in zip(_capacity_terms(network), capacities):
        ratio = np.reshape(params[node.capacity] / np.asarray(capacity, dtype=np.float64), (-1, 1))
        A[:, i, :] *= ratio
        B[:, i, :] *= ratio
    return A, B


def _factors(recipe: list[tuple[str, str]], params: Params) -> np.ndarray:
    """The factor of each step of an `_assembly` recipe (1/C, ∓1/tau) from the parameters."""
    return np.array([_FACTOR[kind](params[name]) if name else 0.0 for kind, name in recipe], dtype=np.float64)


_FACTOR = {"1/C": lambda c: 1.0 / c, "-1/tau": lambda tau: -1.0 / tau, "1/tau": lambda tau: 1.0 / tau}


def _assembly(network: ThermalNetwork) -> tuple[np.ndarray, list[tuple[str, str]]]:
    """The steps of `_system_matrices` (kind, row, column, law row or -1) and, per step, how its factor is made
    from a parameter (1/C of the row's node, ∓1/tau of a lag; none, a factor 0, for a lag's row): the network's
    structure, not its values."""
    states = {name: i for i, name in enumerate(network.state_names)}
    bcol = {b.name: len(network.sources) + j for j, b in enumerate(network.boundaries)}
    capacity = {states[node.name]: node.capacity for node in network.nodes}  # a lag's row has none: 1/C is 0
    steps: list[int] = []  # (kind, row, column, law row) after one another
    recipe: list[tuple[str, str]] = []
    for row, link in enumerate(network.links):
        for here, there in ((link.a, link.b), (link.b, link.a)):
            if here not in states:
                continue
            i = states[here]
            steps += (_SUB_A, i, i, row)
            steps += (_ADD_A, i, states[there], row) if there in states else (_ADD_B, i, bcol[there], row)
            recipe += [("1/C", capacity.get(i, "")), ("1/C", capacity.get(i, ""))]
    for k, src in enumerate(network.sources):
        i = states[src.node]
        steps += (_SET_B, i, k, -1)
        recipe.append(("1/C", capacity.get(i, "")))
    for row, (src, node, _) in enumerate(_coefficient_terms(network), start=len(network.links)):
        i = states[src.node]
        steps += (_ADD_A, i, states[node], row)
        recipe.append(("1/C", capacity.get(i, "")))
    for lag in network.lags:
        s, i = states[lag.name], states[lag.node]
        steps += (_SET_A, s, s, -1, _SET_A, s, i, -1)
        recipe += [("-1/tau", lag.time_constant), ("1/tau", lag.time_constant)]
    return np.array(steps, dtype=np.int64).reshape(-1, 4), recipe


_SUB_A, _ADD_A, _ADD_B, _SET_A, _SET_B = range(5)  # the kinds of `_system_matrices`' steps


@njit(cache=True, nogil=True)
def _assemble(steps: np.ndarray, factors: np.ndarray, laws: np.ndarray, A: np.ndarray,
              B: np.ndarray) -> None:  # pragma: no cover - compiled
    """Apply `_system_matrices`' steps in order to every operating point: subtract or add law × factor, or set the
    factor, at (row, column) of A or B."""
    for k in range(steps.shape[0]):
        kind, i, j, law = steps[k, 0], steps[k, 1], steps[k, 2], steps[k, 3]
        for o in range(A.shape[0]):
            if kind == _SUB_A:
                A[o, i, j] -= laws[law, o] * factors[k]
            elif kind == _ADD_A:
                A[o, i, j] += laws[law, o] * factors[k]
            elif kind == _ADD_B:
                B[o, i, j] += laws[law, o] * factors[k]
            elif kind == _SET_A:
                A[o, i, j] = factors[k]
            else:
                B[o, i, j] = factors[k]


def _coefficient_terms(network: ThermalNetwork) -> list[tuple]:
    """(source, node, coefficient law) of every temperature-affine term of the network's sources."""
    return [(src, node, law) for src in network.sources for node, law in src.coefficients]


def _coefficients(network: ThermalNetwork, params: Params, channels: Channels,
                  memo: LawMemo = NO_MEMO) -> list[np.ndarray | float]:
    """W/K of each temperature-affine source term: a scalar, or one value per sample."""
    return [memo.value(law, params, lambda: _coefficient(src, node, law, params, channels))
            for src, node, law in _coefficient_terms(network)]


def _coefficient(src: Source, node: str, law: Callable, params: Params, channels: Channels) -> np.ndarray | float:
    """One temperature-affine term's W/K, checked finite."""
    k = np.asarray(law(params, channels), dtype=np.float64)
    if not np.all(np.isfinite(k)):
        raise ValueError(f"heat flow of source {src.label} per kelvin of {node} is not finite")
    return float(k) if k.ndim == 0 else k


def _capacity_terms(network: ThermalNetwork) -> list[tuple[int, Node]]:
    """(state index, node) of every node whose capacity is a law."""
    return [(i, node) for i, node in enumerate(network.nodes) if node.capacity_law is not None]


def _capacities(network: ThermalNetwork, params: Params, channels: Channels,
                memo: LawMemo = NO_MEMO) -> list[np.ndarray | float]:
    """J/K of each capacity law: a scalar, or one value per sample."""
    return [memo.value(node.capacity_law, params, lambda: _capacity(node, params, channels))
            for _, node in _capacity_terms(network)]


def _capacity(node: Node, params: Params, channels: Channels) -> np.ndarray | float:
    """One node's capacity law in J/K, checked positive and finite."""
    c = np.asarray(node.capacity_law(params, channels), dtype=np.float64)
    if not (_all_positive_finite(c.ravel()) if c.ndim else math.isfinite(float(c)) and float(c) > 0):
        raise ValueError(f"heat capacity of node {node.name} is not positive and finite")
    return float(c) if c.ndim == 0 else c


def matrix_laws(network: ThermalNetwork, params: Params, channels: Channels, n: int,
                memo: LawMemo = NO_MEMO) -> tuple[list[np.ndarray | float], list[bool]]:
    """Every law the operating points are made of, in the solver's order (conductances, temperature coefficients of
    sources, capacity laws), and whether each is keyed as positive (on a log scale)."""
    laws = (_conductances(network, params, channels, n, memo) + _coefficients(network, params, channels, memo)
            + _capacities(network, params, channels, memo))
    return laws, law_signs(network)


def law_signs(network: ThermalNetwork) -> list[bool]:
    """Per law of `matrix_laws`, whether it is positive (a conductance, a capacity) or signed (a coefficient)."""
    return ([True] * len(network.links) + [False] * len(_coefficient_terms(network))
            + [True] * len(_capacity_terms(network)))


def split_laws(network: ThermalNetwork, per_point: list) -> tuple[list, list, list]:
    """`matrix_laws`' values split into conductances, coefficients and capacities (`_system_matrices`' arguments)."""
    links, terms = len(network.links), len(_coefficient_terms(network))
    return per_point[:links], per_point[links:links + terms], per_point[links + terms:]


TAYLOR_THETA = 0.5  # 1-norm of A*h after scaling by 2**-s
TAYLOR_TOL = 1e-17  # bound on the truncated Taylor tail of Psi, relative to its unit leading term


@njit(cache=True, nogil=True)
def _horner_step(a, h, c, P, T):  # pragma: no cover - compiled
    """P = c I + a h P, with T as scratch."""
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for l in range(n):
                acc += a[i, l] * P[l, j]
            T[i, j] = acc * h
    for i in range(n):
        for j in range(n):
            P[i, j] = T[i, j]
        P[i, i] += c


@njit(cache=True, nogil=True)
def _sparse_horner_step(a, cols, counts, h, c, P, T):  # pragma: no cover - compiled
    """_horner_step's P = c I + a h P with row i of a h P summed over the columns of a that are not zero
    (cols[i, :counts[i]], in increasing order) and a whole row of P at a time: the same sums in the same order, bit
    for bit (a zero of a adds ±0 to a finite sum that starts at +0, which changes no bit), on a third of the
    products of a network whose nodes each touch a few others (the reference clutch: 50 of 169), vectorised."""
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            T[i, j] = 0.0
        for k in range(counts[i]):
            l = cols[i, k]
            ail = a[i, l]
            for j in range(n):
                T[i, j] += ail * P[l, j]
        for j in range(n):
            T[i, j] *= h
    for i in range(n):
        for j in range(n):
            P[i, j] = T[i, j]
        P[i, i] += c


@njit(cache=True, nogil=True)
def _zoh_kernel(A, B, dt, Ad, Bd):  # pragma: no cover - compiled
    """Ad = exp(A dt), Bd = int_0^dt exp(A s) ds B for each point: Taylor series of Psi, then scaling and squaring.

    With h = dt / 2**s and ||A h||_1 <= TAYLOR_THETA, Psi = sum_k (A h)^k / (k + 1)! gives
    exp(A h) = I + A h Psi and Gamma(h) = Psi B h; squaring doubles the step:
    exp(2Ah) = exp(Ah)^2, Gamma(2h) = exp(Ah) Gamma(h) + Gamma(h). No BLAS, no LAPACK.
    """
    n, m = A.shape[1], B.shape[2]
    P = np.empty((n, n))
    T = np.empty((n, n))
    G = np.empty((n, m))
    G2 = np.empty((n, m))
    cols = np.empty((n, n), dtype=np.int64)  # per row of A, its columns that are not zero (_sparse_horner_step)
    counts = np.empty(n, dtype=np.int64)
    for o in range(A.shape[0]):
        a = A[o]
        norm = 0.0
        for j in range(n):
            col = 0.0
            for i in range(n):
                col += abs(a[i, j])
            norm = max(norm, col)
        norm *= dt
        if not np.isfinite(norm):
            Ad[o] = np.nan
            Bd[o] = np.nan
            continue
        s = 0
        while norm > TAYLOR_THETA:
            norm *= 0.5
            s += 1
        h = dt / 2.0 ** s
        nonzero = 0
        for i in range(n):
            counts[i] = 0
            for j in range(n):
                if a[i, j] != 0.0:
                    cols[i, counts[i]] = j
                    counts[i] += 1
            nonzero += counts[i]
        # the row-wise sparse step is faster from 7 states on where at most a third of A is not zero (measured n = 4..13;
        # below 7 the dense step's few products cost less than the sparse one's indexing)
        sparse = n >= 7 and 3 * nonzero <= n * n
        q = 1  # tail of Psi after degree q <= theta^(q+1) / (q+2)! / (1 - theta)
        tail = norm * norm / 6.0 / (1.0 - TAYLOR_THETA)
        while tail > TAYLOR_TOL:
            q += 1
            tail *= norm / (q + 2)
        f = 1.0
        for k in range(2, q + 2):
            f *= k
        for i in range(n):  # Horner: P = I/(q+1)!, then P = I/(k+1)! + A h P for k = q-1 .. 0 gives Psi
            for j in range(n):
                P[i, j] = 0.0
            P[i, i] = 1.0 / f
        for k in range(q - 1, -1, -1):
            f /= k + 2
            if sparse:
                _sparse_horner_step(a, cols, counts, h, 1.0 / f, P, T)
            else:
                _horner_step(a, h, 1.0 / f, P, T)
        for i in range(n):
            for j in range(m):
                acc = 0.0
                for l in range(n):
                    acc += P[i, l] * B[o, l, j]
                G[i, j] = acc * h
        if sparse:  # P = exp(A h) = I + A h Psi
            _sparse_horner_step(a, cols, counts, h, 1.0, P, T)
        else:
            _horner_step(a, h, 1.0, P, T)
        for _ in range(s):
            for i in range(n):
                for j in range(m):
                    acc = G[i, j]
                    for l in range(n):
                        acc += P[i, l] * G[l, j]
                    G2[i, j] = acc
                for j in range(n):
                    acc = 0.0
                    for l in range(n):
                        acc += P[i, l] * P[l, j]
                    T[i, j] = acc
            P, T = T, P  # the squares become the factors: the buffers swap roles, nothing is copied
            G, G2 = G2, G
        for i in range(n):  # element by element: an array assignment compiles numba's shape-mismatch error
            for j in range(n):
                Ad[o, i, j] = P[i, j]
            for j in range(m):
                Bd[o, i, j] = G[i, j]


def _zoh(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold matrices (M, n, n) and (M, n, m) of continuous systems (M, n, n), (M, n, m)."""
    Ad = np.empty(A.shape)
    Bd = np.empty(B.shape)
    _zoh_kernel(np.ascontiguousarray(A, dtype=np.float64), np.ascontiguousarray(B, dtype=np.float64), float(dt), Ad, Bd)
    return Ad, Bd


@njit(cache=True, nogil=True)
def _factorize(keys: np.ndarray) -> tuple:  # pragma: no cover - compiled
    """Integer keys as (index of each key's distinct value, the distinct values), both in order of first appearance
    (pandas.factorize's result), by one pass over an open-addressing hash table."""
    n = keys.shape[0]
    bits = 4
    while (1 << bits) < 2 * n:
        bits += 1
    mask = (1 << bits) - 1
    table = np.full(1 << bits, -1, dtype=np.int64)
    uniques = np.empty(n, dtype=np.int64)
    codes = np.empty(n, dtype=np.int64)
    distinct = 0
    for i in range(n):
        key = keys[i]
        if i > 0 and key == keys[i - 1]:  # runs of one value are the usual case
            codes[i] = codes[i - 1]
            continue
        slot = np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(64 - bits)) & mask
        while True:
            j = table[slot]
            if j < 0:
                table[slot] = distinct
                uniques[distinct] = key
                codes[i] = distinct
                distinct += 1
                break
            if uniques[j] == key:
                codes[i] = j
                break
            slot = (slot + 1) & mask
    return codes, uniques[:distinct].copy()


def _combined_key(columns: list[np.ndarray], n: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """Index per sample of the distinct combinations of the key columns, and each column's value per combination."""
    code = np.zeros(n, dtype=np.int64)
    uniques = []
    for col in columns:
        col_codes, col_uniques = _factorize(col)
        uniques.append(col_uniques)
        code = code * len(col_uniques) + col_codes
    op_index, op_codes = _factorize(code)
    per_column = []
    for col_uniques in reversed(uniques):
        per_column.append(col_uniques[op_codes % len(col_uniques)])
        op_codes = op_codes // len(col_uniques)
    per_column.reverse()
    return op_index.astype(np.int64), per_column


def _quantised(values: np.ndarray, positive: bool, resolution: float) -> tuple[np.ndarray, Callable]:
    """Integer keys of per-sample values and the map from keys back to values: conductances (positive) on a
    log scale of relative step `resolution`, signed coefficients on a linear one relative to their largest size."""
    if positive:
        keys = np.log(values)  # rint(log(values) / resolution), in place: one temporary, not three
        np.divide(keys, resolution, out=keys)
        return np.rint(keys, out=keys).astype(np.int64), lambda codes: np.exp(codes * resolution)
    step = float(np.max(np.abs(values))) * resolution or 1.0
    return np.rint(values / step).astype(np.int64), lambda codes: codes * step


def _operating_points(laws: list, n: int, resolution: float,
                      positive: list[bool] | None = None) -> tuple[np.ndarray, list[np.ndarray]]:
    """Group samples by quantised varying law values; return index per sample and per-point values.

    `laws`: conductances (positive, the default) and temperature coefficients of sources, scalars or one
    value per sample. Laws that share one array (R_PA = R_FA) share one key column; the key columns are
    combined into one integer code per sample and factorised in linear time.
    """
    op_index, varying = _varying_points(laws, n, resolution, positive)
    return op_index, _per_point(laws, varying)


def _varying_points(laws: list, n: int, resolution: float,
                    positive: list[bool] | None = None) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """`_operating_points` of the varying laws: the index per sample, and per varying law (by its place in `laws`)
    its value at each point."""
    positive = positive if positive is not None else [True] * len(laws)
    varying = [i for i, g in enumerate(laws) if isinstance(g, np.ndarray)]
    if not varying:
        return np.zeros(n, dtype=np.int64), {}
    columns: list[np.ndarray] = []
    decoders: list[Callable] = []
    keyed: list[np.ndarray] = []  # the values each column was made from
    column_of: dict[int, int] = {}
    for i in varying:
        g = laws[i]
        same = next((j for j, k in enumerate(keyed) if k is g or np.array_equal(k, g)), None)
        if same is None:
            codes, decode = _quantised(g, positive[i], resolution)
            columns.append(codes)
            decoders.append(decode)
            keyed.append(g)
            same = len(columns) - 1
        column_of[i] = same
    if len(columns) == 1:  # one key column (the paper's clutch): its codes are the operating points
        op_index, col_uniques = _factorize(columns[0])
        op_index, per_column = op_index.astype(np.int64), [col_uniques]
    else:
        op_index, per_column = _combined_key(columns, n)
    return op_index, {i: decoders[column_of[i]](per_column[column_of[i]]) for i in varying}


def _per_point(laws: list, varying: dict[int, np.ndarray]) -> list[np.ndarray]:
    """Every law's value at each operating point: the varying ones' (`_varying_points`), the scalars repeated."""
    if not varying:
        return [np.array([g]) for g in laws]
    points = len(next(iter(varying.values())))
    return [varying[i] if i in varying else np.full(points, g) for i, g in enumerate(laws)]


def discretise(network: ThermalNetwork, params: Params, channels: Channels, dt: float,
               resolution: float = DEFAULT_RESOLUTION, memo: LawMemo | None = None) -> Discretised:
    """Evaluate the network's laws on the channels and discretise every distinct operating point.

    `memo` (benchlab.network.memo): what earlier calls on these channels computed, reused where this call repeats
    it (a fit's finite differences); the result is the same either way.
    """
    memo = memo if memo is not None and memo.holds(channels) else NO_MEMO
    stages = memo.stages(network)
    n = len(next(iter(channels.values())))
    laws, positive = matrix_laws(network, params, channels, n, memo)
    arrays = [g for g in laws if isinstance(g, np.ndarray)]
    keyed_by = (n, resolution, len(network.links), tuple(isinstance(g, np.ndarray) for g in laws))
    if not (stages.same_laws(arrays) and stages.points[2] == keyed_by):
        stages.laws, stages.matrices_key = arrays, None
        stages.points = (*_varying_points(laws, n, resolution, positive), keyed_by)
    op_index, varying = stages.points[:2]
    stages.assembly = stages.assembly or _assembly(network)
    key = (parameter_bits(params, [name for _, name in stages.assembly[1] if name])
           + float_bits([dt] + [g for g in laws if not isinstance(g, np.ndarray)]) if memo is not NO_MEMO else None)
    if key is None or key != stages.matrices_key:
        per_op = _per_point(laws, varying)
        conductances, coefficients, capacities = split_laws(network, per_op)
        A, B = _system_matrices(network, params, conductances, coefficients, len(per_op[0]) if per_op else 1,
                                stages.assembly, capacities=capacities)
        stages.matrices, stages.matrices_key = _zoh(A, B, dt), key
    Ad, Bd = stages.matrices
    columns = [memo.value(s.heat_flow, params, lambda: as_samples(s.heat_flow(params, channels), n))
               for s in network.sources]
    columns += [memo.value(b.temperature, params, lambda: as_samples(b.temperature(channels), n))
                for b in network.boundaries]
    if not stages.same_columns(columns):
        stages.columns = columns
        stages.inputs = sample_matrix(columns, n)
    return Discretised(op_index, Ad, Bd, stages.inputs)


@njit(cache=True, nogil=True)
def _propagate(op_index, Ad, Bd, inputs, x0, out, offset):  # pragma: no cover - compiled
    """States from x0 over the samples, state-major: out[i, offset + k] is state i at sample k (the last column,
    offset + N, the state after the last step), so that each state's series is one contiguous row."""
    n = x0.shape[0]
    m = inputs.shape[1]
    x = x0.copy()
    nxt = np.empty(n)
    steps = op_index.shape[0]
    for k in range(steps):
        for i in range(n):
            out[i, offset + k] = x[i]
        a = Ad[op_index[k]]
        b = Bd[op_index[k]]
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += a[i, j] * x[j]
            for j in range(m):
                acc += b[i, j] * inputs[k, j]
            nxt[i] = acc
        for i in range(n):
            x[i] = nxt[i]
    for i in range(n):
        out[i, offset + steps] = x[i]


@njit(cache=True, nogil=True)
def _propagate4(op_index, Ad, Bd, inputs, x0, out, offset):  # pragma: no cover - compiled
    """_propagate for four states (the paper's clutch), unrolled: the state lives in registers."""
    m = inputs.shape[1]
    x0_, x1, x2, x3 = x0[0], x0[1], x0[2], x0[3]
    steps = op_index.shape[0]
    for k in range(steps):
        out[0, offset + k] = x0_
        out[1, offset + k] = x1
        out[2, offset + k] = x2
        out[3, offset + k] = x3
        o = op_index[k]
        y0 = Ad[o, 0, 0] * x0_ + Ad[o, 0, 1] * x1 + Ad[o, 0, 2] * x2 + Ad[o, 0, 3] * x3
        y1 = Ad[o, 1, 0] * x0_ + Ad[o, 1, 1] * x1 + Ad[o, 1, 2] * x2 + Ad[o, 1, 3] * x3
        y2 = Ad[o, 2, 0] * x0_ + Ad[o, 2, 1] * x1 + Ad[o, 2, 2] * x2 + Ad[o, 2, 3] * x3
        y3 = Ad[o, 3, 0] * x0_ + Ad[o, 3, 1] * x1 + Ad[o, 3, 2] * x2 + Ad[o, 3, 3] * x3
        for j in range(m):
            u = inputs[k, j]
            y0 += Bd[o, 0, j] * u
            y1 += Bd[o, 1, j] * u
            y2 += Bd[o, 2, j] * u
            y3 += Bd[o, 3, j] * u
        x0_, x1, x2, x3 = y0, y1, y2, y3
    out[0, offset + steps] = x0_
    out[1, offset + steps] = x1
    out[2, offset + steps] = x2
    out[3, offset + steps] = x3


def propagate_into(op_index: np.ndarray, Ad: np.ndarray, Bd: np.ndarray, inputs: np.ndarray, x0: np.ndarray,
                   out: np.ndarray, offset: int = 0) -> None:
    """Write the states from x0 into the state-major `out` from column `offset` on (`_propagate`)."""
    kernel = _propagate4 if x0.shape[0] == 4 else _propagate
    kernel(op_index, Ad, Bd, inputs, np.ascontiguousarray(x0, dtype=np.float64), out, offset)


@njit(cache=True, nogil=True)
def _propagate_combined44(op_index, ABd, inputs, x0, out, offset):  # pragma: no cover - compiled
    """_propagate4 for four inputs too (the paper's clutch), each point's [Ad Bd] side by side (ABd: points × 4 × 8):
    its sums in its order, on one contiguous 256-byte record per step (about a fifth less time than _propagate4 on
    1 M samples of 13,076 points: the record's four cache lines are adjacent)."""
    x0_, x1, x2, x3 = x0[0], x0[1], x0[2], x0[3]
    steps = op_index.shape[0]
    for k in range(steps):
        out[0, offset + k] = x0_
        out[1, offset + k] = x1
        out[2, offset + k] = x2
        out[3, offset + k] = x3
        a = ABd[op_index[k]]
        u0, u1, u2, u3 = inputs[k, 0], inputs[k, 1], inputs[k, 2], inputs[k, 3]
        y0 = a[0, 0] * x0_ + a[0, 1] * x1 + a[0, 2] * x2 + a[0, 3] * x3 + a[0, 4] * u0 + a[0, 5] * u1 + a[0, 6] * u2 + a[0, 7] * u3
        y1 = a[1, 0] * x0_ + a[1, 1] * x1 + a[1, 2] * x2 + a[1, 3] * x3 + a[1, 4] * u0 + a[1, 5] * u1 + a[1, 6] * u2 + a[1, 7] * u3
        y2 = a[2, 0] * x0_ + a[2, 1] * x1 + a[2, 2] * x2 + a[2, 3] * x3 + a[2, 4] * u0 + a[2, 5] * u1 + a[2, 6] * u2 + a[2, 7] * u3
        y3 = a[3, 0] * x0_ + a[3, 1] * x1 + a[3, 2] * x2 + a[3, 3] * x3 + a[3, 4] * u0 + a[3, 5] * u1 + a[3, 6] * u2 + a[3, 7] * u3
        x0_, x1, x2, x3 = y0, y1, y2, y3
    out[0, offset + steps] = x0_
    out[1, offset + steps] = x1
    out[2, offset + steps] = x2
    out[3, offset + steps] = x3


def propagate(disc: Discretised, x0: np.ndarray) -> np.ndarray:
    """States (N + 1, n): row k at time k*dt from x0 at row 0; the last row is the state after the last step.
    (A transposed view of the state-major result: each state's column is contiguous.)"""
    x0 = np.asarray(x0, dtype=np.float64)
    out = np.empty((x0.shape[0], disc.op_index.shape[0] + 1))
    propagate_into(disc.op_index, disc.Ad, disc.Bd, disc.inputs, x0, out)
    return out.T


def run_network(network: ThermalNetwork, params: Params, channels: Channels, dt: float, x0: np.ndarray,
                resolution: float = DEFAULT_RESOLUTION, memo: LawMemo | None = None) -> np.ndarray:
    """Simulate the network over the channels: states (N + 1, n), row k at time k*dt (`memo`: see discretise).

    Without a memo the run is streamed in blocks (benchlab.network.stream: the same numbers, flat cost per sample);
    a fit's memo keeps the whole-run stages it reuses."""
    if memo is None:
        from benchlab.network.stream import stream_network

        states = stream_network(network, params, channels, dt, x0, resolution)
        if states is not None:
            return states.T
    return propagate(discretise(network, params, channels, dt, resolution, memo), x0)


def conductance_matrices(network: ThermalNetwork, params: Params, links: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """dA/dg (n, n) and dB/dg (n, m): how the continuous system changes per W/K of conductance added to each of
    the links `links` (indices into network.links); an observer that corrects a link law online needs them."""
    on = [np.ones(1) if i in links else np.zeros(1) for i in range(len(network.links))]
    off = [np.zeros(1)] * len(network.links)
    affine = [np.zeros(1)] * len(_coefficient_terms(network))  # temperature-affine heat: no conductance, cancels
    A1, B1 = _system_matrices(network, params, on, affine, 1)
    A0, B0 = _system_matrices(network, params, off, affine, 1)
    return A1[0] - A0[0], B1[0] - B0[0]
