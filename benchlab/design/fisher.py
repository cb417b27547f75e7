"""Fisher information of a model's parameters from runs, measured or predicted: the Jacobian of the measured
outputs (identification's residual vector, `benchlab.identify.fit.residual_vectors`) by forward differences,
each output weighted by its noise at the fitting step; the parameters of interest with the others as nuisance
(the Schur complement).

Parameters move relatively (the Jacobian's column is d output / d ln|θ|), so the information of a parameter
whose value is negative (b1, b2) reads like that of a positive one, and a standard error comes out as a share of
the value.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from benchlab.drivetrain import DrivetrainFacts
from benchlab.identify.data import FitData, prepare
from benchlab.identify.defaults import FIT_STEP_S
from benchlab.identify.fit import residual_vector, residual_vectors
from benchlab.identify.residuals import white_noise_variance
from benchlab.network import ThermalNetwork
from protocols.schedule import Step

#: Relative step of the forward differences: large against the solver's rounding, small against curvature.
RELATIVE_STEP = 1e-4
#: Grid the predicted run is played on (s): the fitting step's divisor.
PREDICTION_DT_S = 0.1
#: Added to the information's diagonal (per unit of ln θ squared) so that a parameter no run sees has a finite,
#: very large standard error instead of a singular matrix: a prior of ±1000 %.
RIDGE = 1e-2


def channel_noise(datasets: Sequence[FitData]) -> dict[str, float]:
    """Each measured channel's white noise at the fitting step (K, 1 sigma), pooled over the runs: from the first
    differences of the targets (`white_noise_variance`), which the slow temperatures hardly reach."""
    pooled: dict[str, list[float]] = {}
    for data in datasets:
        for channel, target in data.targets.items():
            pooled.setdefault(channel, []).append(white_noise_variance(target))
    return {c: float(np.sqrt(np.mean(v))) for c, v in pooled.items()}


def weights(data: FitData, noise: Mapping[str, float]) -> np.ndarray:
    """1/sigma for each entry of the run's residual vector (its channels in `FitData.fitted` order)."""
    return np.concatenate([np.full(len(index), 1.0 / noise[c]) for c, (index, _) in data.fitted.items()])


def jacobian(network: ThermalNetwork, params: Mapping[str, float], names: Sequence[str],
             data: FitData) -> np.ndarray:
    """d residual / d ln|θ| for each of `names` on one run (columns in `names` order)."""
    base = residual_vector(network, params, [data])
    moved = [{**params, name: params[name] * (1.0 + RELATIVE_STEP)} for name in names]
    columns = residual_vectors(network, params, moved, [data])
    return np.column_stack([(c - base) / np.log1p(RELATIVE_STEP) for c in columns])


def information(network: ThermalNetwork, params: Mapping[str, float], names: Sequence[str],
                datasets: Sequence[FitData], noise: Mapping[str, float]) -> np.ndarray:
    """Fisher information of ln|θ| for `names` from `datasets`, each output weighted by its noise."""
    total = np.zeros((len(names), len(names)))
    for data in datasets:
        weighted = jacobian(network, params, names, data) * weights(data, noise)[:, None]
        total += weighted.T @ weighted
    return total


def schur(info: np.ndarray, names: Sequence[str], interest: Sequence[str]) -> np.ndarray:
    """The information on `interest` with every other parameter a nuisance: F_ii − F_in F_nn⁻¹ F_ni."""
    i = [names.index(n) for n in interest]
    n = [k for k in range(len(names)) if k not in i]
    ridged = info + RIDGE * np.eye(len(names))
    if not n:
        return ridged[np.ix_(i, i)]
    return ridged[np.ix_(i, i)] - ridged[np.ix_(i, n)] @ np.linalg.solve(ridged[np.ix_(n, n)], ridged[np.ix_(n, i)])


def relative_errors(info: np.ndarray, names: Sequence[str], interest: Sequence[str]) -> dict[str, float]:
    """Standard error of each parameter of `interest` as a share of its value (the others nuisance)."""
    cov = np.linalg.inv(schur(info, names, interest))
    return {name: float(np.sqrt(max(cov[k, k], 0.0))) for k, name in enumerate(interest)}


def log_det(info: np.ndarray, names: Sequence[str], interest: Sequence[str]) -> float:
    """D-criterion: log det of the information on `interest` with the others as nuisance."""
    sign, value = np.linalg.slogdet(schur(info, names, interest))
    return float(value) if sign > 0 else -np.inf


def open_loop(steps: Sequence[Step], params, network: ThermalNetwork, ambient_c: float) -> tuple[Step, ...]:
    """`steps` as the model at `params` expects them to go from a bench at rest at `ambient_c`: each closed-loop
    step (a heat-up to a steady flywheel, a cool-down to a temperature) the open-loop steps it becomes
    (`protocols.estimates.played`, the runner's rules on the model); an open-loop schedule as it is."""
    if not any(s.until or s.phase == "heat" for s in steps):
        return tuple(steps)
    from benchlab.network.plant import NetworkPlant
    from protocols.estimates import played

    plant = NetworkPlant(network, params)
    plant.reset(ambient_c)
    return tuple(s for went in played(steps, plant, ambient_c=ambient_c) for s in went)


def predicted_run(steps: Sequence[Step], params, network: ThermalNetwork, ambient_c: float,
                  drivetrain: DrivetrainFacts, dt: float = PREDICTION_DT_S, name: str = "design") -> pd.DataFrame:
    """The run `steps` would give on a bench with this drivetrain and the model at `params`, noise-free: the
    drivetrain's channels (`sim_bench.drivetrain`, the bench's own dynamics; closed-loop steps as the model expects
    them to go, `open_loop`), the ambient held, every state starting at the ambient (a bench at rest), every
    temperature the model outputs (measured or not) the model's, as its sensor reads it (`network/sensors.py`)."""
    from benchlab.network.simulation import simulate
    from sim_bench.virtual_run import drive_schedule

    channels, _ = drive_schedule(open_loop(steps, params, network, ambient_c), dt, drivetrain)
    n = len(channels["engine_speed"])
    frame = pd.DataFrame({"time": np.arange(n) * dt, **channels, "T_ambient": np.full(n, ambient_c)})
    for channel in network.measured:
        frame[channel] = ambient_c
    frame.attrs.update(dt=dt, source=name)
    simulated = simulate(frame, params, network, initial={s: ambient_c for s in network.state_names})
    for channel in network.outputs:
        frame[channel] = simulated[channel].to_numpy()
    return frame


def predicted_data(steps: Sequence[Step], params, network: ThermalNetwork, ambient_c: float,
                   drivetrain: DrivetrainFacts, name: str = "design") -> FitData:
    """`predicted_run` at identification's fitting step, ready for `information`."""
    return prepare(predicted_run(steps, params, network, ambient_c, drivetrain, name=name), FIT_STEP_S, name=name,
                   network=network)
