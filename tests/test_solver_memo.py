"""The solver memo of a fit's run (benchlab.solver_memo) changes no number: with it, every discretisation and every
residual equals the one computed from scratch, bit for bit, as parameters move one at a time and all at once."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from benchlab.diagnose.engine import STEP_S, diagnosed_spec
from benchlab.diagnose.library import candidates
from benchlab.identify.data import prepare
from benchlab.identify.fit import KEY_RESOLUTION, residual_vector
from benchlab.model.catalog import resolve_model
from benchlab.params import paper_params
from benchlab.runfile import ALIGNED_UNITS
from benchlab.solver import discretise
from benchlab.solver_memo import LawMemo
from protocols.table1 import table1_schedule
from sim_bench import plant as P
from sim_bench.virtual_run import run_schedule


@pytest.fixture(scope="module")
def setting():
    """A 20 min run with a hidden heat source, the nonlinear model and one extension of each kind: a node, a lag,
    a source."""
    plant = P.ThermalPlant(paper_params("nonlinear"), [P.gearbox_churning(40.0)])
    run = run_schedule(table1_schedule(7, duration_s=1200.0), plant, seed=7)
    model = resolve_model("nonlinear")
    data = prepare(run, STEP_S, name="0", network=diagnosed_spec(model, []).network)
    library = candidates(model, data.channels, ALIGNED_UNITS)
    picked = [next(c for c in library if c.mechanism == m) for m in ("capacity", "sensor", "heat_source")]
    specs = [diagnosed_spec(model, [data])] + [diagnosed_spec(c.build(model, data.channels), [data]) for c in picked]
    return data, specs


def _moves(spec):
    """Parameter sets as a fit's finite differences visit them: the start, each parameter moved alone (and back),
    then all of them at once."""
    start = {**spec.fixed, **{p.name: p.initial for p in spec.free}}
    yield start
    for p in spec.free:
        yield {**start, p.name: start[p.name] * 1.001 + 1e-6}
        yield start
    yield {**start, **{p.name: start[p.name] * 0.999 - 1e-6 for p in spec.free}}


def test_memoised_discretisation_is_bit_identical(setting):
    data, specs = setting
    for spec in specs:
        for params in _moves(spec):
            kept = discretise(spec.network, params, data.channels, data.dt, KEY_RESOLUTION, data.memo)
            new = discretise(spec.network, params, data.channels, data.dt, KEY_RESOLUTION)
            for field in ("op_index", "Ad", "Bd", "inputs"):
                assert np.array_equal(getattr(kept, field), getattr(new, field)), (spec.name, field)
            scratch = replace(data, memo=LawMemo())  # a memo of its own, empty: everything computed
            assert np.array_equal(residual_vector(spec.network, params, [data]),
                                  residual_vector(spec.network, params, [scratch]))


def test_memo_serves_only_the_channels_it_was_bound_to(setting):
    """Other channels (a noisy copy, as identify.uncertainty makes) are computed afresh, not taken from the memo."""
    data, specs = setting
    spec = specs[0]
    params = {**spec.fixed, **{p.name: p.initial for p in spec.free}}
    residual_vector(spec.network, params, [data])  # binds the memo to data.channels
    noisy = dict(data.channels, friction_power=data.channels["friction_power"] * 1.1)
    other = replace(data, channels=noisy)  # shares the memo object
    expected = replace(data, channels=noisy, memo=LawMemo())
    assert np.array_equal(residual_vector(spec.network, params, [other]),
                          residual_vector(spec.network, params, [expected]))
    assert not np.array_equal(residual_vector(spec.network, params, [other]),
                              residual_vector(spec.network, params, [data]))
