"""The multistart search stops when two independent starts agree and still finds the minimum when the first fails."""

import numpy as np
import pytest

from benchlab.identify.data import prepare, scout_runs
from benchlab.identify.defaults import FIT_STEP_S
from benchlab.identify.fit import _start, fit, fit_multistart, same_minimum
from benchlab.model.catalog import builtin, model_spec
from protocols.table1 import table1_schedule
from sim_bench.plant import ThermalPlant
from sim_bench.virtual_run import run_schedule

SCOUT_NFEV = 25  # fit_multistart's default


@pytest.fixture(scope="module")
def datasets():
    run = run_schedule(table1_schedule(5, duration_s=1800), ThermalPlant(), seed=5)
    return [prepare(run, FIT_STEP_S, network=model_spec("nonlinear").network)]


def _every_start(spec, datasets, starts=6):
    """The search before it could stop: every start scouted, the best polished."""
    rng = np.random.default_rng(0)
    scouts = [fit(spec, datasets, max_nfev=SCOUT_NFEV, start=_start(spec, i, rng, 3.0)) for i in range(starts)]
    best = min(scouts, key=lambda r: r.cost)
    return fit(spec, datasets, start={k: best.params[k] for k in best.free_names})


def test_agreeing_starts_stop_the_search_at_the_answer_of_every_start(datasets):
    spec = model_spec("nonlinear")
    result = fit_multistart(spec, datasets, starts=6)
    assert result.starts < 6
    everything = _every_start(spec, datasets)
    assert same_minimum(result, everything)
    assert result.cost == pytest.approx(everything.cost, rel=1e-6)


def test_a_failed_first_start_is_outvoted(datasets):
    """Priors far off (R0 ten times, the speed terms a thirtieth): the first scout stops far above the minimum; the
    search spends its budget there and ends where good priors end."""
    spec = model_spec(builtin("nonlinear").with_starts({"R0": 3.0, "a1": 0.01, "a2": 0.01}))
    target = fit_multistart(model_spec("nonlinear"), datasets)
    first = fit(spec, datasets, max_nfev=SCOUT_NFEV, start=_start(spec, 0, np.random.default_rng(0), 3.0))
    assert not first.converged and first.cost > 1.5 * target.cost
    result = fit_multistart(spec, datasets, starts=6)
    assert same_minimum(result, target)
    assert result.cost == pytest.approx(target.cost, rel=1e-6)


def test_a_failed_first_start_is_outvoted_on_scout_runs(datasets):
    """identify's search: the scouts fit a coarser, thinned version of the run (scout_runs), the polish the run
    itself; from the failed priors it still ends at the minimum the good priors reach on the run."""
    spec = model_spec(builtin("nonlinear").with_starts({"R0": 3.0, "a1": 0.01, "a2": 0.01}))
    scouted = [scout_runs(data) for data in datasets]
    first = fit(spec, scouted, max_nfev=SCOUT_NFEV, start=_start(spec, 0, np.random.default_rng(0), 3.0))
    settled = fit(model_spec("nonlinear"), scouted)
    assert not first.converged and first.cost > 1.5 * settled.cost
    target = fit(model_spec("nonlinear"), datasets)
    result = fit_multistart(spec, datasets, starts=6, scout_data=scouted)
    assert result.starts >= 2 and same_minimum(result, target)
    assert result.cost == pytest.approx(target.cost, rel=1e-6)


def test_minima_apart_by_more_than_a_standard_error_differ(datasets):
    spec = model_spec("nonlinear")
    result = fit(spec, datasets)
    moved = dict(result.params)
    moved["R_AT"] *= 1.2
    other = fit(spec, datasets, max_nfev=1, start={k: moved[k] for k in result.free_names})
    assert same_minimum(result, result) and not same_minimum(result, other)
