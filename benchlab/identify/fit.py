"""Output-error fit of a ModelSpec to one or more runs: simulate, compare, adjust (scipy's trust-region reflective
least squares, benchlab.identify.trust_region).

Positive parameters are fitted as logarithms, signed ones scaled by their start value, so
every coordinate moves on a scale of one. The problem has local minima, so fits start from
several points spread around the neutral priors and the best is polished to convergence.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from benchlab._blas import single_threaded_blas
from benchlab.identify.data import FitData
from benchlab.identify.spec import ModelSpec
from benchlab.identify.trust_region import least_squares_trf
from benchlab.network import ThermalNetwork
from benchlab.progress import Task
from benchlab.network.sensors import reading
from benchlab.network.simulation import started_from
from benchlab.network.solver import run_network
from benchlab.network.sets import run_network_sets

KEY_RESOLUTION = 1e-12  # operating points are already exact repeats after prepare(); keep them apart exactly


@dataclass
class FitResult:
    """Fitted values, their uncertainty, and the residuals on the fitting data."""

    spec: ModelSpec
    params: dict[str, float]
    cost: float
    rmse_k: float
    n_residuals: int
    jacobian: np.ndarray  # d residual / d parameter (physical units), fitting samples only
    residuals: np.ndarray
    starts: int = 1
    start_costs: list[float] = field(default_factory=list)  # each start's latest cost on the runs themselves
    start_params: list[dict[str, float]] = field(default_factory=list)  # each start's parameters at that cost
    converged: bool = True  # False where the fit stopped at its evaluation budget (a scout), not at a minimum

    @property
    def free_names(self) -> list[str]:
        return [p.name for p in self.spec.free]


def to_coordinates(spec: ModelSpec, values: Mapping[str, float]) -> np.ndarray:
    """The fitted coordinates of parameter values: logarithms of positive ones, signed ones in steps of their scale."""
    return np.array([np.log(values[p.name]) if p.log else values[p.name] / p.linear_scale for p in spec.free])


def from_coordinates(spec: ModelSpec, x: np.ndarray) -> dict[str, float]:
    """Parameter values (the fixed ones included) from fitted coordinates."""
    out = dict(spec.fixed)
    for p, xi in zip(spec.free, x):
        out[p.name] = float(np.exp(xi)) if p.log else float(xi * p.linear_scale)
    return out


def coordinate_bounds(spec: ModelSpec) -> tuple[np.ndarray, np.ndarray]:
    """The free parameters' bounds in fitted coordinates."""
    lo = [np.log(p.lower) if p.log else p.lower / p.linear_scale for p in spec.free]
    hi = [np.log(p.upper) if p.log else p.upper / p.linear_scale for p in spec.free]
    return np.array(lo), np.array(hi)


def initial_state(network: ThermalNetwork, data: FitData, params: Mapping[str, float]) -> np.ndarray:
    """States start at the first valid measurement of their channel, or at its fitted value for this run
    (`init_<channel>@<run name>`), as the temperature that reading stands for where the channel's sensor is
    calibrated; an `init_<state>` parameter overrides either."""
    def first(channel: str) -> float:
        return started_from(network, params, channel, params.get(f"init_{channel}@{data.name}",
                                                                data.first_valid[channel]))
    return np.array([params.get(f"init_{s}", first(network.initial[s])) for s in network.state_names])


def run_values(params: Mapping[str, float], data: FitData) -> Mapping[str, float]:
    """The parameter values one run is simulated with: a parameter fitted per run group (`X@<group>`) overrides X for
    the runs of that group (`FitData.group_label`); every other parameter is shared by all runs."""
    suffix = f"@{data.group_label}"
    own = {name[:-len(suffix)]: value for name, value in params.items()
           if name.endswith(suffix) and not name.startswith("init_")}
    return {**params, **own} if own else params


def simulate_outputs(network: ThermalNetwork, params: Mapping[str, float], data: FitData,
                     channels: Iterable[str] | None = None) -> dict[str, np.ndarray]:
    """Model outputs at the fitting step for the measured channels of `data` (or for `channels`, outputs of the
    model, measured or not)."""
    states = _states(network, params, data)[:-1]
    index = {s: i for i, s in enumerate(network.state_names)}
    seconds = np.arange(len(states)) * data.dt
    values = run_values(params, data)
    return {c: reading(network.calibrations.get(c), values, states[:, index[network.outputs[c]]], seconds)
            for c in (data.targets if channels is None else channels)}


