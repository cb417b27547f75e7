"""The simulated bench's physics: chunked advancing with cuts at set-point changes equals one continuous run."""

from __future__ import annotations

import numpy as np
import pytest

from sim_bench.bench import SimBenchConfig, SimPhysics
from sim_bench.clock import SimClock
from benchlab.drivetrain import DrivetrainFacts
from sim_bench.drivetrain import Drivetrain
from sim_bench.plant import ThermalPlant

SCRIPT = [(0.0, "drive", 1500.0), (0.0, "clutch", (45.0, False)), (0.0, "load", 300.0), (7.3, "clutch", (0.0, True)),
          (9.0, "drive", 1000.0), (20.0, "clutch", (30.0, False)), (20.0, "load", 500.0), (31.0, "clutch", (0.0, True))]


def _trace(chunk_s: float, probes: np.ndarray, noop_every: float | None = None, plant=None) -> np.ndarray:
    clock = SimClock()
    phys = SimPhysics(SimBenchConfig(seed=1, chunk_s=chunk_s), clock, plant)
    out, script = [], list(SCRIPT)
    for t in probes:
        while script and script[0][0] <= t:
            t_set, what, value = script.pop(0)
            clock.sleep_until(t_set)
            phys.advance(t_set)  # the controllers' set-points hold from the time the physics was advanced to
            {"drive": lambda v: phys.set_drive_speed(v), "load": lambda v: phys.set_load_torque(v),
             "clutch": lambda v: phys.set_clutch(*v)}[what](value)
        clock.sleep_until(t)
        if noop_every and (t / noop_every) % 1 < 1e-9:
            phys._cut(t)  # a cut without a change must not change anything
        cols, temps, i = phys._at(t)
        out.append([cols["clutch_speed"][i], cols["friction_power"][i], temps["T_flywheel"][i], temps["T_air"][i]])
    return np.array(out)


@pytest.mark.parametrize("plant,atol_k", [(ThermalPlant, 1e-9), (None, 1e-5)], ids=["paper", "reference"])
def test_chunks_and_cuts_do_not_change_the_physics(plant, atol_k):
    """Exact on the paper's plant. The reference plant (the default) holds its lining's μ(ϑ) over fixed 1 s periods
    of the grid, so chunks do not change the torque either; its laws of its own temperatures (natural convection,
    radiation) are solved per chunk, which moves the air by 3e-7 K here: far below any sensor, bounded at 1e-5 K."""
    probes = np.round(np.arange(0.0, 40.0, 0.05), 10)
    a = _trace(0.37, probes, plant=plant and plant())
    b = _trace(5.0, probes, noop_every=1.0, plant=plant and plant())
    np.testing.assert_allclose(a[:, :2], b[:, :2], rtol=1e-9, atol=1e-9)  # speeds and friction power: exact
    np.testing.assert_allclose(a[:, 2:], b[:, 2:], rtol=0.0, atol=atol_k)
    assert a[:, 1].max() > 5000 and a[-1, 2] > a[0, 2] + 1  # launches happened and heated the flywheel


def test_stalled_clutch_keeps_slipping():
    dt = Drivetrain(DrivetrainFacts())
    dt.set_points(1500.0, True, 20.0, 500.0)  # 20 N*m cannot move 500 N*m / 15
    for _ in range(3):
        cols = dt.advance(100, 0.01)
        assert np.all(cols["clutch_speed"] == 0.0) and np.all(cols["friction_power"] > 3000)
    assert dt.slipping


def test_same_seed_same_sensor_noise():
    readings = []
    for _ in range(2):
        clock = SimClock()
        phys = SimPhysics(SimBenchConfig(seed=4), clock)
        clock.sleep_until(3.0)
        actuals = phys.actuals_at(np.array([2.5, 3.0]))
        readings.append((phys.get_resistances(), phys.node_inputs(2.95),
                         [getattr(actuals, f).tolist() for f in actuals.__dataclass_fields__]))
    assert readings[0] == readings[1]


def test_a_stuck_clutch_during_one_under_way_extends_it_never_shortens_it():
    """Issue 44 (the radio silence's overwrite, checked for every fault with a duration): a second, shorter
    stuck_clutch at 10 s does not end the 60 s one at 15 s; a longer one extends it."""
    clock = SimClock()
    phys = SimPhysics(SimBenchConfig(seed=1), clock)
    phys.stick_clutch(100.0, 60.0)
    clock.sleep_until(10.0)
    phys.advance(10.0)
    phys.stick_clutch(80.0, 5.0)
    assert phys.stuck == (80.0, 60.0)
    clock.sleep_until(50.0)
    phys.advance(50.0)
    phys.stick_clutch(80.0, 30.0)
    assert phys.stuck == (80.0, 80.0)
