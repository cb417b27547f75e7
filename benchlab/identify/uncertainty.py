"""Standard errors, correlations and identifiability warnings that hold on bench data.

An output-error fit treats the measured inputs as exact and the residuals as white noise; on a bench
neither holds, and the plain (JᵀJ)⁻¹s² was 3–100× too small against the true error (benchmarks/README.md):

- the friction power is measured torque times measured slip speed; its noise is small per sample but
  the thermal masses integrate it into a slow temperature error, which the fit absorbs into the slow
  parameters (C_T, R_Feng, R_AT, R_Tamb) and which therefore barely shows in the residuals: no
  residual-based estimator (HAC, residual bootstrap) can see it;
- residuals are autocorrelated (held sensor readings, model error).

So the covariance is the sandwich A⁻¹ (S_res + S_in) A⁻¹ with A = JᵀJ, where S_res is the Newey–West
(Bartlett) long-run covariance of the per-step scores Jₜᵀrₜ of each run, VAR(1)-prewhitened (Andrews &
Monahan 1992), bandwidth by Andrews' AR(1) rule on the whitened scores, and S_in the covariance of the score Jᵀe that the input noise e causes: the friction power's level at
each fitting step estimated from the run's own full-rate record (`power_noise`), the boundary temperatures'
(T_ambient, T_engine) from their step means (`temperature_input_noise`), pushed through the fitted network by
Monte Carlo (the temperatures respond linearly to these inputs, so this is exact up to sampling). The parameter
file names the method (`METHOD`, its key "uncertainty_method"); benchmarks/coverage_study.py measures its coverage. A is inverted with its columns scaled to unit norm: in physical units its entries span
sixteen decades and a plain pseudo-inverse truncates the weakest direction (C_T's error came out up
to 14× too small). Initial states are fitted per run (api.py) rather than taken from one noisy reading, which
otherwise biases the slow parameters far beyond any error bar.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from benchlab.identify.adjoint import ScoreResponse
from benchlab.identify.data import FitData
from benchlab.identify.fit import FitResult, residual_index, simulate_outputs
from benchlab.identify.identifiability import not_identified, not_identified_lines, starts_at_the_minimum
from benchlab.identify.metrics import MAD_TO_SIGMA, robust_sigma

CORRELATION_LIMIT = 0.95
RELATIVE_SE_LIMIT = 0.5
INPUT_NOISE_DRAWS = 200
DRAWS_TOGETHER = 16  # input-noise draws scored in one matrix product (their input changes held at once)
PREWHITEN_CAP = 0.97  # largest singular value of the prewhitening VAR(1) (Andrews & Monahan 1992)
PREWHITEN_MIN_STEPS = 10  # fitting steps per score column a run needs for the prewhitening VAR(1)
MIN_NOISE_SAMPLES = 8  # slipping samples a fitting step needs for its own noise estimate (else the run's)
POWER_NOISE_STEPS = 4096  # fitting steps `power_noise` reads at a time
#: How the parameter file's standard errors were made (its "uncertainty_method"): named methods, not inflation.
METHOD = {"name": "HAC sandwich (prewhitened Newey-West) with Monte Carlo input noise",
          "covariance": "sandwich A^-1 (S_res + S_in) A^-1, A = J^T J with columns scaled to unit norm",
          "residuals": "Newey-West (Bartlett kernel) long-run covariance of the per-step scores J_t^T r_t per run, "
                       "VAR(1)-prewhitened and recoloured (Andrews & Monahan 1992; singular values capped at 0.97)",
          "bandwidth": "Andrews (1991) AR(1) plug-in rule on the prewhitened scores, per run, in fitting steps "
                       "(uncertainty_bandwidths)",
          "input_noise": "noise of the friction power (full-rate record) and of the boundary temperatures (step "
                         "means' differences) per fitting step, pushed through the fitted network by Monte Carlo",
          "interval": "estimate +- 1.96 standard errors: 95 %, normal"}


@dataclass(frozen=True)
class Uncertainty:
    """Standard errors (physical units), correlation matrix, the error sources' shares, and warnings."""

    names: list[str]
    standard_errors: dict[str, float]
    correlation: np.ndarray
    sources: dict[str, dict[str, float]]  # "residuals" / "input_noise": the standard error each alone gives
    bandwidths: list[int]  # Newey–West bandwidth per run, in fitting steps
    warnings: list[str]
    not_identified: dict[str, str] = field(default_factory=dict)  # parameter -> why and what would identify it