def read_fitted(network: ThermalNetwork, params: Mapping[str, float], data: FitData,
                predicted: np.ndarray) -> np.ndarray:
    """The fitted samples' states (`fitted_flat`'s order) as their sensors read them: each calibrated channel's part
    through its calibration (benchlab.network.sensors), in place."""
    if not network.calibrations:
        return predicted
    values, start = run_values(params, data), 0
    for channel, (index, _) in data.fitted.items():
        stop = start + len(index)
        calibration = network.calibrations.get(channel)
        if calibration is not None:
            predicted[start:stop] = reading(calibration, values, predicted[start:stop], index * data.dt)
        start = stop
    return predicted


def reading_gains(network: ThermalNetwork, params: Mapping[str, float], data: FitData) -> np.ndarray | None:
    """d reading / d state of each fitted sample (`fitted_flat`'s order): its sensor's gain; None where all are 1."""
    if not any(c.gain for c in network.calibrations.values()):
        return None
    values = run_values(params, data)
    return np.concatenate([np.full(len(index), network.calibrations[c].values(values)[0]
                                   if c in network.calibrations else 1.0)
                           for c, (index, _) in data.fitted.items()])


def _states(network: ThermalNetwork, params: Mapping[str, float], data: FitData) -> np.ndarray:
    """The network's states ((samples + 1) × states, the last after the last step) at the fitting step of `data`."""
    values = run_values(params, data)
    return run_network(network, values, data.channels, data.dt, initial_state(network, data, values),
                       KEY_RESOLUTION, data.memo)


def residual_vector(network: ThermalNetwork, params: Mapping[str, float], datasets: Sequence[FitData]) -> np.ndarray:
    """Simulated minus measured, every fitted channel of every run, valid masked samples only."""
    parts = []
    for data in datasets:
        flat, targets = data.fitted_flat(network.state_names, network.outputs)
        parts.append(read_fitted(network, params, data, _state_major(_states(network, params, data)).take(flat))
                     - targets)
    return np.concatenate(parts)


def residual_vectors(network: ThermalNetwork, base: Mapping[str, float], param_sets: Sequence[Mapping[str, float]],
                     datasets: Sequence[FitData], base_residuals: np.ndarray | None = None) -> list[np.ndarray]:
    """`residual_vector` of each parameter set, bit for bit, computed together: the sets of a forward-difference
    Jacobian, each near `base` (benchlab.network.sets). `base_residuals`: `residual_vector` of `base`, where the
    caller has it; a run that a set leaves as the base has it (another run's start temperature moved) then takes
    its part instead of a simulation."""
    parts: list[list[np.ndarray]] = [[] for _ in param_sets]
    offset = 0
    for data in datasets if param_sets else ():
        base_values = run_values(base, data)
        own_sets = [run_values(params, data) for params in param_sets]
        x0s = np.array([initial_state(network, data, params) for params in own_sets])
        # a calibrated output's drift moves its reading, not its state: such a network keeps simulating every set
        reuse = base_residuals is not None and not network.calibrations
        base_x0 = initial_state(network, data, base_values) if reuse else None
        runs = run_network_sets(network, base_values, own_sets, data.channels, data.dt, x0s, KEY_RESOLUTION,
                                data.memo, base_x0)
        flat, targets = data.fitted_flat(network.state_names, network.outputs)
        for part, states, params in zip(parts, runs, param_sets):
            part.append(base_residuals[offset:offset + len(flat)] if states is None else
                        read_fitted(network, params, data, _state_major(states).take(flat)) - targets)
        offset += len(flat)
    return [np.concatenate(part) for part in parts]


def _state_major(states: np.ndarray) -> np.ndarray:
    """The solver's states (N + 1, n), a transposed view of its state-major array, raveled state after state:
    a view, not a copy of the whole run for every residual."""
    return np.ascontiguousarray(states.T).ravel()


