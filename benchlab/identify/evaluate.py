"""Error figures of a parameter set on a full-resolution run (contract section 5)."""

from __future__ import annotations

from collections.abc import Mapping

import pandas as pd

from benchlab.identify.metrics import error_figures
from benchlab.network import ThermalNetwork
from benchlab.network.simulation import model_network, simulate


def evaluate(run: pd.DataFrame, params: Mapping[str, float], network: ThermalNetwork | None = None) -> dict:
    """RMSE (K) and NRMSE (%) overall and per measured channel of the model, simulated at the run's own step."""
    network = model_network(params, network)
    sim = simulate(run, params, network)
    measured = [c for c in network.measured if c in run.columns]
    return error_figures(run, sim, measured)
