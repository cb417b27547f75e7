"""One `benchlab run`: protocol + bench + run file, from the checks before anything moves to the summary.

Used by the CLI command and by tests (which pass a `sim_bench.bench.SimulatedBench` with a plant, faults or
limits, or a smaller grid, directly). The hardware path never imports the simulator: "sim" is resolved to the
simulated bench only when asked for, and that bench opens itself.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

from benchlab.acquire import RunWriter
from benchlab.progress import SILENT, Progress
from benchlab.errors import InputError
from benchlab.provenance import bench_text
from benchlab.runfile.read import load_stopped_run
from benchlab.runfile.schema import SCHEDULE_UNITS
from benchlab.runner import opening
from benchlab.runner.clock import Clock, RealClock
from benchlab.runner.devices import BenchConfig, DriverBench, prime_drivers
from benchlab.runner.engine import STATE_FIELDS, Runner, RunSummary
from drivers.errors import CanLogError
from protocols import catalog
from protocols.estimates import ESTIMATE_CHANNELS
from protocols.limits import BenchLimits, check_schedule, schedule_problems, with_launch_estimates
from protocols.schedule import Step, describe, duration_s

if TYPE_CHECKING:
    from protocols.estimates import Plant
    from sim_bench.bench import SimBench, SimulatedBench

# what a run asks for: a BENCH.toml path, "sim" (the default simulated bench) or a simulated bench of its own
BenchChoice = Union[str, "os.PathLike[str]", "SimulatedBench"]


@dataclass
class RunRequest:
    protocol: str
    out: Path
    bench: BenchChoice = "sim"  # a BENCH.toml path, "sim" or a sim_bench.bench.SimulatedBench (plant, faults, limits)
    seed: int = 1
    cycles: int | None = None
    duration_s: float | None = None
    grid: str | None = None
    dry_run: bool = False
    resume: bool = False
    progress: Progress = SILENT  # a bar over the planned bench time (benchlab.progress.for_terminal in commands)
    install_signals: bool = True
    steps: tuple[Step, ...] | None = None  # a custom schedule instead of the named protocol's (tests, scripts, plans)
    options: dict[str, Any] | None = None  # what the run file records of a custom schedule (a plan's source)
    params: str | None = None  # a parameter file whose model times a hardware bench's cool-down sweep in advance


def software_version() -> str:
    import benchlab

    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=2,
                             cwd=Path(__file__).resolve().parent).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        rev = ""
    return f"benchlab {benchlab.__version__}" + (f" ({rev})" if rev else "")


def simulated(bench: BenchChoice) -> "SimulatedBench | None":
    """The simulated bench `bench` asks for ("sim": the default one), or None for a BENCH.toml path.

    The one place that tells the two apart; sim_bench is imported only here, and only for "sim".
    """
    if not isinstance(bench, (str, os.PathLike)):
        return bench
    if bench != "sim":
        return None
    from sim_bench.bench import SimulatedBench

    return SimulatedBench()


def bench_name(bench: BenchChoice) -> str:
    """What the run file records as its `bench` (and resume compares): "sim" or the BENCH.toml path given."""
    return os.fspath(bench) if isinstance(bench, (str, os.PathLike)) else bench.name


def _simulated(request: RunRequest, config: BenchConfig) -> str:
    """The `sim://` devices of a hardware bench, in words (opening.simulated_devices); "" for the simulated one."""
    return "" if simulated(request.bench) is not None else opening.simulated_devices(config)


def estimate_plant(request: RunRequest) -> "Plant | None":
    """A fresh copy of the thermal plant a cool-down sweep will run on, for its expected durations
    (protocols.estimates.timed): the simulated bench's, or on hardware the model of `request.params`;
    None for other protocols and on hardware without a parameter file (the paper's closed forms)."""
    if request.protocol != "cooldown-sweep":
        return None
    sim = simulated(request.bench)
    if sim is not None:
        from sim_bench.reference_plant import DEFAULT_PLANT, plant_named

        return sim.plant.with_effects(()) if sim.plant is not None else plant_named(DEFAULT_PLANT)
    if request.params is None or request.params == "sim-truth":
        return None
    from benchlab.model.params import load_params
    from benchlab.network.plant import NetworkPlant

    params = load_params(request.params)
    model = params.definition
    unknown = sorted(model.law_channels() - set(ESTIMATE_CHANNELS))
    if "T_flywheel" not in model.outputs or unknown:
        raise InputError(request.params, "model", f"a clutch model that reads only {', '.join(ESTIMATE_CHANNELS)} "
                                                  f"and has a T_flywheel output, to time the sweep (model "
                                                  f"{model.label} reads {', '.join(unknown) or 'no T_flywheel'})")
    try:
        return NetworkPlant(params.network, params)
    except ValueError as exc:  # a switch with hysteresis
        raise InputError(request.params, "model", str(exc)) from None


def bench_config(request: RunRequest) -> BenchConfig:
    """The bench's configuration: the simulated bench's, or BENCH.toml checked field by field."""
    sim = simulated(request.bench)
    if sim is not None:
        return sim.bench_config()
    from benchlab.runner.config import load_bench_config

    return load_bench_config(request.bench)


def plan(request: RunRequest) -> tuple[tuple[Step, ...], BenchConfig, dict[str, Any]]:
    """Schedule and bench config, checked: InputError before anything moves."""
    config = bench_config(request)
    if request.steps is not None:
        protocol = catalog.Protocol(request.protocol, with_launch_estimates(request.steps, config.limits),
                                    request.options or {"custom": True})
    else:
        try:
            protocol = catalog.build(request.protocol, request.seed, request.cycles, request.duration_s, request.grid,
                                     config.limits, estimate_plant(request))
        except ValueError as exc:
            field = "--grid" if request.grid and "grid" in str(exc) else "protocol"
            raise InputError(request.protocol, field, str(exc)) from None
    if not request.dry_run:
        refuse_over_limits(protocol.steps, config.limits, request.protocol, "schedule")
    return protocol.steps, config, protocol.options


def refuse_over_limits(steps: Sequence[Step], limits: BenchLimits, source: "str | Path", where: str) -> None:
    """InputError naming `source`, the step and the field of the first limit problem; nothing if there is none.

    The one gate between a schedule and the bench: a new run's (`where` "schedule") and a resumed one's
    ("/schedule", read back from the run file) alike.
    """
    problems = schedule_problems(steps, limits)
    if problems:
        first = problems[0]
        field = f"{where} step {first.step} {first.field}" if first.step is not None else f"{where} {first.field}"
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise InputError(source, field, f"within the bench limits: {first.text}{more}")


def dry_run(request: RunRequest, out: Any = None) -> int:
    out = out or sys.stdout
    steps, config, options = plan(request)
    for line in describe(steps):
        print(line, file=out)
    problems = check_schedule(steps, config.limits)
    total = duration_s(steps)
    cycles = len({s.cycle for s in steps})
    for note in options.get("dropped", []):
        print(f"plan: {note}", file=out)
    print(f"protocol {request.protocol} on {bench_text(bench_name(request.bench), simulated=_simulated(request, config))}"
          f": {len(steps)} steps, {cycles} "
          f"cycles, estimated {total:.0f} s ({total / 3600:.2f} h)", file=out)
    if problems:
        for p in problems:
            print(f"limit: {p}", file=out)
        print(f"{len(problems)} problem(s) against the bench limits: the run would not start", file=out)
        return 2
    print("schedule within the bench limits", file=out)
    return 0


def can_log_path(run_path: Path, resumes: int = 0) -> Path:
    """The raw CAN log beside a run file: RUN.blf, and RUN.resumeN.blf for the N-th resume."""
    return run_path.with_suffix(f".resume{resumes}.blf" if resumes else ".blf")


def prime_real_time(simulated_devices: bool) -> None:
    """Compile (or load from numba's cache) every kernel the drivers' loop calls, and the emulators' where the
    bench has `sim://` devices, before the run's real clock starts (DriverBench primes them again: cache hits)."""
    prime_drivers()
    if simulated_devices:
        from sim_bench.emulators import can_controllers, sim_can_bus
        from sim_bench.emulators import clutch_node as node_emulator

        for module in (can_controllers, node_emulator, sim_can_bus):
            module.prime()


def open_bench(bench_choice: BenchChoice, config: BenchConfig, can_log: Path, t0: float, seed: int,
               initial_c: Any = None) -> "tuple[DriverBench, Clock, SimBench | None, BenchConfig]":
    """The drivers on the bench, with its clock: the hardware of BENCH.toml on real time, or the simulated bench
    (its emulators behind the same drivers, opened by the bench itself with `seed`) on simulated time.

    A BENCH.toml's `sim://` devices are emulated by one simulated plant on real time (sim_bench.mixed), closed
    with the bench. Returns (bench, clock, the simulated bench or None, the config with the simulated devices'
    addresses). Exit 2 for a CAN log that cannot be made or a device that does not open (the key to fix named).
    """
    sim = None
    spec = simulated(bench_choice)
    if spec is not None:
        sim, config = spec.open(config, seed, t0, initial_c)
    else:  # on the real clock, compiled before it starts: a cold cache's compile (15 s) is not run time lost
        prime_real_time(opening.has_simulated_devices(config))
    clock: Clock = sim.clock if sim is not None else RealClock(t0)
    devices = None
    if sim is None and opening.has_simulated_devices(config):
        from sim_bench.mixed import SimulatedDevices  # BENCH.toml's sim:// devices: one plant behind them

        devices = SimulatedDevices(config, clock, seed, t0, initial_c)
        config = devices.config
    try:
        if sim is not None:
            bench = DriverBench(config, clock, bus=sim.driver_bus, service=sim.service, can_log=can_log)
        elif devices is not None:
            bench = DriverBench(config, clock, bus=devices.bus, service=devices.service, can_log=can_log,
                                companion=devices)
        else:
            bench = DriverBench(config, clock, can_log=can_log)
    except Exception as exc:  # noqa: BLE001 - no bench: the simulated one is closed, one line
        for simulator in (sim, devices):
            if simulator is not None:
                simulator.close()
        if isinstance(exc, CanLogError):  # the log's path follows the user's --out: exit 2
            raise InputError(can_log, "CAN log", f"a writable file beside the run file ({exc})") from None
        if isinstance(exc, InputError):  # a device that did not open: the key to fix named (opening.py), exit 2
            raise
        raise RuntimeError(f"cannot open the bench: {exc}") from exc  # anything else: exit 1
    return bench, clock, sim, config


def _restore_signals(previous: dict) -> None:
    """The signal handlers `execute` replaced, put back."""
    for sig, handler in previous.items():
        signal.signal(sig, handler)


def execute(request: RunRequest) -> tuple[int, RunSummary | None]:
    """Run (or resume) and return (exit code, summary)."""
    if request.dry_run:
        return dry_run(request), None
    resume_state: dict[str, Any] | None = None
    if request.resume:
        resume_state = _resume_state(request)
        steps = resume_state["steps"]
        options: dict[str, Any] = resume_state["options"]
        config = bench_config(request)
        refuse_over_limits(steps, config.limits, request.out, "/schedule")  # before anything is opened or moved
        request = replace(request, protocol=resume_state["protocol"], seed=resume_state["seed"])
    else:
        steps, config, options = plan(request)
    t0 = resume_state["t0"] if resume_state else 0.0
    seed = request.seed + (7919 * resume_state["resumes"] if resume_state else 0)
    can_log = can_log_path(request.out, resume_state["resumes"] if resume_state else 0)
    runner: Runner | None = None
    pending: list[tuple[str, int]] = []  # a signal that came before the runner existed

    def stop(signum: int, code: int) -> None:
        name = signal.Signals(signum).name
        if runner is None:
            pending.append((name, code))
        else:
            runner.request_stop(name, code)

    previous = {}
    if request.install_signals:  # before the bench opens (it makes the CAN log): a signal from then on ends the
        for sig, code in ((signal.SIGINT, 130), (signal.SIGTERM, 143)):  # run as aborted, its files whole
            previous[sig] = signal.signal(sig, lambda s, f, c=code: stop(s, c))
    simulated_text = _simulated(request, config)  # before open_bench gives the sim:// devices their addresses
    try:
        bench, clock, sim, config = open_bench(request.bench, config, can_log, t0, seed,
                                               resume_state["initial"] if resume_state else None)
    except BaseException:
        _restore_signals(previous)
        raise
    layout = bench.layout
    truth_units = sim.truth_units() if sim is not None else {}  # the simulated bench's /truth
    try:
        if resume_state:
            writer = RunWriter.resume(request.out, layout, extra_s=duration_s(steps[resume_state["start"]:]),
                                      flush_every_s=config.flush_every_s, truth_units=truth_units)
            writer.state["resumes"] = resume_state["resumes"]
            start = resume_state["start"]
            writer.event(t0, "resume", int(resume_state["cycle"]),
                         f"resume {resume_state['resumes']}: continuing with step {start}; CAN log {can_log.name}",
                         step=start if start < len(steps) else -1)
        else:
            attrs = {"seed": request.seed, "software_version": software_version(), "bench": bench_name(request.bench),
                     "bench_config": json.dumps(config.as_dict(), default=str),
                     "protocol_options": json.dumps(options, default=str),
                     "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"), "idn": bench.idn,
                     "can_log": can_log.name, "can_log_time_base": config.can_timestamps}
            if sim is not None:
                attrs.update(sim.run_attrs())
            if simulated_text:
                attrs["bench_simulated"] = simulated_text
            writer = RunWriter(request.out, layout, protocol=request.protocol, attrs=attrs,
                               schedule=[s.as_dict() for s in steps], schedule_units=SCHEDULE_UNITS,
                               planned_s=duration_s(steps), flush_every_s=config.flush_every_s,
                               state_fields=STATE_FIELDS, durable=sim is None, truth_units=truth_units)
            writer.state["resumes"] = 0
        if sim is not None:  # the plant's true states into /truth as they become final
            sim.record_truth_into(writer.put_truth)
        task = request.progress.task(f"{request.protocol} on the {'simulated ' if sim is not None else ''}bench",
                                     duration_s(steps), unit="s")
        runner = Runner(bench, clock, steps, writer, config.limits, tick_s=config.tick_s,
                        fast_tick_s=config.fast_tick_s, dt=config.dt, progress=task)
        runner.summary.bench = bench_text(bench_name(request.bench), simulated=simulated_text)
        for name, code in pending:
            runner.request_stop(name, code)
        try:
            summary = runner.run(resume_state["start"] if resume_state else 0)
        except Exception as exc:  # an unexpected failure: bench safe, file closed as aborted, then report it
            try:
                bench.safe_state(runner.safe)
                writer.event(clock(), "run_aborted", runner.cycle, f"failure: {type(exc).__name__}: {exc}",
                             step=runner.current_step)
                _close(writer, sim, "aborted")
            finally:
                raise
        finally:
            task.close()
        _close(writer, sim, summary.status)
        if runner.stop_request is not None and summary.status == "complete":  # a signal after the last step or
            writer.set_status("aborted")  # during the compaction: the run ends as it would have a moment earlier
            summary.status, summary.reason = "aborted", runner.stop_request
            summary.exit_code = runner.stop_code  # type: ignore[attr-defined]
    finally:
        _restore_signals(previous)
        bench.close()
        if sim is not None:
            sim.close()
        if not request.out.exists():  # stopped before the run file was made: no CAN log without its run
            can_log.unlink(missing_ok=True)
    code = 0 if summary.status == "complete" else getattr(summary, "exit_code", 1)
    return code, summary


