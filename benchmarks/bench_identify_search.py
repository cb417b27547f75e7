"""CPU of `identify` (nonlinear) beside a plain scipy `least_squares` peer on the same prepared data, and its scaling.

    .venv/bin/python benchmarks/bench_identify_search.py [--seed S] [--repeats N] [--scaling]

1. A simulated 2 h Table 1 run at 10 ms. Ours: `benchlab.identify.api.identify` end to end (data preparation,
   the multistart search, the fit with the start states, uncertainty, evaluation at 10 ms, residual tests). Its
   search alone beside the search before issue 36 (every one of the six starts scouted, the best polished); and
   the search as identify runs it (scouts on `scout_runs`, the polish fitting the start states) beside the search
   on the run followed by a second fit with the start states (identify before).
   Peer: `scipy.optimize.least_squares` (trf, its own 2-point Jacobian, x_scale="jac", tolerances 1e-10) on the
   same prepared data from the same start (the priors, log coordinates, bounds) fitting the same parameters
   (the model's and the run's start temperatures): one local fit, nothing else. CPU seconds (user + system of this process), median of N; the parameters of both
   printed with their largest relative difference. Target: identify <= 1.2x the peer.
2. --scaling: identify on 8 h and 24 h runs (one each); target: 24 h within 1.1x of three times 8 h.
Exit code 1 if a target is missed (after printing everything).
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from bench_identify import simulated_run  # noqa: E402
from benchlab.identify.api import identify, with_initial_states  # noqa: E402
from benchlab.identify.data import prepare, scout_runs  # noqa: E402
from benchlab.identify.defaults import FIT_STEP_S  # noqa: E402
from benchlab.identify.fit import (_start, coordinate_bounds, fit, fit_multistart, from_coordinates,  # noqa: E402
                                   residual_vector, to_coordinates)
from benchlab.model.catalog import model_spec  # noqa: E402
from targets import print_target, summarise_targets  # noqa: E402

TARGET_VS_PEER = 1.2
TARGET_SCALING = 1.1


def cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def timed(fn, repeats: int):
    """(median CPU seconds, last result)."""
    spent, result = [], None
    for _ in range(repeats):
        start = cpu()
        result = fn()
        spent.append(cpu() - start)
    return float(np.median(spent)), result


def peer(spec, datasets) -> dict[str, float]:
    """Plain least_squares from the priors: scipy's own Jacobian, no sets, no search."""
    lo, hi = coordinate_bounds(spec)
    x0 = np.clip(to_coordinates(spec, {p.name: p.initial for p in spec.free}), lo + 1e-9, hi - 1e-9)
    sol = least_squares(lambda x: residual_vector(spec.network, from_coordinates(spec, x), datasets), x0,
                        bounds=(lo, hi), method="trf", x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10)
    return from_coordinates(spec, sol.x)


def every_start(spec, datasets, starts: int = 6):
    """The search before issue 36: every start scouted (25 evaluations), the best polished."""
    rng = np.random.default_rng(0)
    scouts = [fit(spec, datasets, max_nfev=25, start=_start(spec, i, rng, 3.0)) for i in range(starts)]
    best = min(scouts, key=lambda r: r.cost)
    return fit(spec, datasets, start={k: best.params[k] for k in best.free_names})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--scaling", action="store_true", help="also identify on 8 h and 24 h runs")
    args = ap.parse_args(argv)
    started = time.perf_counter()
    targets = []
    print(f"bench_identify_search: seed {args.seed}, load avg {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    run = simulated_run(args.seed, 7200.0)
    identify([run.iloc[:20_000].copy()], "nonlinear")  # warm-up: numba's cache loads and compiles excluded
    spec = model_spec("nonlinear")
    datasets = [prepare(run, FIT_STEP_S, network=spec.network)]

    ours_s, ours = timed(lambda: identify([run], "nonlinear"), args.repeats)
    peer_s, theirs = timed(lambda: peer(with_initial_states(spec, datasets), datasets), args.repeats)
    search_s, search = timed(lambda: fit_multistart(spec, datasets), args.repeats)
    before_s, before = timed(lambda: every_start(spec, datasets), args.repeats)
    full = with_initial_states(spec, datasets)
    scouts = [scout_runs(data) for data in datasets]
    as_identify_s, as_identify = timed(lambda: fit_multistart(spec, datasets, scout_data=scouts, polish=full),
                                       args.repeats)
    two_fits_s, two_fits = timed(lambda: fit(full, datasets, start=fit_multistart(spec, datasets).params),
                                 args.repeats)
    names = [p.name for p in spec.free]
    gap = max(abs(ours.params[n] - theirs[n]) / abs(theirs[n]) for n in names)
    search_gap = max(abs(search.params[n] - before.params[n]) / abs(before.params[n]) for n in names)
    print(f"\n1. 2 h Table 1 run ({len(run):,} samples at 10 ms), CPU seconds, median of {args.repeats}")
    print(f"   {'identify (end to end)':<44}{ours_s:>8.2f} s   {ours.fit.starts} starts")
    print(f"   {'peer: plain least_squares, same data':<44}{peer_s:>8.2f} s")
    print(f"   {'search alone: stops when two starts agree':<44}{search_s:>8.2f} s   {search.starts} starts, "
          f"cost {search.cost:.6f}")
    print(f"   {'search before: every start scouted':<44}{before_s:>8.2f} s   6 starts, cost {before.cost:.6f}")
    print(f"   {'search as identify: scout runs, one polish':<44}{as_identify_s:>8.2f} s   {as_identify.starts} starts, "
          f"cost {as_identify.cost:.6f}")
    print(f"   {'before: search on the run, then start states':<44}{two_fits_s:>8.2f} s   cost {two_fits.cost:.6f}")
    print(f"   {'parameter':<10}{'identify':>14}{'peer':>14}")
    for n in names:
        print(f"   {n:<10}{ours.params[n]:>14.6g}{theirs[n]:>14.6g}")
    print(f"   largest relative difference identify - peer {gap:.1e}; search - search before {search_gap:.1e}")
    ratio = ours_s / peer_s
    targets.append(("identify / peer", f"{ratio:.2f}x <= {TARGET_VS_PEER}x", ratio <= TARGET_VS_PEER))
    print_target("identify / peer", f"{ratio:.2f}x <= {TARGET_VS_PEER}x", ratio <= TARGET_VS_PEER)
    print(f"   search / search before: {search_s / before_s:.2f}x; as identify / before: "
          f"{as_identify_s / two_fits_s:.2f}x, parameters within "
          f"{max(abs(as_identify.params[n] - two_fits.params[n]) / abs(two_fits.params[n]) for n in names):.1e}")

    if args.scaling:
        spent = {}
        for hours in (8, 24):
            long_run = simulated_run(args.seed, 3600.0 * hours)
            spent[hours], _ = timed(lambda: identify([long_run], "nonlinear"), 1)
            print(f"   identify, {hours:>2} h run: {spent[hours]:.1f} s CPU")
            del long_run
        scaling = spent[24] / (3 * spent[8])
        targets.append(("24 h / (3 x 8 h)", f"{scaling:.2f}x <= {TARGET_SCALING}x", scaling <= TARGET_SCALING))
        print_target("24 h / (3 x 8 h)", f"{scaling:.2f}x <= {TARGET_SCALING}x", scaling <= TARGET_SCALING)
    return summarise_targets(targets, started)


if __name__ == "__main__":
    sys.exit(main())
