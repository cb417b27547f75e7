"""Each model on each run: its simulation and error figures (contract section 5, by benchlab.metrics)."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from benchlab.metrics import channel_nrmse_pct, channel_rmse_k, nrmse_pct, rmse_k
from benchlab.network import Params
from benchlab.simulation import simulate


@dataclass(frozen=True)
class Scores:
    """RMSE (K) and NRMSE (%) per predicted channel and over all of them, as contract section 5 defines."""

    rmse_k: float
    nrmse_pct: float
    channel_rmse_k: dict[str, float]
    channel_nrmse_pct: dict[str, float]


def score(measured: pd.DataFrame, simulated: pd.DataFrame) -> Scores:
    """The contract's error figures of a simulation already made (the report simulates once per model and run)."""
    return Scores(rmse_k(measured, simulated), nrmse_pct(measured, simulated),
                  channel_rmse_k(measured, simulated), channel_nrmse_pct(measured, simulated))


@dataclass(frozen=True)
class Estimate:
    """One model's simulation of one run, with its error figures and the label the report shows it under."""

    label: str
    simulated: pd.DataFrame
    scores: Scores


def estimate(run: pd.DataFrame, params: Params, label: str) -> Estimate:
    """Simulate `run` with `params` (benchlab.simulate) and score the result."""
    simulated = simulate(run, params)
    return Estimate(label, simulated, score(run, simulated))
