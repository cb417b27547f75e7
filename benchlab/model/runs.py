"""Run files read for a model: `time` plus the channels the model names (contract section 6), each usable.

The clutch models also require the channels of contract section 1 (their `requires`). A channel a law or a
boundary reads must hold a valid sample (a boundary list falls back to its later channels); a measured output
must too, since the fit compares with it and the state starts from it.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence

import numpy as np
import pandas as pd

from benchlab.errors import InputError
from benchlab.model.definition import ModelDefinition
from benchlab.runfile import ALIGNED_UNITS, load_run


def check_run(model: ModelDefinition, run: pd.DataFrame, params: Mapping[str, float] | None = None,
              params_source: str = "") -> None:
    """Bad input where the run lacks what the model reads, a channel shares a parameter's name (the model's fault for
    a contract channel, the run's for one its maker added), or a law is no number
    the solver can use on the run (check_laws; at `params`, read from `params_source`, where given)."""
    source = str(run.attrs.get("source", "<run>"))
    usable = {c for c in run.columns if not np.isnan(run[c].to_numpy(np.float64)).all()}
    for channel in model.required_channels():
        if channel not in run.columns:
            unit = f" in {ALIGNED_UNITS[channel]}" if channel in ALIGNED_UNITS else ""
            raise InputError(source, f"/aligned/{channel}", f"a required channel{unit} (model {model.label} names it; "
                                                            "missing)")
        if channel not in usable and (channel in model.law_channels() or channel in model.outputs):
            raise InputError(source, f"/aligned/{channel}", f"at least one measured sample (all {len(run)} are NaN; "
                                                            f"model {model.label} reads it)")
    for boundary, channels in model.boundaries.items():
        if not any(c in usable for c in channels):
            raise InputError(source, f"/aligned/{channels[-1]}",
                             f"at least one valid sample (boundary {boundary} of model {model.label})")
    for name in model.parameters:
        if name in run.columns and name in ALIGNED_UNITS:  # the contract's channel: the model chose the name
            raise InputError(model.source, f"parameters.{name}", f"a name no channel of {source} has")
        if name in run.columns:  # a channel the run's maker added (an import's mapping): the run's name is at fault
            raise InputError(source, f"/aligned/{name}", f"a channel name other than a parameter's of model "
                                                         f"{model.label} (rename the channel where the run was made, "
                                                         "e.g. in the import's mapping file)")
    check_laws(model, run, params, params_source)


def check_laws(model: ModelDefinition, run: pd.DataFrame, params: Mapping[str, float] | None = None,
               params_source: str = "") -> None:
    """Bad input where a law on the run's samples is not a number the solver can use: a resistance that is not
    positive and finite, a heat flow that is not finite, a capacity law that is not positive and finite (a division by
    zero, an overflow of exp). Asked at the model's
    starting (or fixed) values, the model file's fault, then at `params`, the parameter file's. Samples where a
    channel the law reads is NaN are not asked. A law's text is asked once (R_PA = R_FA of the paper's clutch)."""
    from benchlab.model.build import build_network  # the identify package: only once a run is at hand

    network = build_network(model)
    laws: dict[tuple[str, str], tuple[str, Callable, frozenset[str]]] = {}
    for entry, link in zip(model.links, network.links):
        laws.setdefault((entry.resistance.text, "resistance"),
                        (f"links[{entry.name}].resistance", link.resistance, entry.resistance.names))
    for entry, flow in zip(model.sources, network.sources):
        laws.setdefault((entry.heat.text, "heat"), (f"sources[{entry.name}].heat", flow.heat_flow, entry.heat.names))
    node_laws = {node.name: node.capacity_law for node in network.nodes}
    for i, entry in enumerate(model.capacities):
        laws.setdefault((entry.capacity.text, "capacity"),
                        (f"capacities[{i}].capacity", node_laws[entry.node], entry.capacity.names))
    channels = {c: run[c].to_numpy(np.float64) for c in model.law_channels() if c in run.columns}
    starts = {p.name: p.start if p.fixed is None else p.fixed for p in model.parameters.values()}
    _check_laws_at(laws, channels, run, starts, model.source, "the parameters' starting values")
    if params is not None:
        _check_laws_at(laws, channels, run, dict(params), params_source or "parameter file",
                       f"this file's values (model {model.label})")


#: What each kind of law must be on every sample: positive or only finite, and how the message says it
USABLE = {"resistance": (True, "a positive finite resistance in K/W"), "heat": (False, "a finite heat flow in W"),
          "capacity": (True, "a positive finite heat capacity in J/K")}


def _check_laws_at(laws: Mapping[tuple[str, str], tuple[str, Callable, frozenset[str]]],
                   channels: Mapping[str, np.ndarray], run: pd.DataFrame, params: dict[str, float], source: str,
                   values: str) -> None:
    """check_laws at one set of parameter values; InputError on `source`, saying they are `values`. The samples
    asked are sought only where some value is unusable."""
    for (_, kind), (entry, law, names) in laws.items():
        positive, what = USABLE[kind]
        with np.errstate(all="ignore"):
            law_values = np.asarray(law(params, channels), dtype=np.float64)
            usable = np.isfinite(law_values) & (law_values > 0) if positive else np.isfinite(law_values)
        if usable.all():
            continue
        reads = [channels[c] for c in names if c in channels]
        asked = np.logical_and.reduce([np.isfinite(v) for v in reads]) if reads else np.ones(len(run), bool)
        bad = asked & ~np.broadcast_to(usable, asked.shape)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(source, entry, f"{what} at {values} on {run.attrs.get('source', 'the run')}, got "
                                            f"{np.broadcast_to(law_values, asked.shape)[i]:g} at sample {i} "
                                            "(a division by zero or an overflow?)")


def load_runs(paths: Sequence["str | os.PathLike[str]"], model: ModelDefinition,
              params: Mapping[str, float] | None = None, params_source: str = "",
              model_channels_only: bool = False) -> list[pd.DataFrame]:
    """Each run file read and checked for the model (its laws at `params` where given: see check_laws).
    `model_channels_only`: read no channel the model does not name (a command that only simulates it)."""
    runs = []
    for path in paths:
        run = load_run(path, required=(), only=model.channels() if model_channels_only else None)
        check_run(model, run, params, params_source)
        runs.append(run)
    return runs
