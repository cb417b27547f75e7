"""How far the cool-down sweep's reading of the unmeasured plate is from the plate itself (the simulated plant's /truth).

    .venv/bin/python benchmarks/accuracy_plate_reading.py [--seeds 1 2 11] [--work DIR]

The main job widens the observer's plate band by the sweep's reading of the plate: each cool-down's fit takes the
plate's start temperature T_P0 from the measured decay, and its disagreement with the model's plate at that moment,
relative to the model's rise above ambient (`benchlab.observer.spread.start_discrepancy`, r), becomes a spread
σ = r·|plate − ambient|. Here, per seed, `benchlab pipeline --seed N` runs (or its output in WORK/seedN is reused),
and r is computed twice with that same function on the job's own cool-downs: from the readings (what the band
uses) and from /truth's plate at each cool-down's start in place of T_P0 (the peer: what the band should carry).
Beside them, the job's own figures: the observer's plate RMSE against /truth, the band's coverage and mean
half-width. A study, no target: exit 0.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchlab.identify.cooldown import analyse
from benchlab.model.params import load_params
from benchlab.network.simulation import simulate
from benchlab.observer.spread import start_discrepancy
from benchlab.report.showcase import PLATE
from benchlab.runfile import load_run, load_truth


def job(seed: int, work: Path) -> Path:
    """The main job's output for `seed` in work/seedN, run where it is not there yet."""
    out = work / f"seed{seed}"
    if not (out / "summary.json").exists():
        subprocess.run([str(Path(sys.executable).parent / "benchlab"), "pipeline", "--out", str(out), "--seed",
                        str(seed), "--quiet", "--force"], check=True, stdout=subprocess.DEVNULL)
    return out


def readings(out: Path) -> tuple[list, list, np.ndarray, np.ndarray, float]:
    """The sweep's cool-downs as read (the job's Table 1 model) and with /truth's plate as T_P0; the sweep's time,
    the model's plate on it, the ambient."""
    nonlinear = load_params(out / "nonlinear.json")
    sweep, truth = load_run(out / "sweep.h5"), load_truth(out / "sweep.h5")
    points = analyse(out / "sweep.h5", nonlinear, run=sweep)
    time_s = sweep["time"].to_numpy()
    true_plate = truth[PLATE].to_numpy()
    at = [min(np.searchsorted(time_s, p.t_start), len(true_plate) - 1) for p in points]
    true_points = [replace(p, T_P0=float(true_plate[i])) for p, i in zip(points, at)]
    model = simulate(sweep, nonlinear, nonlinear.network)[PLATE].to_numpy()
    return points, true_points, time_s, model, float(np.nanmedian(sweep["T_ambient"]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 11])
    ap.add_argument("--work", type=Path, default=None, help="keep the jobs' outputs here (default: a temporary folder)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        print(f"{'seed':>4} {'r read':>7} {'r truth':>8} {'read/truth':>11} {'T_P0 - truth, K (RMS, max)':>27} "
              f"{'plate RMSE K':>13} {'band covers':>12} {'half-width K':>13}")
        for seed in args.seeds:
            out = job(seed, work)
            points, true_points, time_s, model, ambient = readings(out)
            r_read = start_discrepancy(points, time_s, model, ambient)
            r_truth = start_discrepancy(true_points, time_s, model, ambient)
            misses = np.array([p.T_P0 - t.T_P0 for p, t in zip(points, true_points) if np.isfinite(p.T_P0)])
            summary = json.loads((out / "summary.json").read_text())
            ratio = r_read / r_truth if r_read is not None and r_truth else float("nan")
            print(f"{seed:>4} {r_read:>7.2f} {r_truth:>8.2f} {ratio:>10.1f}x "
                  f"{np.sqrt(np.mean(misses ** 2)):>17.1f} {np.max(np.abs(misses)):>8.1f} "
                  f"{summary['plate_rmse_k']:>13.2f} {100 * summary['plate_band_coverage']:>11.1f}% "
                  f"{summary['plate_band_half_width_k']:>13.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
