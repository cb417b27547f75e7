"""The full stack (runner, drivers, emulated bench) agrees with the model at the plant's true parameters.

With the plant's exact inputs a 20-30 minute Table 1 run sits at the sensor-noise floor (0.041 K RMSE).
The CAN drivers keep the newest status frame per poll, so clutch torque and speeds are sampled at the
runner's 50 ms fast tick during slips and held: decelerating-slip power is over-counted (+7 % on short
launches) and the run sits at 0.10 K. The bound 0.07 K separates the two. Known defect: the fix is
frame time stamps in the CAN driver (each drained frame at its own time, not the poll's).
"""

import pytest

from benchlab.identify.evaluate import evaluate
from benchlab.params import paper_params
from benchlab.runfile import load_run
from benchlab.runner.session import RunRequest, execute
from sim_bench.plant import ThermalPlant


@pytest.mark.xfail(strict=True, raises=AssertionError, reason="CAN status frames stamped with the poll time: friction power sampled at 50 ms")
def test_full_stack_run_matches_model_at_truth(tmp_path):
    path = tmp_path / "t1.h5"
    code, _ = execute(RunRequest(protocol="table1", out=path, seed=1, duration_s=1200, plant=ThermalPlant(),
                                 install_signals=False))
    assert code == 0
    assert evaluate(load_run(path), paper_params("nonlinear"))["rmse_K"] < 0.07