def power_noise(run: pd.DataFrame, block: int, steps: int) -> np.ndarray:
    """Standard deviation (W) of the noise in each fitting step's mean friction power, from the full-rate record.

    While slipping, the measured power is smooth (torque held, slip ramping), so second differences of three
    slipping samples are noise of variance 6σ² (σ from their median, robust to engagement edges); samples are
    taken as independent, so a step's mean over n slipping samples of `block` carries √n·σ/block. The record is
    read POWER_NOISE_STEPS fitting steps at a time: no run-sized temporaries (on a 24 h run they cost more system
    time in fresh pages than the arithmetic).
    """
    if "friction_power" not in run.columns:  # a model without the clutch's heat input: no such noise
        return np.zeros(steps)
    power = run["friction_power"].to_numpy(np.float64)
    samples = steps * block
    medians, slipping, finite = np.empty(steps), np.empty(steps), []
    for first in range(0, steps, POWER_NOISE_STEPS):
        last = min(first + POWER_NOISE_STEPS, steps)
        lo, hi = first * block, last * block
        p = np.zeros(hi - lo + 2)  # samples lo - 1 .. hi; none beyond the record (0: not slipping)
        a, b = max(lo - 1, 0), min(hi + 1, samples)
        p[a - lo + 1: b - lo + 1] = np.nan_to_num(power[a:b])
        slips = p != 0
        usable = slips[2:] & slips[1:-1] & slips[:-2]
        per_step = np.where(usable, np.abs(p[2:] - 2 * p[1:-1] + p[:-2]), np.nan).reshape(last - first, block)
        finite.append(per_step[np.isfinite(per_step)])
        enough = np.sum(np.isfinite(per_step), axis=1) >= MIN_NOISE_SAMPLES
        medians[first:last] = np.nan
        if np.any(enough):
            medians[first:last][enough] = np.nanmedian(per_step[enough], axis=1)
        slipping[first:last] = slips[1:-1].reshape(last - first, block).sum(axis=1)
    finite = np.concatenate(finite) if finite else np.zeros(0)
    medians[np.isnan(medians)] = float(np.median(finite)) if finite.size else 0.0
    sigma = MAD_TO_SIGMA * medians / np.sqrt(6.0)
    return np.sqrt(slipping) * sigma / block


def run_scores(result: FitResult, datasets: Sequence[FitData]) -> list[np.ndarray]:
    """Per run, the score Jₜᵀrₜ of each fitting step (channels of the same step summed): steps × parameters."""
    out, offset = [], 0
    for data, index in zip(datasets, residual_index(datasets)):
        rows = slice(offset, offset + len(index))
        scores = np.zeros((len(data), result.jacobian.shape[1]))
        np.add.at(scores, index, result.jacobian[rows] * result.residuals[rows, None])
        out.append(scores)
        offset += len(index)
    return out


