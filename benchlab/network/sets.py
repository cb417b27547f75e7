"""Many parameter sets near one base, simulated together: the columns of a fit's forward-difference Jacobian.

Each set differs from `base` in a few parameters (a finite difference moves one). Only the laws that read a moved
parameter are evaluated again; the base's operating points are kept where the moved laws group the samples as the
base's did (checked; a set that regroups them is discretised on its own); the matrices of all sets are discretised in
one compiled call and every trajectory is propagated in another. Each set's states are bit for bit what
`benchlab.network.solver.run_network` gives for it: the same functions compute the same numbers, and only the Python around
them runs once per Jacobian instead of once per column (a diagnosis spends most of its time in those columns).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from benchlab.jit import njit

from benchlab.network.structure import Channels, Params, ThermalNetwork, as_samples, sample_matrix
from benchlab.network.solver import (_capacity, _capacity_terms, _coefficient, _coefficient_terms, _conductance,
                             _per_point, _propagate, _propagate4, _quantised, _system_matrices, _zoh, discretise,
                             matrix_laws, propagate, split_laws)
from benchlab.network.memo import LawMemo, NoMemo


@dataclass
class _Law:
    """One law of the matrices (a link's conductance, a source's W/K term or a node's capacity), how to evaluate it,
    what it reads."""

    key: int  # id of the law object: links that share one law share its value
    reads: frozenset[str] | None  # None: unknown, evaluated again for every set
    positive: bool  # conductances and capacities are keyed on a log scale, signed coefficients on a linear one
    evaluate: Callable[[Params], "np.ndarray | float"]


@dataclass
class _Base:
    """The base set's laws, operating points, matrices and inputs."""

    laws: list  # value of each law of `_laws`: a scalar or one per sample
    varying: dict[int, np.ndarray]  # per varying law (index into laws) its value at each operating point
    op_index: np.ndarray
    first: np.ndarray  # the first sample of each operating point
    Ad: np.ndarray
    Bd: np.ndarray
    columns: list[np.ndarray]  # the input columns: heat flows, then boundary temperatures
    inputs: np.ndarray
    assembly: tuple  # the network's matrix assembly steps (solver._assembly)


def _laws(network: ThermalNetwork, channels: Channels) -> list[_Law]:
    """The laws `benchlab.network.solver.discretise` evaluates for the matrices, in its order."""
    laws = [_Law(id(link.resistance), _reads(link.resistance), True,
                 lambda p, link=link: _conductance(link, p, channels)) for link in network.links]
    laws += [_Law(id(law), _reads(law), False, lambda p, src=src, node=node, law=law: _coefficient(src, node, law, p,
                                                                                                    channels))
             for src, node, law in _coefficient_terms(network)]
    laws += [_Law(id(node.capacity_law), _reads(node.capacity_law), True,
                  lambda p, node=node: _capacity(node, p, channels)) for _, node in _capacity_terms(network)]
    return laws


def _reads(law: Callable) -> frozenset[str] | None:
    reads = getattr(law, "reads", None)
    return None if reads is None else frozenset(reads)


def _moved(base: Params, params: Params) -> set[str]:
    """The parameters whose value differs from the base's (or that the base lacks); 0.0 and -0.0 differ, and NaN
    counts as moved (a law may tell them apart)."""
    return {k for k, v in params.items()
            if k not in base or not (v == base[k] and (v or math.copysign(1.0, v) == math.copysign(1.0, base[k])))}


def _base(network: ThermalNetwork, params: Params, channels: Channels, dt: float,
          resolution: float, memo: LawMemo) -> _Base:
    disc = discretise(network, params, channels, dt, resolution, memo)
    stages = memo.stages(network)
    n = len(disc.op_index)
    values, _ = matrix_laws(network, params, channels, n, memo)
    # points are numbered in order of first appearance: a point's first sample is where the running maximum grows
    first = np.flatnonzero(np.diff(np.maximum.accumulate(disc.op_index), prepend=-1))
    return _Base(values, stages.points[1], disc.op_index, first, disc.Ad, disc.Bd, list(stages.columns), disc.inputs,
                 stages.assembly)


def run_network_sets(network: ThermalNetwork, base: Params, param_sets: Sequence[Params], channels: Channels,
                     dt: float, x0s: np.ndarray, resolution: float, memo: LawMemo,
                     base_x0: np.ndarray | None = None) -> list[np.ndarray | None]:
    """The states (N + 1, n) of each parameter set from its row of `x0s`: `run_network` of each, computed together.

    `memo` must serve `channels` (a fit's run); the base is discretised through it, the sets are not kept in it.
    With `base_x0` (the base's initial state, for a caller that holds the base's own states), a set that moves no
    parameter the network reads and starts from `base_x0` is None: its states are the base's, bit for bit (a fit's
    column of another run's start temperature, which this run never reads).
    """
    if isinstance(memo, NoMemo) or not memo.holds(channels):
        return [propagate(discretise(network, p, channels, dt, resolution), x0) for p, x0 in zip(param_sets, x0s)]
    n = len(next(iter(channels.values())))
    laws = _laws(network, channels)
    origin = _base(network, base, channels, dt, resolution, memo)
    factor_names = {name for _, name in origin.assembly[1] if name}
    source_reads = [_reads(src.heat_flow) for src in network.sources]
    matrices_of = np.zeros(len(param_sets), dtype=np.int64)  # 0: the base's; k: the k-th moved set's
    inputs_of = np.zeros(len(param_sets), dtype=np.int64)
    moved_A, moved_B, moved_inputs = [], [], [origin.inputs]
    alone: dict[int, np.ndarray] = {}  # sets that regroup the operating points, discretised on their own
    as_base: set[int] = set()  # sets whose states are the base's (None in the result)
    for s, params in enumerate(param_sets):
        moved = _moved(base, params)
        if any(law.reads is None or law.reads & moved for law in laws) or factor_names & moved:
            matrices = _moved_matrices(network, params, moved, laws, origin, resolution)
            if matrices is None:
                alone[s] = propagate(discretise(network, params, channels, dt, resolution), x0s[s])
                continue
            moved_A.append(matrices[0])
            moved_B.append(matrices[1])
            matrices_of[s] = len(moved_A)
        columns = _moved_columns(network, params, moved, source_reads, channels, origin.columns, n)
        if columns is not None:
            inputs_of[s] = len(moved_inputs)
            moved_inputs.append(sample_matrix(columns, n))
        if (base_x0 is not None and not matrices_of[s] and not inputs_of[s]
                and np.array_equal(x0s[s], base_x0)):
            as_base.add(s)
    Ads, Bds = [origin.Ad[None]], [origin.Bd[None]]
    if moved_A:
        Ad, Bd = _zoh(np.concatenate(moved_A), np.concatenate(moved_B), dt)
        points = len(origin.Ad)
        Ads.append(Ad.reshape(-1, points, *Ad.shape[1:]))
        Bds.append(Bd.reshape(-1, points, *Bd.shape[1:]))
    x0s = np.ascontiguousarray(x0s, dtype=np.float64)
    out = np.empty((len(param_sets), x0s.shape[1], len(origin.op_index) + 1))  # state-major, as propagate's
    together = np.array([s for s in range(len(param_sets)) if s not in alone and s not in as_base], dtype=np.int64)
    _propagate_sets(origin.op_index, np.concatenate(Ads), np.concatenate(Bds), matrices_of, np.stack(moved_inputs),
                    inputs_of, x0s, together, out)
    for s, states in alone.items():
        out[s] = states.T
    return [None if s in as_base else states.T for s, states in enumerate(out)]


def _moved_matrices(network: ThermalNetwork, params: Params, moved: set[str], laws: list[_Law], origin: _Base,
                    resolution: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The continuous (A, B) of a set whose moved parameters change them, on the base's operating points; None where
    the set's laws would group the samples otherwise (a point's samples no longer agree)."""
    values = list(origin.laws)
    changed: dict[int, np.ndarray | float] = {}
    for i, law in enumerate(laws):
        if law.reads is None or law.reads & moved:
            if law.key not in changed:
                changed[law.key] = law.evaluate(params)
            values[i] = changed[law.key]
            if isinstance(values[i], np.ndarray) != isinstance(origin.laws[i], np.ndarray):
                return None
    varying = dict(origin.varying)
    for i, law in enumerate(laws):
        if law.key in changed and isinstance(values[i], np.ndarray):
            codes, decode = _quantised(values[i], law.positive, resolution)
            at_points = codes[origin.first]
            if not np.array_equal(codes, at_points[origin.op_index]):
                return None  # (points that now agree need no check: their matrices are equal, bit for bit)
            varying[i] = decode(at_points)
    per_op = _per_point(values, varying)
    conductances, coefficients, capacities = split_laws(network, per_op)
    return _system_matrices(network, params, conductances, coefficients, len(per_op[0]) if per_op else 1,
                            origin.assembly, capacities=capacities)


def _moved_columns(network: ThermalNetwork, params: Params, moved: set[str], source_reads: list,
                   channels: Channels, columns: list[np.ndarray], n: int) -> list[np.ndarray] | None:
    """The input columns of a set whose moved parameters change a heat flow; None where none changes."""
    out = list(columns)
    changed = False
    for k, (src, reads) in enumerate(zip(network.sources, source_reads)):
        if reads is None or reads & moved:
            out[k] = as_samples(src.heat_flow(params, channels), n)
            changed = True
    return out if changed else None


@njit(cache=True, nogil=True)
def _propagate_sets(op_index, Ads, Bds, matrices_of, inputs, inputs_of, x0s, sets, out):  # pragma: no cover
    """`propagate` of each set in `sets` on the shared operating points: its matrices and inputs by index."""
    for s in sets:
        k, j = matrices_of[s], inputs_of[s]
        if x0s.shape[1] == 4:
            _propagate4(op_index, Ads[k], Bds[k], inputs[j], x0s[s], out[s], 0)
        else:
            _propagate(op_index, Ads[k], Bds[k], inputs[j], x0s[s], out[s], 0)
