"""Error figures of a parameter set on a full-resolution run (contract section 5)."""

from __future__ import annotations

from collections.abc import Mapping

import pandas as pd

from benchlab.identify.metrics import channel_nrmse_pct, channel_rmse_k, nrmse_pct, rmse_k
from benchlab.network import ThermalNetwork
from benchlab.network.simulation import model_network, simulate


def evaluate(run: pd.DataFrame, params: Mapping[str, float], network: ThermalNetwork | None = None) -> dict:
    """RMSE (K) and NRMSE (%) overall and per measured channel of the model, simulated at the run's own step."""
    network = model_network(params, network)
    sim = simulate(run, params, network)
    measured = [c for c in network.measured if c in run.columns]
    return {"rmse_K": rmse_k(run, sim, measured), "nrmse_pct": nrmse_pct(run, sim, measured),
            "channels": {c: {"rmse_K": v, "nrmse_pct": channel_nrmse_pct(run, sim, (c,))[c]}
                         for c, v in channel_rmse_k(run, sim, measured).items()}}