def residual_index(datasets: Sequence[FitData]) -> list[np.ndarray]:
    """Per run, the fitting-step sample of each entry of that run's part of `residual_vector` (same order)."""
    return [np.concatenate([index for index, _ in data.fitted.values()]) for data in datasets]


@single_threaded_blas
def fit(spec: ModelSpec, datasets: Sequence[FitData], max_nfev: int | None = None,
        start: Mapping[str, float] | None = None,
        stop: Callable[[Mapping[str, float]], bool] | None = None, tolerance: float = 1e-10,
        stall: tuple[int, float] | None = None) -> FitResult:
    """One local fit from the spec's starting values (or `start`); `stop`: asked after each iteration with the
    parameters reached, True ends the fit there (not converged); `tolerance`: scipy's xtol, ftol and gtol; `stall`
    = (k, share): the fit also ends where its last k steps lowered the cost by less than that share
    (benchlab.identify.trust_region)."""
    x0 = to_coordinates(spec, {p.name: p.initial for p in spec.free} | dict(start or {}))
    lo, hi = coordinate_bounds(spec)
    x0 = np.clip(x0, lo + 1e-9, hi - 1e-9)

    last: list[np.ndarray] = [x0, np.zeros(0)]  # the point the fit evaluated last and its residuals: where it then
    # takes the Jacobian

    def fun(x: np.ndarray) -> np.ndarray:
        residuals = residual_vector(spec.network, from_coordinates(spec, x), datasets)
        last[:] = x.copy(), residuals
        return residuals

    def columns(_fun: object, points: Iterable[np.ndarray]) -> list[np.ndarray]:
        """scipy's forward differences (its steps, its quotients), their residuals computed together."""
        return residual_vectors(spec.network, from_coordinates(spec, last[0]),
                                [from_coordinates(spec, x) for x in points], datasets, last[1])

    sol = least_squares_trf(fun, x0, (lo, hi), columns, max_nfev=max_nfev, xtol=tolerance, ftol=tolerance,
                            gtol=tolerance, stall=stall,
                            stop=None if stop is None else lambda x: stop(from_coordinates(spec, x)))
    params = from_coordinates(spec, sol.x)
    scale = np.array([params[p.name] if p.log else p.linear_scale for p in spec.free])
    jac = sol.jac / scale  # chain rule: d r / d p = d r / d x * d x / d p
    return FitResult(spec, params, float(2 * sol.cost), float(np.sqrt(np.mean(sol.fun ** 2))), len(sol.fun),
                     jac, sol.fun, converged=sol.status > 0)


def standard_errors(result: FitResult) -> np.ndarray:
    """Each free parameter's standard error (physical units) from the fit's Jacobian and residual variance:
    sqrt(diag(s² (JᵀJ)⁻¹)), s² = cost / (residuals - parameters)."""
    from benchlab.identify.uncertainty import scaled_inverse  # (uncertainty builds on this module)

    dof = max(result.n_residuals - len(result.free_names), 1)
    return np.sqrt(np.abs(np.diag(scaled_inverse(result.jacobian.T @ result.jacobian))) * result.cost / dof)


def same_minimum(a: FitResult, b: FitResult) -> bool:
    """Whether two fits reached one minimum: every free parameter apart by less than the better fit's standard
    error (its statistical resolution: closer than that, the data cannot tell the two apart)."""
    better = a if a.cost <= b.cost else b
    return within_errors(better, b.params if better is a else a.params)


def within_errors(result: FitResult, params: Mapping[str, float], errors: np.ndarray | None = None) -> bool:
    """Whether every free parameter of `result` is within its standard error (`errors`, where already computed)
    of `params`."""
    errors = standard_errors(result) if errors is None else errors
    gaps = np.array([abs(result.params[name] - params[name]) for name in result.free_names])
    return bool(np.all(np.isfinite(errors)) and np.all(gaps <= errors))


def arrived(best: FitResult) -> Callable[[Mapping[str, float]], bool] | None:
    """A scout's `stop` once `best` has converged: the scout has arrived where its parameters are within the
    standard errors of best's, the agreement `same_minimum` asks for; None while best is still moving."""
    if not best.converged:
        return None
    errors = standard_errors(best)
    return lambda params: within_errors(best, params, errors)