def _close(writer: RunWriter, sim: "SimBench | None", status: str) -> None:
    """Close the run file with `status`, the simulated bench's true states not final yet handed to /truth first."""
    if sim is not None:
        sim.hand_over_truth()
    writer.close(status)


def _resume_state(request: RunRequest) -> dict[str, Any]:
    path = request.out
    if not path.exists():
        raise InputError(path, "file", "an existing run file to resume (not found)")
    stopped = load_stopped_run(path, ("T_flywheel", "T_air", "T_housing"))
    status = stopped.attrs.get("status", "")
    if status == "complete":
        raise InputError(path, "status", "a run that is not complete ('running' or 'aborted'), got 'complete'")
    bench, asked = stopped.attrs.get("bench", ""), bench_name(request.bench)
    if bench != asked:
        raise InputError(path, "bench", f"the same bench as the run ({bench!r}), got --bench {asked!r}")
    steps = stopped.steps()
    progress, rows, initial = stopped.progress, stopped.rows, stopped.last_valid
    cycle = progress.get("state/cycle", math.nan)
    cycle = -1 if not math.isfinite(cycle) else int(cycle)
    start = next((i for i, s in enumerate(steps) if s.cycle > cycle), len(steps))
    resumes = progress.get("state/resumes", 0.0)
    protocol = stopped.attrs.get("protocol", "None")
    options = json.loads(stopped.attrs.get("protocol_options", "{}"))
    seed = int(stopped.attrs.get("seed", request.seed))
    f_init = initial["T_flywheel"] if math.isfinite(initial["T_flywheel"]) else 22.0
    states = {"P": f_init, "F": f_init, "A": initial["T_air"] if math.isfinite(initial["T_air"]) else f_init,
              "T": initial["T_housing"] if math.isfinite(initial["T_housing"]) else f_init}
    return {"steps": steps, "start": start, "cycle": cycle, "t0": rows * stopped.dt, "initial": states,
            "resumes": int(resumes if math.isfinite(resumes) else 0) + 1, "protocol": protocol,
            "options": options, "seed": seed}
