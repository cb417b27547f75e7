"""What `benchlab.network.solver.discretise` computed on one run's channels, kept to be reused where a call repeats it.

A fit's finite differences move one parameter at a time: the laws that do not read it, the operating points
when no varying law changed, the matrices when neither those nor a capacity or time constant changed, and the
input columns when no source changed are the ones of the call before. A memo hands back the very objects
computed before, so a result with the memo is bit for bit the result without it.

A memo is bound to the first channels mapping it is used with, whose arrays must never change afterwards (a
fit's run: `benchlab.identify.data.prepare`); any other mapping passes through uncached. A law is cached only
where it names the parameters it reads (`reads`: the laws of model files do, `benchlab.model.build`), keyed by
their exact bits.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

from benchlab.network.structure import Channels, Params, ThermalNetwork

MAX_LAWS = 256  # cached law values per memo before it starts over (a diagnosis builds hundreds of candidates)
MAX_NETWORKS = 32  # networks whose last stages are kept


def float_bits(values: Sequence[float]) -> bytes:
    """The exact bits of the values (-0.0 and 0.0 apart, as a law may tell them apart)."""
    return _packer(len(values)).pack(*values)


@lru_cache(maxsize=None)
def _packer(count: int) -> struct.Struct:
    return struct.Struct(f"{count}d")


def parameter_bits(params: Params, names: Sequence[str]) -> bytes:
    """The exact bits of the named parameters' values."""
    return float_bits([params[name] for name in names])


@dataclass
class Stages:
    """One network's last operating points, discrete matrices and input matrix, with what each was made from."""

    network: ThermalNetwork | None = None
    laws: list = field(default_factory=list)  # the varying law values the operating points were keyed from
    points: tuple | None = None  # (op_index, per varying law its value per point, what else they were keyed by)
    matrices_key: bytes | None = None  # capacities, time constants and step the matrices were made with
    matrices: tuple | None = None  # (Ad, Bd)
    columns: list = field(default_factory=list)  # the input columns the input matrix was stacked from
    inputs: Any = None
    assembly: tuple | None = None  # the network's matrix assembly steps (solver._assembly)

    def same_laws(self, laws: Sequence) -> bool:
        return self.points is not None and _same(self.laws, laws)

    def same_columns(self, columns: Sequence) -> bool:
        return self.inputs is not None and _same(self.columns, columns)


def _same(before: Sequence, now: Sequence) -> bool:
    return len(before) == len(now) and all(a is b for a, b in zip(before, now))


class LawMemo:
    """Law values and solver stages on one channels mapping (see the module docstring)."""

    def __init__(self) -> None:
        self.channels: Channels | None = None
        self.values: dict[Callable, tuple[bytes, Any]] = {}
        self.networks: dict[int, Stages] = {}

    def __reduce__(self) -> tuple:
        return LawMemo, ()  # an empty memo travels: the cached laws are closures, which cannot be pickled

    def holds(self, channels: Channels) -> bool:
        """Whether the memo serves these channels (it binds to the first mapping it is asked about)."""
        if self.channels is None:
            self.channels = channels
        return self.channels is channels

    def value(self, law: Callable, params: Params, compute: Callable[[], Any]) -> Any:
        """`compute()` (a function of the law's value), or what it gave before for the same parameter bits."""
        reads = getattr(law, "reads", None)
        if reads is None:
            return compute()
        key = parameter_bits(params, reads)
        hit = self.values.get(law)
        if hit is not None and hit[0] == key:
            return hit[1]
        value = compute()
        if len(self.values) >= MAX_LAWS:
            self.values.clear()
        self.values[law] = (key, value)
        return value

    def stages(self, network: ThermalNetwork) -> Stages:
        """The network's last stages (new, empty ones the first time)."""
        found = self.networks.get(id(network))
        if found is not None and found.network is network:
            return found
        if len(self.networks) >= MAX_NETWORKS:
            self.networks.clear()
        found = self.networks[id(network)] = Stages(network)
        return found


class NoMemo(LawMemo):
    """Computes everything every time: the path of callers without a memo."""

    def holds(self, channels: Channels) -> bool:
        return True

    def value(self, law: Callable, params: Params, compute: Callable[[], Any]) -> Any:
        return compute()

    def stages(self, network: ThermalNetwork) -> Stages:
        return Stages(network)


NO_MEMO = NoMemo()
