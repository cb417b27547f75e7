"""examples/ipmsm.md and its figures, from what benchmarks/accuracy_ipmsm.py measured through the command line.

The figures are benchlab's own: `benchlab report` of a held-out profile (Fig. 4 of the fit, Fig. 5 of the other
held-out profile, residual analysis) and the page of `benchlab diagnose --report` of the model without its rotor
losses (written by accuracy_ipmsm.py's diagnose into DIAGNOSE_PAGE); one more figure shows the reduced targets of
both held-out profiles against the model.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

from benchlab.model.definition import load_model
from benchlab.report.plotting import new_figure, save

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples"
FIGURES = EXAMPLE / "ipmsm"
DIAGNOSE_PAGE = FIGURES / "diagnose"


def _targets_figure(runs: dict[int, Path], work: Path, targets: dict[str, tuple[str, ...]],
                    per_profile: dict[int, dict[str, float]]) -> Path:
    held = sorted(per_profile)
    fig = new_figure(11.0, 8.0)
    axes = fig.subplots(len(targets), len(held), squeeze=False, sharex="col")
    for col, k in enumerate(held):
        with h5py.File(runs[k]) as f, h5py.File(work / f"sim_{k}.h5") as s:
            minutes = f["aligned/time"][()] / 60.0
            for row, (name, channels) in enumerate(targets.items()):
                ax = axes[row][col]
                ax.plot(minutes, np.mean([f["aligned"][c][()] for c in channels], axis=0), color="k", lw=0.9,
                        label="measured")
                ax.plot(minutes, np.mean([s["simulated"][c][()] for c in channels], axis=0), color="tab:red", lw=1.0,
                        label="model (never fitted on this profile)")
                ax.set_title(f"profile {k}, {name}: RMSE {per_profile[k][name]:.2f} K", fontsize=9)
                ax.set_ylabel("°C")
        axes[-1][col].set_xlabel("time (min)")
    axes[0][0].legend(fontsize=8)
    fig.suptitle("IPMSM held-out profiles: measured and simulated node temperatures")
    return save(fig, FIGURES / "held_out.png")


def write_page(runs: dict[int, Path], params: Path, rmse: dict[str, float], per_profile: dict[int, dict[str, float]],
               diagnosis: dict, identify_cpu: float, diagnose_cpu: float, args: argparse.Namespace) -> Path:
    """Run `benchlab report` into examples/ipmsm/, draw the held-out figure, write examples/ipmsm.md."""
    from accuracy_ipmsm import BENCHLAB, HELD_OUT, LEFT_OUT, MODEL, REFERENCE_K, REMOVED, TARGETS, UNITS

    FIGURES.mkdir(parents=True, exist_ok=True)
    first, second = HELD_OUT
    # run from the work directory with relative names, so the page names the files, not where they sat
    subprocess.run([*BENCHLAB, "report", runs[first].name, "--params", params.name, "--validate", runs[second].name,
                    "--out", str(FIGURES.resolve() / "report")], check=True, capture_output=True, cwd=args.work)
    held = _targets_figure(runs, args.work, TARGETS, per_profile)
    fitted = json.loads(params.read_text())
    fixed = {name for name, p in load_model(MODEL).parameters.items() if p.fixed is not None}
    mean = float(np.mean(list(rmse.values())))
    train = ", ".join(str(k) for k in runs if k not in LEFT_OUT)
    rows = "\n".join(f"| {name} | {' + '.join(f'`{c}`' for c in TARGETS[name])} | {v:.2f} |"
                     + "".join(f" {per_profile[k][name]:.2f} |" for k in HELD_OUT) for name, v in rmse.items())
    params_rows = "\n".join(f"| `{k}` | {v:.4g} | {fitted['units'].get(k, '')} | "
                            + ("fixed |" if k in fixed else f"{fitted['uncertainty'][k]:.2g} |")
                            for k, v in fitted["params"].items())
    findings = "\n".join(f"| `{f['candidate']}` | `{f['signal']}` | {f['mechanism']} | {f['rmse_before_K']:.3f} | "
                         f"{f['rmse_after_K']:.3f} | {f['gain_pct']:.1f} |" for f in diagnosis["findings"])
    page = f"""# Example: a motor on a test bench (real data, not the clutch)

