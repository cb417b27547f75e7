"""Laws of a temperature's own level (issue 45): a switch with hysteresis in model files, carried through a whole run,
refused where its state cannot be carried yet; diagnose's level candidates start nested; the bench's thermostat
is the same whether a run is advanced whole or in chunks."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.diagnose.engine import STEP_S
from benchlab.diagnose.library import candidates
from benchlab.errors import InputError
from benchlab.identify.data import prepare
from benchlab.model.build import build_network, build_spec
from benchlab.model.catalog import builtin
from benchlab.model.definition import parse_model
from benchlab.model.params import ModelParams
from benchlab.network.solver import discretise, propagate, run_network
from benchlab.network.stream import BLOCK
from benchlab.network.switching import hysteresis


def test_the_switch_keeps_its_state_between_its_thresholds_and_takes_the_share_of_a_crossing_step():
    x = np.array([20.0, 25.0, 29.0, 31.0, 33.0, 32.0, 30.5, 29.5, 28.0, 30.0, 31.0, 33.0])
    np.testing.assert_allclose(hysteresis(x, 29.8, 32.0), [0, 0, 0, 0.5, 1, 1, 0.7, 0, 0, 0, 0.5, 1])
    assert hysteresis(np.array([33.0, 31.0]), 29.8, 32.0).tolist() == [1.0, 1.0]  # starts on at or above "on"
    assert np.isnan(hysteresis(x, 32.5, 32.0)).all()  # off above on is no switch


def _switched_model():
    """A node warmed by a heater a thermostat on its own measured temperature switches (a channel, as diagnose's
    level laws read it)."""
    return parse_model({"schema": "benchlab-model/1", "nodes": {"W": "C"}, "outputs": {"T_w": "W"},
                        "boundaries": {"amb": "T_amb"},
                        "links": [{"name": "R", "between": ["W", "amb"], "resistance": "R"}],
                        "sources": [{"name": "heater", "node": "W", "heat": "q * hysteresis(T_w, off, on)"}],
                        "parameters": {"C": {"start": 100.0, "min": 1.0, "max": 1e4},
                                       "R": {"start": 0.5, "min": 0.01, "max": 10.0},
                                       "q": {"start": 40.0, "min": 0.0, "max": 100.0},
                                       "on": {"start": 31.0, "min": 0.0, "max": 100.0},
                                       "off": {"start": 29.0, "min": 0.0, "max": 100.0}}}, "w.toml")


def test_a_switch_runs_through_the_whole_run_not_block_by_block():
    """On a run of several stream blocks the states are those of the whole-run solver: a block alone would start
    its switch afresh (the third block starts inside the band, where the switch is still on)."""
    model = _switched_model()
    network = build_network(model)
    p = {"C": 100.0, "R": 0.5, "q": 40.0, "on": 31.0, "off": 29.0}
    n = 3 * BLOCK
    t = np.arange(n)
    reading = 30.0 + 2.5 * np.sin(2 * np.pi * t / (4 * BLOCK))  # on from the first block, falling through the band
    channels = {"T_w": reading, "T_amb": np.full(n, 20.0)}
    streamed = run_network(network, p, channels, 1.0, np.array([25.0]))
    whole = propagate(discretise(network, p, channels, 1.0), np.array([25.0]))
    np.testing.assert_array_equal(streamed, whole)
    last = {name: values[2 * BLOCK:] for name, values in channels.items()}
    alone = propagate(discretise(network, p, last, 1.0), whole[2 * BLOCK])
    assert np.max(np.abs(alone - whole[2 * BLOCK:])) > 1.0


def test_the_deployed_module_refuses_a_switch_in_one_line():
    params = ModelParams(_switched_model(), {"C": 100.0, "R": 0.5, "q": 40.0, "on": 31.0, "off": 29.0})
    from benchlab.deploy.plan import make_plan

    with pytest.raises(InputError, match="heater: a law without hysteresis"):
        make_plan(params, ["T_w"], 1.0, None)


def test_level_candidates_start_nested_inside_their_bounds(short_run):
    """Each level law at its start values, and a switch at each of its screening starts, is its parent."""
    from benchlab.identify.fit import simulate_outputs

    model = builtin("nonlinear")
    spec = build_spec(model)
    data = prepare(short_run, STEP_S, network=spec.network)
    parent = simulate_outputs(spec.network, {p.name: p.initial for p in spec.free}, data)
    plain = {c.key for c in candidates(model, data.channels, data.units)}
    level = [c for c in candidates(model, data.channels, data.units, ("T_housing", "T_ambient"))
             if c.key not in plain]
    assert {c.signal for c in level} == {"T_housing", "T_ambient"}
    assert any("switch" in c.key and c.mechanism == "heat_source" for c in level)
    for cand in level:
        ext = build_spec(cand.build(model, data.channels))
        start = {p.name: p.initial for p in ext.free}
        for p in ext.free:
            assert p.lower <= p.initial < p.upper, (cand.key, p.name)
        for probe in [{}] + (cand.probes(start) if cand.nested_probes else []):
            out = simulate_outputs(ext.network, {**start, **probe}, data)
            assert max(float(np.nanmax(np.abs(out[c] - parent[c]))) for c in parent) < 0.01, (cand.key, probe)


def test_every_measured_temperature_gets_its_level_laws_whatever_its_evidence_rank(short_run):
    """A housing thermostat's residual explained alike by every temperature's level (they all rise with the heat):
    the housing, ranked behind the flywheel and the air by p-value, is still one whose level laws are tried, in the
    evidence's order, and so are those the evidence left out; the plate (unmeasured) and a speed are not. Without
    evidence (design rebuilding a diagnosis' rivals) the same temperatures."""
    from benchlab.diagnose.engine import level_channels
    from benchlab.diagnose.evidence import Evidence

    def row(signal: str, kind: str, unit: str, p: float) -> Evidence:
        return Evidence(signal, kind, unit, "T_flywheel", "level", 60.0, 30.0, p, 5000)
    evidence = [row("model T_pressure_plate", "model", "degC", 0.001), row("model T_flywheel", "model", "degC", 0.002),
                row("T_air", "measured", "degC", 0.005), row("engine_speed", "input", "rpm", 0.006),
                row("T_housing", "measured", "degC", 0.018)]
    spec = build_spec(builtin("nonlinear"))
    data = [prepare(short_run, STEP_S, network=spec.network)]
    ranked = level_channels(data, spec.network.measured, evidence)
    assert ranked == ("T_flywheel", "T_air", "T_housing", "T_ambient")
    assert set(level_channels(data, spec.network.measured)) == set(ranked)


def test_a_switch_threshold_is_refined_between_the_quantiles_beside_its_best_start():
    """The grid's best "on" gets SWITCH_REFINE_POINTS points into the quantile interval on each side, strictly
    inside it, the band kept; a switch's band also at half and twice the best, never beyond the range; a latch (no
    band) and a best start at the grid's end get only what exists."""
    from benchlab.diagnose.library import SWITCH_QUANTILES, SWITCH_REFINE_POINTS, switch_refinements

    values = np.linspace(20.0, 40.0, 2001)
    ons = np.quantile(values, SWITCH_QUANTILES)
    refine = switch_refinements("T_air", "t", "switch", {"T_air": values})
    probes = refine({"on_t": float(ons[4]), "band_t": 12.0})
    on_points = sorted(p["on_t"] for p in probes if p["band_t"] == 12.0 and p["on_t"] != ons[4])
    assert len(on_points) == 2 * SWITCH_REFINE_POINTS
    assert all(ons[3] < v < ons[5] and v != ons[4] for v in on_points)
    assert sorted(p["band_t"] for p in probes if p["on_t"] == ons[4]) == [6.0, 20.0]  # 24 K clipped to the range
    latch = switch_refinements("T_air", "t", "latch", {"T_air": values})({"on_t": float(ons[0])})
    assert len(latch) == SWITCH_REFINE_POINTS and all(ons[0] < p["on_t"] < ons[1] for p in latch)
    assert all(set(p) == {"on_t"} for p in latch)


def test_the_benchs_thermostat_is_carried_from_chunk_to_chunk():
    """A run advanced in two chunks equals the run advanced whole: the thermostat's switch goes on with the state."""
    from benchlab.model.params import paper_params
    from protocols.table1 import table1_schedule
    from sim_bench import plant as P
    from sim_bench.virtual_run import drive_schedule

    truth, _ = drive_schedule(table1_schedule(5, duration_s=600.0), 0.1)
    truth["T_ambient"] = np.full(len(truth["engine_speed"]), 22.0)

    def advanced(cuts):
        plant = P.ThermalPlant(paper_params("nonlinear"), [P.thermostat_fan("R_Tamb", "A", "T_air", 24.0, 23.0, 4.0)])
        plant.reset(22.0)
        parts = [plant.advance({k: v[a:b] for k, v in truth.items()}, 0.1) for a, b in zip(cuts, cuts[1:])]
        return np.concatenate([part["A"] for part in parts])

    n = len(truth["engine_speed"])
    whole, chunked = advanced([0, n]), advanced([0, 3000, n])  # at a thermostat period (10 samples)
    np.testing.assert_allclose(chunked, whole, atol=1e-9)
    assert whole.max() > 24.0


def test_a_housing_fan_switched_by_its_thermostat_is_named_a_law_of_the_housing_temperature():
    """A fan on the housing's outside, switched on where the housing reaches 27.0 °C and off below 25.8 °C (a 40 min
    Table 1 run heats it through "on" and never back below "off"), tripling the housing–ambient conductance: named
    convection on R_Tamb as a switch of T_housing (a latch: the band is not exercised), its threshold within 0.3 K
    and its factor within 15 %, a cause, the model below 3x the noise floor. (A correct model gets no finding with the
    level laws in the library: tests/test_diagnose.py's correct models.)"""
    from benchlab.diagnose import diagnose
    from benchlab.model.params import paper_params
    from protocols.table1 import table1_schedule
    from sim_bench import plant as P
    from sim_bench.virtual_run import run_schedule

    on_c, factor = 27.0, 3.0
    plant = P.ThermalPlant(paper_params("nonlinear"), [P.thermostat_fan("R_Tamb", "T", "T_housing", on_c, 25.8, factor)])
    run = run_schedule(table1_schedule(261, duration_s=2400.0), plant, seed=261)
    result = diagnose([run], baseline="nonlinear")
    assert [(f["signal"], f["mechanism"], f["label"]) for f in result["findings"]] == [
        ("T_housing", "convection", "cause")]
    finding = result["findings"][0]
    assert finding["candidate"].startswith("level_T_housing_") and finding["candidate"].endswith("_R_Tamb")
    on = next(v for k, v in finding["params"].items() if k.startswith("on_"))
    g = next(v for k, v in finding["params"].items() if k.startswith("g_"))
    assert on == pytest.approx(on_c, abs=0.3)
    assert 1.0 + g == pytest.approx(factor, rel=0.15)
    assert not result["floor"]["beyond_library"]
