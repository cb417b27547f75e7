"""The solver's shortcuts for fits change no number. With the memo of a fit's run (benchlab.network.memo) every
discretisation and every residual equals the one computed from scratch, bit for bit, as parameters move one at a time
and all at once; so do the parameter sets of a Jacobian computed together (benchlab.network.sets), and a fit takes the
very steps it takes with scipy's own forward differences."""

from __future__ import annotations

from dataclasses import replace

import benchlab.identify.fit as fit_module

import numpy as np
import pytest

from benchlab.diagnose.engine import STEP_S, diagnosed_spec
from benchlab.diagnose.library import candidates
from benchlab.identify.data import prepare
from benchlab.identify.fit import KEY_RESOLUTION, fit, residual_vector, residual_vectors
from benchlab.network import Boundary, Link, Node, Source, ThermalNetwork
from benchlab.model.catalog import resolve_model
from benchlab.model.params import paper_params
from benchlab.runfile import ALIGNED_UNITS
from benchlab.network.solver import discretise, run_network
from benchlab.network.sets import run_network_sets
from benchlab.network.memo import LawMemo
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


def _jacobian_sets(spec, start):
    """A forward-difference Jacobian's sets (each parameter moved alone, by scipy's relative step and by a large one),
    then all parameters moved at once, and the start itself."""
    for step in (1.5e-8, 1e-3):
        for p in spec.free:
            yield {**start, p.name: start[p.name] * (1 + step)}
    yield {**start, **{p.name: start[p.name] * 0.999 for p in spec.free}}
    yield start


def test_sets_computed_together_are_bit_identical(setting):
    data, specs = setting
    for spec in specs:
        start = {**spec.fixed, **{p.name: p.initial for p in spec.free}}
        sets = list(_jacobian_sets(spec, start))
        together = residual_vectors(spec.network, start, sets, [data])
        for params, residuals in zip(sets, together):
            assert np.array_equal(residuals, residual_vector(spec.network, params, [data])), spec.name


def test_a_set_that_leaves_a_run_as_the_base_takes_the_base_residuals_bit_for_bit(setting):
    """Two runs, each with its fitted start temperature: the column of one run's start leaves the other run as the base
    (not simulated again, its part of the base's residuals taken), and every set's residuals are still exact."""
    data, _ = setting
    runs = [data, replace(data, name="1", memo=LawMemo())]
    spec = diagnosed_spec(resolve_model("nonlinear"), runs)
    start = {**spec.fixed, **{p.name: p.initial for p in spec.free}}
    sets = list(_jacobian_sets(spec, start))
    together = residual_vectors(spec.network, start, sets, runs, residual_vector(spec.network, start, runs))
    for params, residuals in zip(sets, together):
        assert np.array_equal(residuals, residual_vector(spec.network, params, runs))
    other_start = [{**start, "init_T_flywheel@1": start["init_T_flywheel@1"] + 0.5}]
    x0 = fit_module.initial_state(spec.network, data, start)
    assert run_network_sets(spec.network, start, other_start, data.channels, data.dt, np.array([x0]), KEY_RESOLUTION,
                            data.memo, x0) == [None]


def test_a_set_that_moves_a_sensors_drift_is_read_again(setting):
    """A drift moves a calibrated output's reading, not its state, nor the state it starts from: with the base's
    residuals given, a set that moves only the drift is still its own residual vector (not the base's)."""
    from benchlab.diagnose.library import candidates as library_of

    data, _ = setting
    runs = [data, replace(data, name="1", memo=LawMemo())]
    model = resolve_model("nonlinear")
    drift = next(c for c in library_of(model, data.channels, ALIGNED_UNITS) if c.key.startswith("sensor_drift_"))
    spec = diagnosed_spec(drift.build(model, data.channels), runs)
    start = {**spec.fixed, **{p.name: p.initial for p in spec.free}}
    name = spec.network.calibrations[drift.signal].drift
    moved = [{**start, name: start[name] + 1e-4}]
    [together] = residual_vectors(spec.network, start, moved, runs, residual_vector(spec.network, start, runs))
    assert np.array_equal(together, residual_vector(spec.network, moved[0], runs))
    assert not np.array_equal(together, residual_vector(spec.network, start, runs))


def test_fit_takes_the_same_steps_as_with_one_run_per_jacobian_column(setting, monkeypatch):
    data, specs = setting
    spec = specs[-1]  # the nonlinear model with an extra heat source: convection laws, a source, a fitted start
    together = fit(spec, [data], max_nfev=6)
    monkeypatch.setattr(fit_module, "residual_vectors",
                        lambda network, base, sets, datasets, *_: [residual_vector(network, p, datasets) for p in sets])
    one_by_one = fit(spec, [data], max_nfev=6)
    assert together.params == one_by_one.params and together.cost == one_by_one.cost
    assert np.array_equal(together.jacobian, one_by_one.jacobian)


def _law(function, reads):
    function.reads = reads
    return function


def test_sets_that_regroup_operating_points_or_read_unnamed_parameters_are_still_exact():
    """A moved law that splits an operating point (two samples of equal resistance that now differ) is discretised
    on its own; a law that does not name what it reads is evaluated for every set."""
    n = 400
    x = np.tile([1.0, 2.0], n // 2)
    channels = {"x": x, "y": 3.0 - x, "u": np.linspace(0.0, 50.0, n), "Ta": np.full(n, 25.0)}
    network = ThermalNetwork(
        nodes=(Node("P", "C_P"),), boundaries=(Boundary("amb", _law(lambda ch: ch["Ta"], ())),),
        links=(Link("P", "amb", _law(lambda p, ch: p["a"] + p["b"] * ch["x"] + p["c"] * ch["y"], ("a", "b", "c"))),
               Link("P", "amb", lambda p, ch: p["r2"] * (1.0 + 0.0 * ch["x"]))),
        sources=(Source("P", _law(lambda p, ch: p["q"] * ch["u"], ("q",))),), outputs={"T": "P"})
    base = {"C_P": 500.0, "a": 0.5, "b": 0.1, "c": 0.1, "r2": 2.0, "q": 0.2}
    sets = [{**base, name: base[name] * 1.01} for name in base] + [base]
    x0s = np.full((len(sets), 1), 30.0)
    assert len(discretise(network, base, channels, 1.0).Ad) == 1  # x and y trade places: one resistance
    assert len(discretise(network, sets[list(base).index("b")], channels, 1.0).Ad) == 2  # b moved: two
    runs = run_network_sets(network, base, sets, channels, 1.0, x0s, KEY_RESOLUTION, LawMemo())
    for params, x0, states in zip(sets, x0s, runs):
        assert np.array_equal(states, run_network(network, params, channels, 1.0, x0, KEY_RESOLUTION)), params
