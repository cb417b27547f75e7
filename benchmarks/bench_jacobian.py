"""The Jacobian of a fit: its columns computed together (benchlab.network.sets) against one run per column.

    .venv/bin/python benchmarks/bench_jacobian.py [--repeats N]

Data: a simulated 20 min Table 1 run with a hidden heat source, at the diagnosis' fitting step; models: the nonlinear
clutch, and the first extension of each mechanism a diagnosis tries (a node, a lag, a source, a convection law...), each at the
point a short fit (5 evaluations) reaches from the start values, as within a fit (at the start values themselves
the engaged and open convection laws coincide, and every column that moves one of them is discretised on its own). Ours: scipy's forward differences (`approx_derivative`, '2-point') with their residual
vectors computed together, as `benchlab.identify.fit` hands them to least_squares (`workers=`). Peer, in the same
process: the same call evaluating `residual_vector` once per column, as scipy does without `workers`. CPU time per
Jacobian (process time, median of the repeats); the two Jacobians must be equal bit for bit.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import benchlab  # noqa: E402,F401 - first: sets single-threaded BLAS before numpy loads
import numpy as np  # noqa: E402
from scipy.optimize._numdiff import approx_derivative  # noqa: E402

from benchlab.diagnose.engine import STEP_S, diagnosed_spec  # noqa: E402
from benchlab.diagnose.library import candidates  # noqa: E402
from benchlab.identify.data import prepare  # noqa: E402
from benchlab.identify.fit import coordinate_bounds, from_coordinates, residual_vector, residual_vectors  # noqa: E402
from benchlab.identify.fit import fit, to_coordinates  # noqa: E402
from benchlab.model.catalog import resolve_model  # noqa: E402
from benchlab.model.params import paper_params  # noqa: E402
from benchlab.runfile import ALIGNED_UNITS  # noqa: E402
from protocols.table1 import table1_schedule  # noqa: E402
from sim_bench import plant as P  # noqa: E402
from sim_bench.virtual_run import run_schedule  # noqa: E402


def _specs():
    """The run at the diagnosis' fitting step, and the model with the first candidate of each mechanism."""
    plant = P.ThermalPlant(paper_params("nonlinear"), [P.gearbox_churning(40.0)])
    data = prepare(run_schedule(table1_schedule(7, duration_s=1200.0), plant, seed=7), STEP_S, name="0")
    model = resolve_model("nonlinear")
    first = {}
    for candidate in candidates(model, data.channels, ALIGNED_UNITS):
        first.setdefault(candidate.mechanism, candidate)
    return data, [("nonlinear", diagnosed_spec(model, [data]))] + [
        (c.key, diagnosed_spec(c.build(model, data.channels), [data])) for c in first.values()]


def _jacobian(spec, data, x, together: bool) -> np.ndarray:
    def fun(point):
        return residual_vector(spec.network, from_coordinates(spec, point), [data])

    def columns(_fun, points):
        return residual_vectors(spec.network, from_coordinates(spec, x), [from_coordinates(spec, p) for p in points],
                                [data])

    return approx_derivative(fun, x, method="2-point", f0=fun(x), bounds=coordinate_bounds(spec),
                             workers=columns if together else map)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    data, specs = _specs()
    print(f"{'model':32s} {'columns':>7s} {'together ms':>12s} {'one by one ms':>14s} {'ratio':>6s}  equal")
    ratios = []
    for name, spec in specs:
        x = to_coordinates(spec, fit(spec, [data], max_nfev=5).params)
        times = {}
        jacobians = {}
        for together in (True, False):
            jacobians[together] = _jacobian(spec, data, x, together)  # warm-up: compile, fill the run's memo
            spent = []
            for _ in range(args.repeats):
                t0 = time.process_time()
                _jacobian(spec, data, x, together)
                spent.append(time.process_time() - t0)
            times[together] = statistics.median(spent)
        ratios.append(times[False] / times[True])
        print(f"{name:32s} {len(x):7d} {1e3 * times[True]:12.2f} {1e3 * times[False]:14.2f} {ratios[-1]:6.2f}  "
              f"{np.array_equal(jacobians[True], jacobians[False])}")
    print(f"one by one / together, median over the models: {statistics.median(ratios):.2f}x less CPU")


if __name__ == "__main__":
    main()
