"""Each model on each run: its simulation and error figures (contract section 5, by benchlab.identify.metrics)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd

from benchlab.identify.metrics import channel_nrmse_pct, channel_rmse_k, nrmse_pct, rmse_k
from benchlab.network import Params
from benchlab.network.simulation import model_network, simulate


@dataclass(frozen=True)
class Scores:
    """RMSE (K) and NRMSE (%) per predicted channel and over all of them, as contract section 5 defines."""

    rmse_k: float
    nrmse_pct: float
    channel_rmse_k: dict[str, float]
    channel_nrmse_pct: dict[str, float]


def score(measured: pd.DataFrame, simulated: pd.DataFrame, channels: Sequence[str]) -> Scores:
    """The contract's error figures of a simulation already made (the report simulates once per model and run)
    over the model's measured channels."""
    return Scores(rmse_k(measured, simulated, channels), nrmse_pct(measured, simulated, channels),
                  channel_rmse_k(measured, simulated, channels), channel_nrmse_pct(measured, simulated, channels))


@dataclass(frozen=True)
class Estimate:
    """One model's simulation of one run, with its error figures and the label the report shows it under."""

    label: str
    simulated: pd.DataFrame
    scores: Scores
    channels: tuple[str, ...]  # the measured channels scored


def estimate(run: pd.DataFrame, params: Params, label: str) -> Estimate:
    """Simulate `run` with `params` (benchlab.simulate, the parameters' own model) and score the result."""
    network = model_network(params)
    simulated = simulate(run, params, network)
    channels = tuple(c for c in network.measured if c in run.columns)
    return Estimate(label, simulated, score(run, simulated, channels), channels)