def _start(spec: ModelSpec, i: int, rng: np.random.Generator, spread: float) -> dict[str, float]:
    """Start i: the priors (i = 0), else magnitudes drawn log-uniform within ×/÷ spread of them."""
    start = {p.name: p.initial for p in spec.free}
    if i:
        for p in (p for p in spec.free if p.log or not p.scale):  # magnitudes; offsets (°C starts) stay
            factor = float(np.exp(rng.uniform(-np.log(spread), np.log(spread))))
            start[p.name] = float(np.clip(p.initial * factor, p.lower, p.upper))
    return start


@single_threaded_blas
def fit_multistart(spec: ModelSpec, datasets: Sequence[FitData], starts: int = 6, seed: int = 0,
                   spread: float = 3.0, scout_nfev: int = 25, task: Task = Task(),
                   scout_data: Sequence[FitData] | None = None, polish: ModelSpec | None = None) -> FitResult:
    """Search from independent starts (the priors, then log-uniform within ×/÷ spread) until two agree on the best
    minimum, then polish it; at most `starts` scout runs of `scout_nfev` evaluations each.

    `scout_data`: the runs the scouts fit, where not `datasets` (identify's: coarser and thinned, `scout_runs`):
    agreement is then judged by that data's standard errors, and the polish fits `datasets` from the best scout.
    `polish`: the spec the best start is polished in (default `spec`; identify adds each run's start states, fitted
    once, in the polish, instead of a second fit after it).

    Two starts agree when they reach one minimum within its parameters' standard errors (`same_minimum`): a further
    start could only land there again or higher, so the search stops. While they disagree, the budget goes where
    they do: a scout stopped by its budget short of a minimum is continued (the start that has come lowest first),
    and only where every other start has settled in a different minimum is a new one drawn. Only magnitudes are
    spread (log parameters and signed ones scaled by their own start value); parameters with an absolute scale,
    such as start temperatures in °C, start at their prior. `task` advances by one per scout run (the unused
    budget at the end) and one for the polish; `starts` of the result counts the independent starts drawn, and
    `start_costs` and `start_params` hold where each ended (its cost on the runs, lowest first, and its parameters
    there: starts at one cost far apart show a flat direction, benchlab.identify.identifiability).
    """
    rng = np.random.default_rng(seed)
    scouted = datasets if scout_data is None else scout_data
    found: list[FitResult] = []  # each start's latest scout
    for run in range(starts):
        best = min(found, key=lambda r: r.cost) if found else None
        if best is not None and any(same_minimum(best, other) for other in found if other is not best):
            task.advance(starts - run)
            break
        unsettled = sorted((r for r in found if not r.converged and r is not best), key=lambda r: r.cost)
        if len(found) >= 2 and unsettled:
            k = next(k for k, r in enumerate(found) if r is unsettled[0])
            found[k] = fit(spec, scouted, max_nfev=scout_nfev, start={n: unsettled[0].params[n] for n in
                                                                       unsettled[0].free_names}, stop=arrived(best))
        elif len(found) >= 2 and not best.converged and all(r.converged for r in found if r is not best):
            found[found.index(best)] = fit(spec, scouted, max_nfev=scout_nfev,
                                           start={n: best.params[n] for n in best.free_names})
        else:
            found.append(fit(spec, scouted, max_nfev=scout_nfev, start=_start(spec, len(found), rng, spread),
                             stop=arrived(best) if best is not None else None))
        task.advance()
    best = min(found, key=lambda r: r.cost)
    final = fit(polish or spec, datasets, start={k: best.params[k] for k in best.free_names})
    task.advance()
    final.starts = len(found)
    ends = sorted(((r.cost if scouted is datasets else _cost(spec, r.params, datasets), r.params) for r in found),
                  key=lambda end: end[0])
    final.start_costs = [cost for cost, _ in ends]
    final.start_params = [{p.name: params[p.name] for p in spec.free} for _, params in ends]
    return final


def _cost(spec: ModelSpec, params: Mapping[str, float], datasets: Sequence[FitData]) -> float:
    """The sum of squared residuals of `params` on `datasets`: a scout's end on the runs themselves, comparable with
    the polished fit's cost."""
    residuals = residual_vector(spec.network, {**spec.fixed, **params}, datasets)
    return float(residuals @ residuals)
