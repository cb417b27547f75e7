"""The reference clutch (sim_bench/reference_plant.py): physically sane, richer than the model, μ(ϑ) on the torque,
and the simulated bench's default with `--plant paper` keeping the paper's network."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from benchlab.cli import main
from protocols.schedule import Step
from protocols.table1 import table1_schedule
from sim_bench.bench import SimBench, SimBenchConfig
from sim_bench.reference_plant import CHANNEL_NAMES, reference_plant
from sim_bench.virtual_run import run_schedule


def test_at_rest_at_ambient_it_stays_at_ambient():
    plant = reference_plant()
    plant.reset(22.0)
    n = 600
    channels = {"engine_speed": np.full(n, 1500.0), "clutch_speed": np.zeros(n), "clutch_torque": np.zeros(n),
                "clutch_state": np.zeros(n), "friction_power": np.zeros(n), "load_torque": np.zeros(n),
                "T_ambient": np.full(n, 22.0)}
    states = plant.advance(channels, 1.0)
    assert max(float(np.max(np.abs(v - 22.0))) for v in states.values()) < 1e-6


def test_launches_heat_the_friction_faces_first_and_the_sensors_lag_them():
    run = run_schedule(table1_schedule(5, duration_s=600), reference_plant(), seed=5, dt=0.1)
    truth = run.attrs["true_states"]
    assert set(truth) == set(reference_plant().state_names)
    first = int(np.flatnonzero(run["friction_power"].to_numpy() > 0)[0])
    rise = {s: float(truth[s][first + 20] - truth[s][first]) for s in ("F", "B", "A", "G", "S2")}
    # the ring under the face warms before the bulk behind it, the bulk before the air, the gearbox last;
    # the PT1000 (τ = 4 s) trails its ring
    assert rise["F"] > rise["B"] > 0 and rise["F"] > rise["S2"] > 0 and rise["A"] > rise["G"] >= 0
    # the plate is never measured, but it heats: hotter than ambient by the end
    assert truth["P"][-1] > run["T_ambient"].iloc[-1] + 1.0


def test_a_hot_lining_transmits_less_torque_than_commanded():
    steps = (Step("open", 5.0, 2000.0, 0.0, 0.0, 0), Step("launch", 3.0, 2000.0, 60.0, 100.0, 1))
    torques = {}
    for lining_c in (40.0, 140.0):
        sim = SimBench(SimBenchConfig(dropouts=False, initial_c={"F": lining_c, "L": lining_c, "A": 22.0}),
                       plant=reference_plant())
        try:
            physics = sim.physics
            physics.set_drive_speed(steps[1].engine_speed_rpm)
            physics.set_clutch(steps[1].clutch_torque_nm, False)
            physics.set_load_torque(steps[1].load_torque_nm)
            physics.advance(0.5)
            torques[lining_c] = float(physics.actuals_at(np.array([0.5])).clutch_torque_nm[0])
        finally:
            sim.close()
    assert abs(torques[40.0] - 60.0) < 1.0  # calibrated at 40 degC
    assert torques[140.0] < 0.95 * 60.0  # μ falls 10 % per 100 K


def test_run_records_which_plant_and_every_node(tmp_path, capsys):
    for plant, nodes in (("reference", set(CHANNEL_NAMES.values())),
                         ("paper", {"T_pressure_plate", "T_flywheel", "T_air", "T_housing"})):
        out = tmp_path / f"{plant}.h5"
        assert main(["run", "table1", "--bench", "sim", "--cycles", "1", "--out", str(out), "--plant", plant,
                     "--quiet"]) == 0
        with h5py.File(out, "r") as f:
            assert json.loads(f.attrs["sim_truth"])["plant"] == plant
            assert set(f["truth"]) == nodes | {"time"}
    # a resumed run keeps its plant: another one asked for is refused in one line
    assert main(["run", "--resume", str(tmp_path / "paper.h5"), "--bench", "sim", "--plant", "reference", "--quiet"]) == 2
    assert "sim_truth" in capsys.readouterr().err


def test_the_plant_keeps_the_states_of_its_numpy_laws():
    """Issue 47: the plant's compiled laws and its stream of the network (sim_bench/plant.py) keep the true states
    that the numpy laws and a fresh solver call per pass gave (tests/data/reference_plant_states.json, stored from
    that implementation): a hot lining, two launches with μ(ϑ), set-point changes that cut computed chunks."""
    from sim_bench.bench import SimPhysics
    from sim_bench.clock import SimClock

    stored = json.loads((Path(__file__).parent / "data" / "reference_plant_states.json").read_text())
    clock = SimClock(0.0)
    physics = SimPhysics(SimBenchConfig(seed=3, dropouts=False, initial_c={"F": 90.0, "L": 95.0, "P": 80.0, "A": 30.0,
                                                                           "SA": 30.0, "T": 24.0, "G": 23.0}),
                         clock, reference_plant())
    script = [(0.0, 2000.0, None, 0.0), (3.3, 2000.0, 90.0, 120.0), (9.71, 2000.0, None, 0.0),
              (14.05, 1500.0, None, 0.0), (21.0, 1500.0, 70.0, 80.0), (26.37, 800.0, None, 0.0)]
    for i, (t, rpm, torque, load) in enumerate(script):  # (time, engine rpm, clutch torque or None: open, load)
        clock.t = t
        physics.advance(t)
        physics.set_drive_speed(rpm)
        physics.set_clutch(torque or 0.0, torque is None)
        physics.set_load_torque(load)
        for s in np.arange(t, script[i + 1][0] if i + 1 < len(script) else 40.0, 0.5):  # the devices ask as it goes
            clock.t = float(s)
            physics.advance(float(s))
    clock.t = 40.0
    physics.advance(40.0)
    truth = physics.true_states(4000)
    worst = max(float(np.max(np.abs(truth[name][::stored["every_rows"]] - np.array(values))))
                for name, values in stored["states"].items())
    assert worst <= 1e-3, worst  # within 1 mK; bit for bit where numpy's and the compiled exp/log agree
    assert max(stored["states"]["T_clutch_disc"]) > 95.5 and min(stored["states"]["T_chamber_air"]) < 31.0


def test_a_piece_per_slipping_period_only_keeps_the_states():
    """Issue 47: the plant is advanced one μ period (2 s) at a time only while the clutch slips; a chunk where it
    does not is one piece. The states stay those of a piece per period: the solid nodes within 1 mK, the chamber
    air (and its sensor) within one step of the laws' 0.5 % resolution (reference_plant._BIN) on its largest
    temperature difference to a neighbour: where a law's value sits on a bin's edge, the fixed point may take
    either bin, however the horizon is cut."""
    from sim_bench import reference_plant as ref
    from sim_bench.bench import SimPhysics
    from sim_bench.clock import SimClock

    script = [(0.0, 1800.0, None, 0.0), (4.0, 1800.0, 110.0, 150.0), (12.0, 2500.0, None, 0.0),
              (60.0, 1200.0, 60.0, 0.0), (95.0, 900.0, None, 0.0)]  # (time, engine rpm, clutch torque or None, load)

    def run(piece_end) -> tuple[dict[str, np.ndarray], int]:
        clock = SimClock(0.0)
        physics = SimPhysics(SimBenchConfig(seed=4, dropouts=False, initial_c={"F": 60.0, "L": 62.0, "P": 55.0,
                                                                                "A": 28.0, "SA": 28.0}),
                             clock, reference_plant())
        if piece_end is not None:
            physics._piece_end = piece_end.__get__(physics)
        advances = []
        plant_advance = physics.plant.advance
        physics.plant.advance = lambda channels, dt: advances.append(dt) or plant_advance(channels, dt)
        for t, rpm, torque, load in script:
            clock.t = t
            physics.advance(t)
            physics.set_drive_speed(rpm)
            physics.set_clutch(torque or 0.0, torque is None)
            physics.set_load_torque(load)
        clock.t = 150.0
        physics.advance(150.0)
        return {name: np.asarray(column) for name, column in physics.true_states(15000).items()}, len(advances)

    def per_period(self, k: int, stop: int) -> int:  # the rule before: every μ period its own piece
        return min(stop, (k // self._mu_period + 1) * self._mu_period)

    (merged, merged_pieces), (pieces, per_period_pieces) = run(None), run(per_period)
    air = {"T_chamber_air", "T_air"}
    for name in set(merged) - air:
        assert np.max(np.abs(merged[name] - pieces[name])) <= 1e-3, name
    neighbours = np.maximum.reduce([np.abs(pieces["T_chamber_air"] - pieces[n])
                                    for n in ("T_pressure_plate", "T_cover", "T_flywheel_bulk", "T_housing")])
    for name in air:
        assert np.all(np.abs(merged[name] - pieces[name]) <= ref._BIN * neighbours + 1e-3), name
    # the launches slipped over several periods, each its own piece; the rest of the run came in far fewer
    assert len(script) < merged_pieces < per_period_pieces / 3


def test_a_resistance_inside_a_bin_by_its_edges_test_is_in_that_bin_by_its_log():
    """Issue 47: the laws take a sample's bin from the sample before's where `_inside` says so, without a log; that
    must be the bin the log gives, also next to the bins' edges (where a wrong margin would put it in the next)."""
    from sim_bench.reference_plant import _BIN, _binned, _inside

    rng = np.random.default_rng(7)
    bins = rng.integers(-2000, 2000, 2000).astype(float)
    edges = np.exp((bins + 0.5) * _BIN)
    for bin_, edge in zip(bins, edges):
        value = _binned(float(np.exp(bin_ * _BIN)))
        low = edge / np.exp(_BIN)
        for r in (edge * (1 - 1e-12), edge * (1 - 2e-9), edge * (1 - 1e-6), edge * (1 + 1e-6), value,
                  low * (1 + 2e-9), low * (1 - 1e-6)):
            if _inside(r, value):
                assert _binned(r) == value, (bin_, r)
        assert _inside(value, value) and not _inside(edge * (1 + 1e-12), value)
