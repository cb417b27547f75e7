"""A designed run against a Table 1 run of the same length, on the reference plant (docs/design.md).

    .venv/bin/python benchmarks/bench_design.py [--seeds 101 102 103] [--minutes 30] [--hours 1] [--joint] [--plant reference|paper] [--out DIR]
    .venv/bin/python benchmarks/bench_design.py --discriminate [--seeds …] [--minutes 30] [--hours 1] [--out DIR]

Per seed (seeds the tests do not use): the main job's Table 1 run (`--hours`, default 1 h as `benchlab pipeline`)
on the simulated bench's reference plant, identified with the nonlinear model (4 starts, as the main job); then
`benchlab design --parameters a2,b2 --reading` on it within `--minutes` (the cool-down reading: docs/design.md;
its steady cycles need `--minutes 70` for four points, three engine speeds and one to show their scatter; below
that the design falls back to the joint fit) and `benchlab
run PLAN.json`, and, as the peer, a Table 1 run planned to the designed run's length (seed + 200). The designed run
is read as the plan says (`benchlab cooldown`: each cool-down a point, eq. 11 fitted to them; with `--joint`, the
design is for every parameter Table 1 leaves open and the run identified together with Table 1); the peer both
ways: identified together with Table 1, and its held stretches read as cool-downs (`design.points.held_points`).
Printed for a2 and b2 of eq. (11): the standard error in % of the value after Table 1 alone, expected by the
design, delivered by the designed run (and the value), and by the peer; "agrees" where expected and delivered
shrink alike (the same sign of the change) and lie within a factor of 2; the between-reading scatter the plan
expected and the designed run's points showed (eq. 11's `scatter`), the plan's length and the run's. Targets:
delivered ≤ 20 % of the value; agreement on every seed. Exit 1 if a target is missed.

`--discriminate`: per seed, the Table 1 run diagnosed (nonlinear baseline, as the main job; Table 1 alone),
`benchlab design --diagnosis` on it and the designed run, and the peer Table 1 run of the plan's length. The rivals are
refitted to the Table 1 run with each new run (`design/rivals.py`, as the design refits them) and scored on the
new run: each one's RMSE there, and diagnose's block test (5-min blocks, `engine.block_test`) both ways. Printed:
which one is beaten at alpha on the designed run and on the peer; the expected RMSE gap against the delivered one
("agrees": same sign, within a factor of 2). The block test is in-sample here (both rivals fitted on the new run
too), not held out as in diagnose.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

from benchlab.cli import main

PARAMETERS = ("a2", "b2")
TARGET_SHARE = 0.20


def step(argv: list[str]) -> None:
    """One benchlab command in process; stop the benchmark where it fails."""
    started = time.perf_counter()
    code = main([*argv, "-q"])
    print(f"  [{time.perf_counter() - started:6.0f} s] benchlab {' '.join(argv[:2])} … exit {code}", flush=True)
    if code != 0:
        raise SystemExit(f"benchlab {' '.join(argv)} failed with {code}")


def shares(params_file: Path) -> dict[str, float]:
    """Standard error of each of PARAMETERS in % of its value (inf where the file has none)."""
    doc = json.loads(params_file.read_text())
    return {n: doc["uncertainty"].get(n, float("inf")) / abs(doc["params"][n]) for n in PARAMETERS}


def read_shares(eq11: dict | None) -> dict[str, float]:
    """Standard error of each of PARAMETERS in % of its value from eq. (11) fitted to cool-down points (inf where
    the points do not determine it: no fit, or left on a bound of the fit, where it has no standard error)."""
    eq11 = eq11 or {}
    return {n: eq11[f"{n}_se"] / abs(eq11[n]) if eq11.get(n) and eq11.get(f"{n}_se", 0) > 0 else float("inf")
            for n in PARAMETERS}


def read_designed(run: Path, params: Path) -> dict:
    """`benchlab cooldown RUN --json`: the designed run's cool-downs read one by one, eq. (11) fitted to them."""
    import contextlib
    import io

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        step(["cooldown", str(run), "--params", str(params), "--json", "--no-store"])
    text = printed.getvalue()
    return json.loads(text[text.index("{"):text.rindex("}") + 1])["eq11"]


def read_peer(run: Path, params: Path) -> dict | None:
    """The peer's held stretches read the same way (`design.points.held_points`), eq. (11) fitted to them."""
    from benchlab.design.points import held_points
    from benchlab.identify.cooldown import fit_eq11, segment_model
    from benchlab.model.params import load_params

    loaded = load_params(params)
    try:
        return fit_eq11(held_points([run], dict(loaded.items()), segment_model(loaded)), partial=True)
    except ValueError:
        return None


def run_minutes(run: Path) -> float:
    """How long the run lasted (min): its last sample's time."""
    from benchlab.runfile import load_run

    return float(load_run(run)["time"].iloc[-1]) / 60.0