def bartlett_bandwidth(scores: np.ndarray) -> int:
    """Andrews' (1991) AR(1) plug-in bandwidth of the Bartlett kernel for a score series."""
    num = den = 0.0
    for column in scores.T:
        x = column - column.mean()
        lagged = float(np.dot(x[:-1], x[:-1]))
        if lagged <= 0:
            continue
        rho = min(max(float(np.dot(x[1:], x[:-1])) / lagged, -0.97), 0.97)
        s4 = float(np.mean((x[1:] - rho * x[:-1]) ** 2)) ** 2
        num += 4 * rho ** 2 * s4 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += s4 / (1 - rho) ** 4
    if den <= 0:
        return 1
    return int(min(max(1, np.ceil(1.1447 * (num / den * len(scores)) ** (1 / 3))), max(1, len(scores) // 4)))


def long_run_covariance(scores: np.ndarray, bandwidth: int) -> np.ndarray:
    """Newey–West covariance of the score sum: lag covariances with Bartlett weights 1 − l/bandwidth.

    Computed as the sum of the outer products of window sums over `bandwidth` steps (the series padded with
    zeros, so each pair of steps l apart shares bandwidth − l windows, exactly the Bartlett weight): one pass
    whatever the bandwidth.
    """
    pad = np.zeros((bandwidth - 1, scores.shape[1]))
    cumulative = np.cumsum(np.vstack([np.zeros((1, scores.shape[1])), pad, scores, pad]), axis=0)
    windows = cumulative[bandwidth:] - cumulative[:-bandwidth]
    return windows.T @ windows / bandwidth


def prewhitened_long_run_covariance(scores: np.ndarray) -> tuple[np.ndarray, int]:
    """Long-run covariance of a run's score sum, VAR(1)-prewhitened (Andrews & Monahan 1992), and its bandwidth.

    A small Bartlett bandwidth underweights strong short-lag correlation (the scanner's readings held over two
    fitting steps: lag-1 correlation 0.6 on the drivers' runs), and the standard errors come out too small. So a
    VAR(1) s_t = A s_(t-1) + u_t is fitted first (columns scaled to unit spread, A's singular values capped at
    PREWHITEN_CAP so that I - A stays invertible), the Newey-West covariance is taken of the whitened u_t with
    Andrews' bandwidth for u_t, and recoloured: (I - A)^-1 S_u (I - A)^-T. A run with fewer than
    PREWHITEN_MIN_STEPS steps per parameter is not prewhitened (A is not estimable)."""
    steps, p = scores.shape
    if steps < PREWHITEN_MIN_STEPS * p:
        bandwidth = bartlett_bandwidth(scores)
        return long_run_covariance(scores, bandwidth), bandwidth
    spread = scores.std(axis=0)
    spread[spread == 0] = 1.0
    scaled = scores / spread
    transition = np.linalg.lstsq(scaled[:-1], scaled[1:], rcond=None)[0].T
    left, singular, right = np.linalg.svd(transition)
    transition = left @ np.diag(np.minimum(singular, PREWHITEN_CAP)) @ right
    whitened = scaled[1:] - scaled[:-1] @ transition.T
    bandwidth = bartlett_bandwidth(whitened)
    recolour = np.linalg.inv(np.eye(p) - transition)
    covariance = recolour @ long_run_covariance(whitened, bandwidth) @ recolour.T
    return covariance * np.outer(spread, spread), bandwidth


def temperature_input_noise(data: FitData) -> dict[str, np.ndarray]:
    """Noise (K) per fitting step of each measured temperature the model reads but does not fit (boundaries such
    as T_ambient, T_engine): from the step means' first differences (robust), the temperature being slow."""
    out = {}
    for channel, values in data.channels.items():
        d = np.diff(values)
        d = d[np.isfinite(d)]
        if data.units.get(channel) == "degC" and channel not in data.targets and d.size:
            sigma = robust_sigma(d) / np.sqrt(2.0)
            out[channel] = np.full(len(values), sigma)
    return out


def input_noise_covariance(result: FitResult, datasets: Sequence[FitData], noise: Sequence[Mapping[str, np.ndarray]],
                           draws: int = INPUT_NOISE_DRAWS, seed: int = 0) -> np.ndarray:
    """Covariance of the score Jᵀe caused by input noise of the given level per step and channel (Monte Carlo; each
    draw's scores by the adjoint gains of benchlab.identify.adjoint, one backward pass per parameter instead of one
    simulation per draw, where the noisy channels move no operating point)."""
    rng = np.random.default_rng(seed)
    p = result.jacobian.shape[1]
    cov, offset = np.zeros((p, p)), 0
    network, params = result.spec.network, result.params
    for data, sigmas, index in zip(datasets, noise, residual_index(datasets)):
        jac = result.jacobian[offset: offset + len(index)]
        offset += len(index)
        sigmas = {c: sigma for c, sigma in sigmas.items() if c in data.channels and np.any(sigma > 0)}
        if not sigmas:
            continue
        use = [data.mask & np.isfinite(target) for target in data.targets.values()]
        response = ScoreResponse(network, params, data, jac)
        base = None
        for first in range(0, draws, DRAWS_TOGETHER):
            noisy = []
            for _ in range(first, min(first + DRAWS_TOGETHER, draws)):
                channels = dict(data.channels)
                for c, sigma in sigmas.items():
                    channels[c] = channels[c] + sigma * rng.standard_normal(len(sigma))
                noisy.append(channels)
            for channels, score in zip(noisy, response.scores(noisy)):
                if score is None:  # the noise moves an operating point: simulated (benchlab.identify.adjoint)
                    base = simulate_outputs(network, params, data) if base is None else base
                    sim = simulate_outputs(network, params, replace(data, channels=channels))
                    score = jac.T @ np.concatenate([sim[c][u] - base[c][u] for c, u in zip(data.targets, use)])
                cov += np.outer(score, score) / draws
    return cov


def scaled_inverse(matrix: np.ndarray) -> np.ndarray:
    """Pseudo-inverse after scaling to unit diagonal, so that parameters of any unit keep their weak directions."""
    d = np.sqrt(np.clip(np.diag(matrix), 0, None))
    d[d == 0] = 1.0
    return np.linalg.pinv(matrix / np.outer(d, d)) / np.outer(d, d)


def _errors(inverse: np.ndarray, middle: np.ndarray) -> np.ndarray:
    return np.sqrt(np.clip(np.diag(inverse @ middle @ inverse), 0, None))


def identifiability_warnings(names: Sequence[str], values: Sequence[float], errors: Sequence[float],
                             correlation: np.ndarray, effect: Sequence[float],
                             reasons: Mapping[str, str] | None = None) -> list[str]:
    """What the data cannot tell, the parameters they do not identify first (`reasons`, benchlab.identify.
    identifiability): then each cluster of parameters the data cannot tell apart (connected by |corr| > 0.95; pairs
    with a zero or non-finite standard error have no correlation), poorly excited parameters and parameters without
    effect (those not identified are said once, in their own line)."""
    reasons = dict(reasons or {})
    warnings = not_identified_lines(reasons)
    usable = [i for i, error in enumerate(errors) if np.isfinite(error) and error > 0]
    warnings += [_cluster_line(cluster, names, correlation) for cluster in _clusters(usable, correlation)]
    largest = max(effect, default=0.0)
    for name, value, error, size in zip(names, values, errors, effect):
        if name in reasons:
            continue
        if value != 0 and error / abs(value) > RELATIVE_SE_LIMIT:
            warnings.append(f"{name} is poorly excited by the data (standard error {100 * error / abs(value):.0f} %)")
        elif size < 1e-6 * largest:
            warnings.append(f"{name} has no visible effect on the measured channels")
    return warnings


def _clusters(usable: Sequence[int], correlation: np.ndarray) -> list[list[int]]:
    """The groups of parameters (indices among `usable`) connected by pairs with |corr| > CORRELATION_LIMIT, each of
    two or more, in the order of their first parameter."""
    group = {i: i for i in usable}

    def root(i: int) -> int:
        while group[i] != i:
            i = group[i]
        return i
    for a, i in enumerate(usable):
        for j in usable[a + 1:]:
            if abs(correlation[i, j]) > CORRELATION_LIMIT:
                group[root(j)] = root(i)
    members: dict[int, list[int]] = {}
    for i in usable:
        members.setdefault(root(i), []).append(i)
    return [m for m in members.values() if len(m) > 1]


def _cluster_line(cluster: Sequence[int], names: Sequence[str], correlation: np.ndarray) -> str:
    """One cluster of parameters the data cannot tell apart: its members, how many of their pairs correlate beyond
    the limit and the strongest pair."""
    pairs = [(correlation[i, j], i, j) for a, i in enumerate(cluster) for j in cluster[a + 1:]
             if abs(correlation[i, j]) > CORRELATION_LIMIT]
    strongest, i, j = max(pairs, key=lambda pair: abs(pair[0]))
    listed = ", ".join(names[k] for k in cluster[:-1]) + f" and {names[cluster[-1]]}"
    if len(cluster) == 2:
        return f"{listed} are hard to tell apart (correlation {strongest:+.3f})"
    return (f"{listed} are hard to tell apart ({len(pairs)} of their {len(cluster) * (len(cluster) - 1) // 2} pairs "
            f"correlate beyond ±{CORRELATION_LIMIT:g}; strongest {names[i]} and {names[j]}, {strongest:+.3f})")


def estimate_uncertainty(result: FitResult, datasets: Sequence[FitData], noise: Sequence[Mapping[str, np.ndarray]],
                         model_names: Sequence[str] | None = None) -> Uncertainty:
    """Sandwich covariance (autocorrelated residuals + input noise); warn about what the data cannot tell.

    `noise`: per run, each noisy input's noise per fitting step (`power_noise`, `temperature_input_noise`). `model_names`: the free
    parameters the warnings speak of (default all; initial states are better left out).
    """
    J = result.jacobian
    n, p = J.shape
    inverse = scaled_inverse(J.T @ J)
    per_run = [prewhitened_long_run_covariance(s) for s in run_scores(result, datasets)]
    bandwidths = [bandwidth for _, bandwidth in per_run]
    residual_part = sum(covariance for covariance, _ in per_run) * n / max(n - p, 1)
    input_part = input_noise_covariance(result, datasets, noise)
    cov = inverse @ (residual_part + input_part) @ inverse
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    names = result.free_names
    sources = {"residuals": dict(zip(names, map(float, _errors(inverse, residual_part)))),
               "input_noise": dict(zip(names, map(float, _errors(inverse, input_part))))}
    keep = [i for i, name in enumerate(names) if model_names is None or name in model_names]
    values = [result.params[names[i]] for i in keep]
    effect = np.sqrt(np.diag(J.T @ J))[keep] * np.abs(values)
    kept = [result.spec.free[i] for i in keep]
    reasons = not_identified(kept, result.params, dict(zip(names, map(float, se))),
                             starts_at_the_minimum(result), result.spec.definition)
    warnings = identifiability_warnings([names[i] for i in keep], values, se[keep], corr[np.ix_(keep, keep)],
                                        effect, reasons)
    network = result.spec.network
    measured_states = {network.outputs[c] for c in network.measured if c in network.outputs}
    measured_nodes = measured_states | {lag.node for lag in network.lags if lag.name in measured_states}
    seen_through = ", ".join(network.measured)
    for node in network.nodes:
        if node.name not in measured_nodes and node.capacity in names and node.capacity not in reasons:
            i = names.index(node.capacity)
            warnings.append(f"{node.capacity} is seen only through the measured temperatures ({seen_through}; node "
                            f"{node.name} is not measured): its standard error is "
                            f"{100 * se[i] / result.params[node.capacity]:.1f} % and its temperature is an "
                            f"estimate, not a measurement")
    return Uncertainty(names, dict(zip(names, map(float, se))), corr, sources, bandwidths, warnings, reasons)


#: An eigenvalue of the unit-diagonal information matrix below this share of the largest is a direction the runs do
#: not see at all (float64 round-off is ~1e-16; a weakly seen direction is far above it and gets a large SE instead).
NULL_EIGENVALUE = 1e-12


def _in_null_directions(information: np.ndarray) -> np.ndarray:
    """Per parameter: whether it moves along a direction of zero information (collinear with others on these runs)."""
    d = np.sqrt(np.clip(np.diag(information), 0, None))
    d[d == 0] = 1.0
    values, vectors = np.linalg.eigh(information / np.outer(d, d))
    null = vectors[:, values <= NULL_EIGENVALUE * max(values.max(), 0.0)]
    return np.abs(null).max(axis=1, initial=0.0) > 1e-6


def identified_by_runs(result: FitResult, datasets: Sequence[FitData], labels: Sequence[str]) -> dict[str, list[str]]:
    """Which runs pin each model parameter of a fit to several runs: the labels of the runs that identify it alone
    (`not_identified` on the sandwich covariance from that run's rows of the Jacobian and its own scores), else
    ["together"] where only all of them do, else [] (the runs do not identify it). Tells which experiment carried
    which parameter (Table 1 the capacities, the sweep eq. (11), say)."""
    J, names = result.jacobian, result.free_names
    offsets = np.cumsum([0, *(len(index) for index in residual_index(datasets))])
    middles = [prewhitened_long_run_covariance(s)[0] for s in run_scores(result, datasets)]
    specs = [s for s in result.spec.free if "@" not in s.name]

    def errors(runs: Sequence[int]) -> dict[str, float]:
        rows = np.concatenate([np.arange(offsets[r], offsets[r + 1]) for r in runs])
        information = J[rows].T @ J[rows]
        se = _errors(scaled_inverse(information), sum(middles[r] for r in runs))
        se[_in_null_directions(information)] = np.inf  # the pseudo-inverse would call a blind direction known
        return dict(zip(names, map(float, se)))

    alone = [not_identified(specs, result.params, errors([r])) for r in range(len(datasets))]
    together = not_identified(specs, result.params, errors(range(len(datasets))))
    out = {}
    for spec in specs:
        runs = [label for label, reasons in zip(labels, alone) if spec.name not in reasons]
        out[spec.name] = runs or ([] if spec.name in together else ["together"])
    return out

