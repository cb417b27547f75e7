"""The thermal-network engine: a network as data, its exact zero-order-hold solver, and simulation of a run.

One face for the rest of benchlab. `structure` holds the network (nodes, capacities, links, sources,
boundaries, sensor lags), `sensors` the output equation of a calibrated sensor, `solver` discretises and
propagates it exactly per sample, `memo` keeps what a fit's repeated calls share, `sets` simulates a Jacobian's
parameter sets together, `simulation` drives a network with a run's measured inputs. The structure is light (numpy only) and loads with the package; the
solver (numba) loads on first use of `discretise`, `run_network` or `simulate`.
"""

import typing as _typing

from benchlab._lazy import lazy_exports as _lazy_exports
from benchlab.network.sensors import Calibration
from benchlab.network.structure import (Boundary, Channels, Lag, Link, Node, ParamChannelFunction, Params, Source,
                                        ThermalNetwork, as_samples, sample_matrix, state_channels)

if _typing.TYPE_CHECKING:  # what type checkers see; at run time `__getattr__` imports them on first use
    from benchlab.network.simulation import simulate
    from benchlab.network.solver import discretise, run_network

__all__ = ["Boundary", "Calibration", "Channels", "Lag", "Link", "Node", "ParamChannelFunction", "Params", "Source",
           "ThermalNetwork", "as_samples", "sample_matrix", "state_channels", "discretise", "run_network", "simulate"]

__getattr__, __dir__ = _lazy_exports(__name__, {".solver": ("discretise", "run_network"),
                                                ".simulation": ("simulate",)})