def one_seed(seed: int, minutes: float, hours: float, folder: Path, joint: bool,
             plant: str) -> dict[str, dict[str, float]]:
    """The figures of one seed: share before, expected, delivered (designed) and peer, per parameter."""
    on = ["--bench", "sim", "--plant", plant]
    table1, first = folder / "table1.h5", folder / "table1.params.json"
    step(["run", "table1", *on, "--seed", str(seed), "--duration", str(hours * 3600), "--out",
          str(table1), "--force"])
    step(["identify", str(table1), "--model", "nonlinear", "--starts", "4", "--out", str(first), "--force"])
    plan = folder / "plan.json"
    aim = [] if joint else ["--parameters", ",".join(PARAMETERS), "--reading"]
    step(["design", str(table1), "--params", str(first), *aim, "--budget", str(minutes), "--out", str(plan), "--force"])
    doc = json.loads(plan.read_text())
    designed, peer = folder / "designed.h5", folder / "peer.h5"
    step(["run", str(plan), *on, "--seed", str(seed + 100), "--out", str(designed), "--force"])
    step(["run", "table1", *on, "--seed", str(seed + 200), "--duration", str(doc["planned_min"] * 60),
          "--out", str(peer), "--force"])
    after, with_peer = folder / "designed.params.json", folder / "peer.params.json"
    scatter = {"expected": doc.get("scatter", float("nan")), "delivered": float("nan")}
    if doc.get("identification") == "cooldowns":
        eq11 = read_designed(designed, first)
        delivered, values = read_shares(eq11), {n: (eq11 or {}).get(n, float("nan")) for n in PARAMETERS}
        scatter["delivered"] = (eq11 or {}).get("scatter", float("nan"))
    else:
        step(["identify", str(table1), str(designed), "--model", "nonlinear", "--starts", "4", "--out", str(after),
              "--force"])
        delivered, values = shares(after), {n: json.loads(after.read_text())["params"][n] for n in PARAMETERS}
    peer_read = read_shares(read_peer(peer, first))
    step(["identify", str(table1), str(peer), "--model", "nonlinear", "--starts", "4", "--out", str(with_peer),
          "--force"])
    before, peered = shares(first), shares(with_peer)
    return {n: {"before": before[n], "expected": doc["expected"].get(n, {}).get("relative_error_expected",
                                                                                 float("nan")),
                "delivered": delivered[n], "value": values[n], "peer": peered[n], "peer_read": peer_read[n],
                "scatter_expected": scatter["expected"], "scatter_delivered": scatter["delivered"],
                "planned_min": doc["planned_min"], "run_min": run_minutes(designed)}
            for n in PARAMETERS}


def scored(doc: dict, runs: list[Path]) -> dict[str, float]:
    """The two rivals refitted to `runs` and scored on the last: RMSE of each (K) and the block test both ways."""
    from benchlab.design.rivals import refitted_rivals
    from benchlab.diagnose.engine import HeldOut, block_statistic
    from benchlab.identify.fit import simulate_outputs
    from benchlab.model.catalog import resolve_model
    from benchlab.model.runs import load_runs

    frames = load_runs(runs, resolve_model(doc["baseline"]["model"]))
    favoured, other, data = refitted_rivals(doc, "diagnosis", frames)
    held = [HeldOut([data[-1]], [simulate_outputs(r.network, r.params, data[-1])], []) for r in (favoured, other)]
    t, p = block_statistic(held[1], held[0])
    return {"rmse_favoured": held[0].rmse, "rmse_other": held[1].rmse, "t_other_beaten": t, "p_other_beaten": p,
            "p_favoured_beaten": block_statistic(held[0], held[1])[1]}


def discriminate_seed(seed: int, minutes: float, hours: float, folder: Path) -> dict:
    """Table 1, diagnose, design --diagnosis, the designed run and its peer, each scored (`scored`); {"no_contest":
    the floor's verdict} where the diagnosis names no finding or lead (nothing to tell apart)."""
    import contextlib
    import io

    on = ["--bench", "sim", "--plant", "reference"]
    table1, diagnosis, plan = folder / "table1.h5", folder / "diagnosis.json", folder / "plan.json"
    step(["run", "table1", *on, "--seed", str(seed), "--duration", str(hours * 3600), "--out", str(table1), "--force"])
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        step(["diagnose", str(table1), "--baseline", "nonlinear", "--json"])
    diagnosis.write_text(printed.getvalue()[printed.getvalue().index("{"):printed.getvalue().rindex("}") + 1])
    diag = json.loads(diagnosis.read_text())
    if not diag["findings"] and not diag["leads"]:
        return {"no_contest": diag["floor"]["verdict"]}
    step(["design", str(table1), "--diagnosis", str(diagnosis), "--budget", str(minutes), "--out", str(plan),
          "--force"])
    doc = json.loads(plan.read_text())
    designed, peer = folder / "designed.h5", folder / "peer.h5"
    step(["run", str(plan), *on, "--seed", str(seed + 100), "--out", str(designed), "--force"])
    step(["run", "table1", *on, "--seed", str(seed + 200), "--duration", str(doc["planned_min"] * 60),
          "--out", str(peer), "--force"])
    return {"expected": doc["expected"], "planned_min": doc["planned_min"], "designed": scored(diag, [table1, designed]),
            "peer": scored(diag, [table1, peer])}


