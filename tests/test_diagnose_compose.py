"""Two steps in one round (issue 45): a plate–flywheel contact the model lacks, which only the clutch torque closes
or whose conductance differs run by run, is named as the link it is. Alone, a link at one constant conductance
explains little of either, so the greedy search would never take the second step (docs/diagnose.md, step 3)."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.diagnose import diagnose
from benchlab.model.params import paper_params
from protocols.table1 import table1_schedule
from sim_bench import plant as P
from sim_bench.virtual_run import run_schedule

TORQUE_REFERENCE_NM = 100.0


def test_a_contact_pressed_by_the_clutch_torque_is_named_as_a_link_on_that_signal():
    """The plant's plate–flywheel conductance is |T| / 100 N*m / 0.15 K/W: named a P–F link growing with the clutch
    torque, a cause, its conductance at the runs' largest torque within 15 % of the plant's."""
    resistance, seed = 0.15, 481
    plant = P.ThermalPlant(paper_params("nonlinear"),
                           [P.contact_conduction(resistance, "clutch_torque", TORQUE_REFERENCE_NM)])
    run = run_schedule(table1_schedule(seed, duration_s=1800.0), plant, seed=seed)
    result = diagnose([run], baseline="nonlinear")
    assert result["findings"], f"nothing found; baseline {result['baseline']['rmse_K']:.4f} K"
    first = result["findings"][0]
    assert (first["signal"], first["mechanism"], first["label"]) == ("clutch_torque", "conduction", "cause"), first
    assert first["candidate"] in ("link_P_F_clutch_torque_linear", "link_P_F_clutch_torque_power"), first
    exponent = next((v for k, v in first["params"].items() if k.startswith("n_")), 1.0)
    assert 0.8 < exponent < 1.25  # the plant's conductance is linear in the torque
    largest = float(np.nanmax(np.abs(run["clutch_torque"])))
    truth = largest / TORQUE_REFERENCE_NM / resistance  # W/K at the largest torque the model's law reads
    assert 1.0 / first["params"]["R_PF"] == pytest.approx(truth, rel=0.15)