The data are sixteen measured profiles of an interior permanent-magnet synchronous motor
(`id_0.csv` … `id_15.csv` of the `dataset/` folder of the public repository `Zirui24/lptn_informed_LSTM`,
published with Z. Liu et al., "Hybrid Thermal Modeling with LPTN-Informed Neural Network for Multi-Node
Temperature Estimation in PMSM", IEEE Transactions on Power Electronics, 2024, doi 10.1109/TPEL.2024.3409388;
MIT licence; not copied here: put them in `data/ipmsm-bench/` or name their folder in `BENCHLAB_IPMSM_DATA`).
The model is
[`ipmsm.toml`](ipmsm.toml): winding W, stator tooth T, stator yoke Y and rotor R, coolant and ambient as
boundaries, copper losses from the d/q currents rising with the winding temperature (affine in W, exact in
the solver), iron losses from speed, rotor losses with speed squared, an air gap that conducts better at speed.
Everything below is benchlab's command line (`benchmarks/accuracy_ipmsm.py` runs it and wrote this page).

## Import and identify

```sh
benchlab import id_K.csv --dt 1 --model examples/ipmsm.toml --unit {','.join(UNITS[:3])} … --out id_K.h5
benchlab identify id_0.h5 … (all but 6, 14, 15) --model examples/ipmsm.toml --step {args.step} --starts {args.starts} --out ipmsm.json
benchlab simulate id_6.h5 --params ipmsm.json --out sim_6.h5
```

Fitted on profiles {train} ({identify_cpu:.0f} s CPU at a {args.step} s fitting step, {args.starts} starts),
validated on profiles {first} and {second}, which the fit never saw. Held-out RMSE of the reduced targets
(the mean of a node's sensors), over both profiles' samples and per profile:

| target | sensors | RMSE {first} + {second} (K) | profile {first} (K) | profile {second} (K) |
|---|---|---|---|---|
{rows}
| **mean** | | **{mean:.2f}** | | |

Independent reference (issue 13): a scipy fit of the same kind of network, trained on the same profiles,
**{REFERENCE_K:.2f} K** mean on profiles 6 and 15; the article's own hand-tuned 3rd-order network about 2.5 K.

![held-out profiles](ipmsm/held_out.png)

`benchlab report` of profile {first} with profile {second} as validation: [report](ipmsm/report/report.md)
(Fig. 4 fit, Fig. 5 validation, residual analysis; Fig. 3 is the clutch's and is left out).

| parameter | value | unit | standard error |
|---|---|---|---|
{params_rows}

identify's warnings: {"; ".join(fitted.get("warnings", [])) or "none"}. A link whose resistance ends at its
upper bound carries no heat the data can see: the network could do without it.

The heat inputs and the capacities are identifiable only together (scaling every loss, every capacity and every
conductance alike leaves the temperatures unchanged), so the copper-loss coefficient `k_cu` is fixed from the
measurement itself: at standstill (speed < 50 rpm) the electrical power minus the mechanical one is
0.0228 W/A² · (Id² + Iq²).

## Diagnose: the rotor losses removed, found again

`benchlab diagnose` of the model file without its `{REMOVED}` source (`q_R · (speed/1000)²` into the rotor), on the
training profiles averaged to {args.diag_step} s ({diagnose_cpu:.0f} s CPU), with `--save-model`:

| finding | signal | mechanism | held-out RMSE before (K) | after (K) | gain (%) |
|---|---|---|---|---|---|
{findings}

Baseline held-out RMSE {diagnosis['baseline']['rmse_K']:.3f} K, best model `{diagnosis['best']['model']}`
{diagnosis['best']['rmse_K']:.3f} K. Its page: [diagnose](ipmsm/diagnose/diagnose.md).
"""
    path = EXAMPLE / "ipmsm.md"
    path.write_text(page)
    print(f"page: {path}, figures: {held.parent}")
    return path


if __name__ == "__main__":
    sys.exit("run benchmarks/accuracy_ipmsm.py --page")
