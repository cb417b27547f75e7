"""The paper's dry clutch as other modules use it, read from its model files (models/clutch-*.toml).

Nothing here defines the clutch: the network, the convection law of eq. (11), the measured and
simulated channels all come from the built-in model files (benchlab.model.catalog).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from benchlab.model.build import build_network
from benchlab.model.catalog import builtin
from benchlab.network import Channels, Params, ThermalNetwork

DEFAULT_MODEL = "nonlinear"  # what a parameter set without a model means (the paper's full model)
CONVECTION_LINK = "R_FA"  # R_FA = R_PA, eq. (10)


@lru_cache(maxsize=None)
def clutch_network(model: str = DEFAULT_MODEL) -> ThermalNetwork:
    """Pressure plate P, flywheel F, chamber air A, housing T; boundaries engine and ambient (eq. 6-9)."""
    return build_network(builtin(model))


#: Measured channels the clutch model predicts (contract section 5).
PREDICTED_CHANNELS: tuple[str, ...] = tuple(builtin(DEFAULT_MODEL).outputs)


def convection_resistance(params: Params, channels: Channels) -> "float | np.ndarray":
    """R_FA = R_PA = f_R(ω_e, S), eq. (11), as the nonlinear model file writes it; R0 where a1 = a2 = 0."""
    law = next(l.resistance for l in clutch_network(DEFAULT_MODEL).links if l.label == CONVECTION_LINK)
    return law(params, channels)