def verdict(score: dict[str, float], alpha: float) -> str:
    """Which rival the run beats at alpha (by the block test), or "tie"."""
    if score["p_other_beaten"] < alpha:
        return "other beaten"
    return "favoured beaten" if score["p_favoured_beaten"] < alpha else "tie"


def discriminate(args: argparse.Namespace) -> int:
    """The discrimination benchmark's table (module docstring); exit 1 where a seed's tie is not broken or the
    expected gap does not agree with the delivered one."""
    from benchlab.diagnose.engine import ALPHA

    missed = False
    print("| seed | favoured vs other | planned min | expected gap K | delivered gap K | agrees | expected t (p) "
          "| delivered t (p) | agrees | designed | peer | p (other beaten), designed / peer |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            folder = args.out / f"discriminate{seed}" if args.out else Path(tmp)
            folder.mkdir(parents=True, exist_ok=True)
            row = discriminate_seed(seed, args.minutes, args.hours, folder)
        if "no_contest" in row:  # nothing to tell apart: not a seed of the target either way
            print(f"| {seed} | no contest: the diagnosis names no finding or lead ({row['no_contest']}) |", flush=True)
            continue
        e, d, p = row["expected"], row["designed"], row["peer"]
        gap = d["rmse_other"] - d["rmse_favoured"]
        ok = gap * e["rmse_gap_K"] > 0 and 0.5 <= gap / e["rmse_gap_K"] <= 2.0
        t_ok = d["t_other_beaten"] * e["block_t"] > 0 and 0.5 <= d["t_other_beaten"] / e["block_t"] <= 2.0
        broken = verdict(d, ALPHA) != "tie"
        missed |= not ok or not t_ok or not broken
        print(f"| {seed} | {e['favoured']} vs {e['loser']} | {row['planned_min']:.1f} | {e['rmse_gap_K']:.4f} | "
              f"{gap:.4f} | {'yes' if ok else 'no'} | {e['block_t']:.2f} ({e['block_p']:.2g}) | "
              f"{d['t_other_beaten']:.2f} ({d['p_other_beaten']:.2g}) | {'yes' if t_ok else 'no'} | {verdict(d, ALPHA)} "
              f"| {verdict(p, ALPHA)} | {d['p_other_beaten']:.2g} / {p['p_other_beaten']:.2g} |", flush=True)
    return 1 if missed else 0


def agrees(row: dict[str, float]) -> bool:
    """Expected and delivered shrink alike (same sign of the change from before) and within a factor of 2."""
    same_sign = (row["expected"] - row["before"]) * (row["delivered"] - row["before"]) > 0
    return bool(same_sign and 0.5 <= row["delivered"] / row["expected"] <= 2.0)


def main_(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[101, 102, 103])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--plant", choices=("reference", "paper"), default="reference",
                        help="the simulated clutch (the paper's network: the model's own structure, a check that the "
                             "design works where its assumptions hold)")
    parser.add_argument("--joint", action="store_true", help="design for every parameter the Table 1 run leaves "
                        "open, identified jointly with it (default: for a2 and b2 alone, read from the designed run's "
                        "cool-downs)")
    parser.add_argument("--out", type=Path, help="keep the runs and files here (default: a temporary directory)")
    parser.add_argument("--discriminate", action="store_true", help="measure `design --diagnosis` instead: the tie "
                        "of the Table 1 run's diagnosis broken by the designed run, and not by the peer")
    args = parser.parse_args(argv)
    print(f"load average at start {os.getloadavg()[0]:.1f}")
    if args.discriminate:
        return discriminate(args)
    missed = False
    print("| seed | parameter | SE before | expected | delivered (designed) | value | peer, joint | peer, read alike "
          "| agrees | scatter expected / delivered | planned / run min |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            folder = args.out / f"seed{seed}" if args.out else Path(tmp)
            folder.mkdir(parents=True, exist_ok=True)
            rows = one_seed(seed, args.minutes, args.hours, folder, args.joint, args.plant)
        for name, row in rows.items():
            ok = agrees(row)
            missed |= not ok or not row["delivered"] <= TARGET_SHARE
            print(f"| {seed} | {name} | {100 * row['before']:.3g} % | {100 * row['expected']:.3g} % | "
                  f"{100 * row['delivered']:.3g} % | {row['value']:.4g} | {100 * row['peer']:.3g} % | "
                  f"{100 * row['peer_read']:.3g} % | {'yes' if ok else 'no'} | {100 * row['scatter_expected']:.3g} / "
                  f"{100 * row['scatter_delivered']:.3g} % | {row['planned_min']:.1f} / {row['run_min']:.1f} |",
                  flush=True)
    print(f"load average at end {os.getloadavg()[0]:.1f}")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main_())
